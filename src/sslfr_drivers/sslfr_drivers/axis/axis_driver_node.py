"""``axis_driver``: lifecycle node driving one SSLFR axis board (stepper + sensor).

One instance per axis (parameter ``axis``; node names ``<axis>_driver`` by
convention, ``-r __node:=mirrors_driver``). This file only wires ROS to pure code:
parameters :mod:`.params`, decisions :class:`.core.AxisSupervisor`, trajectory
:mod:`.trajectory`, lifecycle policy :mod:`.activation` (via :mod:`.managed_node`),
board I/O :class:`.board_session.AxisBoardSession` (docs/architecture.md).

Control tick (steady clock, ``control_rate``): read (board STATUS) -> update
(``AxisSupervisor.tick``) -> write (one board command). Lifecycle: configure = open
the board and read INFO (refused boards leave it unconfigured); activate = follow
``tracker/trajectory``; deactivate = STOP; cleanup / shutdown = STOP + close. With
``autostart`` (default) the node reaches and keeps ``active`` by itself, configure
retried with back-off; outside requests still work and are respected, and every
``change_state`` request gets an answer. ``axes/<axis>/status`` has its own timer and
never waits for board I/O: 5 Hz in every lifecycle state.
"""
from __future__ import annotations

import threading

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from sslfr_common.contract import LinkState
from sslfr_common.node import ParameterGuard, declare_parameters, run_node, stamp, steady_now, to_sec
from sslfr_common.params import ParamTable
from sslfr_interfaces.msg import AxisStatus, SafetyState, TrackerPhase
from sslfr_interfaces.srv import Jog
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from sslfr_drivers.axis.board_session import AxisBoardSession, BoardReading, BoardRefused
from sslfr_drivers.axis.core import (Action, AxisSupervisor, BoardState, Snapshot, TimeRate,
                                     diagnostic_verdict, operator_mode)
from sslfr_drivers.axis.managed_node import ManagedNode
from sslfr_drivers.axis.params import PARAMS, board_port, params_for, port_problem, tuning_from
from sslfr_drivers.axis.trajectory import TrajectoryMsg, TrajectoryPoint
from sslfr_drivers.link.keys import KeyFileError, link_key

_SUCCESS = TransitionCallbackReturn.SUCCESS


def trajectory_msg(msg: JointTrajectory) -> TrajectoryMsg:
    """A ``JointTrajectory`` in numbers (seconds) for :mod:`.trajectory`."""
    return TrajectoryMsg(tuple(msg.joint_names), to_sec(msg.header.stamp), tuple(
        TrajectoryPoint(to_sec(p.time_from_start), tuple(p.positions), tuple(p.velocities),
                        tuple(p.accelerations)) for p in msg.points))


class AxisDriver(ManagedNode):
    """Lifecycle node following ``tracker/trajectory`` on one axis board."""

    def __init__(self, **kwargs):
        super().__init__('axis_driver', **kwargs)
        self._lock = threading.RLock()
        self.axis = declare_parameters(self, ParamTable([PARAMS.by_name['axis']]))['axis']
        table = params_for(self.axis)
        p = {'axis': self.axis, **declare_parameters(self, ParamTable(s for s in table if s.name != 'axis'))}
        errors = table.validate(p) + [why for why in [port_problem(p['port'])] if why]
        if errors:
            raise ValueError('; '.join(errors))                     # run_node: exit 2
        self.p = p
        cfg, stall = tuning_from(p)
        self.sup = AxisSupervisor(cfg, p['safety_timeout'], stall)
        self.sup.safety.silent_stow_after = p['safety_silent_stow_after']
        self.params = ParameterGuard(self, table, p, self._apply)
        self.session: AxisBoardSession | None = None
        self.board: BoardState | None = None
        self.active = self.refused = False
        self._snap = Snapshot()
        self._tick_n = 0
        self._stop_seen = False
        self.rate = TimeRate()

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
        group = MutuallyExclusiveCallbackGroup
        self.create_timer(1.0 / p['control_rate'], self._control_tick, group(), self.steady)
        self._status_timer = self.create_timer(1.0 / p['status_rate'], self._publish_status, group(), self.steady)
        self.create_timer(1.0, self._publish_diagnostics, clock=self.steady)
        if p['autostart']:
            self.start_self_activation(p['retry_period'], p['retry_period_max'])
        self.get_logger().info(f'axis {self.axis}: port {board_port(p)}, '
                               f'{"autostart" if p["autostart"] else "waiting for configure"}')

    def _apply(self, p: dict) -> None:
        """A run-time parameter change that passed the table (ValueError refuses it)."""
        why = port_problem(p['port'])
        if why:
            self.get_logger().warning(f'parameter change refused: {why}')
            raise ValueError(why)
        cfg, stall = tuning_from(p)
        with self._lock:
            self.p, self.sup.cfg, self.sup.stall = p, cfg, stall
            self.sup.safety.timeout = p['safety_timeout']
            self.sup.safety.silent_stow_after = p['safety_silent_stow_after']
            self._status_timer.timer_period_ns = int(1e9 / p['status_rate'])
            self.activation.set_retry(p['retry_period'], p['retry_period_max'])

    # ------------------------------------------------------------ lifecycle
    def on_configure(self, state) -> TransitionCallbackReturn:
        """Open the board link and read INFO (outside the lock: status and control go
        on); FAILURE, logged once per distinct error, when the board cannot be reached
        or is refused. The position counts as lost until re-referenced."""
        port = board_port(self.p)
        try:
            session = AxisBoardSession(port, self.p['baudrate'], self.p['request_timeout'],
                                       self.p['link_timeout'], self.p['heartbeat_period'],
                                       key=link_key(self.p['key_file']))
            info = session.open()
        except Exception as exc:  # noqa: BLE001 - any link failure refuses configure
            refused = isinstance(exc, (BoardRefused, KeyFileError))   # wrong key, version, key file
            error = str(exc) if refused else f'cannot reach the board on {port}: {exc}'
            if error != self.last_error:
                self.get_logger().error(f'configure {"refused" if refused else "failed"}: {error}')
            self.last_error, self.refused = error, refused
            return TransitionCallbackReturn.FAILURE
        with self._lock:
            self.session, self.refused = session, False
            self.last_error = self.sup.last_error = ''
            self.sup.position_lost()
        self.get_logger().info(f'configured: board {info} on {port}')
        return _SUCCESS

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
        """Stop the motor and close the board link (also on shutdown and exit)."""
        with self._lock:
            self.active = False
            if self.session is not None:
                self._send_stop('close')
                self.session.close()
                self.session = self.board = None
        return _SUCCESS

    on_shutdown = on_cleanup

    def on_exit(self) -> None:
        """Called by run_node once spinning ends, the context still valid."""
        self.on_cleanup(None)

    def _send_stop(self, why: str) -> None:
        if self.session is not None:
            res = self.session.write(Action('stop'))
            self.sup.counters['stops_sent'] += 1
            if not res.ok:
                self.get_logger().warning(f'STOP ({why}) not acknowledged: {res.detail}')

    # ------------------------------------------------------------ inputs
    def _on_trajectory(self, msg: JointTrajectory) -> None:
        now = to_sec(self.get_clock().now())
        with self._lock:
            reason = self.sup.store.offer(trajectory_msg(msg), self.axis, now, self.sup.cfg.limits)
        if reason:
            self.get_logger().warning(f'trajectory refused ({reason}); keeping the last good one')

    def _on_safety(self, msg: SafetyState) -> None:
        now = steady_now(self.steady)
        session = self.session
        # an ESTOP names the axes it stops; an ESTOP naming none stops every axis
        stop_us = self.axis in msg.stopped_axes or (msg.level == SafetyState.ESTOP and not msg.stopped_axes)
        if session is not None and stop_us and not self._stop_seen:
            session.stop_now()      # before taking the lock: never wait behind a control tick
        self._stop_seen = stop_us
        with self._lock:
            self.sup.safety.receive(now, msg.level, msg.stow_required, list(msg.stopped_axes),
                                    msg.sequence, list(msg.reasons))

    def _on_phase(self, msg: TrackerPhase) -> None:
        mode = operator_mode(msg.phase, msg.mode)
        with self._lock:
            old = self.sup.mode
            if self.sup.set_mode(mode):
                self.get_logger().info(f'operator mode {old} -> {mode} ({msg.phase_name})')

    def _on_home(self, request, response):
        with self._lock:
            response.success, response.message = self.sup.request_home(self.active and self.session is not None)
        return response

    def _on_jog(self, request, response):
        with self._lock:
            ok, response.message, target = self.sup.request_jog(request.delta, request.speed, self.board,
                                                                self.active, self.p['max_jog'])
        response.success = ok
        if ok:
            response.target = target
        return response

    # ------------------------------------------------------------ read -> update -> write
    def _control_tick(self) -> None:
        with self._lock:
            session = self.session
            reading = session.read(steady_now(self.steady), 1.0 / self.p['control_rate']) if session \
                else BoardReading(None)
            now_steady, now_ros = steady_now(self.steady), to_sec(self.get_clock().now())   # as read
            for line in self.sup.note_link_events(reading.reset, reading.reconnected):
                self.get_logger().warning(line)
            self.board = board = reading.board
            act = self.sup.tick(now_ros, now_steady, board, self.active, self.rate.update(now_ros, now_steady))
            fault = self.sup.take_new_fault()
            if fault:
                self.get_logger().error(f'axis fault: {fault}')
            if session is not None and board is not None and act.kind != 'none':
                warning = self.sup.record_write(act, *session.write(act))
                if warning:
                    self.get_logger().warning(warning)
            self._snap = self.sup.snapshot(now_ros, board)
            self._tick_n += 1
            if board is not None and self._tick_n % max(1, round(self.p['control_rate'] / self.p['joint_state_rate'])) == 0:
                js = JointState(name=[self.axis], position=[float(self._snap.measured)],
                                velocity=[float(session.velocity(self.sup.cfg.calibration))])
                js.header.stamp = stamp(now_ros)
                self.pub_joint.publish(js)

    # ------------------------------------------------------------ outputs
    def _publish_status(self) -> None:
        """The 5 Hz heartbeat of every lifecycle state: no lock, no board I/O."""
        snap, session, life = self._snap, self.session, self.lifecycle_state()
        m = AxisStatus(axis=self.axis, state=snap.state if life == 'active' else life,
                       commanded=snap.commanded, setpoint=snap.setpoint, measured=snap.measured,
                       error=snap.measured - snap.setpoint)
        # the time the board was read: measured, setpoint and error belong to it
        m.header.stamp = stamp(snap.stamp) if snap.stamp > 0 else self.get_clock().now().to_msg()
        if snap.board is not None:
            b = snap.board
            m.steps, m.moving, m.homed = int(b.steps), bool(b.moving), bool(b.homed)
            m.limit_bits, m.fault_bits = int(b.limit_bits) & 0xFF, int(b.fault_bits) & 0xFFFF
        if session is None:
            m.link_state = int(LinkState.LINK_FAULT if self.refused else LinkState.LINK_DOWN)
            m.board_info = f'refused: {self.last_error}' if self.refused else ''   # e.g. a wrong key
        else:
            m.link_state = int(session.link_state())
            m.frames_lost, m.frames_bad = session.frames_lost() & 0xFFFFFFFF, session.frames_bad() & 0xFFFFFFFF
            m.board_info = session.refusal() or session.board_info
        self.pub_status.publish(m)

    def _publish_diagnostics(self) -> None:
        now = steady_now(self.steady)
        with self._lock:
            life = self.lifecycle_state()
            last_error = self.last_error or self.sup.last_error
            level, message = diagnostic_verdict(life, self.sup, self.session is not None, last_error)
            pending = self.activation.pending(life, now)
            st = DiagnosticStatus(level=bytes([level]), name=f'{self.get_name()}: axis {self.axis}',
                                  message=f'{message}; {pending}' if pending else message,
                                  hardware_id=self.session.board_info if self.session else board_port(self.p))
            values = {'lifecycle': life, 'state': self.sup.state, 'reason': self.sup.reason,
                      'port': board_port(self.p), 'mode': self.sup.mode,
                      'last_rejected_trajectory': self.sup.store.last_reason, 'last_error': last_error,
                      **self.sup.counts(), **self.activation.values(now),
                      'parameter_changes_refused': self.params.refused,
                      'last_refused_parameter': self.params.last_refusal,
                      **(self.session.counters() if self.session is not None else {})}
        st.values = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        arr = DiagnosticArray(status=[st])
        arr.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(arr)


def main(args=None) -> int:
    """``ros2 run sslfr_drivers axis_driver``: four executor threads (board I/O, status
    heartbeat, lifecycle, everything else); the link's logs reach the node's logger."""
    return run_node('axis_driver', AxisDriver, args=args,
                    executor=lambda ctx: MultiThreadedExecutor(num_threads=4, context=ctx),
                    log_bridge=('sslfr_drivers',))


if __name__ == '__main__':
    raise SystemExit(main())
