"""``axis_driver``: lifecycle node driving one SSLFR axis board (stepper + sensor).

One instance per axis (parameter ``axis`` = mirrors | mobile_structure |
secondary_reflector; node names ``<axis>_driver`` by convention, set with
``-r __node:=mirrors_driver``). The decisions are made by the pure core
:class:`sslfr_drivers.axis.core.AxisSupervisor`; this file only wires ROS and the
board link (:class:`sslfr_drivers.link.board_link.BoardLink`, protocol in docs/protocol.md).

Lifecycle (rclpy.lifecycle, as ros2/demos lifecycle_py):

- configure: open the link on ``port``, read INFO (an old protocol version or a
  board that is not an axis board is refused with the reason, and the node stays
  unconfigured), read STATUS;
- activate: follow ``tracker/trajectory``;
- deactivate: STOP the motor (the node keeps polling and reporting);
- cleanup: STOP and close the link; shutdown: the same.

``autostart`` (default false, the ROS convention that a manager drives lifecycle
nodes): when true the node configures itself at start, retrying every
``retry_period`` seconds while no board answers, and then activates. Without it use
``lifecycle_ctl set active <node>`` (sslfr_drivers.axis.lifecycle_ctl) or call
``<node>/change_state``.

Operator mode comes from ``tracker/phase`` (TL1): phase MAINTENANCE (or mode
``maintenance``) turns automatic motion off and enables ``axes/<axis>/jog``; MANUAL
holds; STOW / STOWING leave following to the planner's trajectory (the planner
publishes the stow motion); a safety STOW always wins. With no tracker/phase
received the driver is in ``auto``.

Board heartbeat: the STATUS poll at ``control_rate`` (a valid frame every 50 ms by
default) feeds the board's 1 s watchdog; a PING is sent when nothing else was sent
for ``heartbeat_period``.
"""
from __future__ import annotations

import math
import threading

import rclpy
import rclpy.lifecycle
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.executors import MultiThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from sslfr_interfaces.msg import AxisStatus, SafetyState, TrackerPhase
from sslfr_interfaces.srv import Jog
from sslfr_common.contract import JOINT_RANGE, JOINTS, STEP_ANGLE, STOW_POSITION
from sslfr_common.node import run_node
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from sslfr_drivers.axis.core import (
    HOME_SWITCHES, Action, AxisConfig,
    AxisSupervisor, BoardState, Calibration, SoftLimits, StallDetector,
)
from sslfr_drivers.axis.board_session import AxisBoardSession, BoardRefused

_F, _I, _S, _B = 'double', 'integer', 'string', 'bool'

#: name -> (type, default (None = per-axis default), description with unit, range)
PARAMETERS: dict[str, tuple] = {
    'axis': (_S, 'mirrors', 'axis driven: mirrors | mobile_structure | secondary_reflector (read-only)', None),
    'port': (_S, '', "board port: pyserial URL/device (/dev/ttyUSB0, a pty, loop://) or "
             "'xbee:<uart>?addr=<64-bit hex>'; '' = /dev/sslfr/<axis>", None),
    'baudrate': (_I, 115200, 'serial line speed [bit/s]', (1200, 4_000_000)),
    'autostart': (_B, False, 'configure + activate by itself at start (retrying every retry_period)', None),
    'retry_period': (_F, 2.0, 'autostart: seconds between configure attempts [s]', (0.1, 3600.0)),
    'control_rate': (_F, 20.0, 'control loop and STATUS poll rate [Hz] (steady clock)', (1.0, 200.0)),
    'status_rate': (_F, 5.0, 'axes/<axis>/status rate [Hz]', (0.1, 50.0)),
    'joint_state_rate': (_F, 10.0, 'joint_states rate [Hz]', (0.1, 100.0)),
    'request_timeout': (_F, 0.25, 'board answer time-out per try [s] (STATUS polls use min(this, 2 / control_rate))', (0.01, 5.0)),
    'link_timeout': (_F, 1.0, 'no answer for this long -> link down, reconnect [s]', (0.1, 30.0)),
    'heartbeat_period': (_F, 0.25, 'PING when nothing was sent for this long [s] (board watchdog is 1 s)', (0.02, 0.9)),
    'step_angle': (_F, STEP_ANGLE, 'motor rotation per step [rad/step] (seed 000: 0.006 deg)', (1e-7, 0.5)),
    'gear_ratio': (_F, 1.0, 'motor angle per joint angle [-]', (1e-3, 1e4)),
    'offset': (_F, 0.0, 'joint angle at step count 0 [rad]', (-2 * math.pi, 2 * math.pi)),
    'invert': (_B, False, 'positive steps turn the joint negative', None),
    'lower_limit': (_F, None, 'soft lower limit [rad] (mirrors -pi/4, others -pi/2)', (-math.pi, math.pi)),
    'upper_limit': (_F, None, 'soft upper limit [rad] (pi/2)', (-math.pi, math.pi)),
    'max_speed': (_F, 0.05, 'maximum joint speed of a move [rad/s]', (1e-5, 2.0)),
    'min_speed': (_F, 1e-4, 'minimum joint speed of a move [rad/s]', (1e-6, 2.0)),
    'stow_position': (_F, None, 'stow (defocus) position [rad] (mirrors pi/2 sleeping, others 0)', (-math.pi, math.pi)),
    'home_switch': (_S, None, 'limit switch HOME drives to: low | high | sleep (default sleep: mirrors +pi/2, others 0)', None),
    'home_position': (_F, None, 'joint angle where the home switch closes [rad]', (-math.pi, math.pi)),
    'home_speed': (_F, 0.05, 'homing speed [rad/s]', (1e-5, 2.0)),
    'use_sensor': (_B, True, "use the board's position sensor (measured angle, re-referencing after a reset)", None),
    'auto_home': (_B, True, 'home by itself when the board lost its position', None),
    'reference_samples': (_I, 5, 'sensor readings at rest averaged to re-reference (SET_ZERO) [-]', (1, 100)),
    'safety_timeout': (_F, 1.0, 'safety/state silence that stops the axis [s] (steady clock)', (0.05, 10.0)),
    'safety_silent_stow_after': (_F, 1.0, 'further safety/state silence after the stop before the fail-safe '
                                 'stow (defocus) [s] (steady clock)', (0.0, 60.0)),
    'lost_step_tolerance': (_F, 0.005, 'step count vs sensor disagreement that faults [rad]', (1e-5, 1.0)),
    'stall_window': (_F, 1.0, 'stall observation window [s]', (0.1, 60.0)),
    'stall_min_motion': (_F, 0.01, 'commanded motion that must show on the sensor within stall_window [rad]', (1e-5, 1.0)),
    'max_jog': (_F, 0.2, 'largest |delta| of a jog [rad]', (0.0, math.pi)),
    'jog_speed': (_F, 0.02, 'default jog speed [rad/s]', (1e-5, 2.0)),
}


def _axis_default(axis: str, name: str):
    lo, hi = JOINT_RANGE[axis]
    return {
        'lower_limit': lo, 'upper_limit': hi, 'stow_position': STOW_POSITION[axis],
        'home_switch': 'sleep', 'home_position': STOW_POSITION[axis],
    }[name]


def build_config(axis: str, p: dict) -> tuple[AxisConfig, StallDetector]:
    """Validate a full parameter dict into the core's config (ValueError with the reason)."""
    if axis not in JOINTS:
        raise ValueError(f'axis {axis!r} is not one of {", ".join(JOINTS)}')
    if p['home_switch'] not in HOME_SWITCHES:
        raise ValueError(f"home_switch {p['home_switch']!r} is not low | high | sleep")
    cal = Calibration(p['step_angle'], p['gear_ratio'], p['offset'], p['invert'])
    limits = SoftLimits(p['lower_limit'], p['upper_limit'])
    mech = JOINT_RANGE[axis]
    if limits.lower < mech[0] - 1e-9 or limits.upper > mech[1] + 1e-9:
        raise ValueError(f'soft limits [{limits.lower:.4f}, {limits.upper:.4f}] rad exceed the '
                         f'mechanical range [{mech[0]:.4f}, {mech[1]:.4f}] rad of {axis}')
    if not limits.contains(p['stow_position']):
        raise ValueError(f"stow_position {p['stow_position']:.4f} rad outside the soft limits")
    if p['min_speed'] > p['max_speed']:
        raise ValueError('min_speed > max_speed')
    cfg = AxisConfig(axis, cal, limits, p['max_speed'], p['min_speed'], 1.0 / p['control_rate'],
                     p['stow_position'], p['home_switch'], p['home_position'], p['home_speed'],
                     p['use_sensor'], p['auto_home'], p['reference_samples'])
    stall = StallDetector(p['lost_step_tolerance'], p['stall_window'], p['stall_min_motion'])
    return cfg, stall


def _stamp_to_s(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def _duration_to_s(d) -> float:
    return d.sec + d.nanosec * 1e-9


class AxisDriver(rclpy.lifecycle.Node):
    """Lifecycle node following ``tracker/trajectory`` on one axis board."""

    def __init__(self, **kwargs):
        super().__init__('axis_driver', **kwargs)
        self._lock = threading.RLock()
        self._declare()
        self.p = {name: self.get_parameter(name).value for name in PARAMETERS}
        self.axis = self.p['axis']
        cfg, stall = build_config(self.axis, self.p)     # ValueError -> main() exits 2
        self.sup = AxisSupervisor(cfg, self.p['safety_timeout'], stall)
        self.sup.safety.silent_stow_after = self.p['safety_silent_stow_after']
        self.session: AxisBoardSession | None = None
        self.board: BoardState | None = None
        self.active = False
        self.counters = {'trajectories_accepted': 0, 'trajectories_rejected': 0,
                         'moves_sent': 0, 'nacks': 0, 'nacks_not_homed': 0, 'stops_sent': 0,
                         'homes_sent': 0, 'set_zero_sent': 0, 'request_timeouts': 0,
                         'reconnects': 0, 'board_resets': 0, 'faults': 0}
        self.last_reject = ''
        self.last_error = ''
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._io_group = MutuallyExclusiveCallbackGroup()
        tl1 = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.pub_status = self.create_publisher(AxisStatus, f'axes/{self.axis}/status', 10)
        self.pub_joint = self.create_publisher(JointState, 'joint_states', 10)
        self.pub_diag = self.create_publisher(DiagnosticArray, 'diagnostics', 10)
        self.create_subscription(JointTrajectory, 'tracker/trajectory', self._on_trajectory, tl1)
        self.create_subscription(SafetyState, 'safety/state', self._on_safety, 10)
        self.create_subscription(TrackerPhase, 'tracker/phase', self._on_phase, tl1)
        self.create_service(Trigger, f'axes/{self.axis}/home', self._on_home)
        self.create_service(Jog, f'axes/{self.axis}/jog', self._on_jog)

        period = 1.0 / self.p['control_rate']
        self._tick_n = 0
        self._stop_seen = False
        self._clock_pair: tuple[float, float] | None = None
        self._rate = 1.0
        self.create_timer(period, self._control_tick, callback_group=self._io_group, clock=self.steady)
        # the status heartbeat has its own timer and group: it is published at
        # status_rate in every lifecycle state, whatever board I/O is under way
        self._status_timer = self.create_timer(
            1.0 / self.p['status_rate'], self._publish_status,
            callback_group=MutuallyExclusiveCallbackGroup(), clock=self.steady)
        self.create_timer(1.0, self._publish_diagnostics, clock=self.steady)
        self._autostart_timer = None
        if self.p['autostart']:
            self._autostart_timer = self.create_timer(
                0.1, self._autostart, callback_group=self._io_group, clock=self.steady)
        self.get_logger().info(
            f'axis {self.axis}: port {self.port or "(none)"}, {"autostart" if self.p["autostart"] else "waiting for configure"}')

    # ------------------------------------------------------------ parameters
    def _declare(self) -> None:
        axis = self.declare_parameter(
            'axis', 'mirrors', ParameterDescriptor(description=PARAMETERS['axis'][2], read_only=True)).value
        axis = axis if axis in JOINTS else 'mirrors'       # build_config reports the bad name
        for name, (kind, default, desc, rng) in PARAMETERS.items():
            if name == 'axis':
                continue
            if default is None:
                default = _axis_default(axis, name)
            d = ParameterDescriptor(description=desc)
            if rng is not None and kind == _F:
                d.floating_point_range = [FloatingPointRange(from_value=float(rng[0]), to_value=float(rng[1]))]
            elif rng is not None and kind == _I:
                d.integer_range = [IntegerRange(from_value=int(rng[0]), to_value=int(rng[1]), step=1)]
            self.declare_parameter(name, default, d)

    @property
    def port(self) -> str:
        """The board's port: parameter ``port``, default ``/dev/sslfr/<axis>``."""
        return self.p['port'] or f'/dev/sslfr/{self.axis}'

    def _on_set_parameters(self, params) -> SetParametersResult:
        proposed = dict(self.p)
        for prm in params:
            if prm.name not in PARAMETERS:
                continue
            if prm.name in ('control_rate', 'autostart'):
                return SetParametersResult(successful=False, reason=f'{prm.name} is fixed at start-up')
            proposed[prm.name] = prm.value
        try:
            cfg, stall = build_config(self.axis, proposed)
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        with self._lock:
            self.p = proposed
            self.sup.cfg = cfg
            self.sup.stall = stall
            self.sup.safety.timeout = proposed['safety_timeout']
            self.sup.safety.silent_stow_after = proposed['safety_silent_stow_after']
            self._status_timer.timer_period_ns = int(1e9 / proposed['status_rate'])
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------ lifecycle
    def on_configure(self, state) -> TransitionCallbackReturn:
        """Open the board link and read INFO; FAILURE (logged once per distinct
        error) when the board cannot be reached or refuses the protocol. The
        position counts as lost until re-referenced. The board is opened without
        holding the node's lock, so the status heartbeat and the control tick go on
        while INFO is awaited (up to 3 s)."""
        try:
            session = AxisBoardSession(self.port, self.p['baudrate'], self.p['request_timeout'],
                                       self.p['link_timeout'], self.p['heartbeat_period'])
            info = session.open()
        except BoardRefused as exc:
            if str(exc) != self.last_error:      # autostart retries: log changes only
                self.get_logger().error(f'configure refused: {exc}')
            self.last_error = str(exc)
            return TransitionCallbackReturn.FAILURE
        except Exception as exc:  # noqa: BLE001 - any link failure refuses configure
            error = f'cannot reach the board on {self.port}: {exc}'
            if error != self.last_error:      # autostart retries: log changes only
                self.get_logger().error(f'configure failed: {error}')
            self.last_error = error
            return TransitionCallbackReturn.FAILURE
        with self._lock:
            self.session = session
            self.last_error = ''
            self.sup.position_lost()
        self.get_logger().info(f'configured: board {info} on {self.port}')
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        """Start following tracker/trajectory; clears a latched fault."""
        with self._lock:
            self.active = True
            self.sup.clear_fault()
        self.get_logger().info('active: following tracker/trajectory')
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        """Stop the motor and stop following."""
        with self._lock:
            self.active = False
            self._send_stop('deactivate')
        self.get_logger().info('inactive: motor stopped')
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        """Stop the motor and close the board link."""
        with self._lock:
            self.active = False
            self._close_session()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state) -> TransitionCallbackReturn:
        """Stop the motor and close the board link (as :meth:`on_cleanup`)."""
        return self.on_cleanup(state)

    def on_exit(self) -> None:
        """STOP the motor and close the link; called by run_node once spinning ends,
        while the context is still valid (the last logs still reach /rosout)."""
        with self._lock:
            self.active = False
            self._close_session()

    def _close_session(self) -> None:
        if self.session is not None:
            self._send_stop('close')
            self.session.close()
            self.session = None
            self.board = None

    def _autostart(self) -> None:
        """Steady timer: configure (retrying) then activate, once."""
        state = self._state_label()
        if state == 'unconfigured':
            self._autostart_timer.timer_period_ns = int(self.p['retry_period'] * 1e9)
            self.trigger_configure()
            if self._state_label() != 'inactive':
                return
            state = 'inactive'
        if state == 'inactive':
            self.trigger_activate()
        self._autostart_timer.cancel()

    def _state_label(self) -> str:
        try:
            return self._state_machine.current_state[1]
        except AttributeError:  # pragma: no cover - rclpy internals changed
            return 'unknown'

    # ------------------------------------------------------------ inputs
    def _on_trajectory(self, msg: JointTrajectory) -> None:
        now = self.get_clock().now().nanoseconds * 1e-9
        with self._lock:
            if self.axis not in msg.joint_names:
                return          # not for this axis: nothing to refuse
            j = list(msg.joint_names).index(self.axis)
            start = _stamp_to_s(msg.header.stamp) or now   # zero stamp = "now" (ROS convention)
            times, pos, vel = [], [], []
            bad = ''
            for k, pt in enumerate(msg.points):
                if len(pt.positions) != len(msg.joint_names):
                    bad = f'point {k} has {len(pt.positions)} positions for {len(msg.joint_names)} joints'
                    break
                times.append(start + _duration_to_s(pt.time_from_start))
                pos.append(pt.positions[j])
                if len(pt.velocities) == len(msg.joint_names):
                    vel.append(pt.velocities[j])
            if not bad and vel and len(vel) != len(pos):
                vel = []
            reason = bad or self.sup.store.offer(times, pos, vel or None, now, self.sup.cfg.limits)
            if reason:
                if bad:
                    self.sup.store.rejected += 1
                self.counters['trajectories_rejected'] += 1
                self.last_reject = reason
                self.get_logger().warning(f'trajectory refused ({reason}); keeping the last good one')
            else:
                self.counters['trajectories_accepted'] += 1

    def _on_safety(self, msg: SafetyState) -> None:
        now = self.steady.now().nanoseconds * 1e-9
        session = self.session
        # an ESTOP names the axes it stops (a tripped limit switch stops its own axis);
        # an ESTOP naming none stops every axis
        stop_us = self.axis in msg.stopped_axes or (msg.level == SafetyState.ESTOP and not msg.stopped_axes)
        if session is not None and stop_us and not self._stop_seen:
            session.stop_now()      # before taking the lock: never wait behind a control tick
        self._stop_seen = stop_us
        with self._lock:
            self.sup.safety.receive(now, msg.level, msg.stow_required, list(msg.stopped_axes),
                                    msg.sequence, list(msg.reasons))

    def _on_phase(self, msg: TrackerPhase) -> None:
        if msg.phase == TrackerPhase.MAINTENANCE or msg.mode == 'maintenance':
            mode = 'maintenance'
        elif msg.phase == TrackerPhase.MANUAL or msg.mode == 'manual':
            mode = 'manual'
        else:
            mode = 'auto'
        with self._lock:
            if mode != self.sup.mode:
                self.get_logger().info(f'operator mode {self.sup.mode} -> {mode} ({msg.phase_name})')
                if mode != 'maintenance':
                    self.sup.jog_target = None
            self.sup.mode = mode

    def _on_home(self, request, response):
        with self._lock:
            if not self.active or self.session is None:
                response.success, response.message = False, 'driver not active'
                return response
            self.sup.clear_fault()
            self.sup.home_requested = True
            response.success = True
            response.message = (f'homing toward the {self.sup.cfg.home_switch} switch '
                                f'(or re-referencing from the sensor); watch axes/{self.axis}/status')
        return response

    def _on_jog(self, request, response):
        with self._lock:
            cfg = self.sup.cfg
            if self.sup.mode != 'maintenance':
                response.success, response.message = False, 'jog refused: not in maintenance mode (tracker/phase)'
            elif not self.active or self.board is None:
                response.success, response.message = False, 'jog refused: driver not active or board not answering'
            elif self.sup.fault:
                response.success, response.message = False, f'jog refused: fault: {self.sup.fault}'
            elif not self.board.homed:
                response.success, response.message = False, 'jog refused: axis not homed'
            elif not math.isfinite(request.delta) or abs(request.delta) > self.p['max_jog']:
                response.success, response.message = False, (
                    f"jog refused: |delta| must be finite and <= max_jog {self.p['max_jog']:.4f} rad")
            elif not math.isfinite(request.speed) or request.speed < 0:
                response.success, response.message = False, 'jog refused: speed must be finite and >= 0'
            else:
                base = self.sup.jog_target if self.sup.jog_target is not None else self.sup.measured(self.board)
                target = base + request.delta
                if not cfg.limits.contains(target):
                    response.success, response.message = False, (
                        f'jog refused: target {target:.4f} rad outside soft limits')
                else:
                    self.sup.jog_target = target
                    response.success, response.message, response.target = True, 'jogging', target
        return response

    # ------------------------------------------------------------ control
    def _control_tick(self) -> None:
        with self._lock:
            self._tick_n += 1
            session = self.session
            now_steady = self.steady.now().nanoseconds * 1e-9
            now_ros = self.get_clock().now().nanoseconds * 1e-9
            board = None
            if session is not None:
                period = 1.0 / self.p['control_rate']
                board = session.poll(now_steady, 2 * period, 3 * period)
                if session.take_reset():
                    self.counters['board_resets'] += 1
                    self.sup.position_lost()
                    self.get_logger().warning('board reset or reconnected: position must be re-established')
                if session.take_reconnect():
                    self.counters['reconnects'] += 1
                    self.sup.position_lost()
                    self.get_logger().warning('link re-established')
            self.board = board
            act = self.sup.tick(now_ros, now_steady, board, self.active, self._time_rate(now_ros, now_steady))
            if self.sup.fault and self.sup.state == 'fault' and act.kind == 'stop':
                self.counters['faults'] += 1
                self.get_logger().error(f'axis fault: {self.sup.fault}')
            if session is not None and board is not None:
                self._execute(session, act)
            rate = self.p['control_rate']
            if board is not None and self._tick_n % max(1, round(rate / self.p['joint_state_rate'])) == 0:
                self._publish_joint(board)

    def _time_rate(self, now_ros: float, now_steady: float) -> float:
        """ROS seconds per steady second, smoothed (1.0 without sim time)."""
        last = self._clock_pair
        self._clock_pair = (now_ros, now_steady)
        if last is None or now_steady - last[1] <= 0.0:
            return self._rate
        inst = (now_ros - last[0]) / (now_steady - last[1])
        if not (0.0 <= inst <= 1e5):           # clock jump (replay restart, time set): ignore
            return self._rate
        self._rate += 0.3 * (inst - self._rate)
        return self._rate

    def _execute(self, session: AxisBoardSession, act) -> None:
        if act.kind == 'none':
            return
        ok, detail = session.command(act)
        key = {'move': 'moves_sent', 'stop': 'stops_sent', 'home': 'homes_sent',
               'set_zero': 'set_zero_sent'}[act.kind]
        self.counters[key] += 1
        if not ok:
            self.counters['nacks'] += 1
            if detail == 'NOT_HOMED':
                self.counters['nacks_not_homed'] += 1
            self.last_error = f'{act.kind} refused by the board: {detail}'
            self.sup.position_lost()
            if act.kind != 'move' or self.counters['nacks'] % 20 == 1:
                self.get_logger().warning(self.last_error)

    def _send_stop(self, why: str) -> None:
        if self.session is not None:
            ok, detail = self.session.command(Action('stop'))
            self.counters['stops_sent'] += 1
            if not ok:
                self.get_logger().warning(f'STOP ({why}) not acknowledged: {detail}')

    # ------------------------------------------------------------ outputs
    def _measured(self) -> float:
        return self.sup.measured(self.board) if self.board is not None else float('nan')

    def _publish_status(self) -> None:
        with self._lock:
            m = self._status_msg()
        self.pub_status.publish(m)

    def _status_msg(self) -> AxisStatus:
        m = AxisStatus()
        m.header.stamp = self.get_clock().now().to_msg()
        m.axis = self.axis
        life = self._state_label()
        m.state = self.sup.state if life == 'active' else life
        m.commanded = float(self.sup.commanded)
        m.setpoint = float(self.sup.setpoint)
        m.measured = float(self._measured())
        m.error = m.measured - m.setpoint
        s = self.session
        if self.board is not None:
            b = self.board
            m.steps = int(b.steps)
            m.moving, m.homed = bool(b.moving), bool(b.homed)
            m.limit_bits, m.fault_bits = int(b.limit_bits) & 0xFF, int(b.fault_bits) & 0xFFFF
        if s is None:
            m.link_state = AxisStatus.LINK_FAULT if self.last_error.startswith('board') else AxisStatus.LINK_DOWN
        else:
            m.link_state = s.link_state()
            m.frames_lost, m.frames_bad = s.frames_lost() & 0xFFFFFFFF, s.frames_bad() & 0xFFFFFFFF
            m.board_info = s.board_info
        return m

    def _publish_joint(self, board: BoardState) -> None:
        js = JointState()
        js.header.stamp = self.get_clock().now().to_msg()
        js.name = [self.axis]
        js.position = [float(self.sup.measured(board))]
        js.velocity = [float(self.session.velocity(self.sup.cfg.calibration))] if self.session else [0.0]
        self.pub_joint.publish(js)

    def _publish_diagnostics(self) -> None:
        with self._lock:
            st = DiagnosticStatus()
            st.name = f'{self.get_name()}: axis {self.axis}'
            st.hardware_id = self.session.board_info if self.session else self.port
            life = self._state_label()
            if self.sup.fault or (self.session is None and self.last_error):
                st.level, st.message = DiagnosticStatus.ERROR, self.sup.fault or self.last_error
            elif life != 'active':
                st.level, st.message = DiagnosticStatus.WARN, f'{life}: {self.last_error or "not active"}'
            elif self.sup.state in ('stopped', 'link_down', 'holding'):
                st.level, st.message = DiagnosticStatus.WARN, f'{self.sup.state}: {self.sup.reason}'
            else:
                st.level, st.message = DiagnosticStatus.OK, f'{self.sup.state} {self.sup.reason}'.strip()
            values = {'lifecycle': life, 'state': self.sup.state, 'reason': self.sup.reason,
                      'port': self.port, 'mode': self.sup.mode,
                      'last_rejected_trajectory': self.last_reject, 'last_error': self.last_error,
                      **{k: str(v) for k, v in self.counters.items()}}
            if self.session is not None:
                values.update({k: str(v) for k, v in self.session.counters().items()})
            st.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
            arr = DiagnosticArray()
            arr.header.stamp = self.get_clock().now().to_msg()
            arr.status = [st]
        self.pub_diag.publish(arr)


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_drivers axis_driver``: three executor threads
    (board I/O, status heartbeat, everything else); the link's logs reach the node's
    logger until the node is destroyed."""
    return run_node('axis_driver', AxisDriver, args=args,
                    executor=lambda ctx: MultiThreadedExecutor(num_threads=3, context=ctx),
                    log_bridge=('sslfr_drivers',))


if __name__ == '__main__':
    raise SystemExit(main())
