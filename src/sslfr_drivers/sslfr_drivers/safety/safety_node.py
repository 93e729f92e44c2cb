"""``safety``: the safety supervisor node (thin ROS shell around safety_core).

Seed 000 section 3.5.3: absorber above 150 degC -> mirrors to the sleeping position.
The rules live in :mod:`sslfr_drivers.safety.core`; this node only turns messages into
core events (with their arrival time on the steady clock), publishes the verdict and
serves the operator calls.

Publishes
    ``safety/state`` (sslfr_interfaces/SafetyState, R10) at ``publish_rate`` (>= 10 Hz)
    from a STEADY-clock timer, and at once on every transition; stamps in ROS time.
    ``diagnostics`` (diagnostic_msgs/DiagnosticArray) at 1 Hz and on every transition.
Subscribes (best effort, so it matches reliable, best-effort and transient-local publishers)
    ``absorber/inlet_temperature``, ``absorber/outlet_temperature`` (sensor_msgs/Temperature,
    degC, NaN = open thermocouple): over-temperature judged inside the callback;
    ``limit_switches`` (LimitSwitches); ``tracker/phase`` (TrackerPhase) and
    ``tracker/trajectory`` (planner heartbeat); ``axes/<axis>/status`` (AxisStatus:
    homing, measured angle, driver heartbeat); ``gps/fix`` (NavSatFix);
    ``irradiance/beam`` (Irradiance).
Services
    ``safety/estop`` (std_srvs/SetBool): true = stop every axis, false = release;
    ``safety/reset`` (std_srvs/Trigger): clear latched faults once their cause is gone.
"""
from __future__ import annotations

import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import (FloatingPointRange, ParameterDescriptor, ParameterType,
                                SetParametersResult)
from rclpy.clock import Clock, ClockType
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy_impl
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rclpy.time import Time
from sensor_msgs.msg import NavSatFix, NavSatStatus, Temperature
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory

from sslfr_interfaces.msg import AxisStatus, Irradiance, LimitSwitches, SafetyState, TrackerPhase

from sslfr_common.contract import JOINTS, SWITCHES, Level
from sslfr_drivers.safety.core import WATCHABLE, SafetyConfig, SafetyCore
from sslfr_common.node import run_node

_D = SafetyConfig()

#: Every parameter, in one place: name -> (default, description with unit, (min, max) or None).
PARAMS: dict[str, tuple] = {
    'publish_rate': (20.0, 'safety/state publication rate [Hz] (steady clock)', (10.0, 100.0)),
    'temperature.limit': (_D.temperature_limit,
                          'absorber over-temperature limit [degC] (seed 000 section 3.5.3: 150)', (0.0, 1000.0)),
    'temperature.hysteresis': (_D.hysteresis, 'must cool below limit - hysteresis [K] before reset',
                               (0.0, 200.0)),
    'temperature.cool_hold': (_D.cool_hold, 'time below limit - hysteresis before reset [s]', (0.0, 3600.0)),
    'temperature.auto_reset': (False, 'clear temperature latches without safety/reset once cooled [-]', None),
    'temperature.silent_timeout': (_D.silent_timeout, 'thermocouple silent while tracking -> stow [s]',
                                   (0.1, 60.0)),
    'temperature.sensor_recover_hold': (_D.sensor_recover_hold,
                                        'valid samples this long clear a thermocouple fault [s]', (0.0, 600.0)),
    'temperature.sensor_fault_latched': (False, 'thermocouple faults also need safety/reset [-]', None),
    'temperature.stuck_timeout': (_D.stuck_timeout,
                                  'no change while the sun is on the receiver -> stuck [s]', (1.0, 86400.0)),
    'temperature.stuck_tolerance': (_D.stuck_tolerance, 'a change must exceed this [K]', (0.0, 50.0)),
    'temperature.stuck_min_beam': (_D.stuck_min_beam,
                                   'beam irradiance at which the sun counts as on the receiver [W/m^2]',
                                   (0.0, 1500.0)),
    'temperature.valid_min': (_D.valid_min, 'lowest plausible thermocouple reading [degC]', (-273.0, 2000.0)),
    'temperature.valid_max': (_D.valid_max, 'highest plausible thermocouple reading [degC]', (-273.0, 2000.0)),
    'switches.window': (_D.switch_window,
                        'a switch closed within this of its nominal angle is expected [rad]', (0.0, 1.0)),
    'switches.lookback': (_D.switch_lookback,
                          'measured angles of the last this many seconds make up the axis path [s]',
                          (0.0, 10.0)),
    'switches.stuck_travel': (_D.stuck_switch_travel,
                              'travel with a switch closed during homing -> stuck [rad]', (0.001, 3.2)),
    **{f'switches.position.{s}': (_D.switch_positions[s], f'nominal joint angle of the {s} switch [rad]',
                                  (-3.2, 3.2)) for s in SWITCHES},
    'axis_status_max_age': (_D.status_max_age, 'axis status older than this: position unknown [s]',
                            (0.1, 60.0)),
    'beam_max_age': (_D.beam_max_age, 'beam irradiance older than this: unknown [s]', (0.1, 600.0)),
    'watchdog.nodes': (list(_D.watchdogs), 'watched nodes: ' + ', '.join(WATCHABLE) + ' [-]', None),
    'watchdog.timeouts': ([t for t, _ in _D.watchdogs.values()],
                          'silence limit of each watched node, same order [s]', None),
    'watchdog.actions': ([a for _, a in _D.watchdogs.values()],
                         'WARN or STOW for each watched node, same order [-]', None),
    'watchdog.startup_grace': (_D.startup_grace, 'time after start before never-heard nodes are silent [s]',
                               (0.0, 600.0)),
    'require_site_and_time': (True, 'no GPS fix since boot and no persisted site / no time -> stow [-]', None),
    'trust_system_clock': (True, 'a system clock after min_valid_unix_time counts as time [-]', None),
    'min_valid_unix_time': (_D.min_valid_unix_time, 'earliest plausible system time [s since 1970 UTC]',
                            (0.0, 4.0e9)),
}

RCLError = _rclpy_impl.RCLError
_BEST_EFFORT = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
_DIAG_LEVEL = {Level.OK: DiagnosticStatus.OK, Level.WARN: DiagnosticStatus.WARN,
               Level.STOW: DiagnosticStatus.ERROR, Level.ESTOP: DiagnosticStatus.ERROR}


def config_from(values: dict) -> SafetyConfig:
    """Build (and validate) a SafetyConfig from parameter values; raises ValueError."""
    nodes = list(values['watchdog.nodes'])
    timeouts = [float(t) for t in values['watchdog.timeouts']]
    actions = [str(a).upper() for a in values['watchdog.actions']]
    if not (len(nodes) == len(timeouts) == len(actions)):
        raise ValueError(f'watchdog.nodes/timeouts/actions lengths differ: '
                         f'{len(nodes)}/{len(timeouts)}/{len(actions)}')
    if len(set(nodes)) != len(nodes):
        raise ValueError('watchdog.nodes lists a node twice')
    cfg = SafetyConfig(
        temperature_limit=values['temperature.limit'], hysteresis=values['temperature.hysteresis'],
        cool_hold=values['temperature.cool_hold'], auto_reset=values['temperature.auto_reset'],
        silent_timeout=values['temperature.silent_timeout'],
        sensor_recover_hold=values['temperature.sensor_recover_hold'],
        sensor_fault_latched=values['temperature.sensor_fault_latched'],
        stuck_timeout=values['temperature.stuck_timeout'],
        stuck_tolerance=values['temperature.stuck_tolerance'],
        stuck_min_beam=values['temperature.stuck_min_beam'],
        valid_min=values['temperature.valid_min'], valid_max=values['temperature.valid_max'],
        switch_window=values['switches.window'], switch_lookback=values['switches.lookback'],
        stuck_switch_travel=values['switches.stuck_travel'],
        switch_positions={s: values[f'switches.position.{s}'] for s in SWITCHES},
        status_max_age=values['axis_status_max_age'], beam_max_age=values['beam_max_age'],
        startup_grace=values['watchdog.startup_grace'],
        require_site_and_time=values['require_site_and_time'],
        trust_system_clock=values['trust_system_clock'],
        min_valid_unix_time=values['min_valid_unix_time'],
        watchdogs={n: (t, a) for n, t, a in zip(nodes, timeouts, actions)})
    cfg.validate()
    return cfg


class _SteadyClock:
    """The core's clock: ROS STEADY_TIME (CLOCK_MONOTONIC) and the system clock [s]."""

    def __init__(self):
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._system = Clock(clock_type=ClockType.SYSTEM_TIME)

    def steady(self) -> float:
        return self._steady.now().nanoseconds * 1e-9

    def wall(self) -> float:
        return self._system.now().nanoseconds * 1e-9


class SafetyNode(Node):
    """The safety supervisor (see the module docstring)."""

    def __init__(self):
        super().__init__('safety')
        for name, (default, text, bounds) in PARAMS.items():
            desc = ParameterDescriptor(description=text)
            if isinstance(default, list):
                desc.type = (ParameterType.PARAMETER_STRING_ARRAY if isinstance(default[0], str)
                             else ParameterType.PARAMETER_DOUBLE_ARRAY)
            if bounds is not None:
                desc.floating_point_range = [FloatingPointRange(from_value=bounds[0], to_value=bounds[1])]
            self.declare_parameter(name, default, desc)
        self._values = {n: self.get_parameter(n).value for n in PARAMS}
        config = config_from(self._values)          # invalid start-up values: ValueError
        self._core_clock = _SteadyClock()
        self.core = SafetyCore(config, self._core_clock)
        self._sequence = 0
        self._last_transition = 'none'
        self._since_steady = None
        self._since_msg = None
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._pub = self.create_publisher(SafetyState, 'safety/state', 10)
        self._diag = self.create_publisher(DiagnosticArray, 'diagnostics', 10)
        for sensor in ('inlet', 'outlet'):
            self._subscribe(Temperature, f'absorber/{sensor}_temperature',
                            lambda m, s=sensor: self._on_temperature(s, m),
                            lambda s=sensor: self._on_temperature(s, None))
        self._subscribe(LimitSwitches, 'limit_switches', self._on_switches)
        self._subscribe(TrackerPhase, 'tracker/phase', self._on_phase)
        self._subscribe(JointTrajectory, 'tracker/trajectory', self._on_trajectory)
        for axis in JOINTS:
            self._subscribe(AxisStatus, f'axes/{axis}/status', lambda m, a=axis: self._on_axis(a, m))
        self._subscribe(NavSatFix, 'gps/fix', self._on_fix)
        self._subscribe(Irradiance, 'irradiance/beam', self._on_beam)
        self.create_service(SetBool, 'safety/estop', self._srv_estop)
        self.create_service(Trigger, 'safety/reset', self._srv_reset)

        self._steady_ros = Clock(clock_type=ClockType.STEADY_TIME)
        self._timer = self.create_timer(1.0 / self._values['publish_rate'], self._tick, clock=self._steady_ros)
        self._diag_timer = self.create_timer(1.0, self._publish_diagnostics, clock=self._steady_ros)
        self.get_logger().info(
            f'safety supervisor up: limit {config.temperature_limit:.1f} degC, '
            f'hysteresis {config.hysteresis:.1f} K, publishing at {self._values["publish_rate"]:.0f} Hz; '
            f'watching {", ".join(config.watchdogs) or "no node"}')
        self._tick()

    # ------------------------------------------------------------ parameters
    def _on_set_parameters(self, params) -> SetParametersResult:
        values = dict(self._values)
        for p in params:
            if p.name in values:
                values[p.name] = p.value
        try:
            config = config_from(values)
            if not 10.0 <= float(values['publish_rate']) <= 100.0:
                raise ValueError('publish_rate must be 10..100 Hz')
        except (ValueError, TypeError, KeyError) as exc:
            self.core.counters['bad_inputs'] += 1
            self.get_logger().error(f'parameter change refused: {exc}')
            return SetParametersResult(successful=False, reason=str(exc))
        self.core.configure(config)
        if values['publish_rate'] != self._values['publish_rate']:
            self._timer.cancel()
            self.destroy_timer(self._timer)
            self._timer = self.create_timer(1.0 / values['publish_rate'], self._tick, clock=self._steady_ros)
        self._values = values
        self.get_logger().info('parameters changed: ' + ', '.join(f'{p.name}={p.value}' for p in params))
        return SetParametersResult(successful=True)

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
        self.create_subscription(msg_type, topic, receive, _BEST_EFFORT, raw=True)

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

    def _on_trajectory(self, _msg: JointTrajectory) -> None:
        self.core.heartbeat('planner')

    def _on_axis(self, axis: str, msg: AxisStatus) -> None:
        self.core.on_axis_status(axis, msg.state == 'homing', msg.measured, commanded=msg.commanded)
        self._evaluate(publish_on_change=True)

    def _on_fix(self, msg: NavSatFix) -> None:
        has_fix = (msg.status.status >= NavSatStatus.STATUS_FIX and math.isfinite(msg.latitude)
                   and math.isfinite(msg.longitude))
        self.core.on_gps_fix(has_fix)
        self._evaluate(publish_on_change=True)

    def _on_beam(self, msg: Irradiance) -> None:
        self.core.on_beam(msg.beam)

    # ------------------------------------------------------------ services
    def _srv_estop(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        response.success, response.message = self.core.estop(bool(request.data))
        # (one call site per severity: rclpy refuses a severity change at a call site)
        if response.success:
            self.get_logger().warning(f'safety/estop {request.data}: {response.message}')
        else:
            self.get_logger().error(f'safety/estop {request.data}: {response.message}')
        self._evaluate(publish_on_change=True)
        return response

    def _srv_reset(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.core.evaluate()
        response.success, response.message = self.core.reset()
        if response.success:
            self.get_logger().info(f'safety/reset: {response.message}')
        else:
            self.get_logger().error(f'safety/reset: {response.message}')
        self._evaluate(publish_on_change=True)
        return response

    # ------------------------------------------------------------ output
    def _tick(self) -> None:
        self._evaluate(publish_on_change=False)
        self._publish_state()

    def _evaluate(self, publish_on_change: bool) -> None:
        self.core.evaluate()
        transitions = self.core.drain_transitions()
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

    def _ros_time_of(self, steady_t: float) -> Time:
        """ROS time [ns] of a steady-clock instant (>= 0, as builtin Time must be)."""
        now_ros = self.get_clock().now()
        age = max(0.0, self._core_clock.steady() - steady_t)
        ns = max(0, now_ros.nanoseconds - int(age * 1e9))
        return Time(nanoseconds=ns, clock_type=now_ros.clock_type)

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
            self._since_msg = self._ros_time_of(state.since).to_msg()
        msg.since = self._since_msg
        msg.sequence = self._sequence
        self._sequence = (self._sequence + 1) % (1 << 32)
        self._pub.publish(msg)

    def _publish_diagnostics(self) -> None:
        state = self.core.state
        status = DiagnosticStatus()
        status.name = f'{self.get_name()}: safety supervisor'
        status.hardware_id = 'sslfr'
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
    """Entry point of ``ros2 run sslfr_drivers safety``. An invalid start-up
    configuration refuses to run (exit 2): the drivers then stop, as they do
    without safety/state."""
    return run_node('safety', SafetyNode, args=args)


if __name__ == '__main__':
    raise SystemExit(main())
