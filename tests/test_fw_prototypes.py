"""Seeds 003 and 004 on their firmware boards (issue 34 item 6): a whole simulated day
each (the dates, sites and sunrise-to-sunset windows of tests/test_prototypes.py)
through ``./sslfr sim --boards firmware``: each collector's own axis board runs its
firmware in simavr (the switchless stepper of seed 003, the inclinometer-closed
actuator of seed 004; fw_board, docs/firmware.md), with the absorber and irradiance
boards' firmware, recorded and reported.

The AVRs run in real (wall) time while the simulated day runs ``SPEEDS`` times faster:
seed 003's stepper holds between its 15-minute steps and reaches each in milliseconds,
so its day runs fast; seed 004's loop (speed = gain x error, docs/firmware.md "Motion
(actuator board)") follows the sun's compressed motion 1/gain wall seconds behind, so
its accuracy is judged against the exact solution that much earlier (the budget check
at 30x on the drive's Python model is tests/test_prototypes.py).
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from collectors_testutil import planned_steps, site_of, tracking
from fw_support import require

from sslfr_bringup import nodeset
from sslfr_common.drives import ActuatorLoop
from sslfr_drivers.axis.params import PARAMS as AXIS_PARAMS
from sslfr_drivers.link import messages as msgs
from sslfr_planner import prototype
from sslfr_planner.description import load
from sslfr_recording.day import read_day, reference
from sslfr_sim import scenario

pytestmark = [pytest.mark.slow, pytest.mark.timeout(400)]
DATE = '2026-06-21'
#: prototype -> (site config, window UTC: sunrise to sunset with margins, simulated s per wall s)
DAYS = {'seed003': ('bucaramanga_single_axis.yaml', '11:45', '22:15', 1600.0),
        'seed004': ('florianopolis_lepten.yaml', '10:00', '20:35', 600.0)}
FAULT_FREE = re.compile(r'mirrors: [^\n]*, 0 samples with fault bits')
ENERGY = re.compile(r'absorbed energy ([\d.]+) kWh achieved vs ([\d.]+) kWh with ideal angles .*?'
                    r"the collector's law gives ([\d.]+) kWh")


@pytest.fixture(scope='module', autouse=True)
def _built():
    require('firmware', 'sim')


def _day(name, env, out):
    """The prototype's whole day on firmware boards, with its report: (output text, Day,
    description, config path, speed)."""
    config, start, end, speed = DAYS[name]
    path = nodeset.resolve_config(config)
    proc, summary, bag = scenario.run_sim(['--boards', 'firmware', '--date', DATE, '--config', str(path),
                                           '--start', start, '--end', end, '--speed', f'{speed:g}'],
                                          env, out, timeout=360.0)
    text = proc.stdout + proc.stderr
    assert proc.returncode == 0 and 'MISSING' not in text and 'Traceback' not in text, text[-4000:]
    assert summary['boards'] == 'firmware' and bag is not None, text[-4000:]
    print(f'\n{name} on firmware boards at {speed:g}x: wall time {summary["wall_time_s"]:.1f} s '
          f'(start-up {summary["startup_s"]:.1f} s)')
    return text, read_day(bag), load(nodeset.for_config(nodeset.load(), path).collector), path, speed


def _energy(text):
    """(achieved, ideal, law) [kWh] of the day report's absorbed energy line."""
    found = ENERGY.search(text)
    assert found, text[-3000:]
    return tuple(float(v) for v in found.groups())


def test_seed003_day_on_its_switchless_stepper_firmware(ros_env, tmp_path):
    text, day, desc, config, speed = _day('seed003', ros_env, tmp_path / 'out')
    assert 'simulated operator referenced mirrors' in text, text[-3000:]
    assert '/axes/mobile_structure/status' not in day.topics and '/gps/fix' not in day.topics
    s, ok = tracking(day)
    t, setpoint, measured = (np.asarray(s.t)[ok], np.asarray(s['setpoint'])[ok], np.asarray(s['measured'])[ok])
    assert ok.sum() > 80, ok.sum()                     # a status every 0.2 s wall: 320 simulated s at 1600x
    # the planner's steps (its recorded 1 s trajectories): every 15 minutes while tracking
    pt, pv, jump = planned_steps(day, t[0], t[-1])
    jumps, gaps = pt[jump], np.diff(pt[jump])
    assert len(jumps) >= 30 and np.all(np.abs(gaps - 900.0) <= 2.0), gaps
    m = desc.movement('mirrors')
    step = m.step or 0.0
    # every step reached within one motor step: the last status that still carries the
    # step's setpoint, taken before the next step's command. The driver commands one control
    # period ahead (AxisTuning.lead, 1 / control_rate wall s: 80 simulated s at this speed)
    # while a status carries the setpoint of its own time: a status shortly before the next
    # planned step may already carry that step with the drive on its way (seen: 1.46 of
    # 1.85 deg), or still the old setpoint with the drive already at the next step (seen:
    # 15.53 deg measured, 14.13 deg set, 1.40 deg before the step at 14.13 + 1.40), when a
    # control tick woken early by an event saw the moving board before the step's time.
    # So the statuses stamped within two leads of the next step are not judged here (a
    # status's stamp is never before the tick its numbers come from).
    reached = 0
    lead = 2.0 * speed / AXIS_PARAMS.defaults()['control_rate']    # [s sim] two control periods
    held = dict(zip(pt[jump].tolist(), pv[jump].tolist()))
    for a, b in zip(jumps[:-1], jumps[1:]):
        k = np.flatnonzero((t > a) & (t < b - lead) & (np.abs(setpoint - held[a]) <= step + 1e-6))
        if len(k):
            reached += 1
            assert abs(measured[k[-1]] - setpoint[k[-1]]) <= step + 1e-6, (a, math.degrees(measured[k[-1]]),
                                                                          math.degrees(setpoint[k[-1]]))
    assert reached >= 30, reached
    late = []                       # statuses of the lead window off their setpoint (printed)
    for a, b in zip(jumps[:-1], jumps[1:]):
        k = np.flatnonzero((t >= b - lead) & (t < b) & (np.abs(setpoint - held[a]) <= step + 1e-6))
        late += [(round(b - t[i]), round(math.degrees(measured[i] - setpoint[i]), 3)) for i in k
                 if abs(measured[i] - setpoint[i]) > step + 1e-6]
    # held between the steps: the statuses of a motor at rest on a setpoint already held at
    # the status before (0.2 s wall earlier). Right after a step a status may carry the new
    # setpoint with the position polled before the move: at 1600x the step's wall-time
    # latency (poll, command, motion in simavr, next poll) is a large part of the 0.56 s
    # between steps, and on a loaded machine more than a tenth of the statuses fell in it
    sp_all = np.asarray(s['setpoint'])
    resting = ok & np.r_[False, np.abs(np.diff(sp_all)) <= 1e-9] & ~np.asarray(s['moving'], dtype=bool)
    err = np.abs(measured - setpoint)
    still = np.abs(np.asarray(s['measured'])[resting] - sp_all[resting])
    assert len(still) > 40 and np.percentile(still, 90) <= step + 1e-6, (len(still), math.degrees(np.percentile(still, 90)))
    rate = abs(setpoint[-1] - setpoint[0]) / (t[-1] - t[0]) * 3600.0
    assert 6.5 <= math.degrees(rate) <= 8.5, math.degrees(rate)                # ~7.4 deg/h
    assert np.all((measured >= m.range[0] - 1e-6) & (measured <= m.range[1] + 1e-6))
    x, h = prototype.line_positions(desc), desc.optics.receiver_height
    lines = measured[:, None] - np.arctan2(x, h)[None, :] / 2.0                # seed 003 eqs. 5-6
    assert np.max(np.abs(lines)) <= m.law_params['max_inclination'] + 1e-6, math.degrees(np.max(np.abs(lines)))
    achieved, ideal, law = _energy(text)
    # the drive on its law all day: no less than the law's energy (3 %: what the statuses'
    # timing at this speed moves, a step's few wall milliseconds being seconds of the day).
    # More is no fault: a step taken late holds an angle nearer the moving sun than the
    # step-middle angle of the law (seen up to 3.0 % more at 1600x)
    assert achieved >= 0.97 * law and achieved <= ideal * 1.01, (achieved, law, ideal)
    print(f'seed 003 day on firmware: {len(jumps)} steps every {np.median(gaps):.0f} s, {reached} reached '
          f'within one motor step ({math.degrees(step):.4f} deg; within {lead:.0f} s before the next step '
          f'{len(late)} statuses already off their setpoint: (s before it, deg) {late}); drive rate {math.degrees(rate):.2f} deg/h; largest '
          f'line inclination {math.degrees(np.max(np.abs(lines))):.2f} deg; |measured - setpoint| p90 '
          f'{math.degrees(np.percentile(err, 90)):.4f} deg ({math.degrees(np.percentile(still, 90)):.4f} deg at rest, '
          f'{len(still)} statuses); absorbed {achieved:.3f} kWh vs ideal {ideal:.3f} '
          f'({100 * achieved / ideal:.1f} %), law {law:.3f} ({100 * achieved / law:.1f} % of it)')


def test_seed004_day_on_its_actuator_firmware(ros_env, tmp_path):
    """Every line against the exact eqs. 3-4 all day. The loop drives at gain x error
    toward a target the driver takes one control period ahead, and a status carries
    the reading polled one control period before: a first-order loop follows a ramp
    1/gain behind, so at ``speed`` the lines ride on the exact solution of speed/gain
    simulated seconds earlier (300 s at 600x: ~0.9 deg of the sun's compressed motion,
    not of the drive). Against that, every line within the budget's 0.12 deg (p90, as
    the 30x window held), and the Table 1 law within 0.08 deg (p95)."""
    text, day, desc, config, speed = _day('seed004', ros_env, tmp_path / 'out')
    assert '/axes/mobile_structure/status' not in day.topics and '/gps/fix' not in day.topics
    # no move refused, no board fault all day (the report's link line)
    assert 'OUT_OF_RANGE' not in text and FAULT_FREE.search(text), text[-3000:]
    s, ok = tracking(day)
    assert ok.sum() > 200, ok.sum()
    t, measured, setpoint = np.asarray(s.t)[ok], np.asarray(s['measured'])[ok], np.asarray(s['setpoint'])[ok]
    mv = desc.movement('mirrors')
    ref = reference(str(config), *site_of(day), 30.0)
    theta_t = np.asarray(ref(t).transversal, dtype=float)
    inside = np.abs(theta_t) <= mv.law_params['transversal_limit']
    t, measured, setpoint, theta_t = t[inside], measured[inside], setpoint[inside], theta_t[inside]
    offsets = np.asarray(mv.law_params['offsets'])
    law = np.degrees(np.abs(setpoint[:, None] + offsets[None, :] - prototype.exact_lines(desc, theta_t)))
    assert np.all(np.percentile(law, 95, axis=0) <= 0.08), np.percentile(law, 95, axis=0)
    lag = speed / ActuatorLoop.gain                                            # [simulated s]
    earlier = np.asarray(ref(t - lag).transversal, dtype=float)
    lines = np.degrees(np.abs(measured[:, None] + offsets[None, :] - prototype.exact_lines(desc, earlier)))
    per_line = np.percentile(lines, 90, axis=0)
    assert np.all(per_line <= 0.12), per_line
    undelayed = np.degrees(np.abs(measured[:, None] + offsets[None, :] - prototype.exact_lines(desc, theta_t)))
    # the sunset: the lines go to their sleeping position on the range end (40 deg), the
    # board takes the move (a deadband inside the range, never refused OUT_OF_RANGE above);
    # they approach it at the actuator's real pace, ~1.5 s of wall time for the last
    # 0.25 deg: at 600x that is past the window's end (at 60x they reach it)
    end = np.asarray(s.t) > t[-1]
    rest, commanded = np.asarray(s['measured'])[end], np.asarray(s['commanded'])[end]
    assert len(rest) and abs(commanded[-1] - (mv.sleep - mv.deadband)) <= 2 * msgs.DEFAULT_STEP_RAD, \
        np.degrees(commanded)
    assert mv.sleep - rest[-1] < mv.sleep - measured[-1], (np.degrees(rest), math.degrees(measured[-1]))
    achieved, ideal, law_kwh = _energy(text)
    # the lag costs the compressed day a few % (~0.9 deg at 600x); on the law within 10 %
    assert achieved >= 0.9 * law_kwh, (achieved, law_kwh)
    print('seed 004 day on firmware: p90 |line - exact eqs. 3-4 of speed/gain earlier| per line [deg]: '
          + ' '.join(f'{v:.3f}' for v in per_line) + f' (p95 max {np.percentile(lines, 95, axis=0).max():.3f}); '
          + f'undelayed p90 {np.percentile(undelayed, 90):.3f} deg; law p95 max '
          + f'{np.percentile(law, 95, axis=0).max():.3f} deg; toward the sleeping position: at '
          + f'{math.degrees(rest[-1]):.3f} deg at the end; absorbed '
          + f'{achieved:.3f} kWh vs ideal {ideal:.3f} ({100 * achieved / ideal:.1f} %), law {law_kwh:.3f} '
          + f'({100 * achieved / law_kwh:.1f} % of it)')
