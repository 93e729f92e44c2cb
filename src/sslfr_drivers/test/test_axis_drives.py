"""The axis driver's drive strategies (sslfr_drivers.axis.drive) against the simulated
boards of the drives without switches, in one process: the supervisor decides, the
board model (sslfr_sim) executes, no ROS."""
from __future__ import annotations

import math
import random

import pytest

from sslfr_drivers.axis.board_session import board_command, board_from_status
from sslfr_drivers.axis.drive import drive_for
from sslfr_drivers.axis.params import PARAMS, params_for, tuning_from
from sslfr_drivers.axis.supervisor import AxisSupervisor
from sslfr_drivers.axis.trajectory import TrajectoryMsg
from sslfr_drivers.link import messages as m
from sslfr_sim.actuator import ActuatorConfig, ActuatorSim, shipped_description
from sslfr_sim.base import Refuse
from sslfr_sim.switchless import SwitchlessAxisSim

R = math.radians
T0 = 1_750_000_000.0


def _params(**kw):
    """The driver's parameters, validated (callers give host_loss_stow_position with
    stow_position: its default, seed 000's sleeping angle, lies outside narrower limits)."""
    v = {**params_for('mirrors').defaults(), **kw}
    assert PARAMS.validate(v) == [], PARAMS.validate(v)
    return v


def _loop(sup, board, t_end, t=0.0, dt=0.05, active=True):
    """Run the driver's read -> decide -> write loop against ``board`` until ``t_end`` [s]
    (ROS time = T0 + steady time); every answer refused is collected."""
    refused = []
    while t < t_end:
        st = board_from_status(board.status())
        act = sup.tick(T0 + t, t, st, active)
        msg = board_command(act)
        if msg is not None:
            try:
                board.handle(msg, None)
                sup.record_write(act, True)
            except Refuse as exc:
                refused.append((msg, exc.code))
        sub = t + dt
        while t < sub:
            t = min(sub, t + 0.005)
            board.tick(t)
        sup.safety.receive(t, 0, False, [], int(t * 20))
    return t, refused


def _lepten_rig(initial_deg: float, seed: int):
    """Seed 004's drive: (description, mirrors movement, the driver's tuning from the
    description, a supervisor with it, its actuator simulator at ``initial_deg``), safety OK."""
    desc = shipped_description('florianopolis_lepten')
    mv = desc.movement('mirrors')
    p = _params(drive=mv.drive, deadband=mv.deadband, lower_limit=mv.range[0], upper_limit=mv.range[1],
                stow_position=mv.stow, host_loss_stow_position=mv.stow, home_position=mv.stow, max_speed=0.03)
    cfg, stall = tuning_from(p)
    sup = AxisSupervisor(cfg, stall=stall)
    sup.safety.receive(0.0, 0, False, [], 1)
    board = ActuatorSim(ActuatorConfig.from_description(desc, initial_angle=R(initial_deg)), rng=random.Random(seed))
    board.tick(0.0)
    return desc, mv, cfg, sup, board


def test_actuator_drive_tracks_a_trajectory_within_the_deadband():
    desc, mv, cfg, sup, board = _lepten_rig(-20.0, 9)
    # a ramp of the lines from -20 deg to -15 deg over 60 s (5 deg/min, far faster than the sun)
    times = [T0 + k for k in range(0, 61, 5)]
    pos = [R(-20.0) + R(5.0) * k / 60 for k in range(0, 61, 5)]
    assert sup.store.offer(TrajectoryMsg.for_joint('mirrors', times, pos, None), 'mirrors', T0, cfg.limits) is None
    t, refused = _loop(sup, board, 5.0)
    assert refused == [] and board.homed                      # referenced from the inclinometer (SET_ZERO)
    assert sup.counters['set_zero_sent'] == 1 and sup.counters['homes_sent'] == 0
    errs, states = [], set()
    while t < 59.0:
        t, refused = _loop(sup, board, t + 1.0, t)
        assert refused == [] and sup.fault is None, (refused, sup.fault)
        sp = sup.store.setpoint(T0 + t)[0]
        errs.append(abs(board.angle - sp))
        states.add(sup.state)
    assert states == {'following'}
    # within the deadband plus what the ramp adds during one settling (5 deg/min x 1 s)
    assert max(errs[5:]) < mv.deadband + R(5.0) / 60 * 1.0, [math.degrees(e) for e in errs]
    t, _ = _loop(sup, board, 65.0, t)                         # the ramp's end: rests within the band
    assert abs(board.angle - R(-15.0)) <= mv.deadband
    assert board.duty == 0.0 and sup.fault is None
    sent = sup.counters['moves_sent']
    t, _ = _loop(sup, board, 75.0, t)                         # at rest inside the band: nothing to chase
    assert sup.counters['moves_sent'] == sent and board.duty == 0.0 and sup.state == 'holding'


def test_actuator_stall_is_a_driver_fault():
    desc = shipped_description('florianopolis_lepten')
    mv = desc.movement('mirrors')
    p = _params(drive=mv.drive, deadband=mv.deadband, lower_limit=mv.range[0], upper_limit=mv.range[1],
                stow_position=mv.stow, host_loss_stow_position=mv.stow, home_position=mv.stow)
    cfg, stall = tuning_from(p)
    sup = AxisSupervisor(cfg, stall=stall)
    sup.safety.receive(0.0, 0, False, [], 1)
    board = ActuatorSim(ActuatorConfig.from_description(desc, initial_angle=R(0.0)), rng=random.Random(9))
    board.tick(0.0)
    t, _ = _loop(sup, board, 2.0)
    board.stalled = True
    sup.store.offer(TrajectoryMsg.for_joint('mirrors', [T0, T0 + 100], [R(10.0), R(10.0)], None),
                    'mirrors', T0 + t, cfg.limits)
    t, _ = _loop(sup, board, t + 5.0, t)
    assert sup.state == 'fault' and 'stall' in sup.fault


def test_switchless_drive_waits_for_the_operator_then_references_at_home_position():
    desc = shipped_description('bucaramanga_single_axis')
    mv = desc.movement('mirrors')
    # the driver's mechanical range is still the contract's seed-000 mirrors range
    # (-45..90 deg): the soft limits are the description's range within it
    p = _params(drive=mv.drive, step_angle=mv.step, lower_limit=max(mv.range[0], R(-45.0)), upper_limit=mv.range[1],
                stow_position=mv.stow, host_loss_stow_position=mv.stow, home_position=mv.reference, use_sensor=False, auto_home=False,
                max_speed=0.2)
    cfg, stall = tuning_from(p)
    sup = AxisSupervisor(cfg, stall=stall)
    sup.safety.receive(0.0, 0, False, [], 1)
    board = SwitchlessAxisSim.from_description(desc, rng=random.Random(1), initial_angle=R(0.0),
                                               max_speed=2000.0, accel=8000.0)
    board.tick(0.0)
    sup.store.offer(TrajectoryMsg.for_joint('mirrors', [T0, T0 + 100], [R(20.0), R(20.0)], None),
                    'mirrors', T0, cfg.limits)
    t, refused = _loop(sup, board, 2.0)
    assert sup.state == 'fault' and 'home service' in sup.reason and board.angle == 0.0    # never moves by itself
    assert sup.counters['homes_sent'] == 0 and refused == []
    ok, msg = sup.request_home(True)                           # the operator: "it is at 0 deg now"
    assert ok and 'referenced at 0.0000 rad' in msg
    t, refused = _loop(sup, board, t + 3.0, t)
    assert refused == [] and sup.counters['set_zero_sent'] == 1 and sup.counters['homes_sent'] == 0
    assert board.angle == pytest.approx(R(20.0), abs=mv.step) and sup.state in ('following', 'waiting')
    board.reset()                                              # power cut: the reference is lost
    t, _ = _loop(sup, board, t + 1.0, t)
    assert sup.state == 'fault' and 'home service' in sup.reason


def test_drive_strategies_and_parameter_rules():
    assert drive_for('linear_actuator_inclinometer').board_kind == m.BoardKind.AXIS_ACTUATOR
    assert drive_for('stepper_no_switches').board_kind == m.BoardKind.AXIS_STEPPER
    with pytest.raises(KeyError, match='unknown drive kind'):
        drive_for('hydraulic_ram')
    base = params_for('mirrors').defaults()
    assert base['drive'] == 'stepper_switches' and base['deadband'] == 0.0
    bad = PARAMS.validate({**base, 'drive': 'linear_actuator_inclinometer'})
    assert any('needs deadband > 0' in e for e in bad)
    bad = PARAMS.validate({**base, 'drive': 'stepper_no_switches'})
    assert any('auto_home and use_sensor must be false' in e for e in bad)
    bad = PARAMS.validate({**base, 'deadband': 0.001})
    assert any('deadband is a property of a linear_actuator_inclinometer drive' in e for e in bad)


def test_reference_keeper_records_on_set_zero_and_marks_lost_on_a_board_reset(tmp_path):
    from sslfr_drivers.axis.commands import Action, BoardState
    from sslfr_drivers.axis.drive import reference_keeper
    p = {**params_for('mirrors').defaults(), 'drive': 'stepper_no_switches', 'state_dir': str(tmp_path),
         'home_position': R(5.0)}
    assert reference_keeper({**p, 'state_dir': ''}) is None
    assert reference_keeper({**p, 'drive': 'stepper_switches'}) is None
    keep = reference_keeper(p)
    homed, lost = BoardState(0, 0, False, True, False, None), BoardState(0, 0, False, False, False, None)
    assert keep.after_read(lost, False, False, 3) is None and keep.state == 'none'
    assert keep.after_write(Action('move', 10, 5.0), True, 3, 1.0) is None
    assert keep.after_write(Action('set_zero', 0), False, 3, 1.0) is None          # refused: nothing kept
    assert 'kept in' in keep.after_write(Action('set_zero', 44), True, 3, 1.0) and keep.state == 'valid'
    ref = keep.store.load()
    assert ref.angle == R(5.0) and ref.steps == 44 and ref.boot_count == 3
    assert keep.after_read(homed, False, False, 3) is None and keep.state == 'valid'
    line = keep.after_read(lost, True, False, 4)                                     # the board rebooted
    assert 'is lost: board reset: boot 4' in line and keep.state.startswith('lost')
    again = reference_keeper(p)                                                      # a restarted driver
    again.after_read(homed, False, False, 4)
    assert again.state.startswith('lost')
    assert 'not kept' in keep.after_write(Action('set_zero', 0), True, None, 2.0)


@pytest.mark.parametrize('seed', range(6))
def test_actuator_drive_reaches_its_stow_on_the_range_end(seed):
    """Seed 004's sleeping and stow positions are the range end (40 deg): the step
    nearest 40 deg lies beyond it (40 / 0.006 is not whole) and the board's step zero,
    taken from its own reading at SET_ZERO, differs from the host's by the reading
    noise; the target stays a deadband inside the range, so the board never refuses it."""
    desc, mv, cfg, sup, board = _lepten_rig(40.0, seed)
    for end in (mv.range[1], mv.range[0]):
        times = [T0 + k for k in range(0, 200, 5)]
        assert sup.store.offer(TrajectoryMsg.for_joint('mirrors', times, [end] * len(times), None), 'mirrors',
                               T0, cfg.limits) is None
        t, refused = _loop(sup, board, 60.0 if end > 0 else 180.0, 0.0 if end > 0 else 60.0)
        assert refused == [] and sup.fault is None, (refused, sup.fault)
        assert abs(board.angle - end) <= 2.0 * mv.deadband and mv.range[0] <= board.angle <= mv.range[1], \
            math.degrees(board.angle)
