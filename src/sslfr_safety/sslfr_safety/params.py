"""The ``safety`` node's parameters: ONE table (pure Python, no rclpy).

:data:`TABLE` (a :class:`sslfr_common.params.ParamTable`) is declared by the node
(``sslfr_common.node.declare_parameters``: description, unit, range), checked at
start-up (an invalid value: exit 2, one line) and on every run-time change
(``ParameterGuard``: refused with the reason, the last good configuration stays), and
usable by the CLI to check a site config's ``safety`` section without ROS. Its cross
check is :func:`config_from`: the values must make a valid :class:`SafetyConfig`.
"""
from __future__ import annotations

from typing import Any

from sslfr_common.contract import SWITCHES
from sslfr_common.params import ParamSpec, ParamTable
from sslfr_safety.config import WATCHABLE, SafetyConfig

_D = SafetyConfig()


def _spec(name: str, default: Any, text: str, unit: str = '-', lo: float | None = None,
          hi: float | None = None) -> ParamSpec:
    return ParamSpec(name, default, f'{text} [{unit}]', unit, lo, hi)


def config_from(values: dict) -> SafetyConfig:
    """Build (and validate) a SafetyConfig from parameter values; raises ValueError."""
    nodes = list(values['watchdog.nodes'])
    timeouts = [float(t) for t in values['watchdog.timeouts']]
    actions = [str(a).upper() for a in values['watchdog.actions']]
    if not (len(nodes) == len(timeouts) == len(actions)):
        raise ValueError(f'watchdog.nodes/timeouts/actions lengths differ: '
                         f'{len(nodes)}/{len(timeouts)}/{len(actions)}')
    if len(set(nodes)) != len(nodes):
        raise ValueError('watchdog.nodes lists a node twice')
    present = tuple(values['collector.nodes'])
    cfg = SafetyConfig(
        temperature_limit=values['temperature.limit'], hysteresis=values['temperature.hysteresis'],
        cool_hold=values['temperature.cool_hold'], auto_reset=values['temperature.auto_reset'],
        silent_timeout=values['temperature.silent_timeout'],
        sensor_recover_hold=values['temperature.sensor_recover_hold'],
        sensor_fault_latched=values['temperature.sensor_fault_latched'],
        stuck_timeout=values['temperature.stuck_timeout'],
        stuck_tolerance=values['temperature.stuck_tolerance'],
        stuck_min_beam=values['temperature.stuck_min_beam'],
        valid_min=values['temperature.valid_min'], valid_max=values['temperature.valid_max'],
        switch_window=values['switches.window'], switch_lookback=values['switches.lookback'],
        stuck_switch_travel=values['switches.stuck_travel'],
        switch_positions={s: values[f'switches.position.{s}'] for s in SWITCHES},
        status_max_age=values['axis_status_max_age'], beam_max_age=values['beam_max_age'],
        startup_grace=values['watchdog.startup_grace'],
        require_site_and_time=values['require_site_and_time'],
        trust_system_clock=values['trust_system_clock'],
        min_valid_unix_time=values['min_valid_unix_time'],
        wind_enabled=values['wind.enabled'], wind_gust_limit=values['wind.gust_limit'],
        wind_mean_limit=values['wind.mean_limit'], wind_hysteresis=values['wind.hysteresis'],
        wind_hold=values['wind.hold'], wind_silent_warn=values['wind.silent_warn'],
        wind_silent_stow=values['wind.silent_stow'], wind_stuck_window=values['wind.stuck_window'],
        wind_stuck_beam_swing=values['wind.stuck_beam_swing'],
        present=present,
        # a node the collector lacks is not a fault: its watchdog is not armed
        watchdogs={n: (t, a) for n, t, a in zip(nodes, timeouts, actions) if n in present})
    cfg.validate()
    return cfg


def _config_errors(values: dict) -> list[str]:
    try:
        config_from(values)
    except (ValueError, TypeError, KeyError) as exc:
        return [str(exc)]
    return []


TABLE = ParamTable((
    _spec('publish_rate', 20.0, 'safety/state publication rate (steady clock)', 'Hz', 10.0, 100.0),
    _spec('temperature.limit', _D.temperature_limit,
          'absorber over-temperature limit (seed 000 section 3.5.3: 150)', 'degC', 0.0, 1000.0),
    _spec('temperature.hysteresis', _D.hysteresis, 'must cool below limit - hysteresis before reset', 'K',
          0.0, 200.0),
    _spec('temperature.cool_hold', _D.cool_hold, 'time below limit - hysteresis before reset', 's', 0.0, 3600.0),
    _spec('temperature.auto_reset', False, 'clear temperature latches without safety/reset once cooled'),
    _spec('temperature.silent_timeout', _D.silent_timeout, 'thermocouple silent while tracking -> stow', 's',
          0.1, 60.0),
    _spec('temperature.sensor_recover_hold', _D.sensor_recover_hold,
          'valid samples this long clear a thermocouple fault', 's', 0.0, 600.0),
    _spec('temperature.sensor_fault_latched', False, 'thermocouple faults also need safety/reset'),
    _spec('temperature.stuck_timeout', _D.stuck_timeout, 'no change while the sun is on the receiver -> stuck',
          's', 1.0, 86400.0),
    _spec('temperature.stuck_tolerance', _D.stuck_tolerance, 'a change must exceed this', 'K', 0.0, 50.0),
    _spec('temperature.stuck_min_beam', _D.stuck_min_beam,
          'beam irradiance at which the sun counts as on the receiver', 'W/m^2', 0.0, 1500.0),
    _spec('temperature.valid_min', _D.valid_min, 'lowest plausible thermocouple reading', 'degC', -273.0, 2000.0),
    _spec('temperature.valid_max', _D.valid_max, 'highest plausible thermocouple reading', 'degC',
          -273.0, 2000.0),
    _spec('switches.window', _D.switch_window, 'a switch closed within this of its nominal angle is expected',
          'rad', 0.0, 1.0),
    _spec('switches.lookback', _D.switch_lookback,
          'measured angles of the last this many seconds make up the axis path', 's', 0.0, 10.0),
    _spec('switches.stuck_travel', _D.stuck_switch_travel, 'travel with a switch closed during homing -> stuck',
          'rad', 0.001, 3.2),
    *(_spec(f'switches.position.{s}', _D.switch_positions[s], f'nominal joint angle of the {s} switch', 'rad',
            -3.2, 3.2) for s in SWITCHES),
    _spec('axis_status_max_age', _D.status_max_age,
          'axis status older than this: position unknown; a driver silent this long must report ready again',
          's', 0.1, 60.0),
    _spec('beam_max_age', _D.beam_max_age, 'beam irradiance older than this: unknown', 's', 0.1, 600.0),
    _spec('wind.enabled', _D.wind_enabled, 'an anemometer is fitted (absorber_board anemometer_pin): '
          'judge the wind topic; false = no wind rules'),
    _spec('wind.gust_limit', _D.wind_gust_limit, 'wind stow when the 3 s gust passes this', 'm/s', 1.0, 80.0),
    _spec('wind.mean_limit', _D.wind_mean_limit, 'wind stow when the 10 min mean passes this', 'm/s', 1.0, 60.0),
    _spec('wind.hysteresis', _D.wind_hysteresis,
          'release only once the mean is below mean_limit - hysteresis ...', 'm/s', 0.0, 30.0),
    _spec('wind.hold', _D.wind_hold, '... and has stayed there this long', 's', 0.0, 86400.0),
    _spec('wind.silent_warn', _D.wind_silent_warn, 'no wind message for this long -> WARN', 's', 0.5, 3600.0),
    _spec('wind.silent_stow', _D.wind_silent_stow,
          'no wind message for this long -> treated as wind (stow); 0 = never', 's', 0.0, 86400.0),
    _spec('wind.stuck_window', _D.wind_stuck_window,
          'anemometer at 0 m/s all along this window while the beam swings -> WARN (stuck cups?)', 's',
          10.0, 86400.0),
    _spec('wind.stuck_beam_swing', _D.wind_stuck_beam_swing,
          'beam irradiance max - min over stuck_window that means moving clouds', 'W/m^2', 1.0, 1500.0),
    ParamSpec('collector.nodes', list(WATCHABLE), 'the watchable nodes this collector\'s node set runs '
              '(set by the node set from the collector description): the axes judged are those of the '
              'drivers listed, and the watchdog of a node not listed is not armed', read_only=True),
    _spec('watchdog.nodes', list(_D.watchdogs), 'watched nodes: ' + ', '.join(WATCHABLE)),
    _spec('watchdog.timeouts', [t for t, _ in _D.watchdogs.values()],
          'silence limit of each watched node, same order', 's'),
    _spec('watchdog.actions', [a for _, a in _D.watchdogs.values()], 'WARN or STOW for each watched node, same order'),
    _spec('watchdog.startup_grace', _D.startup_grace, 'time after start before never-heard nodes are silent', 's',
          0.0, 600.0),
    _spec('require_site_and_time', True, 'no GPS fix since boot and no persisted site / no time -> stow'),
    _spec('trust_system_clock', True, 'a system clock after min_valid_unix_time counts as time'),
    _spec('min_valid_unix_time', _D.min_valid_unix_time, 'earliest plausible system time', 's since 1970 UTC',
          0.0, 4.0e9),
), cross_check=_config_errors)
