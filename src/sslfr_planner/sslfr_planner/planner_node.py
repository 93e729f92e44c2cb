"""``planner`` node: the day cycle of seed 000 section 4 as setpoint trajectories.

Thin ROS 2 shell around pure cores:

* :mod:`sslfr_planner.day_cycle` -- the day's schedule (seed 000 Step 1.2, by the
  ephemeris core), the automatic phase and setpoints at any instant;
* :mod:`sslfr_planner.phase_control` -- the phase in force (operator modes and the
  safety override), the stow ramp and hold poses, when to tick, replan and publish;
* :mod:`sslfr_planner.site_source` (GPS fix / persisted fix / parameters), :mod:`sslfr_planner.timejump`
  (ROS-time jumps), :mod:`sslfr_planner.planner_params` (every parameter, in one table).

Interface (docs/architecture.md): publishes ``tracker/sun`` (SunPosition, R10,
``sun_period``), ``tracker/phase`` (TrackerPhase, TL1, on change and every
``phase_period``), ``tracker/trajectory`` (JointTrajectory, TL1, every
``republish_period`` and on every phase change or replan), ``diagnostics``;
subscribes ``gps/fix``, ``safety/state``; serves ``planner/replan``, ``planner/set_mode``.
Control logic on ROS time (``use_sim_time`` days work); diagnostics on the steady clock.
"""
from __future__ import annotations

import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockChange, ClockType, JumpThreshold
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import NavSatFix
from sslfr_interfaces.msg import SafetyState, SunPosition, TrackerPhase
from sslfr_interfaces.srv import SetMode
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory
from sslfr_common.contract import (DIAGNOSTICS, GPS_FIX, JOINTS, PHASE_NAMES, PLANNER_REPLAN, PLANNER_SET_MODE,
                                   SAFETY_STATE, TRACKER_PHASE, TRACKER_SUN, TRACKER_TRAJECTORY, collector_id)
from sslfr_common.node import LeanEvents, ParameterGuard, declare_parameters, qos, run_node, to_ns, to_sec

from sslfr_planner.day_cycle import DayCycle
from sslfr_planner.description import for_node
from sslfr_planner.messages import phase_msg, sun_msg, trajectory_msg
from sslfr_planner.phase_control import (PHASE, SUN, TRAJECTORY, PhaseControl, diagnostic_summary,
                                         immediate_step)
from sslfr_planner.planner_params import PLANNER_PARAMS
from sslfr_planner.site_source import SiteSelector, distance_m
from sslfr_planner.timejump import ClockJumpDetector
from sslfr_planner.trajectory import finite_or_none

TICK_PERIOD = 0.2      # [s] ROS time: phase/sun/trajectory bookkeeping
ERROR_SHOWN_FOR = 60.0  # [s] steady: diagnostics stay ERROR this long after the last error
DIAG_LEVELS = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN, 'error': DiagnosticStatus.ERROR}


class PlannerNode(LeanEvents, Node):
    """The planner: ephemeris + day cycle -> sun, phase and trajectory."""

    def __init__(self, **kwargs):
        super().__init__('planner', **kwargs)
        self.counters = {'replans': 0, 'time_jumps': 0, 'fixes_rejected': 0,
                         'params_refused': 0, 'mode_refused': 0, 'plan_errors': 0,
                         'trajectories': 0, 'phase_changes': 0, 'persist_errors': 0}
        self.cfg = declare_parameters(self, PLANNER_PARAMS)     # ValueError: exit 2
        self.selector = SiteSelector.from_params(self.cfg)
        self._selector_errors_seen = 0
        self._note_selector_errors(loading=True)
        self.cycle = DayCycle(self.cfg, self.selector.current(),   # ValueError: exit 2 (also a bad description)
                              for_node(self.cfg['collector.description'], kwargs.get('cli_args') or sys.argv))
        self.control = PhaseControl(self.cfg['initial_mode'])
        #: the collector's movements: the joints of tracker/trajectory (all without a description)
        desc = self.cycle.description
        self.joints = desc.joints if desc is not None else JOINTS
        self._last_plan_ms = float('nan')
        self._last_error = ''
        self._last_error_steady = -float('inf')
        self._jump = ClockJumpDetector(self.cfg['time_jump_threshold'])
        self._guard = ParameterGuard(self, PLANNER_PARAMS, self.cfg, self._apply_parameters)

        self.pub_sun = self.create_publisher(SunPosition, TRACKER_SUN.name, qos(TRACKER_SUN))
        self.pub_phase = self.create_publisher(TrackerPhase, TRACKER_PHASE.name, qos(TRACKER_PHASE))
        self.pub_traj = self.create_publisher(JointTrajectory, TRACKER_TRAJECTORY.name, qos(TRACKER_TRAJECTORY))
        self.pub_diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, qos(DIAGNOSTICS))
        self.create_subscription(NavSatFix, GPS_FIX.name, self._on_fix, qos(GPS_FIX))
        self.create_subscription(SafetyState, SAFETY_STATE.name, self._on_safety, qos(SAFETY_STATE))
        self.create_service(Trigger, PLANNER_REPLAN.name, self._srv_replan)
        self.create_service(SetMode, PLANNER_SET_MODE.name, self._srv_set_mode)

        self._jump_step, self._jump_handle = None, None
        self._watch_ros_time()
        self.create_timer(TICK_PERIOD, self._tick)                 # ROS time
        self.create_timer(1.0, self._steady_tick, clock=Clock(clock_type=ClockType.STEADY_TIME))  # diag, jumps
        self.get_logger().info(
            f'planner ready: mode {self.control.mode}, site {self.selector.current().describe()}, '
            f'laws {self.cycle.collector.mirror_law}/{self.cfg["collector.law"]}, horizon {self.cfg["horizon"]} s at {self.cfg["step"]} s')

    def _watch_ros_time(self) -> None:
        """(Re)register the ROS-time jump callback (:func:`phase_control.immediate_step`)."""
        step = immediate_step(self.cfg, TICK_PERIOD)
        if step != self._jump_step:
            if self._jump_handle is not None:
                self._jump_handle.unregister()
            self._jump_step, self._jump_handle = step, self.get_clock().create_jump_callback(
                JumpThreshold(min_forward=Duration(nanoseconds=to_ns(step)),
                              min_backward=Duration(nanoseconds=-1), on_clock_change=True),
                post_callback=self._on_ros_jump)

    # ------------------------------------------------------------------ parameters
    def _apply_parameters(self, cfg: dict) -> None:
        """A run-time change the table accepted: ValueError if the core refuses it."""
        DayCycle.check_config(cfg)
        old, self.cfg = self.cfg, cfg
        changed = sorted(k for k in cfg if cfg[k] != old.get(k))
        if not changed:
            return
        self._jump.threshold = float(cfg['time_jump_threshold'])
        self._watch_ros_time()
        if any(k.startswith(('site.', 'gps.', 'state_dir')) for k in changed):
            self.selector = SiteSelector.from_params(cfg, self.selector.gps)
            self._selector_errors_seen = 0   # e.g. a corrupt persisted file in a new state_dir
            self._note_selector_errors(loading=True)
        self.control.request_replan('parameters changed: ' + ', '.join(changed))

    def _note_selector_errors(self, loading: bool) -> None:
        """Log and count the site selector's errors not reported yet: warnings while
        loading a persisted site (it is ignored), errors of a run (a failed write)."""
        new = self.selector.errors[self._selector_errors_seen:]
        self._selector_errors_seen = len(self.selector.errors)
        for err in new:
            self.counters['persist_errors'] += 1
            if loading:   # one call site per severity: rclpy refuses to mix them
                self.get_logger().warning(f'persisted site ignored: {err}')
            else:
                self.get_logger().error(err)

    # --------------------------------------------------------------------- inputs
    def _on_fix(self, msg: NavSatFix) -> None:
        why = self.selector.on_fix(msg.status.status, msg.latitude, msg.longitude, msg.altitude,
                                   list(msg.position_covariance), msg.position_covariance_type,
                                   to_sec(msg.header.stamp) or self._now())
        if why is not None:
            self.counters['fixes_rejected'] += 1
            return
        self._note_selector_errors(loading=False)
        planned = self.cycle.site_fix
        moved = distance_m(planned, self.selector.current())
        # the first fix of a run always replans (the plan then says it is the GPS
        # site); later fixes only when the site moved beyond site.replan_distance
        if planned.source != 'gps' or moved > self.cfg['site.replan_distance']:
            self.control.request_replan(f'gps fix {moved:.0f} m from the planned site ({planned.source})')
            self._tick()

    def _on_safety(self, msg: SafetyState) -> None:
        if self.control.on_safety(msg.stow_required, msg.reasons, msg.wind_stow):
            self._tick()

    # ------------------------------------------------------------------- services
    def _srv_replan(self, request, response):
        self.control.request_replan(f'{PLANNER_REPLAN.name} service')
        self._tick()
        schedule = self.cycle.current_schedule
        response.success = schedule is not None and self.control.pending_replan is None
        response.message = (f'planned {schedule.describe()} for {self.cycle.site_fix.describe()} '
                            f'in {self._last_plan_ms:.1f} ms' if response.success else
                            f'no plan: {self._last_error or "ROS time not available yet"}')
        return response

    def _srv_set_mode(self, request, response):
        before = self.control.mode
        res = self.control.request_mode(request.mode)
        if res.success:
            if res.mode != before:
                self.get_logger().info(f'mode {res.message}')
            self._tick()
        else:
            self.counters['mode_refused'] += 1
            self.get_logger().warning(f'set_mode refused: {res.message}')
        response.success, response.message, response.mode = res.success, res.message, res.mode
        return response

    # ------------------------------------------------------------------ time jumps
    def _on_ros_jump(self, jump) -> None:
        """ROS time was set (a /clock message) or switched between system and sim time."""
        try:
            delta = to_sec(jump.delta)
            if jump.clock_change in (ClockChange.ROS_TIME_ACTIVATED,
                                     ClockChange.ROS_TIME_DEACTIVATED):
                self.control.request_replan(f'clock source changed ({jump.clock_change.name})')
                self._jump.reset()
            elif abs(delta) >= self.cfg['time_jump_threshold']:
                self.counters['time_jumps'] += 1
                self.control.request_replan(f'ROS time jumped by {delta:+.1f} s')
            self._tick()
        except Exception as exc:  # noqa: BLE001 - must never escape into rcl
            self._note_error(f'time-jump handling failed: {exc!r}')

    def _steady_tick(self) -> None:
        try:
            if not self.get_clock().ros_time_is_active:
                jump = self._jump.update(self._now(), time.monotonic())
                if jump is not None and abs(jump.delta) >= self.cfg['time_jump_threshold']:
                    self.counters['time_jumps'] += 1
                    self.control.request_replan(f'system time jumped by {jump.delta:+.1f} s')
                    self._tick()
            else:
                self._jump.reset()
            self._publish_diagnostics()
        except Exception as exc:  # noqa: BLE001 - a timer must not kill the node
            self._note_error(f'steady tick failed: {exc!r}')

    # ------------------------------------------------------------------------ core
    def _now(self) -> float:
        return to_sec(self.get_clock().now())

    def _note_error(self, text: str) -> None:
        self._last_error = text
        self._last_error_steady = time.monotonic()
        self.get_logger().error(text)

    def _tick(self) -> None:
        try:
            self._tick_inner()
        except Exception as exc:  # noqa: BLE001 - bad input never crashes the node
            self.counters['plan_errors'] += 1
            self._note_error(f'planning failed: {exc!r}')

    def _tick_inner(self) -> None:
        now = self._now()
        if now <= 0.0:              # use_sim_time and no /clock yet
            return
        reason = self.control.replan_reason(now, self.cycle)
        if reason is not None:
            self._replan(now, reason)
        tick = self.control.tick(now, self.cycle, self.cfg)
        if tick.phase_change is not None and tick.phase_change[0] is not None:
            old, new = tick.phase_change
            self.get_logger().info(f'phase {PHASE_NAMES[old]} -> {PHASE_NAMES[new]}')
            self.counters['phase_changes'] += 1
        if tick.publish_phase:
            self._publish_phase(now)
        if tick.publish_sun:
            self._publish_sun(now)
        if tick.publish_trajectory:
            self._publish_trajectory(now)

    def _replan(self, now: float, reason: str) -> None:
        site = self.selector.current()
        if site != self.cycle.site_fix or self.cycle.cfg is not self.cfg:
            self.cycle = DayCycle(self.cfg, site, self.cycle.description)
        t0 = time.process_time()
        schedule = self.cycle.plan(now)
        self._last_plan_ms = (time.process_time() - t0) * 1e3
        self.counters['replans'] += 1
        self.control.replanned()
        self.get_logger().info(f'plan ({reason}): {schedule.describe()} for '
                               f'{site.describe()} in {self._last_plan_ms:.1f} ms CPU')

    # ---------------------------------------------------------------- publishers
    def _publish_trajectory(self, now: float) -> None:
        h = self.control.horizon(now, self.cycle, self.cfg)
        why = finite_or_none(h)
        if why is not None:          # never publish NaN to the drivers
            self.counters['plan_errors'] += 1
            self._note_error(f'trajectory not published: {why}')
            return
        self.pub_traj.publish(trajectory_msg(h, self.joints))
        self.control.published(TRAJECTORY, now)
        self.counters['trajectories'] += 1

    def _publish_phase(self, now: float) -> None:
        self.pub_phase.publish(phase_msg(self.control, self.cycle.current_schedule, self.cycle.site_fix, now))
        self.control.published(PHASE, now)

    def _publish_sun(self, now: float) -> None:
        self.pub_sun.publish(sun_msg(self.cycle.sun(now), now))
        self.control.published(SUN, now)

    def _publish_diagnostics(self) -> None:
        c, site = self.control, self.cycle.site_fix
        level, text = diagnostic_summary(c.phase, site.source, self._last_error,
                                         time.monotonic() - self._last_error_steady, ERROR_SHOWN_FOR)
        self.counters['params_refused'] = self._guard.refused
        values = {'mode': c.mode, 'phase': PHASE_NAMES.get(c.phase, '-'),
                  'site_source': site.source, 'latitude_deg': f'{site.latitude_deg:.6f}',
                  'longitude_deg': f'{site.longitude_deg:.6f}', 'elevation_m': f'{site.elevation:.1f}',
                  'plan_cpu_ms': f'{self._last_plan_ms:.2f}', 'safety_stow': str(c.safety_stow),
                  'last_error': self._last_error}
        values.update({k: str(v) for k, v in self.counters.items()})
        st = DiagnosticStatus(level=DIAG_LEVELS[level], name=f'{self.get_name()}: day cycle',
                              message=text, hardware_id=collector_id(self.get_namespace()),
                              values=[KeyValue(key=k, value=v) for k, v in values.items()])
        arr = DiagnosticArray(status=[st])
        arr.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(arr)


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_planner planner``."""
    return run_node('planner', PlannerNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
