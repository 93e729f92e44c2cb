"""Safety supervisor: the pure core of the ``safety`` node (no rclpy).

Seed 000 section 3.5.3: above 150 degC at the absorber tube "the mirrors would move to
the sleeping position" (beta_0 = +pi/2: defocus). Around that rule the supervisor adds
what a trusted tracker does: thermocouple plausibility, limit switches outside homing,
heartbeat watchdogs, axes whose driver is not driving them, an operator e-stop and "no
site, no time -> sleep". The rules (condition, level, clearing, reason texts, operator
hint) are the table :data:`sslfr_safety.rules.RULES`, described there.

:class:`SafetyCore` keeps the facts and changes them only in its event handlers: the
inputs (``on_*``), :meth:`~SafetyCore.estop`, :meth:`~SafetyCore.reset` and the passing
of time (:meth:`~SafetyCore.on_time`). :meth:`SafetyCore.verdict` is the one read-only
evaluation over every rule. A refused request returns ``(False, reason)`` and changes
nothing.

Every timeout and hold time is measured on the steady clock (``clock.steady()``) from
the inputs' arrival times, never from header stamps; the wall clock only judges whether
the system time is plausible (``min_valid_unix_time``) and labels transitions. A
wall-clock or ROS-time step therefore neither fakes a timeout nor stalls a watchdog.
The exception is control logic that must follow the simulation's speed: the wind stow's
calm hold is measured in ROS time, from the ``wind`` samples' stamps (sim and replay run
it as a real day would); the anemometer's silence is a watchdog, on the steady clock.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import collections

from sslfr_common.contract import (IDLE_DRIVER_STATES, JOINTS, STOW_POSITION, SWITCH_AXIS, SWITCHES, THERMOCOUPLES,
                                   WIND_STOW_POSITION, Level, LinkState, Phase, driver_node)

from sslfr_safety.config import WATCHABLE, FakeClock, SafetyConfig, SystemClock, with_changes
from sslfr_safety.rules import LATCHED, RECOVERS, RULES, WIND_RULE, Clear, Fault, Rule, key_of, link_name

__all__ = ['WATCHABLE', 'FakeClock', 'SafetyConfig', 'SystemClock', 'with_changes', 'Condition',
           'Verdict', 'Transition', 'SafetyCore']


@dataclass(frozen=True)
class Condition:
    """One active rule instance: its level, the reason (naming the source), the axes it
    stops and whether the others stow."""

    key: str
    level: Level
    reason: str
    axes: tuple[str, ...] = ()
    stow_others: bool = False


@dataclass(frozen=True)
class Verdict:
    """The supervisor's verdict (maps 1:1 to sslfr_interfaces/SafetyState).

    ``since`` is the steady time [s] at which ``level`` was entered. ``wind_stow``: the
    stow is for wind only (every condition that stows is a wind rule): the axes go to
    their wind pose. ``wind_release_in`` [s]: time left before a wind stow may release
    (inf while the wind is not yet calm, NaN without a wind stow).
    """

    level: Level
    reasons: tuple[str, ...]
    stopped_axes: tuple[str, ...]
    stow_required: bool
    since: float
    wind_stow: bool = False
    wind_release_in: float = math.nan


@dataclass(frozen=True)
class Transition:
    """A change of the verdict, for the log and /diagnostics."""

    steady: float
    wall: float
    old_level: Level
    new_level: Level
    added: tuple[str, ...]
    removed: tuple[str, ...]

    def __str__(self) -> str:
        parts = [f'{self.old_level.name} -> {self.new_level.name}' if self.old_level != self.new_level
                 else f'{self.new_level.name} (reasons changed)']
        if self.added:
            parts.append('raised: ' + '; '.join(self.added))
        if self.removed:
            parts.append('cleared: ' + '; '.join(self.removed))
        return ' | '.join(parts)


@dataclass
class _Sensor:
    value: float | None = None        # last valid value [degC]
    arrival: float | None = None      # last sample arrival (valid or not) [steady s]
    valid: bool = False               # last sample valid
    last_change: float | None = None  # steady time the value last moved > tolerance
    ref_value: float | None = None    # value the change is measured from
    cool_since: float | None = None   # steady time it went below limit - hysteresis
    valid_since: float | None = None  # steady time of the first of the current valid run


@dataclass
class _Axis:
    arrival: float | None = None
    homing: bool = False
    measured: float | None = None
    commanded: float | None = None
    recent: list = field(default_factory=list)   # [(arrival, measured)] within switch_lookback
    #: switch -> (min, max) measured angle [rad] while homing with the switch continuously closed
    closed_travel: dict = field(default_factory=dict)
    # the driver's own report (lifecycle / link / reference)
    report_arrival: float | None = None
    driver_state: str = ''
    link_state: int = LinkState.LINK_DOWN
    ready: bool | None = None    # None: never reported; True: active, link up, referenced


@dataclass
class _Wind:
    arrival: float | None = None       # last wind message [steady s]
    speed: float = math.nan            # 3 s mean [m/s]
    gust: float = math.nan             # highest 3 s mean over the window [m/s]
    mean: float = math.nan             # window mean [m/s]
    stamp: float | None = None         # ROS time of the last wind message [s]
    calm_since: float | None = None    # ROS time [s] the mean went below limit - hysteresis
    exceeding: bool = False            # the last sample had a gust or a mean over its limit
    zero_since: float | None = None    # first of the current run of 0 m/s readings
    beams: collections.deque = field(default_factory=collections.deque)   # (t, beam) during it


class SafetyCore:
    """The facts and the generic rule machinery; see the module doc.

    Parameters
    ----------
    config : SafetyConfig
        Validated limits.
    clock : object with ``steady()`` and ``wall()`` [s]
        :class:`SystemClock` in the node, :class:`FakeClock` in tests. Event methods
        take an explicit ``arrival`` [steady s] or read ``clock.steady()``.
    rules : tuple of Rule
        The rule table (default :data:`~sslfr_safety.rules.RULES`).
    """

    def __init__(self, config: SafetyConfig | None = None, clock=None, rules: tuple[Rule, ...] = RULES):
        self.config = config or SafetyConfig()
        self.config.validate()
        self.clock = clock or SystemClock()
        self.rules: dict[str, Rule] = {r.kind: r for r in rules}
        self.start = self.clock.steady()
        self.sensors = {s: _Sensor() for s in THERMOCOUPLES}
        self.axes = {a: _Axis() for a in self.config.joints}
        self.switch_closed: dict[str, bool | None] = {s: None for s in SWITCHES}
        self.switch_ack: set[str] = set()        # acknowledged trips, re-armed when open
        self.pending_switches: set[str] = set()   # closed while the axis position was unknown
        self.stow_verdict_at: dict[str, float] = {}   # axis -> last verdict stowing it [steady s]
        self.stow_verdict_pose: dict[str, float] = {}  # axis -> where that verdict sent it [rad]
        self.wind = _Wind()
        self._notes: list[str] = []              # log lines of the wind hold (drain_notes)
        self.heard: dict[str, float] = {}        # node -> last arrival [steady s]
        self.phase: int | None = None
        self.tracking_since: float | None = None
        self.sun_on_since: float | None = None
        self.beam: float | None = None
        self.beam_arrival: float | None = None
        self.gps_fix_seen = False
        self.site_source = ''
        self.faults: dict[str, Fault] = {}       # raised faults of stored rules, by key
        self.counters = {'samples': 0, 'invalid_samples': 0, 'refused_requests': 0,
                         'transitions': 0, 'bad_inputs': 0}
        self._state = Verdict(Level.OK, (), (), False, self.start)
        self._pending: list[Transition] = []
        self.evaluate(self.start)

    # ----------------------------------------------------------------- helpers
    def _now(self, arrival: float | None) -> float:
        return self.clock.steady() if arrival is None else float(arrival)

    def _raise(self, kind: str, name: str, variant: str, fields: dict, now: float) -> None:
        """Raise the fault ``kind:name`` (a stored rule); the first reason is kept."""
        key = key_of(kind, name)
        if key not in self.faults:
            rule = self.rules[kind]
            self.faults[key] = Fault(kind, name, variant, rule.text(variant, fields), now)

    def _blocker(self, fault: Fault, now: float) -> str | None:
        rule = self.rules[fault.kind]
        return rule.blocker(self, fault, now) if rule.blocker is not None else None

    def configure(self, config: SafetyConfig) -> None:
        """Replace the limits (validated first; raises ValueError, keeping the old ones)."""
        config.validate()
        self.config = config

    def heartbeat(self, node: str, arrival: float | None = None) -> None:
        """A message from ``node`` (a :data:`WATCHABLE` name) arrived."""
        self.heard[node] = self._now(arrival)

    # ----------------------------------------------------------------- inputs
    def on_temperature(self, sensor: str, value: float, arrival: float | None = None,
                       open_circuit: bool = False) -> None:
        """A thermocouple sample [degC] (``sensor`` in THERMOCOUPLES).

        NaN, +/-inf, a value outside ``valid_min..valid_max`` or ``open_circuit``
        mark the thermocouple faulty (STOW). A valid value above
        ``temperature_limit`` latches over-temperature (seed 000 section 3.5.3).
        """
        now = self._now(arrival)
        st = self.sensors[sensor]
        cfg = self.config
        self.heartbeat('absorber_board', now)
        self.counters['samples'] += 1
        if st.arrival is None or now - st.arrival > cfg.silent_timeout:
            st.valid_since = None          # a gap: the valid run starts again
        st.arrival = now
        try:
            value = float(value)
        except (TypeError, ValueError):
            value = math.nan
        if open_circuit or not math.isfinite(value) or not (cfg.valid_min <= value <= cfg.valid_max):
            self.counters['invalid_samples'] += 1
            st.valid = False
            st.valid_since = None
            st.cool_since = None
            what = 'open circuit' if open_circuit else (
                'NaN' if math.isnan(value) else f'{value} degC outside {cfg.valid_min}..{cfg.valid_max} degC')
            self._raise('thermocouple', sensor, 'invalid', {'sensor': sensor, 'what': what}, now)
            return
        st.valid = True
        if st.valid_since is None:
            st.valid_since = now
        if st.ref_value is None or abs(value - st.ref_value) > cfg.stuck_tolerance:
            st.ref_value = value
            st.last_change = now
        st.value = value
        if value > cfg.temperature_limit:
            st.cool_since = None
            self._raise('overtemp', sensor, 'hot',
                        {'sensor': sensor, 'value': value, 'limit': cfg.temperature_limit}, now)
        elif value < cfg.temperature_limit - cfg.hysteresis:
            if st.cool_since is None:
                st.cool_since = now
        else:
            st.cool_since = None

    def on_limit_switches(self, states: dict, arrival: float | None = None) -> None:
        """Debounced switch states ``{name: closed}`` for the names in SWITCHES."""
        now = self._now(arrival)
        self.heartbeat('absorber_board', now)
        for name in SWITCHES:
            if SWITCH_AXIS[name] not in self.axes:    # the switches of a movement this collector lacks
                continue
            closed = bool(states[name])
            was = self.switch_closed[name]
            self.switch_closed[name] = closed
            if not closed:
                self.switch_ack.discard(name)
                self.pending_switches.discard(name)
            if closed and was is not True:
                self._judge_closure(name, now)
        self._check_homing(now)

    def on_axis_status(self, axis: str, homing: bool, measured: float, arrival: float | None = None,
                       commanded: float = math.nan) -> None:
        """The motion part of an ``axes/<axis>/status``: homing flag, measured and
        commanded angles [rad] (NaN = unknown, e.g. no board); the driver's heartbeat."""
        now = self._now(arrival)
        ax = self.axes.get(axis)
        if ax is None:                  # a movement this collector lacks: not its axis
            self.counters['invalid_samples'] += 1
            return
        self.heartbeat(driver_node(axis), now)
        ax.arrival = now
        measured, commanded = float(measured), float(commanded)
        ax.measured = measured if math.isfinite(measured) else None
        ax.commanded = commanded if math.isfinite(commanded) else None
        horizon = now - self.config.switch_lookback
        ax.recent = [(t, a) for t, a in ax.recent if t >= horizon]
        if ax.measured is not None:
            ax.recent.append((now, ax.measured))
        ax.homing = bool(homing)
        if not homing:
            ax.closed_travel = {}
        self._check_homing(now)
        for name in [n for n in self.pending_switches if SWITCH_AXIS[n] == axis]:
            self._judge_closure(name, now)

    def on_driver_state(self, axis: str, state: str, link_state: int, homed: bool,
                        arrival: float | None = None) -> None:
        """The driver part of an ``axes/<axis>/status``: ``state`` (a lifecycle label
        when the driver is not active), ``link_state`` (LINK_* code), ``homed`` (the
        axis is referenced). Sets the axis' readiness for the ``axis`` rule."""
        now = self._now(arrival)
        ax = self.axes.get(axis)
        if ax is None:
            self.counters['invalid_samples'] += 1
            return
        gap = ax.report_arrival is None or now - ax.report_arrival > self.config.status_max_age
        ax.report_arrival, ax.driver_state, ax.link_state = now, str(state), int(link_state)
        if ax.driver_state in IDLE_DRIVER_STATES or ax.link_state != LinkState.LINK_UP:
            ax.ready = False
        elif homed:
            ax.ready = True
        elif gap:
            ax.ready = False

    def on_phase(self, phase: int, site_source: str = '', arrival: float | None = None) -> None:
        """A ``tracker/phase``: phase code and the planner's site source."""
        now = self._now(arrival)
        self.heartbeat('planner', now)
        if phase == Phase.TRACKING and self.phase != Phase.TRACKING:
            self.tracking_since = now
        elif phase != Phase.TRACKING:
            self.tracking_since = None
        self.phase = int(phase)
        self.site_source = str(site_source)

    def on_gps_fix(self, has_fix: bool, arrival: float | None = None) -> None:
        """A ``gps/fix``; ``has_fix`` when its status is a fix (>= STATUS_FIX)."""
        self.heartbeat('gps', arrival)
        if has_fix:
            self.gps_fix_seen = True

    def on_beam(self, beam: float, arrival: float | None = None) -> None:
        """Beam irradiance [W/m^2] from ``irradiance/beam``."""
        now = self._now(arrival)
        self.heartbeat('irradiance', now)
        if math.isfinite(beam):
            self.beam, self.beam_arrival = float(beam), now
            if self.wind.zero_since is not None:
                q = self.wind.beams
                q.append((now, float(beam)))
                while q and q[0][0] < now - self.config.wind_stuck_window:
                    q.popleft()
        else:
            self.counters['bad_inputs'] += 1

    def on_wind(self, speed: float, gust: float, mean: float, window: float,
                stamp: float | None = None, arrival: float | None = None) -> None:
        """A ``wind`` message: 3 s mean, gust, mean over ``window`` [s] (all m/s),
        ``stamp`` its header stamp [s, ROS time; None: the arrival]. A gust or a mean
        over its limit raises the wind stow at once; the mean's calm run (below limit -
        hysteresis) starts or ends the release hold, which is measured between the
        stamps (control logic on ROS time: sim and replay hold as long as a real day);
        the anemometer's silence is judged on the steady arrival times (a watchdog)."""
        now = self._now(arrival)
        stamp = now if stamp is None else float(stamp)
        cfg, w = self.config, self.wind
        vals = [float(v) for v in (speed, gust, mean, window)]
        if not (all(math.isfinite(v) and v >= 0.0 for v in vals) and math.isfinite(stamp)):
            self.counters['bad_inputs'] += 1
            return
        speed, gust, mean, window = vals
        if (w.arrival is None or now - w.arrival > cfg.wind_silent_warn
                or (w.stamp is not None and stamp < w.stamp)):
            w.calm_since = None               # after a silence or a step back of ROS time: start again
        w.arrival, w.stamp, w.speed, w.gust, w.mean = now, stamp, speed, gust, mean
        if not cfg.wind_enabled:
            return
        threshold = cfg.wind_mean_limit - cfg.wind_hysteresis
        gusty, windy = speed > cfg.wind_gust_limit, mean > cfg.wind_mean_limit
        if (gusty or windy) and WIND_RULE not in self.faults:
            self._notes.append(f'wind stow: releases once the mean wind stays below {threshold:.1f} m/s '
                               f'for {cfg.wind_hold:.0f} s')
        if gusty:
            # the 3 s running mean crossing the limit is a gust above it (WMO); the gust
            # field (its highest value over 10 min) would re-raise a released stow
            self._raise(WIND_RULE, '', 'gust', {'gust': speed, 'limit': cfg.wind_gust_limit}, now)
        if windy:
            self._raise(WIND_RULE, '', 'mean', {'mean': mean, 'limit': cfg.wind_mean_limit, 'window': window}, now)
        if gusty or windy:
            w.calm_since = stamp if mean < threshold else None     # every exceedance restarts the hold
            w.exceeding = True
            return self._zero_run(speed, now)
        stowed = WIND_RULE in self.faults
        if mean < threshold:
            # the countdown's start is logged once per calm spell: the first calm sample,
            # also when the hold already runs from the last gust (its mean was below)
            if stowed and (w.calm_since is None or w.exceeding):
                self._notes.append(f'wind stow: mean {mean:.1f} m/s below {threshold:.1f} m/s, '
                                   f'release after {cfg.wind_hold:.0f} s of calm')
            if w.calm_since is None:
                w.calm_since = stamp
        else:
            if w.calm_since is not None and stowed:
                self._notes.append(f'wind stow: mean {mean:.1f} m/s back at or above {threshold:.1f} m/s '
                                   f'after {stamp - w.calm_since:.0f} s of calm: hold restarts')
            w.calm_since = None
        w.exceeding = False
        self._zero_run(speed, now)

    def _zero_run(self, speed: float, now: float) -> None:
        """Track the current run of 0 m/s readings (the stuck-anemometer check)."""
        w = self.wind
        if speed == 0.0:
            if w.zero_since is None:
                w.zero_since = now
                w.beams.clear()
        else:
            w.zero_since = None
            w.beams.clear()

    def wind_release_in(self, now: float) -> float:
        """[s of ROS time] left before a wind stow may release (the hold counts up to
        the newest sample's stamp): NaN without one, inf while the anemometer is silent
        (steady ``now``) or the mean not below its release threshold."""
        if WIND_RULE not in self.faults:
            return math.nan
        w, cfg = self.wind, self.config
        if w.arrival is None or now - w.arrival > cfg.wind_silent_warn or w.calm_since is None:
            return math.inf
        return max(0.0, cfg.wind_hold - (w.stamp - w.calm_since))

    def drain_notes(self) -> list[str]:
        """Log lines about the wind stow's release hold since the last call."""
        out, self._notes = self._notes, []
        return out

    # ----------------------------------------------------------------- switches
    def _judge_closure(self, name: str, now: float) -> None:
        """Judge a closed switch: a trip unless acknowledged, its axis homing, or its
        nominal angle on the axis' path (the span of the angles measured over the last
        ``switch_lookback`` s and the commanded angle, +/- ``switch_window``) per a fresh
        axis status. Position unknown: judged later, when one is known (an axis without
        a board cannot move)."""
        self.pending_switches.discard(name)
        if name in self.switch_ack or self.switch_closed[name] is not True:
            return
        axis = SWITCH_AXIS[name]
        ax = self.axes[axis]
        fresh = ax.arrival is not None and now - ax.arrival <= self.config.status_max_age
        if fresh and ax.homing:
            return
        if not fresh or ax.measured is None:
            self.pending_switches.add(name)
            return
        nominal = self.config.switch_positions[name]
        horizon = now - self.config.switch_lookback
        ends = [a for t, a in ax.recent if t >= horizon] + [ax.measured]
        if ax.commanded is not None:
            ends.append(ax.commanded)
        if self.stow_verdict_at.get(axis, -math.inf) >= horizon:
            # this supervisor required a stow within the look-back: the driver may already
            # be there before a status says so (a fast axis, a 5 Hz status)
            ends.append(self.stow_verdict_pose.get(axis, STOW_POSITION[axis]))
        w = self.config.switch_window
        if min(ends) - w <= nominal <= max(ends) + w:
            return
        self._raise('switch', name, 'trip', {
            'switch': name, 'axis': axis, 'measured': ax.measured, 'nominal': nominal,
            'commanded': ax.commanded if ax.commanded is not None else math.nan}, now)

    def _check_homing(self, now: float) -> None:
        """Stuck-closed switches, judged while an axis homes: a switch that stays
        closed while its axis travels > ``stuck_switch_travel`` [rad], or two switches
        of one axis closed together."""
        for axis, ax in self.axes.items():
            if not ax.homing:
                continue
            own = [s for s, a in SWITCH_AXIS.items() if a == axis]
            for s in own:
                if self.switch_closed[s] is not True:
                    ax.closed_travel.pop(s, None)
                    continue
                if ax.measured is None:
                    continue
                lo, hi = ax.closed_travel.get(s, (ax.measured, ax.measured))
                lo, hi = min(lo, ax.measured), max(hi, ax.measured)
                ax.closed_travel[s] = (lo, hi)
                if hi - lo > self.config.stuck_switch_travel:
                    self._raise('stuck_switch', s, 'travel', {'switch': s, 'axis': axis, 'travel': hi - lo}, now)
            closed = [s for s in own if self.switch_closed[s] is True]
            if len(closed) >= 2:
                for s in closed:
                    self._raise('stuck_switch', s, 'together',
                                {'switch': s, 'axis': axis, 'closed': ' and '.join(closed)}, now)

    # ----------------------------------------------------------------- operator
    def estop(self, engage: bool, arrival: float | None = None) -> tuple[bool, str]:
        """``safety/estop``: engage (True) or release (False). Returns (success, message)."""
        now = self._now(arrival)
        if engage:
            if 'estop' in self.faults:
                return True, 'e-stop already engaged'
            self._raise('estop', '', 'engaged', {}, now)
            self.evaluate(now)
            return True, 'e-stop engaged: every axis stopped'
        if 'estop' not in self.faults:
            self.counters['refused_requests'] += 1
            return False, 'refused: no e-stop is engaged, nothing to release'
        del self.faults['estop']
        self._raise('post_estop', '', 'released', {}, now)
        self.evaluate(now)
        return True, 'e-stop released: tracker stows until safety/reset'

    def reset(self, arrival: float | None = None) -> tuple[bool, str]:
        """``safety/reset``: clear every latched fault, or none (with the reasons)."""
        now = self._now(arrival)
        latched = [f for f in self.faults.values() if self.rules[f.kind].clearing(self.config) in LATCHED]
        if not latched:
            self.counters['refused_requests'] += 1
            held = ''.join(f'; {f.key} {self.rules[f.kind].held_note}' for f in self.faults.values()
                           if self.rules[f.kind].held_note)
            return False, 'refused: nothing latched to reset' + held
        blockers = [b for f in latched if (b := self._blocker(f, now))]
        if blockers:
            self.counters['refused_requests'] += 1
            return False, 'refused: ' + '; '.join(blockers)
        for fault in latched:
            del self.faults[fault.key]
            rule = self.rules[fault.kind]
            if rule.on_reset is not None:
                rule.on_reset(self, fault.name)
        self.evaluate(now)
        return True, 'reset: cleared ' + ', '.join(sorted(f.key for f in latched))

    # ----------------------------------------------------------------- time
    def on_time(self, now: float | None = None) -> None:
        """Time has passed (steady ``now`` [s]): the faults judged on time are raised
        (stored rules with a condition: thermocouple silent/stuck) and the faults
        that recover by themselves are cleared once their blocker is gone."""
        now = self._now(now)
        cfg = self.config
        beam_known = self.beam_arrival is not None and now - self.beam_arrival <= cfg.beam_max_age
        sun_on = self.tracking_since is not None and (not beam_known or self.beam >= cfg.stuck_min_beam)
        if not sun_on:
            self.sun_on_since = None
        elif self.sun_on_since is None:
            self.sun_on_since = now
        for rule in self.rules.values():
            if rule.clears is Clear.SELF or rule.condition is None:
                continue
            for name in rule.names(self):
                hit = rule.condition(self, name, now)
                if hit is not None:
                    self._raise(rule.kind, name, hit[0], hit[1], now)
        for fault in list(self.faults.values()):
            if self.rules[fault.kind].clearing(cfg) in RECOVERS and self._blocker(fault, now) is None:
                del self.faults[fault.key]

    # ----------------------------------------------------------------- verdict
    def conditions(self, now: float | None = None) -> list[Condition]:
        """Every active rule instance at steady ``now`` [s] (read-only)."""
        now = self._now(now)
        out = []
        for fault in self.faults.values():
            out.append(self._condition(self.rules[fault.kind], fault.name, fault.reason))
        for rule in self.rules.values():
            if rule.clears is not Clear.SELF:
                continue
            for name in rule.names(self):
                hit = rule.condition(self, name, now)
                if hit is not None:
                    out.append(self._condition(rule, name, rule.text(*hit)))
        return out

    def _condition(self, rule: Rule, name: str, reason: str) -> Condition:
        return Condition(key_of(rule.kind, name), rule.level_of(self, name), reason, rule.stops(name),
                         rule.stow_others)

    def verdict(self, now: float | None = None) -> Verdict:
        """The ONE evaluation: the verdict of every rule at steady ``now`` [s] (read-only;
        ``since`` continues the last recorded verdict's when the level is the same)."""
        now = self._now(now)
        conds = self.conditions(now)
        level = max((c.level for c in conds), default=Level.OK)
        reasons = tuple(c.reason for c in sorted(conds, key=lambda c: (-c.level, c.key)))
        axes = tuple(a for a in self.axes if any(a in c.axes for c in conds if c.level == Level.ESTOP))
        stowing = [c for c in conds if c.level == Level.STOW or c.stow_others]
        stow = bool(stowing)
        wind_stow = stow and all(c.key == WIND_RULE for c in stowing)
        since = self._state.since if level == self._state.level else now
        return Verdict(level, reasons, axes, stow, since, wind_stow, self.wind_release_in(now))

    def evaluate(self, now: float | None = None) -> Verdict:
        """Let time pass to ``now`` (:meth:`on_time`), take the :meth:`verdict` and
        record a :class:`Transition` (see :meth:`drain_transitions`) when the level or
        the set of reasons changed."""
        now = self._now(now)
        self.on_time(now)
        new, old = self.verdict(now), self._state
        self._state = new
        if new.stow_required:
            for axis in self.axes:
                if axis not in new.stopped_axes:
                    self.stow_verdict_at[axis] = now
                    self.stow_verdict_pose[axis] = (WIND_STOW_POSITION if new.wind_stow else STOW_POSITION)[axis]
        if old.wind_release_in == old.wind_release_in and new.wind_release_in != new.wind_release_in:
            self._notes.append('wind stow released: the mean wind stayed calm for the hold time')
        if new.level != old.level or set(new.reasons) != set(old.reasons):
            self.counters['transitions'] += 1
            self._pending.append(Transition(now, self.clock.wall(), old.level, new.level,
                                            tuple(r for r in new.reasons if r not in old.reasons),
                                            tuple(r for r in old.reasons if r not in new.reasons)))
        return new

    @property
    def state(self) -> Verdict:
        """The last recorded verdict (no re-evaluation)."""
        return self._state

    def drain_transitions(self) -> list[Transition]:
        """Transitions recorded since the last call (oldest first)."""
        out, self._pending = self._pending, []
        return out

    def snapshot(self, now: float | None = None) -> dict[str, str]:
        """Key values for /diagnostics (ages [s], temperatures [degC], counters)."""
        now = self._now(now)
        kv = {'level': self._state.level.name}
        for name, st in self.sensors.items():
            kv[f'{name} [degC]'] = 'none' if st.value is None else f'{st.value:.2f}'
            kv[f'{name} age [s]'] = 'never' if st.arrival is None else f'{now - st.arrival:.2f}'
        for node in self.config.watchdogs:
            last = self.heard.get(node)
            kv[f'heartbeat {node} age [s]'] = 'never' if last is None else f'{now - last:.2f}'
        for axis, ax in self.axes.items():
            kv[f'axis {axis} driver'] = 'never reported' if ax.ready is None else (
                f'{"ready" if ax.ready else "not ready"} ({ax.driver_state}, link {link_name(ax.link_state)})')
        for name in SWITCHES:
            kv[f'switch {name}'] = {None: 'unknown', True: 'closed', False: 'open'}[self.switch_closed[name]]
        if self.config.wind_enabled:
            w = self.wind
            kv['wind [m/s]'] = 'none' if w.arrival is None else (
                f'{w.speed:.1f} (gust {w.gust:.1f}, mean {w.mean:.1f})')
            kv['wind age [s]'] = 'never' if w.arrival is None else f'{now - w.arrival:.2f}'
            kv['wind release in [s]'] = f'{self.wind_release_in(now):.0f}'
        kv.update({k: str(v) for k, v in self.counters.items()})
        return kv
