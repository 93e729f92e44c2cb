"""Simulated boards of the drives without switches: the linear actuator closed on an
inclinometer (seed 004) and the switchless stepper (seed 003)."""
import math
import random

import pytest

from drivers_testutil import wait_for
from sslfr_drivers.link import messages as m
from sslfr_drivers.link.board_link import BoardLink, NackError
from sslfr_drivers.link.transport import SerialTransport
from sslfr_sim import board_class
from sslfr_sim.actuator import ActuatorConfig, ActuatorSim, shipped_description
from sslfr_sim.base import Refuse
from sslfr_sim.runner import SimThread
from sslfr_sim.switchless import SwitchlessAxisSim

R = math.radians
STEP = m.DEFAULT_STEP_RAD
SEED004 = shipped_description('florianopolis_lepten')
SEED003 = shipped_description('bucaramanga_single_axis')


def _run(board, t0, t1, dt=0.005):
    t = t0
    while t < t1:
        t += dt
        board.tick(t)
    return t


def test_actuator_board_reaches_targets_within_the_deadband():
    b = ActuatorSim(ActuatorConfig.from_description(SEED004, initial_angle=R(-10.0)), rng=random.Random(2))
    with pytest.raises(Refuse) as exc:
        b.handle(m.MoveTo(0, 100.0), None)
    assert exc.value.code == m.ErrorCode.NOT_HOMED
    b.tick(0.0)
    b.handle(m.SetZero(round(b.measured / STEP)), None)             # referenced to the inclinometer
    t = 0.0
    for deg in (12.0, 12.3, -5.0, 39.0):
        b.handle(m.MoveTo(round(R(deg) / STEP), 1.0 / STEP * R(2.0)), None)    # 2 deg/s limit
        peak = []
        end = t + 40.0
        while t < end:
            t = _run(b, t, t + 0.1)
            peak.append(b.angle)
            if b.duty == 0.0 and abs(b.angle - R(deg)) < R(0.05):
                break
        assert abs(b.angle - R(deg)) <= R(0.05), (deg, math.degrees(b.angle))
        st = b.status()
        assert not st.flags & m.StatusFlags.MOVING and st.flags & m.StatusFlags.HOMED
        assert st.fault_bits == 0
        assert abs(st.sensor_angle - R(deg)) <= R(0.06)
        assert abs(st.position - round(R(deg) / STEP)) * STEP <= R(0.06)
    # the actuator length follows the law of cosines, not a linear map
    assert b.length == pytest.approx(b.cfg.geometry.length(b.angle), abs=1e-12)


def test_actuator_out_of_range_stop_and_no_home():
    b = ActuatorSim(ActuatorConfig.from_description(SEED004), rng=random.Random(2))
    b.tick(0.0)
    b.handle(m.SetZero(round(b.measured / STEP)), None)
    with pytest.raises(Refuse) as exc:
        b.handle(m.MoveTo(round(R(41.0) / STEP), 1000.0), None)
    assert exc.value.code == m.ErrorCode.OUT_OF_RANGE
    assert m.Home.TYPE not in ActuatorSim.REQUESTS                   # no switches: UNKNOWN_TYPE
    b.handle(m.MoveTo(0, 1000.0), None)
    _run(b, 0.0, 1.0)
    moving_angle = b.angle
    assert b.duty != 0.0 and moving_angle < R(39.0)
    b.handle(m.Stop(), None)
    _run(b, 1.0, 2.0)
    assert b.duty == 0.0 and b.angle == pytest.approx(moving_angle, abs=1e-12)   # PWM off: stops at once
    # SET_ZERO while driving ends the move with the PWM off (as the firmware board)
    b.handle(m.MoveTo(0, 1000.0), None)
    _run(b, 2.0, 3.0)
    assert b.duty != 0.0
    b.handle(m.SetZero(0), None)
    _run(b, 3.0, 4.0)
    assert b.duty == 0.0 and not b.status().flags & m.StatusFlags.MOVING


def test_actuator_stall_and_timeout_faults():
    b = ActuatorSim(ActuatorConfig.from_description(SEED004), rng=random.Random(2))
    b.tick(0.0)
    b.handle(m.SetZero(round(b.measured / STEP)), None)
    b.stalled = True                                                  # a jammed bar
    b.handle(m.MoveTo(0, 1000.0), None)
    _run(b, 0.0, 1.5)
    assert b.duty != 0.0 and not b.faults & m.FaultBits.STALL
    _run(b, 1.5, 2.5)
    assert b.faults & m.FaultBits.STALL and b.duty == 0.0 and b.last_fault.startswith('stall')
    b.stalled = False
    b.watch.timeout = 3.0                                             # a move that cannot end in time
    b.handle(m.MoveTo(round(R(-39.0) / STEP), 1000.0), None)         # clears STALL, a new try
    assert not b.faults & m.FaultBits.STALL
    _run(b, 2.5, 6.0)
    assert b.faults & m.FaultBits.STALL and b.last_fault.startswith('time-out')


def test_actuator_inclinometer_offset_error_shows_as_a_bias():
    """The board removes its calibrated offset; a wrong calibration biases the lines."""
    cfg = ActuatorConfig.from_description(SEED004, initial_angle=0.0)
    cfg.inclinometer = type(cfg.inclinometer)(offset=R(0.2), noise=cfg.inclinometer.noise,
                                              resolution=cfg.inclinometer.resolution)
    b = ActuatorSim(cfg, rng=random.Random(5))
    b.tick(0.0)
    b.handle(m.SetZero(round(b.measured / STEP)), None)
    b.handle(m.MoveTo(round(R(10.0) / STEP), 1000.0), None)
    _run(b, 0.0, 20.0)
    assert math.degrees(b.angle) == pytest.approx(10.0 - 0.2, abs=0.05)


def test_switchless_board_has_no_switches_and_loses_its_reference_on_reset():
    b = SwitchlessAxisSim.from_description(SEED003, rng=random.Random(1), max_speed=2000.0, accel=8000.0)
    assert b.cfg.step_rad == pytest.approx(R(0.1125)) and not b.cfg.has_sensor
    assert m.Home.TYPE not in b.REQUESTS
    b.tick(0.0)
    assert b.angle == pytest.approx(R(51.0)) and b.limit_bits() == 0       # at stow, no switch closed
    st = b.status()
    assert not st.flags & m.StatusFlags.HOMED and st.fault_bits & m.FaultBits.RESET
    b.handle(m.SetZero(round(R(51.0) / b.cfg.step_rad)), None)      # the operator: "it is at 51 deg"
    b.handle(m.MoveTo(round(R(10.0) / b.cfg.step_rad), 2000.0), None)
    _run(b, 0.0, 3.0)
    assert b.angle == pytest.approx(R(51.0) + (round(R(10.0) / b.cfg.step_rad) - 453) * b.cfg.step_rad)
    assert b.limit_bits() == 0
    boots = b.boot_count
    b.reset()
    b.tick(3.1)
    st = b.status()
    assert b.boot_count == boots + 1
    assert not st.flags & m.StatusFlags.HOMED and st.fault_bits & m.FaultBits.RESET and st.position == 0
    with pytest.raises(Refuse):
        b.handle(m.MoveTo(0, 100.0), None)


@pytest.mark.parametrize('kind, opts, board_kind', [
    ('actuator', {'initial_angle_deg': '5'}, m.BoardKind.AXIS_ACTUATOR),
    ('axis_noswitch', {'initial_angle_deg': '5', 'max_speed': '2000', 'accel': '8000'}, m.BoardKind.AXIS_STEPPER),
])
def test_protocol_session_with_the_new_boards(kind, opts, board_kind):
    """Over a pty and the authenticated protocol, as a driver talks to them: INFO kind,
    HOME refused UNKNOWN_TYPE, SET_ZERO then MOVE_TO to 2 deg."""
    board = board_class(kind).from_options(opts, random.Random(4))
    sim = SimThread.plain(board).start()
    link = BoardLink(SerialTransport(sim.path), timeout=0.2, retries=3, heartbeat=0.2).start()
    try:
        assert link.wait_up(5)
        assert link.info.board_kind == board_kind
        with pytest.raises(NackError) as exc:
            link.request(m.Home(0, 100.0, 0))
        assert exc.value.code == m.ErrorCode.UNKNOWN_TYPE
        step = STEP if kind == 'actuator' else R(0.1125)
        link.set_zero(round(R(5.0) / step))
        link.move_to(round(R(2.0) / step), R(3.0) / step)
        tol = R(0.06) if kind == 'actuator' else 1.01 * step        # the deadband / one motor step
        assert wait_for(lambda: abs(board.angle - R(2.0)) < tol and not link.get_status().moving, 10)
        assert link.get_status().limit_bits == 0 and link.boot_count == board.boot_count
    finally:
        link.stop()
        sim.stop()


@pytest.mark.parametrize('dt', [0.002, 0.005, 0.0137, 0.02, 0.05])
def test_a_move_seeking_the_sleep_switch_stops_there_at_any_speed_and_tick(dt):
    """The stepper board seeking its SLEEP switch (a host-loss stow, a HOME) stops on it,
    never on the end switch beside it: the simulator moves at most half the switch's
    0.2 deg band between two samples of the switches, as the firmware samples them at
    every step. At 20000 steps/s a 2 ms sub-step was 0.24 deg: from some start
    positions the band was jumped over (fault LIMIT at the HIGH switch)."""
    from sslfr_sim.axis import AxisSim
    for start in range(4000, 4040, 3):                 # the switch met at every phase of a sub-step
        sim = AxisSim.from_options({'axis': 'mirrors', 'max_speed': '20000', 'accel': '200000'}, random.Random(1))
        sim.counter = sim.target = float(start)
        sim.angle = start * sim.cfg.step_rad
        sim.seek, sim.target, sim.cmd_speed = m.Switch.SLEEP, start + 1e9, 20000.0
        for _ in range(int(2.0 / dt)):
            sim.update(dt)
            if sim.seek is None:
                break
        assert sim.seek is None and sim.speed == 0.0, (start, math.degrees(sim.angle))
        assert sim.limit_bits() & m.LimitBits.SLEEP and not sim.faults & m.FaultBits.LIMIT, \
            (start, dt, math.degrees(sim.angle), sim.faults)
