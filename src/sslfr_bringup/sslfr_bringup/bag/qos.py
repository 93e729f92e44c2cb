"""QoS profiles as rosbag2 stores them (metadata version 9).

A profile is a plain dict with the keys rosbag2_storage writes (``qos.cpp``):
``history`` (``keep_last``/``keep_all``/``system_default``), ``depth``,
``reliability`` (``reliable``/``best_effort``/...), ``durability``
(``volatile``/``transient_local``/...), ``deadline``, ``lifespan`` and
``liveliness_lease_duration`` as ``{sec, nsec}``, ``liveliness``
(``automatic``/``manual_by_topic``/...), ``avoid_ros_namespace_conventions``.
The list of offered profiles of a topic is serialised to a YAML string (block style,
as yaml-cpp emits it); that string goes both into the MCAP channel metadata key
``offered_qos_profiles`` and into ``metadata.yaml``.
"""
from __future__ import annotations

import yaml

#: RMW_DURATION_INFINITE as {sec, nsec} (rmw/time.h: INT64_MAX ns).
INFINITE = {'sec': 9223372036, 'nsec': 854775807}
#: RMW_DURATION_UNSPECIFIED.
UNSPECIFIED = {'sec': 0, 'nsec': 0}

_KEYS = ('history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan',
         'liveliness', 'liveliness_lease_duration', 'avoid_ros_namespace_conventions')


def profile(reliability: str = 'reliable', durability: str = 'volatile', depth: int = 10,
            history: str = 'keep_last') -> dict:
    """A QoS profile dict with default deadline/lifespan/liveliness (rmw defaults).

    Parameters
    ----------
    reliability : {'reliable', 'best_effort'}
    durability : {'volatile', 'transient_local'}
    depth : int
        History depth [messages].
    history : {'keep_last', 'keep_all'}
    """
    return {'history': history, 'depth': int(depth), 'reliability': reliability,
            'durability': durability, 'deadline': dict(UNSPECIFIED), 'lifespan': dict(UNSPECIFIED),
            'liveliness': 'automatic', 'liveliness_lease_duration': dict(UNSPECIFIED),
            'avoid_ros_namespace_conventions': False}


def dump_profiles(profiles: list[dict]) -> str:
    """Serialise offered profiles as rosbag2 v9 does (a YAML block sequence string)."""
    if not profiles:
        return ''
    lines = []
    for prof in profiles:
        first = True
        for key in _KEYS:
            value = prof[key]
            lead = '- ' if first else '  '
            first = False
            if isinstance(value, dict):
                lines.append(f'{lead}{key}:')
                lines.append(f'    sec: {int(value["sec"])}')
                lines.append(f'    nsec: {int(value["nsec"])}')
            elif isinstance(value, bool):
                lines.append(f'{lead}{key}: {"true" if value else "false"}')
            else:
                lines.append(f'{lead}{key}: {value}')
    return '\n'.join(lines)


_V8_NAMES = {
    'history': {0: 'system_default', 1: 'keep_last', 2: 'keep_all', 3: 'unknown'},
    'reliability': {0: 'system_default', 1: 'reliable', 2: 'best_effort', 3: 'unknown',
                    4: 'best_available'},
    'durability': {0: 'system_default', 1: 'transient_local', 2: 'volatile', 3: 'unknown',
                   4: 'best_available'},
    'liveliness': {0: 'system_default', 1: 'automatic', 3: 'manual_by_topic', 4: 'unknown',
                   5: 'best_available'},
}


def load_profiles(text: str) -> list[dict]:
    """Parse an ``offered_qos_profiles`` string (v9 names or v8 integers) to dicts."""
    if not text or not text.strip():
        return []
    data = yaml.safe_load(text)
    if not isinstance(data, list):
        raise ValueError('offered_qos_profiles is not a YAML sequence')
    out = []
    for item in data:
        prof = profile()
        for key in _KEYS:
            if key in item:
                value = item[key]
                if key in _V8_NAMES and isinstance(value, int):
                    value = _V8_NAMES[key].get(value, 'unknown')
                prof[key] = value
        out.append(prof)
    return out


def duration_dict(seconds: float | None) -> dict:
    """{sec, nsec} of a duration [s]; None or >= INT64_MAX ns -> INFINITE."""
    if seconds is None or seconds >= 9223372036.854775807:
        return dict(INFINITE)
    ns = int(round(seconds * 1e9))
    return {'sec': ns // 1_000_000_000, 'nsec': ns % 1_000_000_000}


def safe_yaml_dump(data) -> str:
    """YAML block dump with insertion order kept (for metadata.yaml)."""
    return yaml.safe_dump(data, default_flow_style=False, sort_keys=False, allow_unicode=True,
                          width=4096)
