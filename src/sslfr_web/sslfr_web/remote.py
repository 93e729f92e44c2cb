"""Facts the page takes from the other nodes' own parameters (pure Python).

The page shows the absorber against the safety node's ``temperature.limit``, draws
the collector with the planner's geometry and the collector description it names
(:mod:`.collector`), bounds a jog by each driver's ``max_jog``
and soft limits, judges each axis' accuracy with the driver's ``accuracy.*`` thresholds,
and lists the bags in the recorder's ``output_dir``. Rather than a
second copy of those values in the web node's configuration, it asks each node over
its standard ``<node>/get_parameters`` service (the node names of
config/nodeset.yaml; tested) and keeps the last answer.
"""
from __future__ import annotations

from typing import Any

from sslfr_common.contract import JOINTS
from sslfr_common.accuracy import PARAM_SPECS

ACCURACY_PARAMS = tuple(spec.name for spec in PARAM_SPECS)

#: node -> {parameter: key in LiveState.info}
REMOTE_PARAMS: dict[str, dict[str, str]] = {
    'safety': {'temperature.limit': 'temperature_limit', 'temperature.hysteresis': 'temperature_hysteresis',
               'temperature.cool_hold': 'temperature_cool_hold'},
    'planner': {'collector.n_per_side': 'n_per_side', 'collector.mirror_width': 'mirror_width',
                'collector.gap': 'gap', 'collector.receiver_height': 'receiver_height',
                'collector.central_mirror': 'central_mirror', 'collector.azimuth': 'collector_azimuth',
                'collector.description': 'collector_description'},
    'recorder': {'output_dir': 'bag_dir'},
    **{f'{axis}_driver': {'max_jog': f'{axis}.max_jog', 'lower_limit': f'{axis}.lower_limit',
                          'upper_limit': f'{axis}.upper_limit', 'jog_speed': f'{axis}.jog_speed',
                          **{name: f'{axis}.{name}' for name in ACCURACY_PARAMS}}
       for axis in JOINTS},
}

# rcl_interfaces/msg/ParameterType
_BOOL, _INT, _DOUBLE, _STRING, _DOUBLE_ARRAY = 1, 2, 3, 4, 8


def param_value(v) -> Any:
    """rcl_interfaces/ParameterValue -> Python value (a tuple for a double array; None
    when not set or another array type)."""
    t = int(getattr(v, 'type', 0))
    return {_BOOL: lambda: bool(v.bool_value), _INT: lambda: int(v.integer_value),
            _DOUBLE: lambda: float(v.double_value), _STRING: lambda: str(v.string_value),
            _DOUBLE_ARRAY: lambda: tuple(float(x) for x in v.double_array_value)}.get(t, lambda: None)()


def apply(node: str, names: list[str], values: list) -> dict[str, Any]:
    """The info entries of ``node``'s GetParameters answer (values in ``names`` order)."""
    keys = REMOTE_PARAMS[node]
    out = {}
    for name, v in zip(names, values):
        value = param_value(v)
        if value is not None:
            out[keys[name]] = value
    return out
