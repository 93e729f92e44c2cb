"""``planner`` node: the day cycle of seed 000 section 4 as setpoint trajectories.

Thin ROS 2 shell around pure cores:

* :mod:`sslfr_planner.day_planner` -- the day's plan (sunrise, noon, sunset and the
  per-second table of seed 000 Step 1.2, computed by the ephemeris core), the
  automatic phase and setpoints at any instant;
* :mod:`sslfr_planner.modes` -- operator modes and the safety override;
* :mod:`sslfr_planner.site_source` -- GPS fix / persisted fix / parameters;
* :mod:`sslfr_planner.timejump` -- ROS-time jumps against the steady clock;
* :mod:`sslfr_planner.trajectory` -- rolling horizons (auto, stow ramp, hold);
* :mod:`sslfr_planner.planner_params` -- every parameter, declared in one place.

Interface (docs/architecture.md): publishes ``tracker/sun`` (SunPosition, R10,
``sun_period``), ``tracker/phase`` (TrackerPhase, TL1, on change and every
``phase_period``), ``tracker/trajectory`` (JointTrajectory, TL1, every
``republish_period`` and on every phase change or replan), ``diagnostics``;
subscribes ``gps/fix`` and ``safety/state``; serves ``planner/replan`` and
``planner/set_mode``. Control logic runs on ROS time (``use_sim_time`` days work);
diagnostics and the system-clock jump check on the steady clock.
"""
from __future__ import annotations

import math
import os
import sys
import time

import numpy as np
from builtin_interfaces.msg import Duration as DurationMsg
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                SetParametersResult)
from rclpy.clock import Clock, ClockChange, ClockType, JumpThreshold
from rclpy.duration import Duration
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              ParameterException)
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import NavSatFix
from sslfr_interfaces.msg import SafetyState, SunPosition, TrackerPhase
from sslfr_interfaces.srv import SetMode
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from sslfr_common.contract import Phase
from sslfr_common.node import CONFIG_ERRORS, run_node

from sslfr_planner import modes
from sslfr_planner.day_planner import DayPlanner
from sslfr_planner.planner_params import SPEC_BY_NAME, SPECS, validate
from sslfr_planner.site_source import SiteFix, SiteSelector, distance_m
from sslfr_planner.timejump import ClockJumpDetector
from sslfr_planner.trajectory import JOINTS, finite_or_none, hold, horizon_times, ramp

#: QoS of tracker/phase and tracker/trajectory: late joiners get the latest one.
TL1 = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
TICK_PERIOD = 0.2      # [s] ROS time: phase/sun/trajectory bookkeeping
ERROR_SHOWN_FOR = 60.0  # [s] steady: diagnostics stay ERROR this long after the last error
DAY_TYPES = {'normal': TrackerPhase.DAY_NORMAL, 'polar_day': TrackerPhase.DAY_POLAR_DAY,
             'polar_night': TrackerPhase.DAY_POLAR_NIGHT}


class ConfigError(Exception):
    """The start-up parameters are invalid (message lists every problem)."""


def to_time_msg(t: float) -> TimeMsg:
    """Float seconds since the Unix epoch -> builtin_interfaces/Time (exact for ns)."""
    ns = int(round(t * 1e9)) if abs(t) < 9e9 else 0
    return TimeMsg(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def to_duration_msg(d: float) -> DurationMsg:
    """Non-negative float seconds -> builtin_interfaces/Duration."""
    ns = max(0, int(round(d * 1e9)))
    return DurationMsg(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _coerce(spec, value):
    """Accept integers for double parameters (YAML ``22`` for 22.0)."""
    d = spec.default
    if isinstance(d, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(d, list) and isinstance(value, (list, tuple)):
        return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value]
    return value


class PlannerNode(Node):
    """The planner: ephemeris + day cycle -> sun, phase and trajectory."""

    def __init__(self, **kwargs):
        super().__init__('planner', **kwargs)
        self.counters = {'replans': 0, 'time_jumps': 0, 'fixes_rejected': 0,
                         'params_refused': 0, 'mode_refused': 0, 'plan_errors': 0,
                         'trajectories': 0, 'phase_changes': 0, 'persist_errors': 0}
        self.cfg = self._declare_parameters()
        self._pending_cfg = None
        self.selector = self._make_selector(self.cfg)
        for err in self.selector.errors:
            self.get_logger().warning(f'persisted site ignored: {err}')
        self.counters['persist_errors'] += len(self.selector.errors)
        self._selector_errors_seen = len(self.selector.errors)
        try:
            self.planner = DayPlanner(self.cfg, self.selector.current())
        except ValueError as exc:
            raise ConfigError(str(exc)) from exc

        self.mode = self.cfg['initial_mode']
        self.safety_stow = False
        self.safety_reasons: list[str] = []
        self.phase: int | None = None
        self.reason = ''
        self.hold_pose = None
        self.stow_start: tuple[float, object] | None = None
        self._replan_reason: str | None = 'start-up'
        self._force_traj = True
        self._last_phase_pub = -math.inf
        self._last_sun_pub = -math.inf
        self._last_traj_pub = -math.inf
        self._last_tick = None
        self._last_plan_ms = math.nan
        self._last_error = ''
        self._last_error_steady = -math.inf
        self._jump = ClockJumpDetector(self.cfg['time_jump_threshold'])

        self.pub_sun = self.create_publisher(SunPosition, 'tracker/sun', 10)
        self.pub_phase = self.create_publisher(TrackerPhase, 'tracker/phase', TL1)
        self.pub_traj = self.create_publisher(JointTrajectory, 'tracker/trajectory', TL1)
        self.pub_diag = self.create_publisher(DiagnosticArray, 'diagnostics', 10)
        self.create_subscription(NavSatFix, 'gps/fix', self._on_fix, 10)
        self.create_subscription(SafetyState, 'safety/state', self._on_safety, 10)
        self.create_service(Trigger, 'planner/replan', self._srv_replan)
        self.create_service(SetMode, 'planner/set_mode', self._srv_set_mode)

        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)

        # Every ROS-time update (each /clock message with use_sim_time) runs the tick at
        # once: simulated days advance in steps of any size and the ROS-time timer
        # below alone would see them late; jumps beyond time_jump_threshold replan.
        self._jump_handle = self.get_clock().create_jump_callback(
            JumpThreshold(min_forward=Duration(nanoseconds=1), min_backward=Duration(nanoseconds=-1),
                          on_clock_change=True),
            post_callback=self._on_ros_jump)
        self.create_timer(TICK_PERIOD, self._tick)                 # ROS time
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(1.0, self._steady_tick, clock=steady)    # diagnostics, jumps
        self.get_logger().info(
            f'planner ready: mode {self.mode}, site {self._site_text(self.selector.current())}, '
            f'law {self.cfg["collector.law"]}, horizon {self.cfg["horizon"]} s at {self.cfg["step"]} s')

    # ------------------------------------------------------------------ parameters
    def _declare_parameters(self) -> dict:
        problems = []
        for spec in SPECS:
            desc = ParameterDescriptor(description=spec.description,
                                       additional_constraints=spec.constraints,
                                       read_only=spec.read_only)
            d = spec.default
            if isinstance(d, bool) or isinstance(d, str):
                pass
            elif isinstance(d, int):
                desc.integer_range = [IntegerRange(from_value=int(spec.lo), to_value=int(spec.hi),
                                                   step=1)]
            elif isinstance(d, float):
                desc.dynamic_typing = True           # accept 22 for 22.0; checked by validate()
                desc.floating_point_range = [FloatingPointRange(from_value=float(spec.lo),
                                                                to_value=float(spec.hi), step=0.0)]
            else:                                     # number array
                desc.dynamic_typing = True
            try:
                self.declare_parameter(spec.name, d, desc)
            except (InvalidParameterValueException, InvalidParameterTypeException,
                    ParameterException, ValueError, TypeError) as exc:
                problems.append(f'{spec.name}: {exc}')
        if problems:
            raise ConfigError('; '.join(problems))
        cfg = {s.name: _coerce(s, self.get_parameter(s.name).value) for s in SPECS}
        problems = validate(cfg)
        if problems:
            raise ConfigError('; '.join(problems))
        return cfg

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        cand = dict(self.cfg)
        for p in params:
            spec = SPEC_BY_NAME.get(p.name)
            if spec is None:
                continue
            if p.type_ == Parameter.Type.NOT_SET:
                return self._refuse(f'{p.name}: cannot be unset')
            cand[p.name] = _coerce(spec, p.value)
        problems = validate(cand)
        if not problems:
            try:
                DayPlanner.check_config(cand)
            except ValueError as exc:
                problems = [str(exc)]
        if problems:
            return self._refuse('; '.join(problems))
        self._pending_cfg = cand
        return SetParametersResult(successful=True)

    def _refuse(self, reason: str) -> SetParametersResult:
        self.counters['params_refused'] += 1
        self.get_logger().error(f'parameter change refused, keeping the last good '
                                f'configuration: {reason}')
        return SetParametersResult(successful=False, reason=reason)

    def _after_set_parameters(self, params: list[Parameter]) -> None:
        if self._pending_cfg is None:
            return
        old, self.cfg, self._pending_cfg = self.cfg, self._pending_cfg, None
        changed = sorted(k for k in self.cfg if self.cfg[k] != old.get(k))
        if not changed:
            return
        self._jump.threshold = float(self.cfg['time_jump_threshold'])
        if any(k.startswith(('site.', 'gps.', 'state_dir')) for k in changed):
            gps = self.selector.gps
            self.selector = self._make_selector(self.cfg)
            self.selector.gps = gps
            for err in self.selector.errors:  # e.g. a corrupt persisted file in a new state_dir
                self.get_logger().warning(f'persisted site ignored: {err}')
            self.counters['persist_errors'] += len(self.selector.errors)
            self._selector_errors_seen = len(self.selector.errors)
        self._replan_reason = 'parameters changed: ' + ', '.join(changed)

    def _make_selector(self, cfg: dict) -> SiteSelector:
        state_dir = os.path.expanduser(cfg['state_dir']) if cfg['state_dir'] else ''
        params_site = SiteFix(cfg['site.latitude_deg'], cfg['site.longitude_deg'],
                              cfg['site.elevation'], 'parameters')
        return SiteSelector(params_site, state_dir, cfg['gps.max_horizontal_std'],
                            cfg['gps.persist_min_distance'])

    # --------------------------------------------------------------------- inputs
    def _on_fix(self, msg: NavSatFix) -> None:
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        why = self.selector.on_fix(msg.status.status, msg.latitude, msg.longitude, msg.altitude,
                                   list(msg.position_covariance), msg.position_covariance_type,
                                   stamp or self._now())
        if why is not None:
            self.counters['fixes_rejected'] += 1
            return
        new_errors = self.selector.errors[self._selector_errors_seen:]
        self._selector_errors_seen = len(self.selector.errors)
        for err in new_errors:
            self.counters['persist_errors'] += 1
            self.get_logger().error(err)
        planned = self.planner.site_fix
        cur = self.selector.current()
        moved = distance_m(planned, cur)
        # the first fix of a run always replans (the plan then says it is the GPS
        # site); later fixes only when the site moved beyond site.replan_distance
        if planned.source != 'gps' or moved > self.cfg['site.replan_distance']:
            self._replan_reason = f'gps fix {moved:.0f} m from the planned site ({planned.source})'
            self._tick()

    def _on_safety(self, msg: SafetyState) -> None:
        stow, reasons = bool(msg.stow_required), list(msg.reasons)
        if stow != self.safety_stow or (stow and reasons != self.safety_reasons):
            self.safety_stow, self.safety_reasons = stow, reasons
            self._tick()

    # ------------------------------------------------------------------- services
    def _srv_replan(self, request, response):
        self._replan_reason = 'planner/replan service'
        self._tick()
        plan = self.planner.current_plan
        if plan is None or self._replan_reason is not None:
            response.success = False
            response.message = f'no plan: {self._last_error or "ROS time not available yet"}'
            return response
        response.success = True
        response.message = (f'planned {plan.describe()} for {self._site_text(self.planner.site_fix)} '
                            f'in {self._last_plan_ms:.1f} ms')
        return response

    def _srv_set_mode(self, request, response):
        res = modes.request_mode(self.mode, request.mode)
        if res.success:
            if res.mode != self.mode:
                self.get_logger().info(f'mode {res.message}')
            self.mode = res.mode
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
            delta = jump.delta.nanoseconds * 1e-9
            if jump.clock_change in (ClockChange.ROS_TIME_ACTIVATED,
                                     ClockChange.ROS_TIME_DEACTIVATED):
                self._replan_reason = f'clock source changed ({jump.clock_change.name})'
                self._jump.reset()
            elif abs(delta) >= self.cfg['time_jump_threshold']:
                self.counters['time_jumps'] += 1
                self._replan_reason = f'ROS time jumped by {delta:+.1f} s'
            self._tick()
        except Exception as exc:  # noqa: BLE001 - must never escape into rcl
            self._note_error(f'time-jump handling failed: {exc!r}')

    def _steady_tick(self) -> None:
        try:
            if not self.get_clock().ros_time_is_active:
                jump = self._jump.update(self._now(), time.monotonic())
                if jump is not None and abs(jump.delta) >= self.cfg['time_jump_threshold']:
                    self.counters['time_jumps'] += 1
                    self._replan_reason = f'system time jumped by {jump.delta:+.1f} s'
                    self._tick()
            else:
                self._jump.reset()
            self._publish_diagnostics()
        except Exception as exc:  # noqa: BLE001 - a timer must not kill the node
            self._note_error(f'steady tick failed: {exc!r}')

    # ------------------------------------------------------------------------ core
    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

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
        backwards = self._last_tick is not None and now < self._last_tick
        self._last_tick = now
        if self._replan_reason is not None:
            self._replan(now, self._replan_reason)
        elif self.planner.needs_new_day(now):
            # seed 000 Step 5: at 0:00 (local solar) the process starts again from Step 1
            self._replan(now, 'new day')
        auto_phase = self.planner.auto_phase(now)
        dec = modes.resolve_phase(self.mode, auto_phase, self.safety_stow, self.safety_reasons)
        changed = dec.phase != self.phase
        if changed:
            self._enter_phase(dec.phase, now)
        if changed or dec.reason != self.reason or backwards or \
                now - self._last_phase_pub >= self.cfg['phase_period']:
            self.reason = dec.reason
            self._publish_phase(now)
        if backwards or now - self._last_sun_pub >= self.cfg['sun_period']:
            self._publish_sun(now)
        if changed or self._force_traj or backwards or \
                now - self._last_traj_pub >= self.cfg['republish_period']:
            self._publish_trajectory(now)

    def _replan(self, now: float, reason: str) -> None:
        site = self.selector.current()
        if site != self.planner.site_fix or self.planner.cfg is not self.cfg:
            self.planner = DayPlanner(self.cfg, site)
        t0 = time.process_time()
        plan = self.planner.plan(now)
        self._last_plan_ms = (time.process_time() - t0) * 1e3
        self.counters['replans'] += 1
        self._replan_reason = None
        self._force_traj = True
        self.get_logger().info(f'plan ({reason}): {plan.describe()} for '
                               f'{self._site_text(site)} in {self._last_plan_ms:.1f} ms CPU')

    def _enter_phase(self, phase: int, now: float) -> None:
        """Remember where the axes were commanded when an override begins."""
        pose = self._commanded_pose(now)
        if phase == Phase.STOW:
            self.stow_start = (now, pose, self.planner.sleep_pose(now))
        elif phase in (Phase.MANUAL, Phase.MAINTENANCE):
            if self.phase not in (Phase.MANUAL, Phase.MAINTENANCE):
                self.hold_pose = pose
        if self.phase is not None:
            self.get_logger().info(f'phase {modes.PHASE_NAMES[self.phase]} -> '
                                   f'{modes.PHASE_NAMES[phase]}')
            self.counters['phase_changes'] += 1
        self.phase = phase

    def _commanded_pose(self, now: float):
        """The setpoint in force at ``now`` under the current phase [rad] (3,)."""
        if self.phase in modes.AUTO_PHASES or self.phase is None:
            return self.planner.auto_pose(now)
        if self.phase == Phase.STOW and self.stow_start is not None:
            h = ramp(np.array([now]), *self.stow_start, self.cfg['stow.speeds'])
            return h.positions[0]
        return self.hold_pose if self.hold_pose is not None else self.planner.auto_pose(now)

    def _horizon(self, now: float):
        t = horizon_times(now, self.cfg['horizon'], self.cfg['step'])
        if self.phase in modes.AUTO_PHASES:
            return self.planner.auto_horizon(t)
        if self.phase == Phase.STOW:
            return ramp(t, *self.stow_start, self.cfg['stow.speeds'])
        return hold(t, self.hold_pose)

    # ---------------------------------------------------------------- publishers
    def _publish_trajectory(self, now: float) -> None:
        h = self._horizon(now)
        why = finite_or_none(h)
        if why is not None:          # never publish NaN to the drivers
            self.counters['plan_errors'] += 1
            self._note_error(f'trajectory not published: {why}')
            return
        msg = JointTrajectory()
        msg.header.stamp = to_time_msg(float(h.t[0]))
        msg.joint_names = list(JOINTS)
        t0 = float(h.t[0])
        pos, vel = h.positions.tolist(), h.velocities.tolist()
        msg.points = [JointTrajectoryPoint(positions=pos[k], velocities=vel[k],
                                           time_from_start=to_duration_msg(float(h.t[k]) - t0))
                      for k in range(len(h))]
        self.pub_traj.publish(msg)
        self._last_traj_pub = now
        self._force_traj = False
        self.counters['trajectories'] += 1

    def _publish_phase(self, now: float) -> None:
        msg = TrackerPhase()
        msg.header.stamp = to_time_msg(now)
        msg.phase = self.phase
        msg.phase_name = modes.PHASE_NAMES[self.phase]
        msg.mode = self.mode
        msg.reason = self.reason
        plan = self.planner.current_plan
        ev = plan.events if plan is not None else None
        if ev is not None:
            msg.day_type = DAY_TYPES.get(ev.day_type, TrackerPhase.DAY_NORMAL)
            if ev.sunrise is not None:
                msg.sunrise = to_time_msg(ev.sunrise)
            if ev.sunset is not None:
                msg.sunset = to_time_msg(ev.sunset)
            msg.solar_noon = to_time_msg(ev.solar_noon)
        site = self.planner.site_fix
        msg.latitude, msg.longitude, msg.altitude = (site.latitude_deg, site.longitude_deg,
                                                     site.elevation)
        msg.site_source = site.source
        self.pub_phase.publish(msg)
        self._last_phase_pub = now

    def _publish_sun(self, now: float) -> None:
        zen, azi, tra, lon, above, algo = self.planner.sun(now)
        msg = SunPosition()
        msg.header.stamp = to_time_msg(now)
        msg.zenith, msg.azimuth, msg.transversal, msg.longitudinal = zen, azi, tra, lon
        msg.above_horizon = bool(above)
        msg.algorithm = algo
        self.pub_sun.publish(msg)
        self._last_sun_pub = now

    def _publish_diagnostics(self) -> None:
        st = DiagnosticStatus()
        st.name = f'{self.get_name()}: day cycle'
        st.hardware_id = 'sslfr_planner'
        site = self.planner.site_fix
        if self._last_error and time.monotonic() - self._last_error_steady < ERROR_SHOWN_FOR:
            st.level, st.message = DiagnosticStatus.ERROR, self._last_error
        elif self.phase is None:
            st.level, st.message = DiagnosticStatus.WARN, 'waiting for ROS time'
        elif site.source == 'parameters':
            st.level, st.message = DiagnosticStatus.WARN, (
                f'{modes.PHASE_NAMES[self.phase]}; site from parameters (no GPS fix yet)')
        else:
            st.level, st.message = DiagnosticStatus.OK, (
                f'{modes.PHASE_NAMES[self.phase]}; site from {site.source}')
        values = {'mode': self.mode, 'phase': modes.PHASE_NAMES.get(self.phase, '-'),
                  'site_source': site.source, 'latitude_deg': f'{site.latitude_deg:.6f}',
                  'longitude_deg': f'{site.longitude_deg:.6f}', 'elevation_m': f'{site.elevation:.1f}',
                  'plan_cpu_ms': f'{self._last_plan_ms:.2f}', 'safety_stow': str(self.safety_stow),
                  'last_error': self._last_error}
        values.update({k: str(v) for k, v in self.counters.items()})
        st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [st]
        self.pub_diag.publish(arr)

    @staticmethod
    def _site_text(site: SiteFix) -> str:
        return (f'{site.latitude_deg:.5f},{site.longitude_deg:.5f} {site.elevation:.0f} m '
                f'({site.source})')


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_planner planner``."""
    return run_node('planner', PlannerNode, args=args, config_errors=CONFIG_ERRORS + (ConfigError,))


if __name__ == '__main__':
    sys.exit(main())
