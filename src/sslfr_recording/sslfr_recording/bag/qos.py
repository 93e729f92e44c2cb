"""QoS profiles as rosbag2 Jazzy stores them (metadata version 9).

A profile is a plain dict with the keys rosbag2_storage encodes (``qos.cpp``
``convert<rclcpp::QoS>::encode``, rule M10): ``history`` (``keep_last`` /
``keep_all`` / ``system_default``), ``depth``, ``reliability``, ``durability``,
``deadline``, ``lifespan``, ``liveliness``, ``liveliness_lease_duration`` (durations
as ``{sec, nsec}``) and ``avoid_ros_namespace_conventions``.

Where the list of a topic's offered profiles goes:

- ``metadata.yaml`` and the ``rosbag2`` MCAP record (version 9): a YAML sequence of
  those maps (:func:`to_yaml_list`);
- the MCAP channel metadata key ``offered_qos_profiles``: the YAML text of that
  sequence, ``[]`` when there is none (:func:`dump_profiles`).

Reading (:func:`decode_profiles`, :func:`load_profiles`) follows ``qos.cpp``
``convert<rclcpp::QoS>::decode``: a profile whose ``history`` is an integer 0..3 is
in the version-8 integer form, otherwise in the version-9 name form; names rmw does
not know decode to ``unknown`` (rule M11).
"""
from __future__ import annotations

from sslfr_common.timeconv import split_seconds

from . import yamlcpp

#: RMW_DURATION_INFINITE as {sec, nsec} (rmw/time.h: INT64_MAX ns).
INFINITE = {'sec': 9223372036, 'nsec': 854775807}
#: RMW_DURATION_UNSPECIFIED.
UNSPECIFIED = {'sec': 0, 'nsec': 0}

KEYS = ('history', 'depth', 'reliability', 'durability', 'deadline', 'lifespan',
        'liveliness', 'liveliness_lease_duration', 'avoid_ros_namespace_conventions')

#: Names rmw's ``*_from_str`` accept, per policy (rmw qos_string_conversions.c).
NAMES = {
    'history': ('system_default', 'keep_last', 'keep_all'),
    'reliability': ('system_default', 'reliable', 'best_effort', 'best_available'),
    'durability': ('system_default', 'transient_local', 'volatile', 'best_available'),
    'liveliness': ('system_default', 'automatic', 'manual_by_topic', 'best_available'),
}

#: Version-8 integer form (rmw enum values) -> name.
V8_NAMES = {
    'history': {0: 'system_default', 1: 'keep_last', 2: 'keep_all', 3: 'unknown'},
    'reliability': {0: 'system_default', 1: 'reliable', 2: 'best_effort', 3: 'unknown',
                    4: 'best_available'},
    'durability': {0: 'system_default', 1: 'transient_local', 2: 'volatile', 3: 'unknown',
                   4: 'best_available'},
    'liveliness': {0: 'system_default', 1: 'automatic', 3: 'manual_by_topic', 4: 'unknown',
                   5: 'best_available'},
}

#: rosbag2's default offer (Rosbag2QoS(): rmw_qos_profile_default, depth 10).
DEFAULT_DEPTH = 10


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


def to_yaml_list(profiles: list[dict]) -> list[dict]:
    """The profiles as the ordered maps rosbag2 encodes (key order of ``qos.cpp`` encode)."""
    out = []
    for prof in profiles:
        item = {}
        for key in KEYS:
            value = prof[key]
            if isinstance(value, dict):
                value = {'sec': int(value['sec']), 'nsec': int(value['nsec'])}
            elif key == 'avoid_ros_namespace_conventions':
                value = bool(value)
            elif key == 'depth':
                value = int(value)
            else:
                value = str(value)
            item[key] = value
        out.append(item)
    return out


def dump_profiles(profiles: list[dict]) -> str:
    """The channel-metadata string: YAML of the sequence, ``[]`` when empty (``YAML::Dump``)."""
    return yamlcpp.dump(to_yaml_list(profiles))


def _time(node: yamlcpp.Node) -> dict:
    sec = node.get('sec').as_uint64()
    nsec = node.get('nsec').as_uint64()
    # Foxy-era "infinite" values are read as RMW_DURATION_INFINITE (qos.cpp 37-39, 141-147).
    if (sec, nsec) in ((9223372036, 854775807), (0x7FFFFFFF, 0xFFFFFFFF), (0x7FFFFFFF, 0x7FFFFFFF)):
        return dict(INFINITE)
    return {'sec': sec, 'nsec': nsec}


def decode_profile(node: yamlcpp.Node) -> dict:
    """One QoS map -> profile dict, with rosbag2's checks (raises ``yamlcpp.Refused``)."""
    hist = node.get('history')
    prof = profile()
    if hist.is_int() and 0 <= hist.as_int() <= 3:  # version-8 integer form
        prof['history'] = V8_NAMES['history'][hist.as_int()]
        for key in ('reliability', 'durability', 'liveliness'):
            prof[key] = V8_NAMES[key].get(node.get(key).as_int(), 'unknown')
    else:
        name = hist.as_str()
        prof['history'] = name if name in NAMES['history'] else 'unknown'
        for key in ('reliability', 'durability', 'liveliness'):
            name = node.get(key).as_str()
            prof[key] = name if name in NAMES[key] else 'unknown'
    if prof['history'] == 'keep_last':
        prof['depth'] = node.get('depth').as_int()
    else:
        prof['depth'] = 0
    prof['deadline'] = _time(node.get('deadline'))
    prof['lifespan'] = _time(node.get('lifespan'))
    prof['liveliness_lease_duration'] = _time(node.get('liveliness_lease_duration'))
    prof['avoid_ros_namespace_conventions'] = node.get('avoid_ros_namespace_conventions').as_bool()
    return prof


def decode_profiles(node: yamlcpp.Node) -> list[dict]:
    """``decode_for_version<std::vector<rclcpp::QoS>>``: must be a sequence (rule M09)."""
    if node.kind == 'undefined':
        node.as_str()  # raises "required key is missing"
    if node.kind != 'seq':
        raise node.refuse(f'must be a YAML sequence of QoS maps, found a YAML {node.kind}', 'M09')
    return [decode_profile(item.with_rule('M10')) for item in node.elements()]


def load_profiles(text: str, where: str = 'offered_qos_profiles') -> list[dict]:
    """Parse an ``offered_qos_profiles`` string (``to_rclcpp_qos_vector``): '' -> [].

    Raises
    ------
    yamlcpp.Refused
        When rosbag2 would throw on it (a ValueError).
    """
    if text == '':
        return []
    return decode_profiles(yamlcpp.Node.load(text, where, 'M09'))


def unknown_policies(profiles: list[dict]) -> list[str]:
    """``policy=value`` of every policy that decoded to ``unknown`` (rule M11).

    History is left out: DDS does not tell a subscriber the publisher's history, so
    rosbag2 itself records ``unknown`` there (qos.cpp 50-51) and playback replaces it
    by keep_last (``adapt_offer_to_recorded_offers``, qos.cpp 419-421).
    """
    return [f'{k}={p[k]}' for p in profiles for k in NAMES
            if k != 'history' and p[k] == 'unknown']


def duration_dict(seconds: float | None) -> dict:
    """{sec, nsec} of a duration [s]; None or >= INT64_MAX ns -> INFINITE."""
    if seconds is None or seconds >= 9223372036.854775807:
        return dict(INFINITE)
    sec, nsec = split_seconds(seconds)
    return {'sec': sec, 'nsec': nsec}
