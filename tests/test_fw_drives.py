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

from fw_support import KEY, fw_host, provisioned, require  # noqa: F401

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
