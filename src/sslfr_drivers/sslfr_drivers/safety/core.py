"""Safety supervisor rules: the pure core of the ``safety`` node (no rclpy).

The supervisor keeps the SSLFR from damaging itself. Seed 000 section 3.5.3: the two
type-K thermocouples (MAX6675) watch the absorber tube inlet and outlet; "the maximum
temperature value is 150 degC. In the case this value is exceeded, the mirrors would
move to the sleeping position" (beta_0 = +pi/2, seed 000 section 4, i.e. defocus).
Around that rule this module adds what any trusted tracker does: thermocouple
plausibility, limit switches outside homing, heartbeat watchdogs on every link, an
operator e-stop and the "no site, no time -> sleep" rule.

Time model
----------
Every timeout and hold time is measured on the **steady clock** (monotonic seconds,
``clock.steady()``; the node uses ROS ``STEADY_TIME`` = CLOCK_MONOTONIC). Inputs carry
their *arrival* time on that clock; message header stamps (ROS time, possibly sim
time) are never used for ages. The wall clock (``clock.wall()``, Unix seconds UTC) is
used only to judge whether the system time is plausible at all (``min_valid_unix_time``)
and to label transitions for people. A wall-clock or ROS-time step of +/-1 h therefore
neither fakes a timeout nor stalls a watchdog (unit-tested with :class:`FakeClock`).

Rules (each active rule is a :class:`Condition`; the verdict is their maximum)
-------------------------------------------------------------------------------
``overtemp:<sensor>``  STOW, latched. A valid sample > ``temperature_limit`` [degC]
    trips at once (the node evaluates it in the subscription callback). Cleared by
    :meth:`SafetyCore.reset` only when the sensor is fresh and has stayed below
    ``temperature_limit - hysteresis`` for ``cool_hold`` [s]; with ``auto_reset`` the
    same condition clears it without a call (off by default).
``thermocouple:<sensor>``  STOW: open circuit / NaN / out of the physical range
    (immediate); *stuck*: no change > ``stuck_tolerance`` [K] for ``stuck_timeout``
    [s] while the sun is on the receiver (phase TRACKING and beam irradiance, when
    known, >= ``stuck_min_beam`` [W/m^2]); *silent*: no sample for > ``silent_timeout``
    [s] (default 2 s) while TRACKING. Held until the sensor has recovered: fresh valid
    samples for ``sensor_recover_hold`` [s] (and, for *stuck*, a change), whatever the
    phase does meanwhile, so the stow it causes cannot clear it (no stow/track
    oscillation). With ``sensor_fault_latched`` it also needs :meth:`SafetyCore.reset`.
``switch:<name>``  ESTOP for the switch's axis (:data:`SWITCH_AXIS`), latched. A
    switch closing while its axis is not homing and its nominal angle
    (``switch_positions``) is not on the axis' path, i.e. not within the span of the
    angles measured over the last ``switch_lookback`` [s] and the commanded angle
    (+/- ``switch_window`` [rad], from a fresh axis status), is a trip. The look-back
    absorbs the different delays of the switch and status messages of a moving axis. The seed's switches are position references the mechanism reaches or passes
    in normal operation (mirrors on the sleeping switch every night, passing the
    ``last`` switch on the way), hence the path test. With the position unknown (no
    fresh status, or NaN: no board, the axis cannot move) the closure is judged as
    soon as a position is known. Reset acknowledges a trip even while the switch is
    still closed (so the axis can be jogged off it); it re-arms when the switch opens.
``stuck_switch:<name>``  ESTOP for the axis, latched: detected at homing, when the
    switch stays closed while the axis travels more than ``stuck_switch_travel``
    [rad], or when two switches of one axis read closed together during homing.
    Reset refused while the switch still reads closed.
``watchdog:<node>``  WARN or STOW per the ``watchdogs`` table (node -> (timeout [s],
    action)), from the arrival times of the node's topics; self-clearing when the node
    speaks again. A node never heard is judged from start-up + ``startup_grace``.
``estop``  ESTOP of every axis, latched until :meth:`SafetyCore.estop` ``(False)``;
    the release leaves ``post_estop`` (STOW) until :meth:`SafetyCore.reset`, so a
    released e-stop never resumes tracking by itself.
``site`` / ``time``  STOW, self-clearing: no GPS fix since boot and no persisted (or
    configured) site reported by the planner; no GPS fix and an implausible (or, with
    ``trust_system_clock`` false, any) system clock. The tracker stays asleep.

Refused requests (reset while hot, release without e-stop, nothing to reset) return
``(False, reason)`` and leave the state unchanged.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

from sslfr_common.contract import JOINTS, SWITCH_AXIS, SWITCH_POSITION, SWITCHES, THERMOCOUPLES, Level, Phase, driver_node

#: Watchable nodes (default node names, docs/architecture.md).
WATCHABLE = ('planner', *(driver_node(j) for j in JOINTS), 'absorber_board', 'irradiance', 'gps')


class SystemClock:
    """Real clocks: ``steady()`` = CLOCK_MONOTONIC [s], ``wall()`` = Unix time [s]."""

    @staticmethod
    def steady() -> float:
        return time.monotonic()

    @staticmethod
    def wall() -> float:
        return time.time()


class FakeClock:
    """Injectable clock for tests: steady and wall time advanced/stepped by hand."""

    def __init__(self, steady: float = 1000.0, wall: float = 1_750_000_000.0):
        self._steady = float(steady)
        self._wall = float(wall)

    def steady(self) -> float:
        return self._steady

    def wall(self) -> float:
        return self._wall

    def advance(self, dt: float) -> None:
        """Let ``dt`` [s] pass on both clocks."""
        self._steady += dt
        self._wall += dt

    def step_wall(self, dt: float) -> None:
        """Step only the wall clock by ``dt`` [s] (NTP/GPS correction, operator)."""
        self._wall += dt


@dataclass(frozen=True)
class SafetyConfig:
    """Tunable limits. Units: degC, K, s, rad, W/m^2 as named.

    ``watchdogs`` maps a node name (:data:`WATCHABLE`) to ``(timeout [s], action)``
    with action ``'WARN'`` or ``'STOW'``.
    """

    temperature_limit: float = 150.0      # [degC] seed 000 section 3.5.3
    hysteresis: float = 10.0              # [K] must cool below limit - hysteresis
    cool_hold: float = 60.0               # [s] ... for this long before reset
    auto_reset: bool = False              # clear temperature latches without a call
    silent_timeout: float = 2.0           # [s] thermocouple silent while TRACKING
    sensor_recover_hold: float = 2.0      # [s] valid samples before a sensor fault clears
    sensor_fault_latched: bool = False    # thermocouple faults also need safety/reset
    stuck_timeout: float = 300.0          # [s] no change while the sun is on the receiver
    stuck_tolerance: float = 0.0          # [K] a change must exceed this
    stuck_min_beam: float = 200.0         # [W/m^2] beam at which the sun counts as on
    valid_min: float = -40.0              # [degC] plausible thermocouple range
    valid_max: float = 1100.0             # [degC]
    switch_window: float = 0.05           # [rad] closure expected within this of nominal
    switch_lookback: float = 1.0          # [s] measured angles that make up the axis' path
    switch_positions: dict = field(default_factory=lambda: dict(SWITCH_POSITION))
    stuck_switch_travel: float = 0.1      # [rad] travel with a switch closed at homing
    status_max_age: float = 1.0           # [s] axis status older than this is unknown
    beam_max_age: float = 5.0             # [s] beam older than this is unknown
    startup_grace: float = 10.0           # [s] before never-heard nodes count as silent
    require_site_and_time: bool = True
    trust_system_clock: bool = True       # a plausible system clock counts as time
    min_valid_unix_time: float = 1_704_067_200.0  # [s] 2024-01-01T00:00Z
    watchdogs: dict = field(default_factory=lambda: {
        'planner': (5.0, 'STOW'),
        'mirrors_driver': (2.0, 'STOW'),
        'mobile_structure_driver': (2.0, 'STOW'),
        'secondary_reflector_driver': (2.0, 'STOW'),
        'absorber_board': (2.0, 'STOW'),
        'irradiance': (5.0, 'WARN'),
        'gps': (5.0, 'WARN'),
    })

    def validate(self) -> None:
        """Raise ValueError naming the first bad value."""
        def pos(name, v, zero_ok=False):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and (v >= 0 if zero_ok else v > 0)):
                raise ValueError(f'{name} must be a finite {"non-negative" if zero_ok else "positive"} '
                                 f'number, got {v!r}')
        if not (math.isfinite(self.temperature_limit) and -40.0 < self.temperature_limit < 1100.0):
            raise ValueError(f'temperature_limit must be in (-40, 1100) degC, got {self.temperature_limit!r}')
        pos('hysteresis', self.hysteresis, zero_ok=True)
        pos('cool_hold', self.cool_hold, zero_ok=True)
        pos('silent_timeout', self.silent_timeout)
        pos('sensor_recover_hold', self.sensor_recover_hold, zero_ok=True)
        pos('stuck_timeout', self.stuck_timeout)
        pos('stuck_tolerance', self.stuck_tolerance, zero_ok=True)
        pos('stuck_min_beam', self.stuck_min_beam, zero_ok=True)
        pos('switch_window', self.switch_window, zero_ok=True)
        pos('switch_lookback', self.switch_lookback, zero_ok=True)
        pos('stuck_switch_travel', self.stuck_switch_travel)
        pos('status_max_age', self.status_max_age)
        pos('beam_max_age', self.beam_max_age)
        pos('startup_grace', self.startup_grace, zero_ok=True)
        if not (self.valid_min < self.valid_max):
            raise ValueError(f'valid_min {self.valid_min} must be < valid_max {self.valid_max}')
        if set(self.switch_positions) != set(SWITCHES) or not all(
                math.isfinite(v) for v in self.switch_positions.values()):
            raise ValueError(f'switch_positions needs finite angles for exactly {SWITCHES}')
        for node, spec in self.watchdogs.items():
            if node not in WATCHABLE:
                raise ValueError(f'watchdog node {node!r} unknown; known: {", ".join(WATCHABLE)}')
            timeout, action = spec
            pos(f'watchdog {node} timeout', timeout)
            if action not in ('WARN', 'STOW'):
                raise ValueError(f'watchdog {node} action must be WARN or STOW, got {action!r}')


@dataclass(frozen=True)
class Condition:
    """One active rule: its level, the reason (naming the source), axes to stop."""

    key: str
    level: Level
    reason: str
    axes: tuple[str, ...] = ()
    latched: bool = False


@dataclass(frozen=True)
class SafetyState:
    """The supervisor's verdict (maps 1:1 to sslfr_interfaces/SafetyState).

    ``since`` is the steady time [s] at which ``level`` was entered.
    """

    level: Level
    reasons: tuple[str, ...]
    stopped_axes: tuple[str, ...]
    stow_required: bool
    since: float


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
    changed_since_fault: bool = False
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


class SafetyCore:
    """The rules. Feed events (``on_*``), read :meth:`evaluate`; see the module doc.

    Parameters
    ----------
    config : SafetyConfig
        Validated limits.
    clock : object with ``steady()`` and ``wall()`` [s]
        :class:`SystemClock` in the node, :class:`FakeClock` in tests. Event methods
        take an explicit ``arrival`` [steady s] or read ``clock.steady()``.
    """

    def __init__(self, config: SafetyConfig | None = None, clock=None):
        self.config = config or SafetyConfig()
        self.config.validate()
        self.clock = clock or SystemClock()
        self.start = self.clock.steady()
        self.sensors = {s: _Sensor() for s in THERMOCOUPLES}
        self.axes = {a: _Axis() for a in JOINTS}
        self.switch_closed: dict[str, bool | None] = {s: None for s in SWITCHES}
        self.switch_ack: set[str] = set()        # acknowledged trips, re-armed when open
        self.heard: dict[str, float] = {}        # node -> last arrival [steady s]
        self.phase: int | None = None
        self.tracking_since: float | None = None
        self.sun_on_since: float | None = None
        self.beam: float | None = None
        self.beam_arrival: float | None = None
        self.gps_fix_seen = False
        self.site_source = ''
        self.latched: dict[str, Condition] = {}
        self.sensor_faults: dict[str, Condition] = {}   # held until the sensor recovers
        self.counters = {'samples': 0, 'invalid_samples': 0, 'refused_requests': 0,
                         'transitions': 0, 'bad_inputs': 0}
        self._state = SafetyState(Level.OK, (), (), False, self.start)
        self._pending: list[Transition] = []
        self.pending_switches: set[str] = set()   # closed while the axis position was unknown
        self.evaluate(self.start)

    # ----------------------------------------------------------------- helpers
    def _now(self, arrival: float | None) -> float:
        return self.clock.steady() if arrival is None else float(arrival)

    def _latch(self, cond: Condition) -> None:
        if cond.key not in self.latched:
            self.latched[cond.key] = cond

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
        """A thermocouple sample [degC] (``sensor`` in :data:`THERMOCOUPLES`).

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
            self._sensor_fault(Condition(f'thermocouple:{sensor}', Level.STOW,
                                         f'{sensor} thermocouple invalid ({what}): temperature not watched'))
            return
        st.valid = True
        if st.valid_since is None:
            st.valid_since = now
        if st.ref_value is None or abs(value - st.ref_value) > cfg.stuck_tolerance:
            if st.ref_value is not None:
                st.changed_since_fault = True
            st.ref_value = value
            st.last_change = now
        st.value = value
        if value > cfg.temperature_limit:
            st.cool_since = None
            self._latch(Condition(f'overtemp:{sensor}', Level.STOW,
                                  f'{sensor} over-temperature: {value:.1f} degC > '
                                  f'{cfg.temperature_limit:.1f} degC (latched until reset)',
                                  latched=True))
        elif value < cfg.temperature_limit - cfg.hysteresis:
            if st.cool_since is None:
                st.cool_since = now
        else:
            st.cool_since = None

    def on_limit_switches(self, states: dict, arrival: float | None = None) -> None:
        """Debounced switch states ``{name: closed}`` for the names in :data:`SWITCHES`."""
        now = self._now(arrival)
        self.heartbeat('absorber_board', now)
        for name in SWITCHES:
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
        """An ``axes/<axis>/status``: homing flag, measured and commanded angles [rad]
        (NaN = unknown, e.g. no board)."""
        now = self._now(arrival)
        ax = self.axes[axis]
        self.heartbeat(f'{axis}_driver', now)
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
        else:
            self.counters['bad_inputs'] += 1

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
        w = self.config.switch_window
        if min(ends) - w <= nominal <= max(ends) + w:
            return
        self._latch(Condition(f'switch:{name}', Level.ESTOP,
                              f'limit switch {name} tripped outside homing ({axis} at {ax.measured:.3f} rad, '
                              f'commanded {ax.commanded if ax.commanded is not None else math.nan:.3f} rad, '
                              f'switch at {nominal:.3f} rad): {axis} stopped', axes=(axis,), latched=True))

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
                    self._latch(Condition(f'stuck_switch:{s}', Level.ESTOP,
                                          f'limit switch {s} stuck closed (closed over {hi - lo:.3f} rad '
                                          f'of {axis} homing travel): {axis} stopped',
                                          axes=(axis,), latched=True))
            closed = [s for s in own if self.switch_closed[s] is True]
            if len(closed) >= 2:
                for s in closed:
                    self._latch(Condition(f'stuck_switch:{s}', Level.ESTOP,
                                          f'limit switch {s} stuck closed ({" and ".join(closed)} closed '
                                          f'together during {axis} homing): {axis} stopped',
                                          axes=(axis,), latched=True))

    # ----------------------------------------------------------------- operator
    def estop(self, engage: bool, arrival: float | None = None) -> tuple[bool, str]:
        """``safety/estop``: engage (True) or release (False). Returns (success, message)."""
        now = self._now(arrival)
        if engage:
            if 'estop' in self.latched:
                return True, 'e-stop already engaged'
            self._latch(Condition('estop', Level.ESTOP, 'operator e-stop (safety/estop): every axis stopped',
                                  axes=JOINTS, latched=True))
            self.evaluate(now)
            return True, 'e-stop engaged: every axis stopped'
        if 'estop' not in self.latched:
            self.counters['refused_requests'] += 1
            return False, 'refused: no e-stop is engaged, nothing to release'
        del self.latched['estop']
        self._latch(Condition('post_estop', Level.STOW,
                              'e-stop released: stowing until safety/reset', latched=True))
        self.evaluate(now)
        return True, 'e-stop released: tracker stows until safety/reset'

    def _sensor_fault(self, cond: Condition) -> None:
        """Raise a thermocouple fault (held until recovery, or latched by config)."""
        if self.config.sensor_fault_latched:
            self._latch(replace(cond, latched=True))
        elif cond.key not in self.latched:
            self.sensor_faults.setdefault(cond.key, cond)

    def _sensor_blocker(self, name: str, reason: str, now: float) -> str | None:
        """Why the thermocouple ``name`` has not recovered (None: it has)."""
        cfg, st = self.config, self.sensors[name]
        if st.arrival is None or now - st.arrival > cfg.silent_timeout:
            return f'{name} thermocouple still silent'
        if not st.valid or st.valid_since is None:
            return f'{name} thermocouple still invalid'
        if now - st.valid_since < cfg.sensor_recover_hold:
            return (f'{name} thermocouple valid for {now - st.valid_since:.1f} s of '
                    f'{cfg.sensor_recover_hold:.1f} s')
        if 'stuck' in reason and not st.changed_since_fault:
            return f'{name} thermocouple still stuck at {st.value:.2f} degC'
        return None

    def _reset_blocker(self, key: str, now: float) -> str | None:
        """Why the latched condition ``key`` cannot be cleared now (None: it can)."""
        cfg = self.config
        kind, _, name = key.partition(':')
        if kind == 'overtemp':
            st = self.sensors[name]
            if st.arrival is None or now - st.arrival > cfg.silent_timeout or not st.valid:
                return f'{name}: no fresh valid reading to confirm it cooled'
            threshold = cfg.temperature_limit - cfg.hysteresis
            if st.cool_since is None:
                return f'{name} still hot: {st.value:.1f} degC, must be < {threshold:.1f} degC'
            held = now - st.cool_since
            if held < cfg.cool_hold:
                return f'{name} cooling: below {threshold:.1f} degC for {held:.1f} s of {cfg.cool_hold:.1f} s'
            return None
        if kind == 'thermocouple':
            return self._sensor_blocker(name, self.latched[key].reason, now)
        if kind == 'stuck_switch':
            if self.switch_closed[name]:
                return f'limit switch {name} still reads closed'
            return None
        if kind == 'estop':
            return 'e-stop engaged: release it first with safety/estop false'
        return None            # switch trips, post_estop: acknowledged

    def reset(self, arrival: float | None = None) -> tuple[bool, str]:
        """``safety/reset``: clear every latched condition, or none (with the reasons)."""
        now = self._now(arrival)
        if not self.latched:
            self.counters['refused_requests'] += 1
            held = ''.join(f'; {k} clears by itself once the sensor has recovered' for k in self.sensor_faults)
            return False, 'refused: nothing latched to reset' + held
        blockers = [b for k in self.latched if (b := self._reset_blocker(k, now))]
        if blockers:
            self.counters['refused_requests'] += 1
            return False, 'refused: ' + '; '.join(blockers)
        cleared = sorted(self.latched)
        for key in cleared:
            kind, _, name = key.partition(':')
            if kind == 'switch' and self.switch_closed.get(name):
                self.switch_ack.add(name)
            if kind == 'thermocouple':
                self.sensors[name].changed_since_fault = False
        self.latched.clear()
        self.evaluate(now)
        return True, 'reset: cleared ' + ', '.join(cleared)

    # ----------------------------------------------------------------- verdict
    def _live_conditions(self, now: float) -> list[Condition]:
        cfg = self.config
        out: list[Condition] = []
        tracking = self.phase == Phase.TRACKING
        # thermocouple silent / stuck (latched once detected)
        beam_known = self.beam_arrival is not None and now - self.beam_arrival <= cfg.beam_max_age
        sun_on = tracking and (not beam_known or self.beam >= cfg.stuck_min_beam)
        if sun_on and self.sun_on_since is None:
            self.sun_on_since = now
        elif not sun_on:
            self.sun_on_since = None
        for name, st in self.sensors.items():
            if tracking:
                ref = max(st.arrival if st.arrival is not None else -math.inf, self.tracking_since or now)
                if now - ref > cfg.silent_timeout:
                    self._sensor_fault(Condition(f'thermocouple:{name}', Level.STOW,
                                                 f'{name} thermocouple silent > {cfg.silent_timeout:.1f} s '
                                                 'while tracking: temperature not watched'))
            if sun_on and st.valid and st.last_change is not None:
                ref = max(st.last_change, self.sun_on_since)
                if now - ref > cfg.stuck_timeout:
                    st.changed_since_fault = False
                    self._sensor_fault(Condition(f'thermocouple:{name}', Level.STOW,
                                                 f'{name} thermocouple stuck at {st.value:.2f} degC for > '
                                                 f'{cfg.stuck_timeout:.0f} s with the sun on the receiver'))
        # heartbeat watchdogs
        for node, (timeout, action) in cfg.watchdogs.items():
            last = self.heard.get(node)
            ref = last if last is not None else self.start + cfg.startup_grace
            if now - ref > timeout:
                out.append(Condition(f'watchdog:{node}', Level[action],
                                     f'{node} {"silent" if last is not None else "never heard"} > '
                                     f'{timeout:.1f} s (heartbeat watchdog)'))
        # site and time
        if cfg.require_site_and_time:
            if not self.gps_fix_seen and self.site_source not in ('persisted', 'parameters'):
                out.append(Condition('site', Level.STOW, 'no site: no GPS fix since boot and no persisted '
                                     'site from the planner: staying in the sleeping position'))
            wall_ok = cfg.trust_system_clock and self.clock.wall() >= cfg.min_valid_unix_time
            if not self.gps_fix_seen and not wall_ok:
                out.append(Condition('time', Level.STOW, 'no time: no GPS fix since boot and no trusted '
                                     'system clock: staying in the sleeping position'))
        # thermocouple faults clear once the sensor has recovered
        for key, cond in list(self.sensor_faults.items()):
            if self._sensor_blocker(key.partition(':')[2], cond.reason, now) is None:
                del self.sensor_faults[key]
        # auto-reset of temperature latches
        if cfg.auto_reset:
            for key in [k for k in self.latched if k.startswith(('overtemp:', 'thermocouple:'))]:
                if self._reset_blocker(key, now) is None:
                    del self.latched[key]
        return list(self.latched.values()) + list(self.sensor_faults.values()) + out

    def evaluate(self, now: float | None = None) -> SafetyState:
        """Apply every rule at steady time ``now`` [s] and return the verdict.

        Records a :class:`Transition` (see :meth:`drain_transitions`) when the
        level or the set of reasons changed.
        """
        now = self._now(now)
        conds = self._live_conditions(now)
        level = max((c.level for c in conds), default=Level.OK)
        reasons = tuple(c.reason for c in sorted(conds, key=lambda c: (-c.level, c.key)))
        axes = tuple(a for a in JOINTS if any(a in c.axes for c in conds if c.level == Level.ESTOP))
        stow = any(c.level == Level.STOW for c in conds) or any(
            c.key.startswith(('switch:', 'stuck_switch:')) for c in conds)
        old = self._state
        since = old.since if level == old.level else now
        self._state = SafetyState(level, reasons, axes, stow, since)
        if level != old.level or set(reasons) != set(old.reasons):
            self.counters['transitions'] += 1
            self._pending.append(Transition(now, self.clock.wall(), old.level, level,
                                            tuple(r for r in reasons if r not in old.reasons),
                                            tuple(r for r in old.reasons if r not in reasons)))
        return self._state

    @property
    def state(self) -> SafetyState:
        """The last verdict (no re-evaluation)."""
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
        for name in SWITCHES:
            kv[f'switch {name}'] = {None: 'unknown', True: 'closed', False: 'open'}[self.switch_closed[name]]
        kv.update({k: str(v) for k, v in self.counters.items()})
        return kv


def with_changes(config: SafetyConfig, **changes) -> SafetyConfig:
    """A validated copy of ``config`` with ``changes`` applied (raises ValueError)."""
    new = replace(config, **changes)
    new.validate()
    return new
