"""The day report judges tracking error only while an axis tracks; deliberate moves are counted
apart (issue 17): pure numbers, no bag."""
import math

import numpy as np
import pytest

from sslfr_recording.report import MOVE_CAP, SETTLE, axis_moves

SUN_RATE = math.radians(15.0 / 3600 / 2)        # a mirror following the sun [rad/s]


def _slew(t, t0, start, target, speed):
    """Measured angle of an axis slewing from ``start`` toward ``target`` at ``speed`` from ``t0``."""
    travelled = np.clip((t - t0) * speed, 0.0, abs(target - start))
    return np.where(t < t0, start, start + np.sign(target - start) * travelled)


def test_tracking_alone_has_no_moves():
    t = np.arange(0.0, 3600.0, 1.0)
    sp = -0.5 + SUN_RATE * t
    assert axis_moves(t, sp, sp + 2e-4 * np.sin(t / 60.0)) == []


def test_a_setpoint_jump_is_one_move_until_the_axis_settles():
    t = np.arange(0.0, 600.0, 1.0)
    sp = np.where(t < 100, math.pi / 2, -0.6 + SUN_RATE * t)          # sleeping -> initial position
    slew = _slew(t, 100.0, math.pi / 2, -0.6, 0.05)                  # 0.05 rad/s, ~43 s
    me = np.where(t < 100, math.pi / 2, np.maximum(slew, sp + 1e-4))  # then follows the sun
    (mv,) = axis_moves(t, sp, me)
    assert mv['settled'] and mv['start'] == 99.0
    assert mv['duration'] == pytest.approx(1 + (math.pi / 2 + 0.6) / 0.05, abs=2.0)
    assert mv["size"] == pytest.approx(math.pi / 2 - sp[int(mv["end"])], abs=2e-4)
    after = np.arange(mv['i1'], t.size)
    assert np.all(np.abs(me - sp)[after] <= SETTLE)                  # what follows is tracking


def test_a_stuck_axis_is_not_hidden_as_a_move():
    t = np.arange(0.0, 1200.0, 1.0)
    sp = np.where(t < 100, 0.0, 0.3)
    me = np.zeros_like(t)                                            # never moves
    (mv,) = axis_moves(t, sp, me)
    assert not mv['settled'] and mv['duration'] <= MOVE_CAP
    assert mv['i1'] < t.size - 500                                   # the rest counts as tracking error


def test_repeated_steps_and_a_fast_ramp():
    t = np.arange(0.0, 3600.0, 1.0)
    sp = np.floor(t / 900.0) * math.radians(3.75)                     # seed 003: 15-min steps
    me = sp.copy()
    for k in (1, 2, 3):                                              # each step taken in 5 s
        i = 900 * k
        me[i:i + 5] = sp[i - 1] + (sp[i] - sp[i - 1]) * np.arange(1, 6) / 6
    moves = axis_moves(t, sp, me)
    assert len(moves) == 3 and all(m['settled'] for m in moves)
    assert [round(m['duration']) for m in moves] == [6, 6, 6]
    ramp = np.clip((t - 100) * 0.01, 0, 1.0)                        # a stow ramp at 0.01 rad/s
    (mv,) = axis_moves(t, ramp, ramp)
    assert mv['duration'] == pytest.approx(100.0, abs=1.5)


def test_a_recording_that_starts_mid_move_counts_the_arrival_as_a_move():
    """A run started in daytime: the first samples have the axis still slewing from the
    sleeping position to a setpoint already on the sun; the arrival is a move, not
    tracking error. An axis on its setpoint at the first sample has none."""
    t = np.arange(0.0, 600.0, 1.0)
    sp = -0.6 + SUN_RATE * t
    me = np.maximum(_slew(t, 0.0, math.pi / 2, -0.6, 0.05), sp + 1e-4)
    (mv,) = axis_moves(t, sp, me)
    assert mv['i0'] == 0 and mv['settled'] and mv['duration'] == pytest.approx((math.pi / 2 + 0.6) / 0.05, abs=2.0)
    assert np.all(np.abs(me - sp)[mv['i1']:] <= SETTLE)
    assert axis_moves(t, sp, sp + 1e-4) == []
