"""``axis_driver``: lifecycle node driving one SSLFR axis board (stepper + sensor).

One instance per axis (parameter ``axis``; node names ``<axis>_driver``). This file
only wires ROS to pure code: parameters :mod:`.params`, decisions
:class:`.supervisor.AxisSupervisor`, trajectory :mod:`.trajectory`, lifecycle policy
:mod:`.activation` (:mod:`.managed_node`), board I/O :mod:`.board_session`, threads
:mod:`.control_loop`, messages :mod:`.msgs`, accuracy alarm ``sslfr_common.accuracy``.

The control step (read STATUS -> ``AxisSupervisor.tick`` -> write one command) runs in
its own thread (``AxisSupervisor.next_tick``: at ``control_rate`` while something moves,
at once on any event); no executor callback waits for the board (configure at most
``OPEN_WAIT``). With ``autostart`` it keeps ``active`` by itself. One timer publishes
``axes/<axis>/status`` and ``joint_states`` and feeds the accuracy alarm.
"""
from __future__ import annotations

import threading

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.lifecycle import TransitionCallbackReturn
from sensor_msgs.msg import JointState
from sslfr_common.contract import (AXIS_HOME, AXIS_JOG, AXIS_STATUS, DIAGNOSTICS, JOINT_STATES, SAFETY_STATE,
                                   TRACKER_PHASE, TRACKER_TRAJECTORY, collector_id)
from sslfr_common.accuracy import AccuracyAlarm, AccuracyConfig
from sslfr_common.node import ParameterGuard, declare_parameters, diagnostics_msg, qos, run_node, steady_now, to_sec
from sslfr_common.params import ParamTable
from sslfr_interfaces.msg import AxisStatus, SafetyState, TrackerPhase
from sslfr_interfaces.srv import Jog
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from sslfr_drivers.axis.board_session import AxisBoardSession, BoardReading, BoardRefused, open_session
from sslfr_drivers.axis.control_loop import BackgroundOpen, ControlLoop
from sslfr_drivers.axis.commands import STOP, ActionKind, BoardState
from sslfr_drivers.axis.diagnostics import diagnostic_verdict
from sslfr_drivers.axis.operator_input import operator_mode
from sslfr_drivers.axis.rates import TimeRate
from sslfr_drivers.axis.supervisor import AxisSupervisor, Snapshot
from sslfr_drivers.axis.managed_node import ManagedNode
from sslfr_drivers.axis.msgs import joint_msg, status_msg, trajectory_msg
from sslfr_drivers.axis.params import PARAMS, board_port, params_for, port_problem, tuning_from
from sslfr_drivers.link.keys import KeyFileError

_SUCCESS = TransitionCallbackReturn.SUCCESS
OPEN_WAIT = 0.25      # [s] longest wait of a configure for the board's INFO (the attempt goes on)


class AxisDriver(ManagedNode):
    """Lifecycle node following ``tracker/trajectory`` on one axis board."""

    #: Python loggers forwarded to its logger (main() and a composed process)
    LOG_BRIDGE = ('sslfr_drivers',)

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
        self._snap, self._pub_n = Snapshot(), 0
        self._opening: BackgroundOpen | None = None
        self.rate, self.accuracy = TimeRate(), AccuracyAlarm(self.axis, AccuracyConfig.from_params(p))

        self.pub_status = self.create_publisher(AxisStatus, AXIS_STATUS.of(self.axis), qos(AXIS_STATUS))
        self.pub_joint = self.create_publisher(JointState, JOINT_STATES.name, qos(JOINT_STATES))
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, qos(DIAGNOSTICS))
        self.create_subscription(JointTrajectory, TRACKER_TRAJECTORY.name, self._on_trajectory,
                                 qos(TRACKER_TRAJECTORY))
        self.create_subscription(SafetyState, SAFETY_STATE.name, self._on_safety, qos(SAFETY_STATE))
        self.create_subscription(TrackerPhase, TRACKER_PHASE.name, self._on_phase, qos(TRACKER_PHASE))
        self.create_service(Trigger, AXIS_HOME.of(self.axis), self._on_home)
        self.create_service(Jog, AXIS_JOG.of(self.axis), self._on_jog)
        self._status_timer = self.create_timer(self._publish_period(p), self._publish, clock=self.steady)
        self.create_timer(1.0, self._publish_diagnostics, clock=self.steady)
        if p['autostart']:
            self.start_self_activation(p['retry_period'], p['retry_period_max'])
        self.get_logger().info(f'axis {self.axis}: port {board_port(p)}, '
                               f'{"autostart" if p["autostart"] else "waiting for configure"}')
        self._loop = ControlLoop(self._control_step, name=f'{self.axis} control', owner=self.get_name()).start()

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
            self._status_timer.timer_period_ns = int(1e9 * self._publish_period(p))
            self.activation.set_retry(p['retry_period'], p['retry_period_max'])
            self.accuracy.configure(AccuracyConfig.from_params(p))

    # ------------------------------------------------------------ lifecycle
    def on_configure(self, state) -> TransitionCallbackReturn:
        """Open the board and read INFO in a thread, waiting at most ``OPEN_WAIT``; FAILURE,
        logged once per distinct error, when the board cannot be reached (yet) or is
        refused. The position counts as lost until re-referenced."""
        port, p = board_port(self.p), dict(self.p)
        if self._opening is None or self._opening.key != port:
            if self._opening is not None:
                self._opening.discard(AxisBoardSession.close)
            self._opening = BackgroundOpen(port, lambda: open_session(port, p, self.get_name()))
        res = self._opening.result(OPEN_WAIT)
        self._opening = self._opening if res is None else None
        session, exc = res or (None, ConnectionError('no INFO yet (still waiting for the board)'))
        if exc is not None:
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
        self.get_logger().info(f'configured: board {session.board_info} on {port}; {session.host_loss_note}')
        return _SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        """Start following tracker/trajectory; clears a latched fault."""
        with self._lock:
            self.active = True
            self.sup.clear_fault()
        self._loop.wake()
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
        """run_node, spinning ended: the control loop ends, then STOP and close."""
        self._loop.stop()
        if self._opening is not None:
            self._opening.discard(AxisBoardSession.close)
        self.on_cleanup(None)

    def _send_stop(self, why: str) -> None:
        if self.session is not None:
            res = self.session.write(STOP)
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
        else:
            self._loop.wake()

    def _on_safety(self, msg: SafetyState) -> None:
        now = steady_now(self.steady)
        session = self.session
        if self.sup.safety.stop_at_receipt(now, msg) and session is not None:
            session.write(STOP, wait=False)     # before taking the lock: never wait behind a control tick
        with self._lock:
            before = self.sup.safety.verdict(now)[0], self.sup.safety.wind_stow
            self.sup.safety.receive(now, msg.level, msg.stow_required, list(msg.stopped_axes),
                                    msg.sequence, list(msg.reasons), msg.wind_stow)
            changed = self.sup.safety.verdict(now)[0] is not before[0] or self.sup.safety.wind_stow != before[1]
        if changed:
            self._loop.wake()     # stow / stop / follow again: at once, not at the next poll

    def _on_phase(self, msg: TrackerPhase) -> None:
        mode, self.accuracy.phase = operator_mode(msg.phase, msg.mode), int(msg.phase)   # judged in TRACKING
        with self._lock:
            old = self.sup.mode
            if self.sup.set_mode(mode):
                self.get_logger().info(f'operator mode {old} -> {mode} ({msg.phase_name})')
                self._loop.wake()

    def _on_home(self, request, response):
        with self._lock:
            response.success, response.message = self.sup.request_home(self.active and self.session is not None)
        if response.success:
            self._loop.wake()
        return response

    def _on_jog(self, request, response):
        with self._lock:
            ok, response.message, target = self.sup.request_jog(request.delta, request.speed, self.board,
                                                                self.active, self.p['max_jog'])
        response.success = ok
        if ok:
            response.target = target
            self._loop.wake()
        return response

    # ------------------------------------------------------------ read -> update -> write
    def _control_step(self) -> float:
        """One read -> update -> write (control thread); returns the seconds until the
        next one. The lock is held for the decisions only, never during board I/O."""
        session, period = self.session, 1.0 / self.p['control_rate']
        reading = session.read(steady_now(self.steady), period, self.p['idle_poll_period']) if session else BoardReading(None)
        with self._lock:
            now_steady, now_ros = steady_now(self.steady), to_sec(self.get_clock().now())   # as read
            for line in self.sup.note_link_events(reading.reset, reading.reconnected):
                self.get_logger().warning(line)
            self.board = board = reading.board
            rate = self.rate.update(now_ros, now_steady)
            act = self.sup.tick(now_ros, now_steady, board, self.active, rate)
            fault = self.sup.take_new_fault()
        if fault:
            self.get_logger().error(f'axis fault: {fault}')
        result = session.write(act) if session is not None and board is not None and act.kind != ActionKind.NONE else None
        with self._lock:
            warning = self.sup.record_write(act, *result) if result is not None else None
            self._snap = self.sup.snapshot(now_ros, board)
            wait = period if act.kind != ActionKind.NONE else self.sup.next_tick(
                now_ros, now_steady, board, rate, period, self.p['idle_poll_period'])
        if warning:
            self.get_logger().warning(warning)
        return wait

    # ------------------------------------------------------------ outputs
    @staticmethod
    def _publish_period(p: dict) -> float:
        return 1.0 / max(p['status_rate'], p['joint_state_rate'])

    def _publish(self) -> None:
        """One timer at the faster of ``status_rate`` and ``joint_state_rate``: the
        status heartbeat (every lifecycle state) and joint_states (while the board
        answers) from the last tick's snapshot; no lock, no board I/O."""
        p, snap, session = self.p, self._snap, self.session
        fast = max(p['status_rate'], p['joint_state_rate'])
        self._pub_n += 1
        if snap.board is not None and session is not None and self._pub_n % max(1, round(fast / p['joint_state_rate'])) == 0:
            self.pub_joint.publish(joint_msg(self.axis, snap, session, self.sup.cfg.calibration,
                                             self.get_clock().now().to_msg()))
        if self._pub_n % max(1, round(fast / p['status_rate'])) == 0:
            self.pub_status.publish(status_msg(self.axis, snap, self.lifecycle_state(), session, self.refused,
                                               self.get_clock().now().to_msg(), self.last_error))
            self.accuracy.sample_snapshot(snap, self.lifecycle_state(), self.get_logger())   # the status' numbers

    def _publish_diagnostics(self) -> None:
        now = steady_now(self.steady)
        with self._lock:
            life = self.lifecycle_state()
            last_error = self.last_error or self.sup.last_error
            level, message = diagnostic_verdict(life, self.sup, self.session is not None, last_error)
            pending = self.activation.pending(life, now)
            name, hw = f'{self.get_name()}: axis {self.axis}', collector_id(self.get_namespace())
            values = {'lifecycle': life, 'state': self.sup.state, 'reason': self.sup.reason,
                      'port': board_port(self.p), 'board': self.session.board_info if self.session else '', 'mode': self.sup.mode,
                      'last_rejected_trajectory': self.sup.store.last_reason, 'last_error': last_error,
                      **self.sup.counts(), **self.activation.values(now),
                      'parameter_changes_refused': self.params.refused,
                      'last_refused_parameter': self.params.last_refusal,
                      **(self.session.counters() if self.session is not None else {})}
        stamp, acc = self.get_clock().now().to_msg(), self.accuracy       # the alarm: its own status
        arr = diagnostics_msg(name, level, f'{message}; {pending}' if pending else message, hw, values, stamp)
        arr.status += diagnostics_msg(f'{self.get_name()}: accuracy', acc.level, acc.text(), hw, acc.values(), stamp).status
        self.pub_diag.publish(arr)


def main(args=None) -> int:
    """``ros2 run sslfr_drivers axis_driver``: a single-threaded executor (board I/O in
    the driver's own threads); the link's logs reach the node's logger."""
    return run_node('axis_driver', AxisDriver, args=args, log_bridge=AxisDriver.LOG_BRIDGE)


if __name__ == '__main__':
    raise SystemExit(main())
