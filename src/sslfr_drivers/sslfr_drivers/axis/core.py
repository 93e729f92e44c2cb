"""Pure decision core of the axis driver (no rclpy): safety watchdog, stall / lost-step
detection, the per-tick supervisor and the node's small decisions (operator mode,
home and jog requests, the ROS/steady time rate, the diagnostics verdict).

Everything here works on plain numbers so it can be unit-tested on values:

- angles are joint angles in radians (REP-103), the axis conventions of
  docs/architecture.md (``mirrors`` = beta_0 = theta_t / 2, seed 000 eq. 11,
  +pi/2 = sleeping position; ``mobile_structure`` = beta_M, ``secondary_reflector``
  = beta_a);
- motor positions are integer steps of the board's step counter;
- trajectory times are float seconds since the Unix epoch (ROS time, UTC);
- watchdog times are float seconds of a steady (monotonic) clock.

The node (``axis_driver_node``) runs read -> update -> write at the control rate:
the board session reads a :class:`BoardState`, :meth:`AxisSupervisor.tick` decides
one :class:`Action`, the session writes it and :meth:`AxisSupervisor.record_write`
books the result. Joint geometry lives in :mod:`.joint`, the trajectory and its one
validation in :mod:`.trajectory`, the parameters in :mod:`.params`.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import NamedTuple

from sslfr_common.contract import Level, Phase

from sslfr_drivers.axis.joint import Calibration, SoftLimits, move_speed
from sslfr_drivers.axis.trajectory import TrajectoryStore


# --------------------------------------------------------------------------- safety
class SafetyVerdict(enum.Enum):
    FOLLOW = 'follow'
    STOW = 'stow'
    STOP = 'stop'


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
    level: int = Level.OK
    stow_required: bool = False
    stopped_axes: tuple = ()
    reasons: tuple = ()
    wind_stow: bool = False

    def receive(self, now_steady: float, level: int, stow_required: bool, stopped_axes,
                sequence: int, reasons=(), wind_stow: bool = False) -> bool:
        """Record a SafetyState; return True when it was fresh (new sequence)."""
        self.wind_stow = bool(wind_stow)
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
        if self.level == Level.ESTOP and not self.stopped_axes:
            return SafetyVerdict.STOP, 'safety ESTOP: ' + '; '.join(self.reasons)
        if self.axis in self.stopped_axes:
            return SafetyVerdict.STOP, f'safety stops axis {self.axis}: ' + '; '.join(self.reasons)
        if self.stow_required or self.level == Level.STOW:
            return SafetyVerdict.STOW, 'safety requires stow: ' + '; '.join(self.reasons)
        return SafetyVerdict.FOLLOW, ''

    def wind_pose(self, now_steady: float) -> bool:
        """True when a STOW goes to the wind pose: the last fresh message said the stow
        is for wind only (a fail-safe stow on silence goes to the stow position)."""
        return self.wind_stow and self.last_rx is not None and now_steady - self.last_rx <= self.timeout


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
#: The driver's counters (diagnostics keys) [-].
COUNTERS = ('trajectories_accepted', 'trajectories_rejected', 'moves_sent', 'nacks', 'nacks_not_homed',
            'stops_sent', 'homes_sent', 'set_zero_sent', 'request_timeouts', 'reconnects',
            'board_resets', 'faults')
_SENT = {'move': 'moves_sent', 'stop': 'stops_sent', 'home': 'homes_sent', 'set_zero': 'set_zero_sent'}
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
class AxisTuning:
    """Validated tuning of one axis (the node's parameters, in SI units; built by
    :func:`sslfr_drivers.axis.params.tuning_from`).

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
    wind_stow_position : float or None
        Position of a wind stow (safety's ``wind_stow``) [rad]; None: ``stow_position``.
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
    wind_stow_position: float | None = None


class Snapshot(NamedTuple):
    """What one control tick decided and saw (immutable: read by the status heartbeat
    without waiting for the tick): ROS time of the tick [s] (0 before the first),
    supervisor state, commanded / setpoint / measured joint angles [rad] (NaN when
    unknown) and the board state."""

    stamp: float = 0.0
    state: str = 'unconfigured'
    commanded: float = math.nan
    setpoint: float = math.nan
    measured: float = math.nan
    board: BoardState | None = None


class AxisSupervisor:
    """Per-tick decision of the axis driver: board state + inputs -> one board command.

    Inputs kept here: the trajectory store, the safety watchdog, the operator mode
    (from tracker/phase), a jog target, a latched driver fault. :meth:`tick` is
    called at the control rate with ROS time (trajectory) and steady time (watchdogs).

    Besides :meth:`tick` it books the board's answers (:meth:`record_write`,
    :meth:`note_link_events`) and decides the operator requests (:meth:`set_mode`,
    :meth:`request_home`, :meth:`request_jog`).

    Priority (first match wins): inactive -> stop if moving; latched fault -> stop;
    safety STOP (missing heartbeat, ESTOP, axis listed) -> stop; homing in progress ->
    wait; position lost -> SET_ZERO from the sensor or HOME; stall / lost steps ->
    latch fault and stop; safety STOW -> stow position; maintenance -> jog target or
    hold; manual -> hold; trajectory -> setpoint(now + lead); none -> hold.
    """

    def __init__(self, cfg: AxisTuning, safety_timeout: float = 1.0,
                 stall: StallDetector | None = None):
        self.cfg = cfg
        self.store = TrajectoryStore()
        self.safety = SafetyWatch(cfg.axis, safety_timeout)
        self.stall = stall or StallDetector(tolerance=0.005, window=1.0, min_motion=0.01)
        self.mode = 'auto'          # auto | manual | maintenance (operator_mode of tracker/phase)
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
        self.counters: dict[str, int] = dict.fromkeys(COUNTERS, 0)
        self.last_error = ''                      # last command the board refused / did not answer
        self._new_fault: str | None = None

    # -- helpers ------------------------------------------------------------
    def measured(self, board: BoardState) -> float:
        """Measured joint angle [rad]: sensor when present and used, else steps."""
        if self.cfg.use_sensor and board.sensor is not None:
            return board.sensor
        return self.cfg.calibration.angle(board.steps)

    def known_position(self, board: BoardState | None) -> float:
        """The measured joint angle [rad] as published: NaN while the position is
        unknown, i.e. no board, or a board that is not referenced (not homed, after power-up
        or a reset: its step counter starts from 0 wherever the axis is) without a used
        position sensor. While homing the step count is published (relative travel: the
        safety supervisor judges stuck switches on it). A step count published as an
        angle before referencing once made the safety supervisor judge the mirrors'
        sleeping switch, closed at dawn, as tripped 90 deg away from the mirrors."""
        if board is None:
            return math.nan
        if not board.homed and not board.homing and self.state != 'homing' \
                and not (self.cfg.use_sensor and board.sensor is not None):
            return math.nan
        return self.measured(board)

    def snapshot(self, now_ros: float, board: BoardState | None) -> Snapshot:
        """The :class:`Snapshot` after the tick at ROS time ``now_ros`` [s] that saw ``board``."""
        measured = self.known_position(board)
        return Snapshot(now_ros, self.state, float(self.commanded), float(self.setpoint), float(measured), board)

    def counts(self) -> dict[str, int]:
        """Every counter of :data:`COUNTERS` (trajectories from the store) [-]."""
        return {**self.counters, 'trajectories_accepted': self.store.accepted,
                'trajectories_rejected': self.store.rejected}

    def _latch(self, problem: str) -> None:
        self.fault = problem
        self.counters['faults'] += 1
        self._new_fault = problem

    def take_new_fault(self) -> str | None:
        """The fault latched since the last call (to log once), or None."""
        fault, self._new_fault = self._new_fault, None
        return fault

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
            self._latch((f'board reports fault bits {board.fault_bits:#06x} '
                         f'({"stall" if hard & BOARD_FAULT_STALL else ""}'
                         f'{" driver" if hard & BOARD_FAULT_DRIVER else ""})').replace('( ', '('))
            return self._stop(board, 'fault', self.fault)
        pending = self._cmd_steps is not None and abs(self._cmd_steps - board.steps) > 1
        cal = self.cfg.calibration
        problem = self.stall.update(now_steady, cal.angle(board.steps),
                                    board.sensor if self.cfg.use_sensor else None,
                                    board.moving, pending)
        if problem:
            self._latch(problem)
            return self._stop(board, 'fault', problem)
        if verdict is SafetyVerdict.STOW:
            wind = self.cfg.wind_stow_position is not None and self.safety.wind_pose(now_steady)
            return self._move(board, self.cfg.wind_stow_position if wind else self.cfg.stow_position,
                              'stowing', why)
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

    def next_tick(self, now_ros: float, now_steady: float, board: BoardState | None,
                  time_rate: float, fast: float, slow: float) -> float:
        """Steady seconds [s] until the next control tick (rates from the physics).

        ``fast`` (the control period) while anything is under way: no board answer,
        the board moving or homing or not homed, a command not yet reached, a homing
        or re-referencing requested. Otherwise nothing needs the board before the
        first of: ``slow`` (the idle STATUS poll), the safety watchdog's next deadline
        (silence -> STOP, then -> STOW; :class:`SafetyWatch`), and, while following,
        the instant the commanded setpoint (``lead * time_rate`` ahead) crosses to the
        next step (from the trajectory's velocity; a trajectory, safety or mode event
        wakes the tick at once anyway). While the setpoint moves a step or more per
        ``slow`` (a simulation many times faster than real time, where ``time_rate`` is
        estimated from a /clock that jumps) it stays at ``fast``. Never below ``fast``:
        the previous fixed-rate behaviour is the fastest this gets.
        """
        if (board is None or board.moving or board.homing or not board.homed or self._cmd_steps is not None
                or self.home_requested or self._ref):
            return fast
        wait = slow
        w = self.safety
        if w.last_rx is not None:
            age = now_steady - w.last_rx
            for deadline in (w.timeout, w.timeout + w.silent_stow_after):
                if deadline >= age:
                    wait = min(wait, deadline - age + 1e-3)
        if self.state in ('following', 'waiting') and time_rate > 0.0:
            t = now_ros + self.cfg.lead * time_rate
            sp = self.store.setpoint(t)
            cal = self.cfg.calibration
            if sp is not None and sp[2] == 'waiting' and self.store.current is not None:
                wait = min(wait, (self.store.current.start - t) / time_rate)
            elif sp is not None and sp[2] == 'following' and sp[1] != 0.0:
                x = (self.cfg.limits.clamp(sp[0]) - cal.offset) / cal.joint_per_step   # [steps]
                v = sp[1] / cal.joint_per_step                                           # [steps/s ROS]
                if abs(v) * time_rate * slow >= 1.0:
                    return fast     # a step per idle period or more (a fast simulation): no prediction
                boundary = round(x) + (0.5 if v > 0 else -0.5)
                wait = min(wait, max(0.0, (boundary - x) / v) / time_rate + 1e-3)
        return max(fast, wait)

    def _hold(self, board: BoardState, reason: str) -> Action:
        """Hold: finish nothing new; stop if the board is still moving."""
        self.state, self.reason = 'holding', reason
        self._cmd_steps = None
        return Action('stop') if board.moving else Action()

    # -- the board's answers ----------------------------------------------------
    def note_link_events(self, reset: bool, reconnected: bool) -> list[str]:
        """Book a board reset / a reopened port (the position must be re-established);
        return the warnings to log."""
        out = []
        if reset:
            self.counters['board_resets'] += 1
            self.position_lost()
            out.append('board reset or reconnected: position must be re-established')
        if reconnected:
            self.counters['reconnects'] += 1
            self.position_lost()
            out.append('link re-established')
        return out

    def record_write(self, act: Action, ok: bool, detail: str = '', nack: bool = False) -> str | None:
        """Book the result of sending ``act``: counted per kind; a refusal (``nack``,
        ``detail`` = the ErrorCode name) or an unanswered command forgets the commands
        (position lost). Returns the warning to log: every failure of a non-move, one
        in 20 of failed moves (a board refusing moves refuses each tick)."""
        self.counters[_SENT[act.kind]] += 1
        if ok:
            return None
        if nack:
            self.counters['nacks'] += 1
            self.counters['nacks_not_homed'] += detail == 'NOT_HOMED'
            self.last_error = f'{act.kind} refused by the board: {detail}'
        else:
            self.counters['request_timeouts'] += 1
            self.last_error = f'{act.kind} not answered by the board: {detail}'
        self.position_lost()
        failures = self.counters['nacks'] + self.counters['request_timeouts']
        return self.last_error if act.kind != 'move' or failures % 20 == 1 else None

    # -- operator requests --------------------------------------------------------
    def set_mode(self, mode: str) -> bool:
        """Operator mode from :func:`operator_mode`; leaving maintenance drops the jog
        target. True when it changed."""
        if mode == self.mode:
            return False
        if mode != 'maintenance':
            self.jog_target = None
        self.mode = mode
        return True

    def request_home(self, ready: bool) -> tuple[bool, str]:
        """The home service: ``(accepted, message)``; ``ready`` = lifecycle active with
        a board session. Clears a latched fault."""
        if not ready:
            return False, 'driver not active'
        self.clear_fault()
        self.home_requested = True
        return True, (f'homing toward the {self.cfg.home_switch} switch '
                      f'(or re-referencing from the sensor); watch axes/{self.cfg.axis}/status')

    def request_jog(self, delta: float, speed: float, board: BoardState | None, active: bool,
                    max_jog: float) -> tuple[bool, str, float]:
        """The jog service: ``(accepted, message, target [rad])``.

        Refused, in this order: not in maintenance mode; not active or no board
        answer; a latched fault; axis not homed; ``delta`` [rad] not finite or
        ``|delta| > max_jog``; ``speed`` [rad/s] not finite or negative; the target
        (the pending jog target, else the measured angle, + ``delta``) outside the
        soft limits. Jogs add up: a second jog starts from the first one's target.
        """
        if self.mode != 'maintenance':
            return False, 'jog refused: not in maintenance mode (tracker/phase)', math.nan
        if not active or board is None:
            return False, 'jog refused: driver not active or board not answering', math.nan
        if self.fault:
            return False, f'jog refused: fault: {self.fault}', math.nan
        if not board.homed:
            return False, 'jog refused: axis not homed', math.nan
        if not math.isfinite(delta) or abs(delta) > max_jog:
            return False, f'jog refused: |delta| must be finite and <= max_jog {max_jog:.4f} rad', math.nan
        if not math.isfinite(speed) or speed < 0:
            return False, 'jog refused: speed must be finite and >= 0', math.nan
        base = self.jog_target if self.jog_target is not None else self.measured(board)
        target = base + delta
        if not self.cfg.limits.contains(target):
            return False, f'jog refused: target {target:.4f} rad outside soft limits', math.nan
        self.jog_target = target
        return True, 'jogging', target


# --------------------------------------------------------------------------- node decisions
def operator_mode(phase: int, mode: str) -> str:
    """Operator mode of the driver from ``tracker/phase``: ``'maintenance'`` (phase
    MAINTENANCE or mode maintenance: automatic motion off, jog allowed), ``'manual'``
    (phase MANUAL or mode manual: hold), else ``'auto'`` (follow the trajectory; the
    planner plans the stows)."""
    if phase == Phase.MAINTENANCE or mode == 'maintenance':
        return 'maintenance'
    if phase == Phase.MANUAL or mode == 'manual':
        return 'manual'
    return 'auto'


class TimeRate:
    """ROS seconds per steady second, smoothed: 1 in real time, e.g. 400 in a
    simulated day; the supervisor takes its setpoint ``lead * rate`` ROS seconds ahead.

    Each :meth:`update` with a pair of clock readings moves the estimate by ``gain``
    toward the rate since the previous pair; a clock jump (ROS time going back, or
    faster than ``max_rate``: a replay restarting, the time being set) is ignored.
    """

    def __init__(self, gain: float = 0.3, max_rate: float = 1e5, min_interval: float = 0.04) -> None:
        self.rate = 1.0
        self.gain = gain
        self.max_rate = max_rate
        self.min_interval = min_interval
        self._last: tuple[float, float] | None = None

    def update(self, now_ros: float, now_steady: float) -> float:
        """Feed ROS time [s] and steady time [s]; return the rate [-]. A pair less than
        ``min_interval`` [s] after the reference is not used (a control step woken by
        an event just after a /clock jump would read a rate of thousands)."""
        if self._last is not None and now_steady - self._last[1] < self.min_interval:
            return self.rate
        last, self._last = self._last, (now_ros, now_steady)
        if last is None or now_steady - last[1] <= 0.0:
            return self.rate
        inst = (now_ros - last[0]) / (now_steady - last[1])
        if 0.0 <= inst <= self.max_rate:
            self.rate += self.gain * (inst - self.rate)
        return self.rate


#: diagnostic_msgs/DiagnosticStatus levels (tested equal to the message's).
DIAG_OK, DIAG_WARN, DIAG_ERROR = 0, 1, 2


def diagnostic_verdict(lifecycle: str, sup: AxisSupervisor, connected: bool,
                       last_error: str) -> tuple[int, str]:
    """Level and message of the driver's diagnostics status.

    ERROR: a latched fault, or no board session after a failed attempt
    (``last_error``); WARN: lifecycle not active, or active but stopped by safety,
    link down or holding; OK otherwise (following, waiting, stowing, jogging, homing).
    """
    if sup.fault or (not connected and last_error):
        return DIAG_ERROR, sup.fault or last_error
    if lifecycle != 'active':
        return DIAG_WARN, f'{lifecycle}: {last_error or "not active"}'
    if sup.state in ('stopped', 'link_down', 'holding'):
        return DIAG_WARN, f'{sup.state}: {sup.reason}'
    return DIAG_OK, f'{sup.state} {sup.reason}'.strip()
