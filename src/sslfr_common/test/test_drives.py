"""Drive models without switches (sslfr_common.drives): worked examples."""
import json
import math
import random

import pytest

from sslfr_common.drives import (ActuatorLoop, Inclinometer, LeverGeometry, MotionWatch, ReferenceStore,
                                 duty_for_speed, speed_for_duty)

R = math.radians
# the seed-004 description's lever (florianopolis_lepten.yaml): r 0.15 m, d 0.40 m, 90 deg
GEO = LeverGeometry(lever=0.15, mount_distance=0.40, mount_angle=R(90.0), stroke=(0.30, 0.53))


def test_law_of_cosines_worked_examples():
    # theta = 0: gamma = 90 deg, L = sqrt(0.40^2 + 0.15^2) = sqrt(0.1825)
    assert GEO.length(0.0) == pytest.approx(0.4272001872658765, abs=1e-12)
    # theta = +40 deg: gamma = 130 deg, L^2 = 0.1825 - 0.12 cos 130 deg = 0.25963451
    assert GEO.length(R(40.0)) == pytest.approx(math.sqrt(0.1825 + 0.12 * 0.6427876096865393), abs=1e-12)
    assert GEO.length(R(-40.0)) == pytest.approx(math.sqrt(0.1825 - 0.12 * 0.6427876096865393), abs=1e-12)
    # dL/dtheta at 0: d r sin(90) / L = 0.06 / 0.42720
    assert GEO.rate(0.0) == pytest.approx(0.06 / 0.4272001872658765, rel=1e-12)


def test_geometry_is_not_linear_and_inverts():
    lo, hi = GEO.length(R(-40.0)), GEO.length(R(40.0))
    # the middle of the stroke is not the middle of the angle: 4.09 deg apart here
    assert math.degrees(GEO.angle((lo + hi) / 2)) == pytest.approx(-4.0863, abs=1e-3)
    for deg in (-40.0, -12.5, 0.0, 7.3, 40.0):
        assert GEO.angle(GEO.length(R(deg))) == pytest.approx(R(deg), abs=1e-12)
    with pytest.raises(ValueError):
        GEO.angle(0.60)          # longer than d + r = 0.55 m


def test_geometry_problems():
    assert GEO.problems((R(-40.0), R(40.0))) == []
    short = LeverGeometry(0.15, 0.40, R(90.0), (0.35, 0.53))
    assert 'outside stroke_m' in short.problems((R(-40.0), R(40.0)))[0]
    fold = LeverGeometry(0.15, 0.40, R(30.0), (0.1, 0.6))
    assert 'within (5, 175) deg' in fold.problems((R(-40.0), R(40.0)))[0]


def test_pwm_duty_for_speed():
    assert duty_for_speed(0.0025, 0.005, 0.2) == pytest.approx(0.6)
    assert duty_for_speed(-0.0025, 0.005, 0.2) == pytest.approx(-0.6)
    assert duty_for_speed(0.01, 0.005, 0.2) == 1.0            # clamped
    assert duty_for_speed(0.0, 0.005, 0.2) == 0.0
    assert speed_for_duty(0.6, 0.005, 0.2) == pytest.approx(0.0025)
    assert speed_for_duty(0.19, 0.005, 0.2) == 0.0            # below the start duty
    assert speed_for_duty(-1.0, 0.005, 0.2) == pytest.approx(-0.005)


def test_actuator_loop_deadband_and_hysteresis():
    loop = ActuatorLoop(GEO, deadband=R(0.05), max_speed=0.005, min_duty=0.2)
    assert loop.duty(R(10.0), R(10.04), R(1.0)) == 0.0       # inside the band: rests
    d = loop.duty(R(10.0), R(9.9), R(1.0))                    # 0.1 deg below: drives up
    assert d > 0.2 and loop.driving
    assert loop.duty(R(10.0), R(9.97), R(1.0)) > 0            # 0.03 deg: still above band/2
    assert loop.duty(R(10.0), R(9.976), R(1.0)) == 0.0        # within 0.025 deg: settles
    assert loop.duty(R(10.0), R(10.04), R(1.0)) == 0.0        # 0.04 deg < band: stays settled
    assert loop.duty(R(10.0), R(10.06), R(1.0)) < 0           # beyond the band: drives back


def test_actuator_loop_closed_on_the_lever_settles_without_overshoot():
    """A 20 deg step through the real geometry: reaches the band and never crosses it."""
    loop = ActuatorLoop(GEO, deadband=R(0.05), max_speed=0.005, min_duty=0.2)
    length, dt, target = GEO.length(R(-10.0)), 0.01, R(10.0)
    peak = -1.0
    for _ in range(6000):
        theta = GEO.angle(length)
        peak = max(peak, theta)
        length += speed_for_duty(loop.duty(target, theta, R(2.0)), 0.005, 0.2) * dt
    assert abs(GEO.angle(length) - target) <= R(0.025) + 1e-9
    assert peak <= target + R(0.05)
    assert not loop.driving


def test_motion_watch_stall_and_timeout():
    w = MotionWatch(window=2.0, min_change=R(0.03), timeout=10.0)
    assert w.update(0.0, True, 0.0) is None
    assert w.update(1.0, True, R(0.01)) is None
    why = w.update(2.1, True, R(0.02))
    assert why.startswith('stall')
    w.reset()
    for i in range(100):                 # moving steadily: no stall, then the time-out
        why = w.update(i * 0.2, True, R(0.1) * i)
        if why:
            break
    assert why.startswith('time-out') and i * 0.2 > 10.0
    assert w.update(30.0, False, 0.0) is None                # stopped: forgotten
    for i in range(100):                 # tracking: a new target every 0.2 s, driving through
        w.new_target()
        assert w.update(i * 0.2, True, R(0.1) * i) is None
    for i in range(20):                  # ... and a stall is still one (the window kept)
        w.new_target()
        why = w.update(20.0 + i * 0.2, True, R(9.9))
        if why:
            break
    assert why and why.startswith('stall') and 20.0 + i * 0.2 - 19.8 >= 2.0    # 2 s after the last motion


def test_inclinometer_offset_noise_resolution():
    inc = Inclinometer(offset=R(0.5), noise=R(0.01), resolution=R(0.01))
    rng = random.Random(1)
    reads = [inc.read(R(10.0), rng) for _ in range(2000)]
    mean = sum(reads) / len(reads)
    assert math.degrees(mean) == pytest.approx(10.5, abs=0.002)
    sd = math.sqrt(sum((r - mean) ** 2 for r in reads) / len(reads))
    assert math.degrees(sd) == pytest.approx(0.01, rel=0.15)
    assert all(abs(r / R(0.01) - round(r / R(0.01))) < 1e-6 for r in reads)
    assert math.degrees(inc.correct(mean)) == pytest.approx(10.0, abs=0.002)


def test_reference_store_valid_then_lost_on_board_reset(tmp_path):
    store = ReferenceStore(tmp_path, 'mirrors')
    assert store.check(7, True) == ('none', None)
    store.record(R(0.0), 0, boot_count=7, stamp=1.0e9)
    assert [p.name for p in tmp_path.iterdir()] == ['reference_mirrors.json']   # no temporary left
    assert store.check(None, True)[0] == 'unknown'
    state, ref = store.check(7, True)
    assert state == 'valid' and ref.boot_count == 7 and not ref.lost
    state, ref = store.check(8, False)                        # the board rebooted
    assert state == 'lost' and 'boot 8' in ref.why
    again = ReferenceStore(tmp_path, 'mirrors')               # a restarted host still sees it lost
    assert again.check(7, True)[0] == 'lost'
    assert again.load().angle == 0.0
    store.record(R(5.0), 833, boot_count=8, stamp=1.0e9 + 60)    # re-referenced
    assert store.check(8, True)[0] == 'valid'
    assert store.check(8, False)[1].why == 'the board no longer reports HOMED'


def test_reference_store_refuses_a_malformed_file(tmp_path):
    store = ReferenceStore(tmp_path, 'mirrors')
    store.path.write_text('{"axis": "mirrors", "angle": 0.1')
    with pytest.raises(ValueError, match='malformed'):
        store.load()
    store.path.write_text(json.dumps({'axis': 'secondary_reflector', 'angle': 0.0, 'steps': 0,
                                      'boot_count': 1, 'stamp': 0.0}))
    with pytest.raises(ValueError, match='not of'):
        store.load()
