"""The safety supervisor's rules, as data (pure Python, no rclpy).

Modelled on PX4's failsafe framework: every rule is one :class:`Rule` entry naming
its condition, its level, how it clears, its reason texts and how an operator clears
it; :class:`~sslfr_safety.core.SafetyCore` holds the facts (what the inputs
said, when) and runs ONE generic evaluation over :data:`RULES`. Adding a rule is one
entry here (plus, for a rule raised by an input, the line of the event handler that
raises it) and its test.

How a rule clears (:class:`Clear`)
    ``SELF``: active exactly while its condition holds; judged at every verdict,
    read-only (watchdogs, site, time, an axis whose driver is not ready).
    ``RECOVERY``: raised once, then held until its blocker is gone, when it clears by
    itself; ``safety/reset`` does not touch it (thermocouple faults).
    ``RESET``: latched until ``safety/reset``, which is refused while any latched
    fault's blocker says why (over-temperature, switch trips, stuck switches, a
    released e-stop). ``RESET_OR_RECOVERY``: both (over-temperature with
    ``temperature.auto_reset``). ``RELEASE``: the e-stop, cleared only by
    ``safety/estop`` false (its blocker refuses every reset meanwhile).
    ``Rule.option`` names a :class:`SafetyConfig` flag that changes the clearing.

Reasons are ``str.format`` templates, one per variant of the rule; the texts are the
``safety/state`` reasons, so :func:`hint_for` finds the rule of any published reason
(the operator page takes its hints from here).
"""
from __future__ import annotations

import enum
import math
import re
import string
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

from sslfr_common.contract import (IDLE_DRIVER_STATES, JOINTS, SWITCH_AXIS, THERMOCOUPLES, WIND, Level,
                                   LinkState, driver_node)


class Clear(enum.Enum):
    """How a rule's fault goes away (see the module docstring)."""

    SELF = 'self-clearing'
    RECOVERY = 'held until recovered'
    RESET = 'latched until reset'
    RESET_OR_RECOVERY = 'latched until reset or recovered'
    RELEASE = 'latched until released'


#: Clearings that keep a fault until safety/reset (or the e-stop release).
LATCHED = (Clear.RESET, Clear.RESET_OR_RECOVERY, Clear.RELEASE)
#: Clearings under which a fault goes away by itself once its blocker is gone.
RECOVERS = (Clear.RECOVERY, Clear.RESET_OR_RECOVERY)


@dataclass(frozen=True)
class Fault:
    """A raised (stored) fault of a non-SELF rule: first reason kept until it clears.

    ``since`` is the steady time [s] it was raised.
    """

    kind: str
    name: str
    variant: str
    reason: str
    since: float

    @property
    def key(self) -> str:
        return key_of(self.kind, self.name)


def key_of(kind: str, name: str) -> str:
    """``kind:name`` (``kind`` alone for rules without instances: estop, site, time)."""
    return f'{kind}:{name}' if name else kind


@dataclass(frozen=True)
class Rule:
    """One safety rule.

    Attributes
    ----------
    kind : str
        Key prefix of its conditions (``overtemp`` -> ``overtemp:<sensor>``).
    level : Level or callable ``(core, name) -> Level``
        Severity (the watchdogs' comes from their table).
    clears : Clear
        How it clears; ``option = (flag, clear)``: ``clear`` instead when the
        :class:`SafetyConfig` attribute ``flag`` is true.
    reasons : dict variant -> template
        Reason texts (``str.format`` templates over the fields the rule gives).
    hint : str
        How an operator clears it (shown by the operator page).
    names : callable ``core -> iterable of str``
        The instances judged (sensors, watched nodes, axes); ``('',)`` for one.
    condition : callable ``(core, name, now) -> (variant, fields) or None``
        READ-ONLY. SELF rules: active while it returns a hit. Stored rules: a hit
        raises the fault (judged when time passes); None: raised by an event only.
    blocker : callable ``(core, fault, now) -> str or None``
        Why the fault cannot clear now (None: it can).
    stops : callable ``name -> axes``
        Axes an ESTOP rule stops (``stopped_axes``).
    stow_others : bool
        The axes it does not stop go to their safe position (``stow_required``).
    on_reset : callable ``(core, name)``
        What a successful ``safety/reset`` of this fault also does.
    held_note : str
        Said by a refused reset about a fault that clears by itself.
    """

    kind: str
    level: Level | Callable[[Any, str], Level]
    clears: Clear
    reasons: dict[str, str]
    hint: str
    names: Callable[[Any], Iterable[str]] = lambda core: ('',)
    condition: Callable[[Any, str, float], tuple[str, dict] | None] | None = None
    blocker: Callable[[Any, Fault, float], str | None] | None = None
    stops: Callable[[str], tuple[str, ...]] = lambda name: ()
    stow_others: bool = False
    option: tuple[str, Clear] | None = None
    on_reset: Callable[[Any, str], None] | None = None
    held_note: str = ''
    _patterns: tuple = field(default=(), compare=False, repr=False)

    def __post_init__(self):
        pats = tuple(re.compile(_pattern(t), re.DOTALL) for t in self.reasons.values())
        object.__setattr__(self, '_patterns', pats)

    def clearing(self, config) -> Clear:
        """How it clears under ``config`` (a SafetyConfig)."""
        if self.option is not None and getattr(config, self.option[0]):
            return self.option[1]
        return self.clears

    def level_of(self, core, name: str) -> Level:
        return self.level(core, name) if callable(self.level) else self.level

    def text(self, variant: str, fields: dict) -> str:
        """The reason of ``variant`` with ``fields``."""
        return self.reasons[variant].format(**fields)

    def matches(self, reason: str) -> bool:
        """True when ``reason`` is one of this rule's texts."""
        return any(p.fullmatch(reason) for p in self._patterns)


def _pattern(template: str) -> str:
    """Regular expression of a ``str.format`` template: literals exact, fields any text."""
    out = []
    for literal, name, _spec, _conv in string.Formatter().parse(template):
        out.append(re.escape(literal))
        if name is not None:
            out.append('.*?')
    return ''.join(out)


# ------------------------------------------------------------------ conditions (read-only)
def _thermocouple_detect(core, name: str, now: float):
    """Silent > ``silent_timeout`` while TRACKING; stuck (no change > tolerance) for
    > ``stuck_timeout`` while the sun is on the receiver (``core.sun_on_since``)."""
    cfg, st = core.config, core.sensors[name]
    if core.tracking_since is not None:
        ref = max(st.arrival if st.arrival is not None else -math.inf, core.tracking_since)
        if now - ref > cfg.silent_timeout:
            return 'silent', {'sensor': name, 'timeout': cfg.silent_timeout}
    if core.sun_on_since is not None and st.valid and st.last_change is not None:
        if now - max(st.last_change, core.sun_on_since) > cfg.stuck_timeout:
            return 'stuck', {'sensor': name, 'value': st.value, 'timeout': cfg.stuck_timeout}
    return None


def _watchdog(core, node: str, now: float):
    timeout, action = core.config.watchdogs[node]
    last = core.heard.get(node)
    ref = last if last is not None else core.start + core.config.startup_grace
    if now - ref > timeout:
        return ('silent' if last is not None else 'never_heard'), {'node': node, 'timeout': timeout}
    if last is None and action == 'STOW':
        # within the start-up grace: not an alarm yet, but a node the tracker needs
        # (the absorber's temperatures, a driver) is not known to work: no OK before it speaks
        return 'waiting', {'node': node}
    return None


def _no_site(core, _name: str, _now: float):
    if core.config.require_site_and_time and not core.gps_fix_seen \
            and core.site_source not in ('persisted', 'parameters'):
        return 'none', {}
    return None


def _no_time(core, _name: str, _now: float):
    cfg = core.config
    wall_ok = cfg.trust_system_clock and core.clock.wall() >= cfg.min_valid_unix_time
    if cfg.require_site_and_time and not core.gps_fix_seen and not wall_ok:
        return 'none', {}
    return None


def link_name(link_state: int) -> str:
    """'down', 'connecting', 'up', 'fault' for a LINK_* code."""
    try:
        return LinkState(link_state).name.removeprefix('LINK_').lower()
    except ValueError:
        return f'state {link_state}'


def _axis_not_ready(core, axis: str, _now: float):
    """The axis' driver has not reported yet (when it is watched), or said it is not
    active (a lifecycle label of IDLE_DRIVER_STATES), or its board link is not up, and
    has not reported active, link up and referenced since (``core.axes[axis].ready``,
    set by its status)."""
    ax = core.axes[axis]
    if ax.ready is None:
        # never reported: not known to be driving its axis. A watched driver keeps the
        # tracker stowed until its first ready report (no OK while drivers start); an
        # unwatched one (a test bench with fewer axes) is not judged.
        return ('unreported', {'axis': axis}) if driver_node(axis) in core.config.watchdogs else None
    if ax.ready is not False:
        return None
    if ax.driver_state in IDLE_DRIVER_STATES:
        return 'idle', {'axis': axis, 'state': ax.driver_state}
    if ax.link_state != LinkState.LINK_UP:
        return 'link', {'axis': axis, 'link': link_name(ax.link_state)}
    return 'unreferenced', {'axis': axis, 'state': ax.driver_state}


def _wind_silent(core, _name: str, now: float):
    """A fitted anemometer silent (or never heard after the start-up grace) for more
    than ``wind_silent_stow``: the wind is unknown, treated as wind."""
    cfg = core.config
    if not cfg.wind_enabled or not cfg.wind_silent_stow:
        return None
    ref = core.wind.arrival if core.wind.arrival is not None else core.start + cfg.startup_grace
    if now - ref > cfg.wind_silent_stow:
        return 'silent', {'timeout': cfg.wind_silent_stow}
    return None


def _anemometer(core, _name: str, now: float):
    """WARN: a fitted anemometer silent for > ``wind_silent_warn`` (never heard: after
    the start-up grace), or reading 0 m/s for the whole ``wind_stuck_window`` while the
    beam irradiance swung by >= ``wind_stuck_beam_swing`` (clouds moving over the
    collector: there is wind aloft, stuck cups or a broken wire read calm)."""
    cfg, w = core.config, core.wind
    if not cfg.wind_enabled:
        return None
    if w.arrival is None:
        if now - core.start > cfg.startup_grace + cfg.wind_silent_warn:
            return 'never_heard', {'timeout': cfg.startup_grace + cfg.wind_silent_warn}
        return None
    if now - w.arrival > cfg.wind_silent_warn:
        return 'silent', {'age': now - w.arrival}
    if w.zero_since is not None and now - w.zero_since >= cfg.wind_stuck_window:
        beams = [b for t, b in w.beams if t >= now - cfg.wind_stuck_window]
        if beams and max(beams) - min(beams) >= cfg.wind_stuck_beam_swing:
            return 'stuck', {'window': cfg.wind_stuck_window, 'swing': max(beams) - min(beams)}
    return None


# ------------------------------------------------------------------ blockers
def _wind_blocker(core, _fault: Fault, now: float) -> str | None:
    """Why a wind stow cannot release yet: the anemometer must be fresh (steady
    ``now``) and the mean below ``wind_mean_limit - wind_hysteresis`` for ``wind_hold``
    [s of ROS time, between the samples' stamps]."""
    cfg, w = core.config, core.wind
    if w.arrival is None or now - w.arrival > cfg.wind_silent_warn:
        return 'anemometer silent: the wind is unknown'
    threshold = cfg.wind_mean_limit - cfg.wind_hysteresis
    if w.calm_since is None:
        return f'wind mean {w.mean:.1f} m/s, must stay < {threshold:.1f} m/s for {cfg.wind_hold:.0f} s'
    held = w.stamp - w.calm_since
    if held < cfg.wind_hold:
        return f'wind mean below {threshold:.1f} m/s for {held:.0f} s of {cfg.wind_hold:.0f} s'
    return None


def _overtemp_blocker(core, fault: Fault, now: float) -> str | None:
    cfg, name = core.config, fault.name
    st = core.sensors[name]
    if st.arrival is None or now - st.arrival > cfg.silent_timeout or not st.valid:
        return f'{name}: no fresh valid reading to confirm it cooled'
    threshold = cfg.temperature_limit - cfg.hysteresis
    if st.cool_since is None:
        return f'{name} still hot: {st.value:.1f} degC, must be < {threshold:.1f} degC'
    held = now - st.cool_since
    if held < cfg.cool_hold:
        return f'{name} cooling: below {threshold:.1f} degC for {held:.1f} s of {cfg.cool_hold:.1f} s'
    return None


def _sensor_blocker(core, fault: Fault, now: float) -> str | None:
    """Why the thermocouple has not recovered: fresh valid samples for
    ``sensor_recover_hold`` and, for *stuck*, a change since the fault."""
    cfg, name = core.config, fault.name
    st = core.sensors[name]
    if st.arrival is None or now - st.arrival > cfg.silent_timeout:
        return f'{name} thermocouple still silent'
    if not st.valid or st.valid_since is None:
        return f'{name} thermocouple still invalid'
    if now - st.valid_since < cfg.sensor_recover_hold:
        return (f'{name} thermocouple valid for {now - st.valid_since:.1f} s of '
                f'{cfg.sensor_recover_hold:.1f} s')
    if fault.variant == 'stuck' and not (st.last_change is not None and st.last_change > fault.since):
        return f'{name} thermocouple still stuck at {st.value:.2f} degC'
    return None


def _stuck_switch_blocker(core, fault: Fault, _now: float) -> str | None:
    return f'limit switch {fault.name} still reads closed' if core.switch_closed[fault.name] else None


def _estop_blocker(_core, _fault: Fault, _now: float) -> str:
    return 'e-stop engaged: release it first with safety/estop false'


def _acknowledge_switch(core, name: str) -> None:
    """A reset acknowledges a trip while the switch is still closed (jog it off); it
    re-arms when the switch opens."""
    if core.switch_closed.get(name):
        core.switch_ack.add(name)


# ------------------------------------------------------------------ the table
#: The wind stow's rule key: named after the topic it judges.
WIND_RULE = WIND.name

RULES: tuple[Rule, ...] = (
    # A valid sample above ``temperature_limit`` [degC] trips at once (raised by
    # SafetyCore.on_temperature, which the node calls in the subscription callback).
    # Reset once the sensor is fresh and below limit - ``hysteresis`` for ``cool_hold``.
    Rule('overtemp', Level.STOW, Clear.RESET,
         {'hot': '{sensor} over-temperature: {value:.1f} degC > {limit:.1f} degC (latched until reset)'},
         'Wait until the absorber has cooled below the limit minus the hysteresis for the hold time '
         '(stowed mirrors defocus it), then press Safety reset.',
         names=lambda core: THERMOCOUPLES, blocker=_overtemp_blocker,
         option=('auto_reset', Clear.RESET_OR_RECOVERY)),
    # Open circuit / NaN / out of the physical range: raised by on_temperature at once;
    # stuck and silent: the condition. Held until the sensor has recovered, whatever the
    # phase does meanwhile: the stow it causes cannot clear it (no stow/track oscillation).
    Rule('thermocouple', Level.STOW, Clear.RECOVERY,
         {'invalid': '{sensor} thermocouple invalid ({what}): temperature not watched',
          'silent': '{sensor} thermocouple silent > {timeout:.1f} s while tracking: temperature not watched',
          'stuck': '{sensor} thermocouple stuck at {value:.2f} degC for > {timeout:.0f} s '
                   'with the sun on the receiver'},
         'Check the thermocouple and its wiring at the absorber board; it clears by itself once '
         'readings are valid again for the hold time (Safety reset if latched).',
         names=lambda core: THERMOCOUPLES, condition=_thermocouple_detect, blocker=_sensor_blocker,
         option=('sensor_fault_latched', Clear.RESET),
         held_note='clears by itself once the sensor has recovered'),
    # A switch closing while its axis is not homing and its nominal angle
    # (``switch_positions``) is off the axis' path: outside the span of the angles
    # measured over the last ``switch_lookback`` [s] and the commanded angle, +/-
    # ``switch_window`` [rad], plus the axis' stow position when a verdict of the core
    # stowed it within the look-back (a fast axis reaches its stow switch before its next
    # 5 Hz status). The seed's switches are references the mechanism reaches or passes in
    # normal operation, hence the path test. Raised by SafetyCore._judge_closure; with
    # the position unknown (no board) judged once a position is known.
    Rule('switch', Level.ESTOP, Clear.RESET,
         {'trip': 'limit switch {switch} tripped outside homing ({axis} at {measured:.3f} rad, '
                  'commanded {commanded:.3f} rad, switch at {nominal:.3f} rad): {axis} stopped'},
         'Check the axis and the switch on site; once the switch reads open press Safety reset, '
         'then home the axis.',
         stops=lambda name: (SWITCH_AXIS[name],), stow_others=True, on_reset=_acknowledge_switch),
    # At homing: the switch stays closed while the axis travels more than
    # ``stuck_switch_travel`` [rad], or two switches of one axis read closed together.
    Rule('stuck_switch', Level.ESTOP, Clear.RESET,
         {'travel': 'limit switch {switch} stuck closed (closed over {travel:.3f} rad of {axis} homing '
                    'travel): {axis} stopped',
          'together': 'limit switch {switch} stuck closed ({closed} closed together during {axis} '
                      'homing): {axis} stopped'},
         'Free or repair the stuck limit switch (it must read open), then press Safety reset and '
         'home the axis.',
         blocker=_stuck_switch_blocker, stops=lambda name: (SWITCH_AXIS[name],), stow_others=True),
    # ``safety/estop`` true; its release leaves ``post_estop`` until a reset, so a released
    # e-stop never resumes tracking by itself.
    Rule('estop', Level.ESTOP, Clear.RELEASE,
         {'engaged': 'operator e-stop (safety/estop): every axis stopped'},
         'Release the e-stop, then press Safety reset once the cause is gone.',
         blocker=_estop_blocker, stops=lambda name: JOINTS),
    Rule('post_estop', Level.STOW, Clear.RESET,
         {'released': 'e-stop released: stowing until safety/reset'},
         'Press Safety reset: the tracker stays stowed until then.'),
    # Per the ``watchdogs`` table (node -> (timeout [s], action)), from the arrival times
    # of the node's topics; a node never heard is judged from start-up + ``startup_grace``.
    Rule('watchdog', lambda core, node: Level[core.config.watchdogs[node][1]], Clear.SELF,
         {'waiting': '{node} not heard yet (start-up)',
          'silent': '{node} silent > {timeout:.1f} s (heartbeat watchdog)',
          'never_heard': '{node} never heard > {timeout:.1f} s (heartbeat watchdog)'},
         'That node is not publishing: check that it runs (./sslfr up restarts it) and its board '
         'link; clears by itself when it is heard again.',
         names=lambda core: core.config.watchdogs, condition=_watchdog),
    # With ``wind_enabled``: a 3 s gust above ``wind_gust_limit`` or a mean above
    # ``wind_mean_limit`` [m/s] (raised by SafetyCore.on_wind in the ``wind`` callback), or
    # the anemometer silent for ``wind_silent_stow`` [s] (wind unknown is treated as wind;
    # steady clock). Held until the anemometer is fresh and the mean has stayed below
    # ``wind_mean_limit - wind_hysteresis`` for ``wind_hold`` [s] of ROS time (the samples'
    # stamps); every gust or mean above its limit restarts the hold. While only wind rules
    # stow, Verdict.wind_stow says so (the axes go face-up, not to the sleeping position);
    # Verdict.wind_release_in is the time left [s].
    Rule(WIND_RULE, Level.STOW, Clear.RECOVERY,
         {'gust': 'wind gust {gust:.1f} m/s > {limit:.1f} m/s (3 s mean): wind stow',
          'mean': 'wind mean {mean:.1f} m/s > {limit:.1f} m/s ({window:.0f} s mean): wind stow',
          'silent': 'anemometer silent > {timeout:.0f} s: wind unknown, wind stow'},
         'Wait: the tracker releases by itself once the mean wind has stayed below the limit minus '
         'the hysteresis for the hold time (the page shows the time left); a silent anemometer '
         'must be repaired first.',
         condition=_wind_silent, blocker=_wind_blocker,
         held_note='clears by itself once the wind has stayed calm for the hold time'),
    # A fitted anemometer silent > ``wind_silent_warn`` [s] (steady clock), or at 0 m/s for
    # ``wind_stuck_window`` while the beam irradiance swung by ``wind_stuck_beam_swing``
    # (moving clouds, yet a calm anemometer).
    Rule('anemometer', Level.WARN, Clear.SELF,
         {'silent': 'anemometer silent for {age:.0f} s: wind not watched',
          'never_heard': 'anemometer never heard > {timeout:.0f} s: wind not watched',
          'stuck': 'anemometer at 0 m/s for {window:.0f} s while the beam irradiance swung by '
                   '{swing:.0f} W/m^2 (moving clouds): stuck cups or a broken wire?'},
         'Check the anemometer, its cable and the absorber board input (anemometer_pin); a stuck '
         'anemometer means the wind stow cannot work.',
         condition=_anemometer),
    # No GPS fix since boot and no persisted (or configured) site reported by the planner.
    Rule('site', Level.STOW, Clear.SELF,
         {'none': 'no site: no GPS fix since boot and no persisted site from the planner: '
                  'staying in the sleeping position'},
         'Wait for a GPS fix, or set site.latitude_deg / site.longitude_deg in the site config.',
         condition=_no_site),
    # No GPS fix and an implausible (or, with ``trust_system_clock`` false, any) system clock.
    Rule('time', Level.STOW, Clear.SELF,
         {'none': 'no time: no GPS fix since boot and no trusted system clock: staying in the '
                  'sleeping position'},
         'Wait for a GPS fix (a trusted time); check the GPS antenna.',
         condition=_no_time),
    # The condition (_axis_not_ready); after a silence > ``status_max_age`` the first
    # report must show the axis ready again (a restarted driver still homing is not).
    # An active driver re-homing with its link up is no fault; its silence is the
    # watchdog rule's.
    Rule('axis', Level.STOW, Clear.SELF,
         {'unreported': '{axis} axis not ready: no status from its driver yet',
          'idle': '{axis} axis not ready: its driver is {state}, not active',
          'link': '{axis} axis not ready: board link {link}',
          'unreferenced': '{axis} axis not ready: driver active, axis not referenced yet (state {state})'},
         'That axis driver is not driving its axis: check that it runs and is active (its '
         'diagnostics give the reason) and its board link; clears by itself once the driver is '
         'active and the axis homed.',
         names=lambda core: core.config.joints, condition=_axis_not_ready),
)


def rule_for(reason: str) -> Rule | None:
    """The rule whose reason texts include ``reason`` (None: no rule says that)."""
    for rule in RULES:
        if rule.matches(reason):
            return rule
    return None


def hint_for(reason: str) -> str:
    """How an operator clears ``reason`` (a ``safety/state`` reason); '' if unknown."""
    rule = rule_for(reason)
    return rule.hint if rule is not None else ''
