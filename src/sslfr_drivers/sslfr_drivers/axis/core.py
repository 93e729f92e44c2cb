"""Pure decision core of the axis driver (no rclpy): calibration, trajectory store,
soft and speed limits, stall / lost-step detection and the safety watchdog.

Everything here works on plain numbers so it can be unit-tested on values:

- angles are joint angles in radians (REP-103), the axis conventions of
  docs/architecture.md (``mirrors`` = beta_0 = theta_t / 2, seed 000 eq. 11,
  +pi/2 = sleeping position; ``mobile_structure`` = beta_M, ``secondary_reflector``
  = beta_a);
- motor positions are integer steps of the board's step counter;
- trajectory times are float seconds since the Unix epoch (ROS time, UTC);
- watchdog times are float seconds of a steady (monotonic) clock.

The node (``axis_driver_node``) only converts messages to these numbers, calls the
functions below and turns their verdicts into board commands.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from sslfr_common.contract import STEP_ANGLE



# --------------------------------------------------------------------------- calibration
@dataclass(frozen=True)
class Calibration:
    """Joint angle <-> motor step conversion.

    ``theta = offset + sign * steps * step_angle / gear_ratio``

    Parameters
    ----------
    step_angle : float
        Motor shaft rotation per step [rad/step], > 0. Seed 000 section 3.4: 0.006 deg
        (with ``gear_ratio`` 1 the seed's 0.006 deg is the joint resolution).
    gear_ratio : float
        Motor shaft angle per joint angle [-], > 0 (a 10:1 reducer is 10).
    offset : float
        Joint angle at step count 0 [rad] (where SET_ZERO / homing puts the counter).
    invert : bool
        True when positive steps turn the joint in the negative direction.
    """

    step_angle: float = STEP_ANGLE
    gear_ratio: float = 1.0
    offset: float = 0.0
    invert: bool = False

    def __post_init__(self):
        for name in ('step_angle', 'gear_ratio'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be finite and > 0, got {value!r}')
        if not math.isfinite(self.offset):
            raise ValueError(f'offset must be finite, got {self.offset!r}')

    @property
    def joint_per_step(self) -> float:
        """Joint rotation per motor step [rad/step] (signed by ``invert``)."""
        return (-1.0 if self.invert else 1.0) * self.step_angle / self.gear_ratio

    def steps(self, theta: float) -> int:
        """Nearest step count for joint angle ``theta`` [rad] -> [steps]."""
        return int(round((theta - self.offset) / self.joint_per_step))

    def angle(self, steps: float) -> float:
        """Joint angle [rad] for a step count [steps]."""
        return self.offset + steps * self.joint_per_step

    def step_rate(self, speed: float) -> float:
        """Motor step rate [steps/s] (>= 0) for a joint speed [rad/s]."""
        return abs(speed / self.joint_per_step)


# --------------------------------------------------------------------------- limits
@dataclass(frozen=True)
class SoftLimits:
    """Software joint limits ``lower <= theta <= upper`` [rad]."""

    lower: float
    upper: float

    def __post_init__(self):
        if not (math.isfinite(self.lower) and math.isfinite(self.upper) and self.lower < self.upper):
            raise ValueError(f'soft limits need finite lower < upper, got {self.lower!r}..{self.upper!r}')

    def contains(self, theta: float, tol: float = 1e-9) -> bool:
        """True when ``theta`` [rad] is inside the limits (``tol`` [rad] of slack)."""
        return self.lower - tol <= theta <= self.upper + tol

    def clamp(self, theta: float) -> float:
        """``theta`` [rad] clamped into the limits."""
        return min(self.upper, max(self.lower, theta))


def move_speed(current: float, target: float, horizon: float, max_speed: float,
               min_speed: float) -> float:
    """Speed [rad/s] to send with a MOVE_TO so the axis reaches ``target`` in ``horizon``.

    ``v = clamp(|target - current| / horizon, min_speed, max_speed)``: commanding the
    setpoint one control period ahead at this speed keeps the motor moving
    continuously instead of stop-and-go, and never faster than ``max_speed``.

    Parameters
    ----------
    current, target : float
        Measured and target joint angles [rad].
    horizon : float
        Time to reach the target [s], > 0 (the control period).
    max_speed, min_speed : float
        Speed bounds [rad/s], 0 < min_speed <= max_speed.
    """
    if horizon <= 0:
        return max_speed
    return min(max_speed, max(min_speed, abs(target - current) / horizon))


# --------------------------------------------------------------------------- trajectory
class TrajectoryRejected(ValueError):
    """A trajectory was refused; ``str(exc)`` is the reason to log."""


@dataclass(frozen=True)
class Trajectory:
    """One joint's trajectory: absolute times [s, Unix epoch] and positions [rad].

    ``velocities`` [rad/s] is optional; when given, :meth:`sample` uses cubic
    Hermite interpolation between points, otherwise linear.
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None = None

    @property
    def start(self) -> float:
        """Time of the first point [s since the Unix epoch]."""
        return float(self.times[0])

    @property
    def end(self) -> float:
        """Time of the last point [s since the Unix epoch]."""
        return float(self.times[-1])

    def sample(self, t: float) -> tuple[float, float]:
        """Setpoint ``(position [rad], velocity [rad/s])`` at time ``t`` [s].

        Before the first point the first position is held, after the last point the
        last position is held (velocity 0): trajectory starvation holds position.
        """
        ts, ps = self.times, self.positions
        if t <= ts[0]:
            return float(ps[0]), 0.0
        if t >= ts[-1]:
            return float(ps[-1]), 0.0
        i = int(np.searchsorted(ts, t, side='right')) - 1
        t0, t1 = ts[i], ts[i + 1]
        h = t1 - t0
        s = (t - t0) / h
        p0, p1 = ps[i], ps[i + 1]
        if self.velocities is None:
            return float(p0 + s * (p1 - p0)), float((p1 - p0) / h)
        m0, m1 = self.velocities[i] * h, self.velocities[i + 1] * h
        s2, s3 = s * s, s * s * s
        pos = ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0
               + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1)
        dpos = ((6 * s2 - 6 * s) * p0 + (3 * s2 - 4 * s + 1) * m0
                + (-6 * s2 + 6 * s) * p1 + (3 * s2 - 2 * s) * m1) / h
        return float(pos), float(dpos)


def validate_trajectory(times, positions, velocities, now: float, limits: SoftLimits) -> Trajectory:
    """Check one joint's points and return a :class:`Trajectory`.

    Refused (``TrajectoryRejected`` with the reason) when: no points; any time or
    position (or velocity) is NaN/inf; times not strictly increasing; a position
    outside the soft limits; every point is in the past (``times[-1] < now``).

    Parameters
    ----------
    times : array_like
        Absolute point times [s since the Unix epoch].
    positions : array_like
        Joint positions [rad].
    velocities : array_like or None
        Joint velocities [rad/s], same length as positions, or None / empty.
    now : float
        Current ROS time [s since the Unix epoch].
    limits : SoftLimits
        The axis soft limits [rad].
    """
    t = np.asarray(times, dtype=np.float64)
    p = np.asarray(positions, dtype=np.float64)
    if t.size == 0:
        raise TrajectoryRejected('no points')
    if p.shape != t.shape:
        raise TrajectoryRejected(f'{p.size} positions for {t.size} points')
    if not np.all(np.isfinite(t)):
        raise TrajectoryRejected('non-finite point time')
    bad = np.flatnonzero(~np.isfinite(p))
    if bad.size:
        raise TrajectoryRejected(f'non-finite position at point {int(bad[0])}')
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise TrajectoryRejected('point times not strictly increasing')
    out = np.flatnonzero((p < limits.lower - 1e-9) | (p > limits.upper + 1e-9))
    if out.size:
        k = int(out[0])
        raise TrajectoryRejected(
            f'point {k} position {p[k]:.6f} rad outside soft limits '
            f'[{limits.lower:.6f}, {limits.upper:.6f}] rad')
    if t[-1] < now:
        raise TrajectoryRejected(f'past-only trajectory: last point {now - t[-1]:.3f} s before now')
    v = None
    if velocities is not None and len(velocities) > 0:
        v = np.asarray(velocities, dtype=np.float64)
        if v.shape != t.shape:
            raise TrajectoryRejected(f'{v.size} velocities for {t.size} points')
        if not np.all(np.isfinite(v)):
            raise TrajectoryRejected('non-finite velocity')
    return Trajectory(t, p, v)


class TrajectoryStore:
    """Holds the last good trajectory; refused ones leave it untouched."""

    def __init__(self) -> None:
        self.current: Trajectory | None = None
        self.accepted = 0
        self.rejected = 0
        self.last_reason = ''

    def offer(self, times, positions, velocities, now: float, limits: SoftLimits) -> str | None:
        """Validate and keep a trajectory; return None when accepted, else the reason."""
        try:
            traj = validate_trajectory(times, positions, velocities, now, limits)
        except TrajectoryRejected as exc:
            self.rejected += 1
            self.last_reason = str(exc)
            return self.last_reason
        self.current = traj
        self.accepted += 1
        return None

    def clear(self) -> None:
        """Forget the current trajectory (no setpoint until the next one)."""
        self.current = None

    def setpoint(self, t: float) -> tuple[float, float, str] | None:
        """``(position [rad], velocity [rad/s], status)`` at ``t`` [s], or None.

        status: ``'waiting'`` (before the first point: first position held),
        ``'following'``, ``'starved'`` (past the last point: last position held).
        """
        if self.current is None:
            return None
        pos, vel = self.current.sample(t)
        if t < self.current.start:
            return pos, 0.0, 'waiting'
        if t > self.current.end:
            return pos, 0.0, 'starved'
        return pos, vel, 'following'


# --------------------------------------------------------------------------- safety
class SafetyVerdict(enum.Enum):
    FOLLOW = 'follow'
    STOW = 'stow'
    STOP = 'stop'


# SafetyState levels (sslfr_interfaces/msg/SafetyState.msg)
LEVEL_OK, LEVEL_WARN, LEVEL_STOW, LEVEL_ESTOP = 0, 1, 2, 3


@dataclass
class SafetyWatch:
    """Watchdog on ``safety/state`` on the steady clock.

    A message refreshes the watchdog only when its ``sequence`` differs from the
    previous one (a stuck publisher repeating itself is not a heartbeat).

    Parameters
    ----------
    axis : str
        This driver's axis name (matched against ``stopped_axes``).
    timeout : float
        Maximum steady-clock age of the last fresh message [s] (1.0 by the spec).
    silent_stow_after : float
        Further silence after the stop before the fail-safe stow [s]: with the
        supervisor gone nobody watches the absorber, so the axis stops first and then
        defocuses (mirrors to the sleeping position, issues 7 and 9: "stopped within
        1.2 s and stowing"). Only after messages were once received: at boot without a
        supervisor the axis does not move at all.
    """

    axis: str
    timeout: float = 1.0
    silent_stow_after: float = 1.0
    last_rx: float | None = None
    last_sequence: int | None = None
    level: int = LEVEL_OK
    stow_required: bool = False
    stopped_axes: tuple = ()
    reasons: tuple = ()

    def receive(self, now_steady: float, level: int, stow_required: bool, stopped_axes,
                sequence: int, reasons=()) -> bool:
        """Record a SafetyState; return True when it was fresh (new sequence)."""
        fresh = sequence != self.last_sequence
        self.level, self.stow_required = int(level), bool(stow_required)
        self.stopped_axes, self.reasons = tuple(stopped_axes), tuple(reasons)
        if fresh:
            self.last_rx = now_steady
            self.last_sequence = sequence
        return fresh

    def verdict(self, now_steady: float) -> tuple[SafetyVerdict, str]:
        """``(verdict, reason)`` for the current steady time [s].

        STOP when no fresh message for > ``timeout`` (or never), then STOW once the
        silence passes ``timeout + silent_stow_after``; STOP when this axis is in
        ``stopped_axes`` or the level is ESTOP with no axis listed (every axis);
        STOW when ``stow_required`` or level STOW; FOLLOW otherwise.
        """
        if self.last_rx is None:
            return SafetyVerdict.STOP, 'no safety/state received yet'
        age = now_steady - self.last_rx
        if age > self.timeout + self.silent_stow_after:
            return SafetyVerdict.STOW, f'safety/state silent for {age:.2f} s: fail-safe stow (defocus)'
        if age > self.timeout:
            return SafetyVerdict.STOP, f'safety/state silent for {age:.2f} s > {self.timeout:.2f} s'
        if self.level == LEVEL_ESTOP and not self.stopped_axes:
            return SafetyVerdict.STOP, 'safety ESTOP: ' + '; '.join(self.reasons)
        if self.axis in self.stopped_axes:
            return SafetyVerdict.STOP, f'safety stops axis {self.axis}: ' + '; '.join(self.reasons)
        if self.stow_required or self.level == LEVEL_STOW:
            return SafetyVerdict.STOW, 'safety requires stow: ' + '; '.join(self.reasons)
        return SafetyVerdict.FOLLOW, ''


# --------------------------------------------------------------------------- stall
@dataclass
class StallDetector:
    """Stall and lost-step detection from board STATUS samples.

    Two checks:

    1. *stall*: the step counter moved by more than ``min_motion`` [rad] of joint
       angle within the last ``window`` [s] while the position sensor moved by less
       than a quarter of that (commanded motion with no sensor motion); and, for
       boards without a sensor, a MOVE_TO pending (target != position) with no step
       change for ``window`` while the board is not moving.
    2. *lost steps*: ``|angle(steps) - sensor| > tolerance`` [rad].

    Parameters
    ----------
    tolerance : float
        Allowed step-count vs sensor disagreement [rad] (> sensor noise).
    window : float
        Stall observation window [s] (steady clock).
    min_motion : float
        Commanded motion that must show on the sensor [rad] (> sensor noise).
    """

    tolerance: float
    window: float = 1.0
    min_motion: float = 0.01
    _hist: list = field(default_factory=list)
    _pending_since: float | None = None

    def reset(self) -> None:
        """Forget the history (after a fault is cleared or the axis re-referenced)."""
        self._hist.clear()
        self._pending_since = None

    def update(self, now: float, step_angle: float, sensor: float | None, moving: bool,
               target_pending: bool) -> str | None:
        """Feed one sample; return a fault reason or None.

        Parameters
        ----------
        now : float
            Steady time [s].
        step_angle : float
            Joint angle from the step counter [rad].
        sensor : float or None
            Joint angle from the position sensor [rad], None when the board has none.
        moving : bool
            Board reports the motor moving.
        target_pending : bool
            A MOVE_TO target differs from the current step count by more than one step.
        """
        if sensor is not None:
            if abs(step_angle - sensor) > self.tolerance:
                return (f'lost steps: step count says {step_angle:.5f} rad, sensor '
                        f'{sensor:.5f} rad (|diff| > {self.tolerance:.5f} rad)')
            self._hist.append((now, step_angle, sensor))
            while self._hist and now - self._hist[0][0] > self.window:
                self._hist.pop(0)
            if len(self._hist) >= 2 and now - self._hist[0][0] >= 0.8 * self.window:
                d_steps = abs(self._hist[-1][1] - self._hist[0][1])
                d_sensor = abs(self._hist[-1][2] - self._hist[0][2])
                if d_steps > self.min_motion and d_sensor < 0.25 * d_steps:
                    return (f'stall: motor stepped {d_steps:.5f} rad in {self.window:.1f} s '
                            f'but the sensor moved {d_sensor:.5f} rad')
        if target_pending and not moving:
            if self._pending_since is None:
                self._pending_since = now
            elif now - self._pending_since > self.window:
                return f'stall: move pending for {now - self._pending_since:.1f} s but the motor is not moving'
        else:
            self._pending_since = None
        return None


# --------------------------------------------------------------------------- supervisor
HOME_SWITCHES = {'low': 0, 'high': 1, 'sleep': 2}   # messages.Switch indices
#: STATUS.fault_bits that make the driver latch a fault (docs/protocol.md FaultBits)
BOARD_FAULT_STALL = 1 << 2
BOARD_FAULT_DRIVER = 1 << 4


@dataclass(frozen=True)
class BoardState:
    """What the driver knows of the board from its last STATUS (docs/protocol.md).

    steps, target : step counter and board target [steps]; moving, homed, homing :
    status flags; sensor : joint angle from the board's sensor [rad] or None;
    limit_bits, fault_bits : as reported.
    """

    steps: int
    target: int
    moving: bool
    homed: bool
    homing: bool
    sensor: float | None
    limit_bits: int = 0
    fault_bits: int = 0


@dataclass(frozen=True)
class Action:
    """One board command decided by :class:`AxisSupervisor`.

    kind : 'none' | 'stop' | 'home' | 'set_zero' | 'move'
    steps : MOVE_TO target or SET_ZERO / HOME position [steps]
    speed : MOVE_TO / HOME step rate [steps/s] (HOME: signed, + increases steps)
    switch : HOME limit switch index (``HOME_SWITCHES``: low 0, high 1, sleep 2)
    """

    kind: str = 'none'
    steps: int = 0
    speed: float = 0.0
    switch: int = 0


@dataclass
class AxisConfig:
    """Validated tuning of one axis (the node's parameters, in SI units).

    Attributes
    ----------
    axis : str
        mirrors | mobile_structure | secondary_reflector.
    calibration : Calibration
    limits : SoftLimits
        Soft limits [rad].
    max_speed, min_speed : float
        Joint speed bounds of a MOVE_TO [rad/s].
    lead : float
        How far ahead of now the setpoint is commanded [s] (one control period).
    stow_position : float
        Defocus / sleeping position for STOW [rad].
    home_switch : str
        'low' | 'high' | 'sleep': the limit switch HOME drives toward.
    home_position : float
        Joint angle at which that switch closes [rad].
    home_speed : float
        |speed| of a homing move [rad/s].
    use_sensor : bool
        Re-establish a lost position from the board's position sensor (SET_ZERO)
        instead of a homing move, and report the sensor as the measured angle.
    auto_home : bool
        Home by itself when the board lost its position (else wait for the home service).
    ref_samples : int
        Sensor readings (at rest, one per tick) averaged for a SET_ZERO [-].
    """

    axis: str
    calibration: Calibration
    limits: SoftLimits
    max_speed: float
    min_speed: float
    lead: float
    stow_position: float
    home_switch: str
    home_position: float
    home_speed: float
    use_sensor: bool = True
    auto_home: bool = True
    ref_samples: int = 5


class AxisSupervisor:
    """Per-tick decision of the axis driver: board state + inputs -> one board command.

    Inputs kept here: the trajectory store, the safety watchdog, the operator mode
    (from tracker/phase), a jog target, a latched driver fault. :meth:`tick` is
    called at the control rate with ROS time (trajectory) and steady time (watchdogs).

    Priority (first match wins): inactive -> stop if moving; latched fault -> stop;
    safety STOP (missing heartbeat, ESTOP, axis listed) -> stop; homing in progress ->
    wait; position lost -> SET_ZERO from the sensor or HOME; stall / lost steps ->
    latch fault and stop; safety STOW -> stow position; maintenance -> jog target or
    hold; manual -> hold; trajectory -> setpoint(now + lead); none -> hold.
    """

    def __init__(self, cfg: AxisConfig, safety_timeout: float = 1.0,
                 stall: StallDetector | None = None):
        self.cfg = cfg
        self.store = TrajectoryStore()
        self.safety = SafetyWatch(cfg.axis, safety_timeout)
        self.stall = stall or StallDetector(tolerance=0.005, window=1.0, min_motion=0.01)
        self.mode = 'auto'          # auto | manual | maintenance | stow (from tracker/phase)
        self.jog_target: float | None = None
        self.fault: str | None = None
        self.home_requested = False
        self.state = 'unconfigured'
        self.reason = ''
        self.commanded: float = float('nan')     # last joint angle commanded [rad]
        self.setpoint: float = float('nan')      # trajectory setpoint for now [rad]
        self.last_known: float | None = None      # last referenced joint angle [rad]
        self._cmd_steps: int | None = None       # last MOVE_TO target [steps]
        self._ref: list[float] = []               # sensor samples for SET_ZERO [rad]
        self._cmd_speed: float = 0.0

    # -- helpers ------------------------------------------------------------
    def measured(self, board: BoardState) -> float:
        """Measured joint angle [rad]: sensor when present and used, else steps."""
        if self.cfg.use_sensor and board.sensor is not None:
            return board.sensor
        return self.cfg.calibration.angle(board.steps)

    def clear_fault(self) -> None:
        """Clear the latched fault and the stall history."""
        self.fault = None
        self.stall.reset()

    def position_lost(self) -> None:
        """The board reset / reconnected without its reference: forget commands."""
        self._cmd_steps = None
        self._ref.clear()
        self.stall.reset()

    def _stop(self, board: BoardState, state: str, reason: str) -> Action:
        """STOP when the board moves, has a command pending or homes, and always once on
        entering a stop state (the polled ``moving`` may be a tick old: a safety stop must
        show on the wire)."""
        entering = self.state != state
        self.state, self.reason = state, reason
        pending = self._cmd_steps is not None
        self._cmd_steps = None
        if board.moving or pending or board.homing or entering:
            return Action('stop')
        return Action()

    def _home_action(self, board: BoardState) -> Action:
        """Re-reference: SET_ZERO at the mean of ``ref_samples`` sensor readings taken
        at rest (returns no action while collecting), else HOME toward the switch."""
        cfg, cal = self.cfg, self.cfg.calibration
        if cfg.use_sensor and board.sensor is not None:
            self.state, self.reason = 'homing', 'position lost: re-establishing it from the position sensor'
            if board.moving:
                self._ref.clear()
                return Action('stop')
            self._ref.append(board.sensor)
            if len(self._ref) < cfg.ref_samples:
                return Action()
            mean = sum(self._ref) / len(self._ref)
            self._ref.clear()
            return Action('set_zero', cal.steps(mean))
        direction = self._home_direction(board)          # joint direction toward the switch
        rate = cal.step_rate(cfg.home_speed) * direction * (1.0 if cal.joint_per_step > 0 else -1.0)
        self.state, self.reason = 'homing', f'homing toward the {cfg.home_switch} switch'
        return Action('home', cal.steps(cfg.home_position), rate, HOME_SWITCHES[cfg.home_switch])

    def _home_direction(self, board: BoardState) -> float:
        """Joint direction (+1 / -1) toward the home switch.

        'low' -> -1, 'high' -> +1. 'sleep' may lie inside the range (0 rad on the
        structure and reflector axes): go toward it from the last known angle
        (``home_position - last_known``), +1 when unknown; after a homing attempt
        that ended on an end switch (LOW/HIGH closed) go the other way.
        """
        sw = self.cfg.home_switch
        if sw == 'low':
            return -1.0
        if sw == 'high':
            return 1.0
        if board.limit_bits & 0x2:          # HIGH closed: the switch is below
            return -1.0
        if board.limit_bits & 0x1:          # LOW closed: it is above
            return 1.0
        if self.last_known is not None and self.last_known > self.cfg.home_position:
            return -1.0
        return 1.0

    def _move(self, board: BoardState, target: float, state: str, reason: str = '') -> Action:
        cfg, cal = self.cfg, self.cfg.calibration
        target = cfg.limits.clamp(target)
        steps = cal.steps(target)
        self.state, self.reason = state, reason
        self.commanded = cal.angle(steps)
        speed = move_speed(self.measured(board), target, cfg.lead, cfg.max_speed, cfg.min_speed)
        rate = max(1.0, cal.step_rate(speed))
        if steps == board.steps and not board.moving:
            self._cmd_steps = None
            return Action()
        if (self._cmd_steps == steps and board.target == steps and board.moving):
            return Action()          # already going there
        self._cmd_steps, self._cmd_speed = steps, rate
        return Action('move', steps, rate)

    # -- the decision -----------------------------------------------------------
    def tick(self, now_ros: float, now_steady: float, board: BoardState | None,
             active: bool, time_rate: float = 1.0) -> Action:
        """Decide the next board command.

        Parameters
        ----------
        now_ros : float
            ROS time [s since the Unix epoch] (trajectory time base).
        now_steady : float
            Steady clock [s] (safety watchdog, stall windows).
        board : BoardState or None
            Last STATUS, None when the link is down (nothing can be sent then).
        active : bool
            Lifecycle state is active (following allowed).
        time_rate : float
            ROS seconds per steady second (1 in real time; e.g. 400 in a simulated
            day). The setpoint is taken ``lead * time_rate`` ROS seconds ahead so
            the board (which moves in wall time) reaches it in one control period.
        """
        sp = self.store.setpoint(now_ros)
        self.setpoint = sp[0] if sp is not None else float('nan')
        if board is None:
            self.state, self.reason = 'link_down', 'no answer from the board'
            self._cmd_steps = None
            return Action()
        if board.homed and not board.homing:
            self.last_known = self.measured(board)
        if not active:
            return self._stop(board, 'inactive', 'lifecycle state is not active')
        if self.fault:
            return self._stop(board, 'fault', self.fault)
        verdict, why = self.safety.verdict(now_steady)
        if verdict is SafetyVerdict.STOP:
            return self._stop(board, 'stopped', why)
        if board.homing:
            self.state, self.reason = 'homing', 'homing in progress'
            self._cmd_steps = None
            return Action()
        if not board.homed:
            self._cmd_steps = None
            if self.cfg.auto_home or self.home_requested or (self.cfg.use_sensor and board.sensor is not None):
                act = self._home_action(board)
                self.home_requested = self.home_requested and act.kind in ('none', 'stop')
                return act
            self.state, self.reason = 'fault', 'position lost: call the home service'
            return Action()
        if self.home_requested:
            act = self._home_action(board)
            self.home_requested = act.kind in ('none', 'stop')
            return act
        self._ref.clear()
        hard = board.fault_bits & (BOARD_FAULT_STALL | BOARD_FAULT_DRIVER)
        if hard:
            self.fault = (f'board reports fault bits {board.fault_bits:#06x} '
                          f'({"stall" if hard & BOARD_FAULT_STALL else ""}'
                          f'{" driver" if hard & BOARD_FAULT_DRIVER else ""})').replace('( ', '(')
            return self._stop(board, 'fault', self.fault)
        pending = self._cmd_steps is not None and abs(self._cmd_steps - board.steps) > 1
        cal = self.cfg.calibration
        problem = self.stall.update(now_steady, cal.angle(board.steps),
                                    board.sensor if self.cfg.use_sensor else None,
                                    board.moving, pending)
        if problem:
            self.fault = problem
            return self._stop(board, 'fault', problem)
        if verdict is SafetyVerdict.STOW or self.mode == 'stow':
            return self._move(board, self.cfg.stow_position, 'stowing', why or 'stow mode')
        if self.mode == 'maintenance':
            if self.jog_target is not None:
                return self._move(board, self.jog_target, 'jogging', 'maintenance jog')
            return self._hold(board, 'maintenance: automatic motion off')
        if self.mode == 'manual':
            return self._hold(board, 'manual mode: holding')
        if sp is None:
            return self._hold(board, 'no trajectory yet')
        if sp[2] == 'starved':
            return self._move(board, sp[0], 'holding', 'trajectory starved: holding its last position')
        ahead = self.store.setpoint(now_ros + self.cfg.lead * max(0.0, time_rate))
        return self._move(board, ahead[0], 'following' if sp[2] == 'following' else 'waiting')

    def _hold(self, board: BoardState, reason: str) -> Action:
        """Hold: finish nothing new; stop if the board is still moving."""
        self.state, self.reason = 'holding', reason
        self._cmd_steps = None
        return Action('stop') if board.moving else Action()
