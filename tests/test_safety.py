"""Topic-level tests of the real ``safety`` node process (issue 7).

The test process plays the rest of the tracker: a :class:`World` publishes, at 10 Hz
from a timer of the harness node, the absorber temperatures, the limit switches, the
planner's phase, the three axis statuses, a GPS fix and the beam irradiance (the
heartbeats the supervisor watches); tests change its values, silence its sources and
call the node's services. Latencies are measured in the test process from the
publication of the provoking message to the receipt of the verdict, so they include
the transport both ways (an upper bound of the node's own reaction time).
"""
from __future__ import annotations

import math
import time

import pytest
from sslfr_common.contract import (ABSORBER_TEMPERATURE, AXIS_STATUS, CLOCK, GPS_FIX,
                                   IRRADIANCE_BEAM, LIMIT_SWITCHES, SAFETY_ESTOP, SAFETY_RESET,
                                   SAFETY_STATE, TRACKER_PHASE)

pytestmark = pytest.mark.timeout(90)

FAST = {'temperature.cool_hold': 1.0, 'temperature.sensor_recover_hold': 1.0, 'watchdog.startup_grace': 5.0}


class World:
    """The tracker around the supervisor, published at 10 Hz (values editable)."""

    def __init__(self, ros, period: float = 0.1):
        from sensor_msgs.msg import NavSatFix, Temperature

        from sslfr_interfaces.msg import AxisStatus, Irradiance, LimitSwitches, SafetyState, TrackerPhase
        self.ros = ros
        self.node = ros.node
        self.t = {'inlet': 60.0, 'outlet': 80.0}
        self.silent: set[str] = set()
        self.phase = 0
        self.switches = dict.fromkeys(('initial', 'last', 'sleeping', 'longitudinal_1', 'longitudinal_2'),
                                      False)
        self.positions = {'mirrors': 0.3, 'mobile_structure': 0.6, 'secondary_reflector': 0.6}
        self.homing: set[str] = set()
        self.driver_state: dict[str, str] = {}     # axis -> state reported instead of following/homing
        self.link: dict[str, int] = {}             # axis -> link_state instead of LINK_UP
        self.stamp = None          # builtin_interfaces/Time for headers (None: harness clock)
        self._types = (Temperature, LimitSwitches, TrackerPhase, AxisStatus, NavSatFix, Irradiance)
        pub = self.node.create_publisher
        self.temp_pub = {s: pub(Temperature, ABSORBER_TEMPERATURE.of(s), 10) for s in self.t}
        self.sw_pub = pub(LimitSwitches, LIMIT_SWITCHES.name, 10)
        self.phase_pub = pub(TrackerPhase, TRACKER_PHASE.name, 10)
        self.axis_pub = {a: pub(AxisStatus, AXIS_STATUS.of(a), 10) for a in self.positions}
        self.fix_pub = pub(NavSatFix, GPS_FIX.name, 10)
        self.beam_pub = pub(Irradiance, IRRADIANCE_BEAM.name, 10)
        self.states: list = []
        self.arrivals: list[float] = []      # test-process receipt time of each state
        self.node.create_subscription(SafetyState, SAFETY_STATE.name, self._on_state, 10)
        self.timer = self.node.create_timer(period, self.publish_all)
        self._clients: dict = {}
        self.proc = None

    def call(self, srv_type, name: str, request, timeout: float = 5.0):
        """Call a service through one client per service, created once: a fresh client
        per call can lose its response while the server still discovers it."""
        if name not in self._clients:
            client = self.node.create_client(srv_type, name)
            assert self.ros.spin_until(client.service_is_ready, timeout), f'{name} not available'
            self.ros.spin_for(0.2)
            self._clients[name] = client
        future = self._clients[name].call_async(request)
        assert self.ros.spin_until(future.done, timeout), (
            f'{name} did not answer within {timeout} s\n' + (self.proc.output() if self.proc else ''))
        return future.result()

    def _on_state(self, msg) -> None:
        self.arrivals.append(time.monotonic())
        self.states.append(msg)

    def _header(self, msg):
        msg.header.stamp = self.stamp if self.stamp is not None else self.node.get_clock().now().to_msg()
        return msg

    def temperature(self, sensor: str, value: float) -> float:
        """Publish one sample now; return its publication time (steady) [s]."""
        self.t[sensor] = value
        msg = self._header(self._types[0]())
        msg.temperature = float(value)
        t0 = time.monotonic()
        self.temp_pub[sensor].publish(msg)
        return t0

    def publish_switches(self) -> float:
        msg = self._header(self._types[1]())
        for name, closed in self.switches.items():
            setattr(msg, name, closed)
        t0 = time.monotonic()
        self.sw_pub.publish(msg)
        return t0

    def publish_all(self) -> None:
        for sensor, value in self.t.items():
            if sensor not in self.silent:
                self.temperature(sensor, value)
        self.publish_switches()
        TrackerPhase, AxisStatus, NavSatFix, Irradiance = self._types[2:]
        self.phase_pub.publish(self._header(TrackerPhase(phase=self.phase, site_source='parameters',
                                                         mode='auto')))
        for axis, pos in self.positions.items():
            self.axis_pub[axis].publish(self._header(AxisStatus(
                axis=axis, state=self.driver_state.get(axis, 'homing' if axis in self.homing else 'following'),
                measured=pos, setpoint=pos, commanded=pos, homed=axis not in self.homing,
                link_state=self.link.get(axis, AxisStatus.LINK_UP))))
        fix = self._header(NavSatFix(latitude=36.83, longitude=-2.40, altitude=50.0))
        fix.status.status = 0
        self.fix_pub.publish(fix)
        self.beam_pub.publish(self._header(Irradiance(beam=850.0, illuminance=88400.0,
                                                      luminous_efficacy=104.0)))

    def latest(self):
        return self.states[-1] if self.states else None

    def wait_level(self, level: int, timeout: float) -> bool:
        return self.ros.spin_until(lambda: self.states and self.states[-1].level == level, timeout)

    def next_state(self):
        n = len(self.states)
        assert self.ros.spin_until(lambda: len(self.states) > n, 2.0), 'safety/state stalled'
        return self.states[-1]


def _key(state):
    return (state.level, tuple(state.reasons), tuple(state.stopped_axes), state.stow_required,
            state.since.sec, state.since.nanosec)


def _start(launch, ros, **params):
    proc = launch('sslfr_safety', 'safety', params={**FAST, **params})
    world = World(ros)
    world.proc = proc
    from sslfr_interfaces.msg import SafetyState
    ok = world.wait_level(SafetyState.OK, 20.0)
    assert ok, f'never OK: {world.latest()}\n{proc.output()}'
    return proc, world


def test_over_temperature_stows_within_200ms_latched_reset_refused_while_hot(launch, ros):
    from diagnostic_msgs.msg import DiagnosticArray
    from std_srvs.srv import Trigger

    from sslfr_interfaces.msg import SafetyState
    diags = ros.collect(DiagnosticArray, '/diagnostics')
    proc, world = _start(launch, ros)
    # publication rate from the steady-clock timer, measured over 2 s in this process
    n0, t0 = len(world.states), time.monotonic()
    ros.spin_for(2.0)
    rate = (len(world.states) - n0) / (time.monotonic() - t0)
    seqs = [m.sequence for m in world.states[n0:]]
    print(f'safety/state rate {rate:.1f} Hz')
    assert rate >= 10.0, rate
    assert all(b > a for a, b in zip(seqs, seqs[1:])), seqs

    latencies = []
    for value in (150.0, 150.4):          # the limit itself is not exceeded; 150.4 is
        world.t['outlet'] = value
        n = len(world.states)
        sent = world.temperature('outlet', value)
        ros.spin_until(lambda n=n: any(m.level >= SafetyState.STOW for m in world.states[n:]),
                       0.5 if value == 150.0 else 1.0)
        got = [(m, a) for m, a in zip(world.states[n:], world.arrivals[n:]) if m.level >= SafetyState.STOW]
        if value == 150.0:
            assert not got, 'exactly 150 degC must not stow'
            continue
        assert got, f'no STOW after 150.4 degC: {world.latest()}'
        latencies.append(got[0][1] - sent)
    print(f'over-temperature -> STOW received {latencies[0] * 1e3:.1f} ms after the sample was published')
    assert latencies[0] < 0.2
    state = world.latest()
    assert state.stow_required and any('outlet over-temperature: 150.4 degC' in r for r in state.reasons)
    assert ros.spin_until(lambda: any(s.level == s.ERROR and 'STOW' in s.message
                                      for d in diags for s in d.status), 3.0), 'no STOW on /diagnostics'

    # still hot: reset refused, state unchanged
    before = _key(world.next_state())
    res = world.call(Trigger, SAFETY_RESET.name, Trigger.Request())
    assert not res.success and 'still hot' in res.message, res.message
    assert _key(world.next_state()) == before
    # cooled below limit - hysteresis, but not for the hold time: refused
    world.t['outlet'] = 120.0
    ros.spin_for(0.3)
    res = world.call(Trigger, SAFETY_RESET.name, Trigger.Request())
    assert not res.success and 'cooling' in res.message, res.message
    # no return to OK by itself
    ros.spin_for(1.5)
    assert _key(world.next_state()) == before
    res = world.call(Trigger, SAFETY_RESET.name, Trigger.Request())
    assert res.success, res.message
    assert world.wait_level(SafetyState.OK, 1.0)
    assert 'OK -> STOW' in proc.output() and 'STOW -> OK' in proc.output()


def test_thermocouple_nan_and_silence_while_tracking_stow_within_2s(launch, ros):
    from std_srvs.srv import Trigger

    from sslfr_interfaces.msg import SafetyState
    _proc, world = _start(launch, ros)
    sent = world.temperature('inlet', math.nan)
    world.t['inlet'] = math.nan
    assert world.wait_level(SafetyState.STOW, 2.0), world.latest()
    print(f'NaN -> STOW after {time.monotonic() - sent:.3f} s')
    assert any('inlet thermocouple invalid (NaN)' in r for r in world.latest().reasons)
    ros.spin_for(0.5)
    assert world.latest().level == SafetyState.STOW             # held while NaN
    res = world.call(Trigger, SAFETY_RESET.name, Trigger.Request())
    assert not res.success and 'clears by itself' in res.message, res.message
    world.t['inlet'] = 61.0
    back = time.monotonic()
    assert world.wait_level(SafetyState.OK, 3.0), world.latest()
    print(f'valid inlet again -> OK after {time.monotonic() - back:.2f} s (recovery hold 1 s)')
    assert time.monotonic() - back > 0.9

    # a malformed (undecodable) sample: counted, an invalid reading, the node survives
    world.temp_pub['outlet'].publish(b'\x00\x01\x00\x00\xff\xff\xff\x7f garbage')
    assert world.wait_level(SafetyState.STOW, 2.0), world.latest()
    assert any('outlet thermocouple invalid (NaN)' in r for r in world.latest().reasons)
    assert world.wait_level(SafetyState.OK, 3.0), world.latest()
    assert world.proc.running() and 'undecodable message on absorber/outlet_temperature' in world.proc.output()

    # tracking, then the outlet thermocouple goes silent
    world.phase = 2
    ros.spin_for(0.5)
    world.silent.add('outlet')
    last = time.monotonic()
    assert world.wait_level(SafetyState.STOW, 3.0), world.latest()
    elapsed = time.monotonic() - last
    print(f'silent outlet while tracking -> STOW {elapsed:.3f} s after the last sample')
    assert 1.9 < elapsed < 2.5
    assert any('outlet thermocouple silent > 2.0 s while tracking' in r for r in world.latest().reasons)


def test_limit_switch_outside_homing_estops_that_axis_naming_the_switch(launch, ros):
    from std_srvs.srv import Trigger

    from sslfr_interfaces.msg import SafetyState
    _proc, world = _start(launch, ros)
    # homing the mirrors onto the sleeping switch: expected, no stop
    world.homing.add('mirrors')
    world.positions['mirrors'] = 1.2
    ros.spin_for(0.3)
    world.switches['sleeping'] = True
    world.publish_switches()
    ros.spin_for(0.5)
    assert world.latest().level == SafetyState.OK
    world.homing.clear()
    world.positions['mirrors'] = math.pi / 2          # homed at the sleeping position
    ros.spin_for(0.5)
    assert world.latest().level == SafetyState.OK
    # the structure's switch closes while it tracks at 0.6 rad: stop that axis
    world.switches['longitudinal_1'] = True
    sent = world.publish_switches()
    assert world.wait_level(SafetyState.ESTOP, 1.0), world.latest()
    print(f'limit switch -> ESTOP after {(time.monotonic() - sent) * 1e3:.0f} ms')
    state = world.latest()
    assert list(state.stopped_axes) == ['mobile_structure']
    assert any('limit switch longitudinal_1 tripped outside homing' in r for r in state.reasons)
    assert world.call(Trigger, SAFETY_RESET.name, Trigger.Request()).success
    assert world.wait_level(SafetyState.OK, 1.0)


def test_an_idle_driver_or_a_link_down_stows_naming_the_axis_until_active_and_homed(launch, ros):
    """Issue 21: the heartbeats of an unconfigured driver do not make the tracker OK."""
    from sslfr_interfaces.msg import AxisStatus, SafetyState
    _proc, world = _start(launch, ros)
    world.driver_state['mobile_structure'] = 'unconfigured'
    sent = time.monotonic()
    assert world.wait_level(SafetyState.STOW, 1.0), world.latest()
    print(f'unconfigured driver status -> STOW after {(time.monotonic() - sent) * 1e3:.0f} ms')
    assert 'mobile_structure axis not ready: its driver is unconfigured, not active' in world.latest().reasons
    ros.spin_for(1.0)                           # heartbeats keep coming: still STOW, no watchdog reason
    assert world.latest().level == SafetyState.STOW
    assert not any('heartbeat watchdog' in r for r in world.latest().reasons)
    # active again but still homing (not referenced): held
    del world.driver_state['mobile_structure']
    world.homing.add('mobile_structure')
    ros.spin_for(0.8)
    assert world.latest().level == SafetyState.STOW
    assert any(r.startswith('mobile_structure axis not ready: driver active, axis not referenced')
               for r in world.latest().reasons), world.latest().reasons
    world.homing.clear()
    assert world.wait_level(SafetyState.OK, 1.0), world.latest()
    # the mirrors' board link drops: STOW naming the axis; back up (still referenced): OK
    world.link['mirrors'] = AxisStatus.LINK_DOWN
    assert world.wait_level(SafetyState.STOW, 1.0), world.latest()
    assert list(world.latest().reasons) == ['mirrors axis not ready: board link down']
    del world.link['mirrors']
    assert world.wait_level(SafetyState.OK, 1.0), world.latest()


def test_estop_semantics_and_bad_calls_refused_with_state_unchanged(launch, ros):
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from std_srvs.srv import SetBool, Trigger

    from sslfr_interfaces.msg import SafetyState
    _proc, world = _start(launch, ros)
    before = _key(world.next_state())
    res = world.call(SetBool, SAFETY_ESTOP.name, SetBool.Request(data=False))
    assert not res.success and 'no e-stop' in res.message
    res = world.call(Trigger, SAFETY_RESET.name, Trigger.Request())
    assert not res.success and 'nothing latched' in res.message
    bad = SetParameters.Request(parameters=[Parameter(
        name='watchdog.actions', value=ParameterValue(type=ParameterType.PARAMETER_STRING_ARRAY,
                                                      string_array_value=['PANIC'] * 7))])
    out = world.call(SetParameters, 'safety/set_parameters', bad)
    assert not out.results[0].successful and 'WARN or STOW' in out.results[0].reason
    assert _key(world.next_state()) == before

    res = world.call(SetBool, SAFETY_ESTOP.name, SetBool.Request(data=True))
    assert res.success
    assert world.wait_level(SafetyState.ESTOP, 1.0)
    assert sorted(world.latest().stopped_axes) == ['mirrors', 'mobile_structure', 'secondary_reflector']
    ros.spin_for(0.5)
    assert world.latest().level == SafetyState.ESTOP             # latched
    held = _key(world.next_state())
    res = world.call(Trigger, SAFETY_RESET.name, Trigger.Request())
    assert not res.success and 'release it first' in res.message
    assert _key(world.next_state()) == held
    res = world.call(SetBool, SAFETY_ESTOP.name, SetBool.Request(data=False))
    assert res.success
    assert world.wait_level(SafetyState.STOW, 1.0)                # released to stow
    assert world.latest().stow_required and not world.latest().stopped_axes
    ros.spin_for(0.5)
    assert world.latest().level == SafetyState.STOW
    assert world.call(Trigger, SAFETY_RESET.name, Trigger.Request()).success
    assert world.wait_level(SafetyState.OK, 1.0)

    # a valid runtime change is applied: a lower limit makes 120 degC an over-temperature
    good = SetParameters.Request(parameters=[Parameter(
        name='temperature.limit', value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=100.0))])
    assert world.call(SetParameters, 'safety/set_parameters', good).results[0].successful
    world.temperature('inlet', 120.0)
    world.t['inlet'] = 120.0
    assert world.wait_level(SafetyState.STOW, 1.0)
    assert any('inlet over-temperature: 120.0 degC > 100.0 degC' in r for r in world.latest().reasons)


def test_sim_time_jumps_of_one_hour_cause_no_stow_and_no_stall(launch, ros):
    from rosgraph_msgs.msg import Clock

    from sslfr_common.node import qos, stamp, to_sec
    from sslfr_interfaces.msg import SafetyState
    clock_pub = ros.node.create_publisher(Clock, CLOCK.name,
                                          qos(CLOCK))
    sim = {'t': 1_750_000_000.0}

    def tick():
        sim['t'] += 0.05
        now = stamp(sim['t'])
        clock_pub.publish(Clock(clock=now))
        world.stamp = now
    proc = launch('sslfr_safety', 'safety', params={**FAST, 'use_sim_time': True})
    world = World(ros)
    ros.node.create_timer(0.05, tick)
    assert world.wait_level(SafetyState.OK, 20.0), f'{world.latest()}\n{proc.output()}'
    ros.spin_for(1.0)
    for jump in (3600.0, -3600.0, -3600.0):
        start_stamp = sim['t']
        sim['t'] += jump
        n0, t0 = len(world.states), time.monotonic()
        ros.spin_for(1.2)
        window = world.states[n0:]
        rate = len(window) / (time.monotonic() - t0)
        print(f'sim-time jump {jump:+.0f} s: {rate:.1f} Hz, levels {sorted({m.level for m in window})}')
        assert rate >= 10.0, f'stalled after a {jump} s jump: {rate:.1f} Hz'
        assert all(m.level == SafetyState.OK for m in window), [list(m.reasons) for m in window if m.level]
        # the node really runs on sim time: its stamps followed the jump
        last = to_sec(window[-1].header.stamp)
        assert abs(last - (start_stamp + jump)) < 5.0, (last, start_stamp + jump)
