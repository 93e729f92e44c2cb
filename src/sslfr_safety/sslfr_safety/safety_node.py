"""``safety``: the safety supervisor node (thin ROS shell around the safety core).

Seed 000 section 3.5.3: absorber above 150 degC -> mirrors to the sleeping position.
The rules are data (:mod:`sslfr_safety.rules`), judged by the pure
:mod:`sslfr_safety.core`; the parameters are one table
(:mod:`sslfr_safety.params`). This node only turns messages into core events
(with their arrival time on the steady clock), publishes the verdict and serves the
operator calls.

Publishes
    ``safety/state`` (sslfr_interfaces/SafetyState, R10) at ``publish_rate`` (>= 10 Hz)
    from a STEADY-clock timer, and at once on every transition; stamps in ROS time.
    ``diagnostics`` (diagnostic_msgs/DiagnosticArray) at 1 Hz and on every transition.
Subscribes (best effort, so it matches reliable, best-effort and transient-local publishers)
    ``absorber/inlet_temperature``, ``absorber/outlet_temperature`` (sensor_msgs/Temperature,
    degC, NaN = open thermocouple): over-temperature judged inside the callback;
    ``limit_switches`` (LimitSwitches); ``tracker/phase`` (TrackerPhase) and
    ``tracker/trajectory`` (planner heartbeat); ``axes/<axis>/status`` (AxisStatus:
    homing, measured and commanded angles, lifecycle state, link state, homed; the
    driver heartbeat); ``gps/fix`` (NavSatFix);
    ``irradiance/beam`` (Irradiance); ``wind`` (Wind: gust and mean judged inside the
    callback).
Services
    ``safety/estop`` (std_srvs/SetBool): true = stop every axis, false = release;
    ``safety/reset`` (std_srvs/Trigger): clear latched faults once their cause is gone.
"""
from __future__ import annotations

import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import NavSatFix, NavSatStatus, Temperature
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory

from sslfr_interfaces.msg import AxisStatus, Irradiance, LimitSwitches, SafetyState, TrackerPhase, Wind

from sslfr_common.contract import (ABSORBER_TEMPERATURE, AXIS_STATUS, DIAGNOSTICS, GPS_FIX, IRRADIANCE_BEAM, JOINTS,
                                   LIMIT_SWITCHES, SAFETY_ESTOP, SAFETY_RESET, SAFETY_STATE, SWITCHES,
                                   THERMOCOUPLES, TRACKER_PHASE, TRACKER_TRAJECTORY, WIND, Level, Qos,
                                   collector_id)
from sslfr_common.node import LeanEvents, ParameterGuard, declare_parameters, qos, run_node, stamp, steady_now, to_sec
from sslfr_safety.core import SafetyCore
from sslfr_safety.params import TABLE, config_from

_DIAG_LEVEL = {Level.OK: DiagnosticStatus.OK, Level.WARN: DiagnosticStatus.WARN,
               Level.STOW: DiagnosticStatus.ERROR, Level.ESTOP: DiagnosticStatus.ERROR}


class _SteadyClock:
    """The core's clock: ROS STEADY_TIME (CLOCK_MONOTONIC) and the system clock [s]."""

    def __init__(self):
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._system = Clock(clock_type=ClockType.SYSTEM_TIME)

    def steady(self) -> float:
        return steady_now(self._steady)

    def wall(self) -> float:
        return steady_now(self._system)


class _Guard(ParameterGuard):
    """ParameterGuard that also logs each refusal and counts it in ``bad_inputs``."""

    def __init__(self, node: 'SafetyNode', values: dict):
        self._node = node
        super().__init__(node, TABLE, values, node._apply_parameters)

    def _refuse(self, reason: str):
        self._node.core.counters['bad_inputs'] += 1
        self._node.get_logger().error(f'parameter change refused: {reason}')
        return super()._refuse(reason)


class SafetyNode(LeanEvents, Node):
    """The safety supervisor (see the module docstring)."""

    def __init__(self, **kwargs):
        super().__init__('safety', **kwargs)
        values = declare_parameters(self, TABLE)     # invalid start-up values: ValueError
        config = config_from(values)
        self._core_clock = _SteadyClock()
        self.core = SafetyCore(config, self._core_clock)
        self._sequence = 0
        self._last_transition = 'none'
        self._since_steady = None
        self._since_msg = None
        self._guard = _Guard(self, values)

        self._pub = self.create_publisher(SafetyState, SAFETY_STATE.name, qos(SAFETY_STATE))
        self._diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, qos(DIAGNOSTICS))
        for sensor in THERMOCOUPLES:
            self._subscribe(Temperature, ABSORBER_TEMPERATURE.of(sensor),
                            lambda m, s=sensor: self._on_temperature(s, m),
                            lambda s=sensor: self._on_temperature(s, None))
        self._subscribe(LimitSwitches, LIMIT_SWITCHES.name, self._on_switches)
        self._subscribe(TrackerPhase, TRACKER_PHASE.name, self._on_phase)
        # the planner's trajectory is only a heartbeat here: its arrival, never decoded (a
        # 61-point trajectory takes ~2.5 ms to decode in Python; the drivers judge it)
        self.create_subscription(JointTrajectory, TRACKER_TRAJECTORY.name, self._on_trajectory,
                                 qos(Qos.BE), raw=True)
        for axis in config.joints:
            self._subscribe(AxisStatus, AXIS_STATUS.of(axis), lambda m, a=axis: self._on_axis(a, m))
        self._subscribe(NavSatFix, GPS_FIX.name, self._on_fix)
        self._subscribe(Irradiance, IRRADIANCE_BEAM.name, self._on_beam)
        self._subscribe(Wind, WIND.name, self._on_wind)
        self.create_service(SetBool, SAFETY_ESTOP.name, self._srv_estop)
        self.create_service(Trigger, SAFETY_RESET.name, self._srv_reset)

        self._steady_ros = Clock(clock_type=ClockType.STEADY_TIME)
        self._timer = self.create_timer(1.0 / values['publish_rate'], self._tick, clock=self._steady_ros)
        self._diag_timer = self.create_timer(1.0, self._publish_diagnostics, clock=self._steady_ros)
        self.get_logger().info(
            f'safety supervisor up: limit {config.temperature_limit:.1f} degC, '
            f'hysteresis {config.hysteresis:.1f} K, publishing at {values["publish_rate"]:.0f} Hz; '
            f'watching {", ".join(config.watchdogs) or "no node"}')
        self._tick()

    # ------------------------------------------------------------ parameters
    def _apply_parameters(self, proposed: dict) -> None:
        """A run-time change the table accepted: new limits, a new publication rate."""
        old = self._guard.values
        self.core.configure(config_from(proposed))
        if proposed['publish_rate'] != old['publish_rate']:
            self._timer.cancel()
            self.destroy_timer(self._timer)
            self._timer = self.create_timer(1.0 / proposed['publish_rate'], self._tick, clock=self._steady_ros)
        self.get_logger().info('parameters changed: ' + ', '.join(
            f'{k}={v}' for k, v in proposed.items() if v != old[k]))

    # ------------------------------------------------------------ inputs
    def _subscribe(self, msg_type, topic: str, handler, on_bad=None) -> None:
        """Subscribe (best effort) to serialized messages and decode them here, so a
        message that cannot be converted is counted and logged instead of raising
        inside the executor (which would kill the supervisor). ``on_bad`` is called
        for such a message (temperatures: an unreadable sample is an invalid one)."""
        def receive(raw: bytes) -> None:
            try:
                msg = deserialize_message(raw, msg_type)
            except Exception as exc:  # noqa: BLE001 - any decoding failure is bad input
                self.core.counters['bad_inputs'] += 1
                self.get_logger().error(f'undecodable message on {topic} ({len(raw)} bytes): {exc}',
                                        throttle_duration_sec=5.0)
                if on_bad is not None:
                    on_bad()
                return
            handler(msg)
        self.create_subscription(msg_type, topic, receive, qos(Qos.BE), raw=True)

    def _on_temperature(self, sensor: str, msg: Temperature | None) -> None:
        value = math.nan if msg is None else msg.temperature
        self.core.on_temperature(sensor, value, open_circuit=False)
        self._evaluate(publish_on_change=True)

    def _on_switches(self, msg: LimitSwitches) -> None:
        self.core.on_limit_switches({s: getattr(msg, s) for s in SWITCHES})
        self._evaluate(publish_on_change=True)

    def _on_phase(self, msg: TrackerPhase) -> None:
        self.core.on_phase(msg.phase, msg.site_source)
        self._evaluate(publish_on_change=True)

    def _on_trajectory(self, _raw: bytes) -> None:
        self.core.heartbeat('planner')

    def _on_axis(self, axis: str, msg: AxisStatus) -> None:
        now = self._core_clock.steady()
        self.core.on_axis_status(axis, msg.state == 'homing', msg.measured, now, commanded=msg.commanded)
        self.core.on_driver_state(axis, msg.state, msg.link_state, msg.homed, now)
        self._evaluate(publish_on_change=True)

    def _on_fix(self, msg: NavSatFix) -> None:
        has_fix = (msg.status.status >= NavSatStatus.STATUS_FIX and math.isfinite(msg.latitude)
                   and math.isfinite(msg.longitude))
        self.core.on_gps_fix(has_fix)
        self._evaluate(publish_on_change=True)

    def _on_beam(self, msg: Irradiance) -> None:
        self.core.on_beam(msg.beam)

    def _on_wind(self, msg: Wind) -> None:
        self.core.on_wind(msg.speed, msg.gust, msg.mean, msg.window, stamp=to_sec(msg.header.stamp))
        self._evaluate(publish_on_change=True)

    # ------------------------------------------------------------ services
    def _srv_estop(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        response.success, response.message = self.core.estop(bool(request.data))
        # (one call site per severity: rclpy refuses a severity change at a call site)
        if response.success:
            self.get_logger().warning(f'{SAFETY_ESTOP.name} {request.data}: {response.message}')
        else:
            self.get_logger().error(f'{SAFETY_ESTOP.name} {request.data}: {response.message}')
        self._evaluate(publish_on_change=True)
        return response

    def _srv_reset(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.core.evaluate()
        response.success, response.message = self.core.reset()
        if response.success:
            self.get_logger().info(f'{SAFETY_RESET.name}: {response.message}')
        else:
            self.get_logger().error(f'{SAFETY_RESET.name}: {response.message}')
        self._evaluate(publish_on_change=True)
        return response

    # ------------------------------------------------------------ output
    def _tick(self) -> None:
        self._evaluate(publish_on_change=False)
        self._publish_state()

    def _evaluate(self, publish_on_change: bool) -> None:
        self.core.evaluate()
        transitions = self.core.drain_transitions()
        for note in self.core.drain_notes():
            self.get_logger().info(note)
        for tr in transitions:
            self._last_transition = str(tr)
            if tr.new_level >= Level.STOW and tr.added:
                self.get_logger().error(f'safety transition: {tr}')
            elif tr.new_level == Level.WARN and tr.added:
                self.get_logger().warning(f'safety transition: {tr}')
            else:
                self.get_logger().info(f'safety transition: {tr}')
        if transitions and publish_on_change:
            self._publish_state()
        if transitions:
            self._publish_diagnostics()

    def _ros_time_of(self, steady_t: float):
        """builtin Time (ROS time) of a steady-clock instant (>= 0, as builtin Time must be)."""
        age = max(0.0, self._core_clock.steady() - steady_t)
        return stamp(max(0.0, to_sec(self.get_clock().now()) - age))

    def _publish_state(self) -> None:
        state = self.core.state
        msg = SafetyState()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = ''
        msg.level = int(state.level)
        msg.stow_required = state.stow_required
        msg.reasons = list(state.reasons)
        msg.stopped_axes = list(state.stopped_axes)
        if state.since != self._since_steady:      # a new level: stamp its entry once
            self._since_steady = state.since
            self._since_msg = self._ros_time_of(state.since)
        msg.since = self._since_msg
        msg.wind_stow = state.wind_stow
        msg.wind_release_in = state.wind_release_in
        msg.sequence = self._sequence
        self._sequence = (self._sequence + 1) % (1 << 32)
        self._pub.publish(msg)

    def _publish_diagnostics(self) -> None:
        state = self.core.state
        status = DiagnosticStatus()
        status.name = f'{self.get_name()}: safety supervisor'
        status.hardware_id = collector_id(self.get_namespace())
        status.level = _DIAG_LEVEL[state.level]
        status.message = state.level.name + (': ' + state.reasons[0] if state.reasons else '')
        kv = self.core.snapshot()
        kv['reasons'] = ' | '.join(state.reasons) or 'none'
        kv['stopped axes'] = ', '.join(state.stopped_axes) or 'none'
        kv['stow required'] = str(state.stow_required)
        kv['last transition'] = self._last_transition
        kv['published'] = str(self._sequence)
        status.values = [KeyValue(key=k, value=v) for k, v in kv.items()]
        arr = DiagnosticArray()
        arr.header.stamp = self.get_clock().now().to_msg()
        arr.status = [status]
        self._diag.publish(arr)


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_safety safety``. An invalid start-up
    configuration refuses to run (exit 2): the drivers then stop, as they do
    without safety/state."""
    return run_node('safety', SafetyNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
