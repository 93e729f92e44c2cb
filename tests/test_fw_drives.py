"""The firmware of the two drives without limit switches, exact binaries in simavr
(docs/firmware.md "Actuator board", "Switchless axis board"):

* ``axis_noswitch`` (seed 003: stepper, no switches): HOME refused UNKNOWN_TYPE, limit
  bits 0 even where the stepper board's switches would be closed, referenced by
  SET_ZERO only, then tracks MOVE_TO like the stepper board; conformance with the
  Python simulator (sim/switchless.py) on the same requests.
* ``actuator`` (seed 004: linear actuator with PWM speed control, inclinometer on an
  analogue input) — see the tests below.

Real time (the harnesses paced), the conditions polled, never slept on."""
from __future__ import annotations

import math
import time

import pytest

from fw_support import KEY, fw_host, provisioned, require, wait_for  # noqa: F401

from sslfr_drivers.link import messages as m

pytestmark = pytest.mark.timeout(180)


@pytest.fixture(scope='module', autouse=True)
def _built():
    require('firmware', 'sim')


def _settle(host, timeout=20.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        st = host.request(m.GetStatus())
        if st is not None and not st.moving and not st.homing:
            return st
        time.sleep(0.05)
    raise AssertionError('still moving')


# ------------------------------------------------------------ switchless stepper
def _noswitch_harness(tmp_path, angle=math.pi / 2, pace=0.5):
    from sslfr_drivers import firmware as fw
    from sslfr_sim.fw_board import config_record
    from sslfr_sim.fw_harness import Harness, axis_mech
    rec = config_record('axis', {'axis': 'mirrors'}, 3)
    return Harness('axis', eeprom=provisioned(rec), link=str(tmp_path / 'nosw'), pace=pace,
                   mech=axis_mech('mirrors', angle), elf_path=str(fw.elf('axis_noswitch'))).start()


def noswitch_session(host) -> list[tuple[str, object]]:
    """Scripted requests for the switchless board (firmware and simulator alike)."""
    out = []

    def step(name, msg):
        out.append((name, host.request(msg)))

    host.poll(0.3)
    step('status at power-up', m.GetStatus())
    step('home (no switch to look for)', m.Home(m.Switch.SLEEP, 2000.0, 15000))
    step('move before the reference', m.MoveTo(14000, 1000.0))
    step('operator reference at +90 deg', m.SetZero(15000))
    step('status referenced', m.GetStatus())
    step('track down', m.MoveTo(13000, 3000.0))
    out.append(('arrived', _settle(host)))
    step('track further', m.MoveTo(12950, 500.0))
    out.append(('arrived again', _settle(host)))
    step('stop at rest', m.Stop())
    step('host-loss stow toward a switch (none)', m.SetHostLossStow(m.HostLossMode.SWITCH, 0, 0, -2000.0, 5000))
    step('host-loss stow to a position', m.SetHostLossStow(m.HostLossMode.POSITION, 0, 14000, 2000.0, 5000))
    step('host-loss stow off', m.SetHostLossStow())
    return out


def _norm(answer):
    if isinstance(answer, m.Status):
        return (answer.position, answer.target, answer.speed, answer.flags, answer.limit_bits, answer.fault_bits)
    return answer


def test_switchless_refuses_home_and_tracks(tmp_path):
    """HOME -> UNKNOWN_TYPE; limit bits 0 at +90 deg (where the stepper board's HIGH and
    SLEEP switches are closed); MOVE_TO refused NOT_HOMED until SET_ZERO; then the
    counter follows MOVE_TO and the joint turns by the steps."""
    h = _noswitch_harness(tmp_path)
    host = fw_host(h.path).heartbeat()
    try:
        info = host.request(m.GetInfo())
        assert (info.board_kind, info.name_str) == (m.BoardKind.AXIS_STEPPER, 'sslfr-axis-nosw')
        out = dict(noswitch_session(host))
        E = m.ErrorCode
        assert out['home (no switch to look for)'] == m.Nack(m.Home.TYPE, E.UNKNOWN_TYPE)
        assert out['host-loss stow toward a switch (none)'] == m.Nack(m.SetHostLossStow.TYPE, E.OUT_OF_RANGE)
        assert out['host-loss stow to a position'] == m.Ack(m.SetHostLossStow.TYPE)
        assert out['move before the reference'] == m.Nack(m.MoveTo.TYPE, E.NOT_HOMED)
        st0 = out['status at power-up']
        assert st0.limit_bits == 0 and not st0.homed and st0.fault_bits & m.FaultBits.RESET
        assert out['operator reference at +90 deg'] == m.Ack(m.SetZero.TYPE)
        assert out['arrived'].position == 13000 and out['arrived'].limit_bits == 0
        st = out['arrived again']
        assert st.position == 12950 and st.homed and st.fault_bits == 0
        angle = h.status()['angle']
        assert abs(angle - (math.pi / 2 - 2050 * math.radians(0.006))) < 1e-6, angle
    finally:
        host.close()
        h.stop()


def test_switchless_conforms_to_the_python_simulator(tmp_path):
    """The same requests to sim/switchless.py and to the firmware: the same answers."""
    from sslfr_sim.axis import AxisConfig
    from sslfr_sim.runner import SimThread
    from sslfr_sim.switchless import SwitchlessAxisSim
    h = _noswitch_harness(tmp_path)
    host = fw_host(h.path).heartbeat()
    try:
        fw = noswitch_session(host)
    finally:
        host.close()
        h.stop()
    sim = SwitchlessAxisSim(AxisConfig.for_axis('mirrors', has_sensor=False, initial_angle=math.pi / 2),
                            board_id=3, key=KEY)
    with SimThread.plain(sim) as thread:
        host = fw_host(thread.path).heartbeat()
        try:
            py = noswitch_session(host)
        finally:
            host.close()
    diffs = [(n, _norm(a), _norm(b)) for (n, a), (_, b) in zip(fw, py) if _norm(a) != _norm(b)]
    assert [n for n, _ in fw] == [n for n, _ in py]
    assert not diffs, '\n'.join(f'{n}: firmware {a} / simulator {b}' for n, a, b in diffs)


# ------------------------------------------------------------------ actuator board
DEADBAND = math.radians(0.05)
STEP = m.DEFAULT_STEP_RAD


def _act_config(**kw):
    from sslfr_sim.actuator import ActuatorConfig, shipped_description
    return ActuatorConfig.from_description(shipped_description(), **kw)


def _act_harness(tmp_path, angle=0.0, pace=1.0, offset=None, noise_mv=3.0):
    import dataclasses
    from sslfr_sim.fw_harness import Harness, actuator_mech
    cfg = _act_config()
    if offset is not None:
        cfg.inclinometer = dataclasses.replace(cfg.inclinometer, offset=offset)
    rec = dataclasses.replace(m.ConfigRecord.defaults(int(m.BoardKind.AXIS_ACTUATOR)), board_id=4,
                              axis=m.ConfigRecord.AXES.index('mirrors'))
    return Harness('actuator', eeprom=provisioned(rec), link=str(tmp_path / 'act'), pace=pace,
                   act=actuator_mech(cfg, angle, noise_mv=noise_mv)).start()


@pytest.fixture
def actuator(tmp_path):
    h = _act_harness(tmp_path)
    host = fw_host(h.path).heartbeat()
    yield h, host
    host.close()
    h.stop()


def test_actuator_parameters_are_the_descriptions():
    """boards/actuator_params.h holds the shipped seed-004 description's drive."""
    import re
    from sslfr_drivers.firmware import firmware_dir
    text = (firmware_dir() / 'boards' / 'actuator_params.h').read_text()
    val = {k: float(v) for k, v in re.findall(r'#define (ACT_\w+) \(?(-?[0-9.]+)f', text)}
    c = _act_config()
    g = c.geometry
    want = {'ACT_LEVER_M': g.lever, 'ACT_MOUNT_M': g.mount_distance, 'ACT_MOUNT_ANGLE': math.degrees(g.mount_angle),
            'ACT_STROKE_MIN': g.stroke[0], 'ACT_STROKE_MAX': g.stroke[1], 'ACT_RANGE_LO': math.degrees(c.range[0]),
            'ACT_RANGE_HI': math.degrees(c.range[1]), 'ACT_DEADBAND': math.degrees(c.deadband),
            'ACT_MAX_SPEED': c.max_speed, 'ACT_MIN_DUTY': c.min_duty, 'ACT_STALL_MIN': math.degrees(c.stall_min),
            'ACT_OFFSET_CAL': math.degrees(c.offset_cal), 'ACT_STEP_RAD': math.degrees(c.step_rad)}
    for k, v in want.items():
        assert val[k] == pytest.approx(v, rel=1e-6, abs=1e-9), k
    ms = {k: int(v) for k, v in re.findall(r'#define (ACT_\w+_MS) ([0-9]+)u', text)}
    assert ms['ACT_STALL_WINDOW_MS'] == round(c.stall_window * 1000)
    assert ms['ACT_TIMEOUT_MS'] == round(c.move_timeout * 1000)


def test_actuator_follows_move_to_within_the_deadband(actuator):
    """SET_ZERO at rest, then MOVE_TOs up and down: the PWM drives until the measured
    angle is within the deadband of the target (the true line angle too, within the
    inclinometer's noise), MOVING while the PWM is on, no overshoot past the band."""
    h, host = actuator
    info = host.request(m.GetInfo())
    assert (info.board_kind, info.name_str) == (m.BoardKind.AXIS_ACTUATOR, 'sslfr-actuator')
    st = host.request(m.GetStatus())
    assert not st.homed and st.fault_bits & m.FaultBits.RESET and st.flags & m.StatusFlags.HAS_SENSOR
    assert abs(st.sensor_angle) < math.radians(0.03)          # the line at 0, offset 0
    assert host.request(m.SetZero(0)) == m.Ack(m.SetZero.TYPE)
    prev = 0.0
    for deg in (5.0, 2.0, -3.0):
        up = deg > prev
        prev = deg
        steps = round(math.radians(deg) / STEP)
        assert host.request(m.MoveTo(steps, 2000.0)) == m.Ack(m.MoveTo.TYPE)
        assert wait_for(lambda: host.request(m.GetStatus()).moving, 2.0)
        peak = -1e9 if up else 1e9
        deadline = time.monotonic() + 15
        while True:
            st = host.request(m.GetStatus())
            a = h.status()['angle']
            peak = max(peak, a) if up else min(peak, a)
            if not st.moving:
                break
            assert time.monotonic() < deadline
            time.sleep(0.03)
        assert st.fault_bits == 0 and st.homed and st.limit_bits == 0
        # the loop stops on a reading within half the band; a later reading adds its noise
        # (0.01 deg 1-sigma: 3 sigma allowed, as for the true angle below)
        assert abs(st.sensor_angle - math.radians(deg)) <= DEADBAND + math.radians(0.03), \
            (deg, math.degrees(st.sensor_angle))
        assert abs(st.position - steps) <= DEADBAND / STEP + 1
        true = h.status()['angle']
        assert abs(true - math.radians(deg)) <= DEADBAND + math.radians(0.03), (deg, math.degrees(true))
        overshoot = (peak - math.radians(deg)) if up else (math.radians(deg) - peak)
        assert overshoot <= DEADBAND / 2 + math.radians(0.03), math.degrees(overshoot)


def test_actuator_stop_and_host_silence_cut_the_pwm(tmp_path):
    """STOP: the PWM is off when the ACK arrives. Host silence: off 1.0-1.3 s after the
    last request, fault WATCHDOG; a new MOVE_TO clears it."""
    h = _act_harness(tmp_path)
    host = fw_host(h.path).heartbeat()
    try:
        host.request(m.SetZero(0))
        far = round(math.radians(30) / STEP)
        host.request(m.MoveTo(far, 5000.0))
        assert wait_for(lambda: h.status()['duty'] != 0.0, 3.0)
        assert host.request(m.Stop()) == m.Ack(m.Stop.TYPE)
        assert h.status()['duty'] == 0.0
        assert not host.request(m.GetStatus()).moving
        host.request(m.MoveTo(far, 5000.0))
        assert wait_for(lambda: h.status()['duty'] != 0.0, 3.0)
        host.close()                                   # the host goes silent
        host = None
        t0 = time.monotonic()
        assert wait_for(lambda: h.status()['duty'] == 0.0, 3.0, step=0.01)
        silent = time.monotonic() - t0
        assert 0.9 <= silent <= 1.4, silent
        host = fw_host(h.path).heartbeat()
        st = host.request(m.GetStatus())
        assert st.fault_bits & m.FaultBits.WATCHDOG and not st.moving
        assert host.request(m.MoveTo(far, 5000.0)) == m.Ack(m.MoveTo.TYPE)
        assert not host.request(m.GetStatus()).fault_bits & m.FaultBits.WATCHDOG
        host.request(m.Stop())
    finally:
        if host is not None:
            host.close()
        h.stop()


def test_actuator_reports_a_stall(actuator):
    """The motor powered, the inclinometer still (a jammed bar): fault STALL after the
    stall window (2 s), PWM off; the next MOVE_TO clears STALL and drives again."""
    h, host = actuator
    host.request(m.SetZero(0))
    h.cmd('stall 1')
    target = round(math.radians(10) / STEP)
    host.request(m.MoveTo(target, 2000.0))
    assert wait_for(lambda: h.status()['duty'] != 0.0, 3.0)
    t0 = time.monotonic()
    assert wait_for(lambda: host.request(m.GetStatus()).fault_bits & m.FaultBits.STALL, 6.0, step=0.05)
    assert 1.8 <= time.monotonic() - t0 <= 4.0
    st = host.request(m.GetStatus())
    assert not st.moving and h.status()['duty'] == 0.0
    h.cmd('stall 0')
    assert host.request(m.MoveTo(target, 2000.0)) == m.Ack(m.MoveTo.TYPE)
    assert not host.request(m.GetStatus()).fault_bits & m.FaultBits.STALL
    assert wait_for(lambda: h.status()['angle'] > math.radians(1.0), 5.0)
    host.request(m.Stop())


def actuator_session(host) -> list[tuple[str, object]]:
    """Scripted requests for the actuator board (firmware and simulator alike)."""
    out = []

    def step(name, msg=None, **kw):
        out.append((name, host.request(msg, **kw)))

    host.poll(0.3)
    step('status at power-up', m.GetStatus())
    step('info', m.GetInfo())
    step('config', m.GetConfig())
    step('home (not implemented)', m.Home(m.Switch.LOW, 1000.0, 0))
    step('move before the reference', m.MoveTo(100, 1000.0))
    step('bad payload', None, mtype=m.MoveTo.TYPE, payload=b'\x01\x02\x03')
    step('reference at rest', m.SetZero(0))
    step('beyond the range', m.MoveTo(round(math.radians(41) / STEP), 1000.0))
    step('zero speed', m.MoveTo(100, 0.0))
    step('move up 4 deg', m.MoveTo(round(math.radians(4) / STEP), 3000.0))
    arrived = _settle(host)
    out.append(('arrived', arrived))
    step('move to where it is (inside the deadband)', m.MoveTo(arrived.position, 3000.0))
    step('status (no drive inside the band)', m.GetStatus())
    step('stop', m.Stop())
    step('status after stop', m.GetStatus())
    return out


def _act_norm(name, answer):
    if isinstance(answer, m.Info):
        return (answer.board_kind, answer.firmware, answer.protocol, answer.board_id)
    if isinstance(answer, m.Status):
        return (answer.flags, answer.limit_bits, answer.fault_bits)
    return answer


def test_actuator_conforms_to_the_python_simulator(tmp_path):
    """The same requests to sim/actuator.py and to the firmware: the same answers (ACK /
    NACK codes, INFO, the configuration record, STATUS flags, limit and fault bits) and
    positions within the deadband of each other. Both inclinometers are noise-free here:
    with noise, a move to the reported position starts driving when two readings differ
    by more than the deadband (0.05 deg, 3.5 sigma of their difference: a run in ~10^3
    did), on either side, and the answers would differ by chance."""
    import dataclasses
    from sslfr_sim.actuator import ActuatorSim
    from sslfr_sim.runner import SimThread
    h = _act_harness(tmp_path, noise_mv=0.0)
    host = fw_host(h.path).heartbeat()
    try:
        fw = actuator_session(host)
    finally:
        host.close()
        h.stop()
    cfg = _act_config(initial_angle=0.0)
    cfg.inclinometer = dataclasses.replace(cfg.inclinometer, noise=0.0)
    sim = ActuatorSim(cfg, board_id=4, key=KEY)
    with SimThread.plain(sim) as thread:
        host = fw_host(thread.path).heartbeat()
        try:
            py = actuator_session(host)
        finally:
            host.close()
    assert [n for n, _ in fw] == [n for n, _ in py]
    diffs = []
    for (name, a), (_, b) in zip(fw, py):
        if _act_norm(name, a) != _act_norm(name, b):
            diffs.append((name, _act_norm(name, a), _act_norm(name, b)))
        if isinstance(a, m.Status) and a.homed:
            if abs(a.position - b.position) > DEADBAND / STEP + 2 or (name == 'arrived' and a.target != b.target):
                diffs.append((name, (a.position, a.target), (b.position, b.target)))
        print(f'{name:36s} {_act_norm(name, a)}  {_act_norm(name, b)}')
    assert not diffs, '\n'.join(f'{n}: firmware {a} / simulator {b}' for n, a, b in diffs)


def test_actuator_built_for_another_descriptions_drive(tmp_path):
    """A description whose drive differs from boards/actuator_params.h (here a 0.3 deg
    deadband) runs an image built for it (fw_harness.actuator_elf, as fw_board does): a
    MOVE_TO 0.2 deg away is inside its deadband (never driven; the shipped build's 0.05
    deg band would drive), one 1 deg away ends within 0.3 deg."""
    import dataclasses
    from sslfr_drivers import firmware as fw
    from sslfr_sim.fw_harness import Harness, actuator_elf, actuator_mech
    cfg = dataclasses.replace(_act_config(), deadband=math.radians(0.3))
    path = actuator_elf(cfg)
    assert path != fw.elf('actuator') and path.exists()
    rec = dataclasses.replace(m.ConfigRecord.defaults(int(m.BoardKind.AXIS_ACTUATOR)), board_id=4, axis=0)
    h = Harness('actuator', eeprom=provisioned(rec), link=str(tmp_path / 'act'), act=actuator_mech(cfg, 0.0),
                elf_path=str(path)).start()
    host = fw_host(h.path).heartbeat()
    try:
        assert host.request(m.SetZero(0)) == m.Ack(m.SetZero.TYPE)
        assert host.request(m.MoveTo(round(math.radians(0.2) / STEP), 2000.0)) == m.Ack(m.MoveTo.TYPE)
        assert not wait_for(lambda: h.status()['duty'] != 0.0, 1.0)
        assert host.request(m.MoveTo(round(math.radians(1.0) / STEP), 2000.0)) == m.Ack(m.MoveTo.TYPE)
        assert wait_for(lambda: h.status()['duty'] != 0.0, 2.0)
        st = _settle(host)
        assert abs(st.sensor_angle - math.radians(1.0)) <= math.radians(0.3) and st.fault_bits == 0
    finally:
        host.close()
        h.stop()
