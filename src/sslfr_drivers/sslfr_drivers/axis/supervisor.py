"""The axis driver's per-tick decision (no rclpy): board state + inputs -> one board
command (:class:`AxisSupervisor`), with its tuning and its published snapshot.

Angles are joint angles [rad] (REP-103, docs/architecture.md axis conventions),
motor positions integer steps, trajectory times ROS seconds since the Unix epoch,
watchdog times steady-clock seconds. The node runs read -> update -> write: the board
session reads a :class:`BoardState`, :meth:`AxisSupervisor.tick` decides one
:class:`Action`, the session writes it and :meth:`AxisSupervisor.record_write` books it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from sslfr_drivers.axis.commands import (BOARD_FAULT_DRIVER, BOARD_FAULT_STALL, NOTHING, STOP, Action,
                                         ActionKind, BoardState)
from sslfr_drivers.axis.drive import drive_for
from sslfr_drivers.axis.joint import Calibration, SoftLimits, move_speed
from sslfr_drivers.axis.operator_input import check_jog
from sslfr_drivers.axis.rates import setpoint_wait
from sslfr_drivers.axis.safety_watch import SafetyVerdict, SafetyWatch
from sslfr_drivers.axis.stall import StallDetector
from sslfr_drivers.axis.trajectory import TrajectoryStore

#: The driver's counters (diagnostics keys) [-].
COUNTERS = ('trajectories_accepted', 'trajectories_rejected', 'moves_sent', 'nacks', 'nacks_not_homed',
            'stops_sent', 'homes_sent', 'set_zero_sent', 'request_timeouts', 'reconnects',
            'board_resets', 'faults')
_SENT = {ActionKind.MOVE: 'moves_sent', ActionKind.STOP: 'stops_sent', ActionKind.HOME: 'homes_sent',
         ActionKind.SET_ZERO: 'set_zero_sent'}


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
    drive : str
        The drive kind (:mod:`sslfr_drivers.axis.drive`): how the position is
        re-established and when a target counts as reached.
    deadband : float
        Position deadband of a closed-loop drive [rad] (linear actuator), else 0.
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
    drive: str = 'stepper_switches'
    deadband: float = 0.0
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
    It also books the board's answers and decides the operator's requests.

    Priority (first match wins): inactive -> stop if moving; latched fault -> stop;
    safety STOP (missing heartbeat, ESTOP, axis listed) -> stop; homing in progress ->
    wait; position lost -> SET_ZERO from the sensor or HOME; stall / lost steps ->
    latch fault and stop; safety STOW -> stow position; maintenance -> jog target or
    hold; manual -> hold; trajectory -> setpoint(now + lead); none -> hold.
    """

    def __init__(self, cfg: AxisTuning, safety_timeout: float = 1.0,
                 stall: StallDetector | None = None):
        self.cfg = cfg
        self.drive = drive_for(cfg.drive)
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
        unknown (no board, or not referenced and no used position sensor: a step count
        from 0 is no angle). While homing the step count is published (relative travel:
        the safety supervisor judges stuck switches on it)."""
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

    def stop(self, board: BoardState, state: str, reason: str) -> Action:
        """The one stop decision of every cause (inactive, fault, safety, e-stop, lost
        heartbeat): enter ``state`` for ``reason``; STOP when the board moves, has a command
        pending or homes, and always once on entering a stop state (the polled ``moving``
        may be a tick old: a stop must show on the wire)."""
        entering = self.state != state
        self.state, self.reason = state, reason
        pending = self._cmd_steps is not None
        self._cmd_steps = None
        if board.moving or pending or board.homing or entering:
            return STOP
        return NOTHING

    def _home_action(self, board: BoardState) -> Action:
        act, self.reason = self.drive.reference(self.cfg, board, self._ref, self.last_known,
                                                self.home_requested)
        self.state = 'homing'
        return act

    def _move(self, board: BoardState, target: float, state: str, reason: str = '') -> Action:
        cfg, cal = self.cfg, self.cfg.calibration
        target = cfg.limits.clamp(target)
        steps = cfg.limits.steps(cal, target, self.drive.range_margin(cfg))
        self.state, self.reason = state, reason
        self.commanded = cal.angle(steps)
        speed = move_speed(self.measured(board), target, cfg.lead, cfg.max_speed, cfg.min_speed)
        rate = max(1.0, cal.step_rate(speed))
        if not board.moving and self.drive.settled(cfg, steps, board.steps):
            self._cmd_steps = None
            return NOTHING
        if (self._cmd_steps == steps and board.target == steps and board.moving):
            return NOTHING           # already going there
        self._cmd_steps, self._cmd_speed = steps, rate
        return Action(ActionKind.MOVE, steps, rate)

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
            return NOTHING
        if board.homed and not board.homing:
            self.last_known = self.measured(board)
        if not active:
            return self.stop(board, 'inactive', 'lifecycle state is not active')
        if self.fault:
            return self.stop(board, 'fault', self.fault)
        verdict, why = self.safety.verdict(now_steady)
        if verdict is SafetyVerdict.STOP:
            return self.stop(board, 'stopped', why)
        if board.homing:
            self.state, self.reason = 'homing', 'homing in progress'
            self._cmd_steps = None
            return NOTHING
        if not board.homed:
            self._cmd_steps = None
            if self.home_requested or self.drive.references_itself(self.cfg, board):
                act = self._home_action(board)
                self.home_requested = self.home_requested and act.kind in (ActionKind.NONE, ActionKind.STOP)
                return act
            self.state, self.reason = 'fault', 'position lost: call the home service'
            return NOTHING
        if self.home_requested:
            act = self._home_action(board)
            self.home_requested = act.kind in (ActionKind.NONE, ActionKind.STOP)
            return act
        self._ref.clear()
        hard = board.fault_bits & (BOARD_FAULT_STALL | BOARD_FAULT_DRIVER)
        if hard:
            self._latch((f'board reports fault bits {board.fault_bits:#06x} '
                         f'({"stall" if hard & BOARD_FAULT_STALL else ""}'
                         f'{" driver" if hard & BOARD_FAULT_DRIVER else ""})').replace('( ', '('))
            return self.stop(board, 'fault', self.fault)
        pending = self._cmd_steps is not None and not self.drive.reached(self.cfg, self._cmd_steps, board.steps)
        cal = self.cfg.calibration
        problem = self.stall.update(now_steady, cal.angle(board.steps),
                                    board.sensor if self.cfg.use_sensor else None,
                                    board.moving, pending)
        if problem:
            self._latch(problem)
            return self.stop(board, 'fault', problem)
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
        """Steady seconds [s] until the next control tick: ``fast`` (the control period)
        while anything is under way (no board answer, moving, homing, not homed, a command
        not reached, a re-referencing); else the first of ``slow`` (the idle STATUS poll),
        the safety watchdog's next deadline and the setpoint's next motor step
        (:func:`~.rates.setpoint_wait`), never below ``fast``. Events wake the tick anyway."""
        if (board is None or board.moving or board.homing or not board.homed or self._cmd_steps is not None
                or self.home_requested or self._ref):
            return fast
        wait = min(slow, self.safety.next_deadline(now_steady))
        if self.state in ('following', 'waiting'):
            step = setpoint_wait(self.store, self.cfg, now_ros, time_rate, slow)
            if step is None:
                return fast     # a step per idle period or more (a fast simulation): no prediction
            wait = min(wait, step)
        return max(fast, wait)

    def _hold(self, board: BoardState, reason: str) -> Action:
        """Hold: finish nothing new; stop if the board is still moving."""
        self.state, self.reason = 'holding', reason
        self._cmd_steps = None
        return STOP if board.moving else NOTHING

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
        return self.last_error if act.kind != ActionKind.MOVE or failures % 20 == 1 else None

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
        return True, f'{self.drive.home_message(self.cfg)}; watch axes/{self.cfg.axis}/status'

    def request_jog(self, delta: float, speed: float, board: BoardState | None, active: bool,
                    max_jog: float) -> tuple[bool, str, float]:
        """The jog service: ``(accepted, message, target [rad])``. Refused as
        :func:`~.operator_input.check_jog` says, or when the target (the pending jog
        target, else the measured angle, + ``delta`` [rad]) leaves the soft limits. Jogs
        add up: a second jog starts from the first one's target."""
        why = check_jog(self.mode, active, board, self.fault, delta, speed, max_jog)
        if why:
            return False, why, math.nan
        base = self.jog_target if self.jog_target is not None else self.measured(board)
        target = base + delta
        if not self.cfg.limits.contains(target):
            return False, f'jog refused: target {target:.4f} rad outside soft limits', math.nan
        self.jog_target = target
        return True, 'jogging', target
