"""Each prototype runs on its own simulated hardware (issue 34 items 6 and 7): a whole
simulated day of seed 003 at Bucaramanga and of seed 004 at Florianopolis through
`./sslfr sim` (one run per prototype, shared by its tests), recorded and reported; and
a fourth collector with two movements, written as a description in a temporary
directory, runs a short window. Seed 000's day is tests/test_system_tracking.py.
"""
from __future__ import annotations

import math
import os
import re
import subprocess

import numpy as np
import pytest

from collectors_testutil import planned_steps, site_of, tracking, write_fourth_collector
from conftest import ROOT

from sslfr_bringup import nodeset
from sslfr_planner import prototype
from sslfr_planner.description import load
from sslfr_recording import report
from sslfr_recording.report_energy import energy_estimate
from sslfr_recording.day import read_day, reference
from sslfr_sim.sim_cli import day_epoch

DATE = '2026-06-21'
DAY0 = day_epoch(DATE)
TRACKING = 2
SPEED = 600.0
#: prototype -> (site config, window UTC): sunrise to sunset with margins (seed 003:
#: UTC-5, its 7:00-17:00 tracking; seed 004: UTC-3)
DAYS = {'seed003': ('bucaramanga_single_axis.yaml', '11:45', '22:15'),
        'seed004': ('florianopolis_lepten.yaml', '10:00', '20:35')}


def _log_tails(out, n: int = 800) -> str:
    """The end of each node's log of a failed run (the run's directory goes with the test)."""
    logs = sorted((out / 'logs').glob('*.log')) if (out / 'logs').is_dir() else []
    return ''.join(f'\n--- {p.name}: ...{p.read_text(errors="replace")[-n:]}' for p in logs)


def run_sim(config: str, start: str, end: str, out, speed: float = SPEED, timeout: float = 400.0):
    """`./sslfr sim` over [start, end] UTC on its own ROS domain: (output text, Day)."""
    env = {k: v for k, v in os.environ.items() if k != 'ROS_DOMAIN_ID'}   # sim takes a free domain
    proc = subprocess.run([str(ROOT / 'sslfr'), 'sim', '--config', str(config), '--date', DATE, '--start', start,
                           '--end', end, '--speed', f'{speed:g}', '--out', str(out)],
                          env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stdout[-4000:] + _log_tails(out)
    assert 'MISSING' not in proc.stdout and 'Traceback' not in proc.stdout, proc.stdout[-4000:]
    bags = sorted(p for p in (out / 'bags').iterdir() if (p / 'metadata.yaml').exists())
    return proc.stdout, read_day(bags[-1])


@pytest.fixture(scope='module')
def prototype_day(tmp_path_factory):
    days = {}

    def get(name):
        if name not in days:
            config, start, end = DAYS[name]
            path = nodeset.resolve_config(config)
            # seed 003's stepper holds between 15-minute steps: a faster day costs it nothing
            text, day = run_sim(path, start, end, tmp_path_factory.mktemp(name),
                                speed=800.0 if name == 'seed003' else SPEED)
            ns = nodeset.for_config(nodeset.load(), path)
            days[name] = (text, day, load(ns.collector), path)
        return days[name]
    return get


def _energy(text: str) -> dict:
    """The day report's absorbed energy [kWh] (exact ideal, the collector's law, achieved)
    from the summary `./sslfr sim` prints at the end of its run."""
    m = re.search(r'absorbed energy ([0-9.]+) kWh achieved vs ([0-9.]+) kWh with ideal angles .*?'
                  r"the collector's law gives ([0-9.]+) kWh", text)
    assert m, text[-3000:]
    achieved, ideal, law = (float(g) for g in m.groups())
    return {'achieved_kwh': achieved, 'ideal_kwh': ideal, 'law_kwh': law}


def _energy_text(e) -> str:
    return (f"absorbed {e['achieved_kwh']:.2f} kWh: {100 * e['achieved_kwh'] / e['law_kwh']:.1f} % of its law's "
            f"{e['law_kwh']:.2f} kWh ({100 * e['law_kwh'] / e['ideal_kwh']:.1f} % of the exact ideal)")


def test_seed003_day_steps_every_15_minutes_within_72_deg_on_its_switchless_stepper(prototype_day):
    text, day, desc, config = prototype_day('seed003')
    assert 'simulated operator referenced mirrors' in text, text[-3000:]
    assert set(day.topics) >= {'/axes/mirrors/status'} and '/axes/mobile_structure/status' not in day.topics
    assert '/gps/fix' not in day.topics                      # seed 003 lists no GPS board
    s, ok = tracking(day)
    assert ok.sum() > 200, ok.sum()
    setpoint = np.asarray(s['setpoint'])[ok]
    t = np.asarray(s.t)[ok]
    # the steps in the planner's recorded trajectories (1 s points; a status is sampled
    # too seldom at 600x to time them): every 15 minutes while tracking (section 2.3.1)
    pt, _, jump = planned_steps(day, t[0], t[-1])
    jumps = pt[jump]
    gaps = np.diff(jumps)
    assert len(jumps) >= 30 and np.all(np.abs(gaps - 900.0) <= 2.0), gaps
    rate = abs(setpoint[-1] - setpoint[0]) / (t[-1] - t[0]) * 3600.0
    assert 6.5 <= math.degrees(rate) <= 8.5, math.degrees(rate)                # ~7.4 deg/h
    m = desc.movement('mirrors')
    measured = np.asarray(s['measured'])[ok]
    assert np.all((measured >= m.range[0] - 1e-6) & (measured <= m.range[1] + 1e-6))
    # every mirror within the seed's 72 deg: the recorded drive angle through the linkage
    x, h = prototype.line_positions(desc), desc.optics.receiver_height
    lines = measured[:, None] - np.arctan2(x, h)[None, :] / 2.0                # seed 003 eqs. 5-6
    assert np.max(np.abs(lines)) <= m.law_params['max_inclination'] + 1e-6, math.degrees(np.max(np.abs(lines)))
    err = np.abs(measured - setpoint)
    # on its setpoint to the microstep between steps (a status during a 24 s move aside)
    assert np.percentile(err, 90) <= (m.step or 0.0) + 1e-6, math.degrees(np.percentile(err, 90))
    e = _energy(text)
    # the collector's own ideal is its stepped law (the 15-minute steps cost ~9 % of the
    # exact ideal on the bench, docs/measurements.md): the drive loses nothing of it
    assert e['achieved_kwh'] >= 0.98 * e['law_kwh'] and e['law_kwh'] >= 0.85 * e['ideal_kwh'], e
    print(f'\nseed 003 day: {len(jumps)} steps, every {np.median(gaps):.0f} s; drive rate {math.degrees(rate):.2f} '
          f'deg/h; largest line inclination {math.degrees(np.max(np.abs(lines))):.2f} deg; |measured - '
          f'setpoint| p90 {math.degrees(np.percentile(err, 90)):.4f} deg; {_energy_text(e)}')


def test_seed004_day_every_line_within_the_budget_of_the_exact_solution(prototype_day):
    text, day, desc, config = prototype_day('seed004')
    assert '/axes/mobile_structure/status' not in day.topics and '/gps/fix' not in day.topics
    s, ok = tracking(day)
    assert ok.sum() > 200, ok.sum()
    t, measured = np.asarray(s.t)[ok], np.asarray(s['measured'])[ok]
    setpoint = np.asarray(s['setpoint'])[ok]
    lat, lon = site_of(day)
    table = reference(config, lat, lon, 30.0)(t)
    theta_t = np.asarray(table.transversal, dtype=float)
    inside = np.abs(theta_t) <= desc.movement('mirrors').law_params['transversal_limit']
    offsets = np.asarray(desc.movement('mirrors').law_params['offsets'])
    exact = prototype.exact_lines(desc, theta_t)                                # seed 004 eqs. 3-4
    # the law: every line's commanded angle (seed 004 eq. 5, Table 1) vs the exact one
    law = np.degrees(np.abs(setpoint[:, None] + offsets[None, :] - exact))[inside]
    # Table 1's fit (<= 0.06 deg) + the sun's motion within a status' age at 600x (p95)
    assert np.all(np.percentile(law, 95, axis=0) <= 0.08), np.percentile(law, 95, axis=0)
    # the drive follows all day; at 600x its loop (speed = 2/s x error) lags the sun's
    # 600-fold motion by ~0.6 deg: its accuracy is judged at 30x below
    track = np.degrees(np.abs(measured - setpoint))
    assert np.percentile(track, 95) <= 1.5, np.percentile(track, 95)
    e = _energy(text)
    # Table 1's law is within 0.06 deg of the exact lines (within the actuator's range: the
    # collector's own ideal); at 600x the drive's lag above costs a few %
    assert e['law_kwh'] >= 0.98 * e['ideal_kwh'] and e['achieved_kwh'] >= 0.95 * e['law_kwh'], e
    print('\nseed 004 day: p95 |law - exact| per line [deg]: ' + ' '.join(f'{v:.3f}' for v in np.percentile(law, 95, axis=0))
          + f'; |measured - setpoint| at {SPEED:g}x p50 {np.percentile(track, 50):.3f} deg; {_energy_text(e)}')


def test_seed004_every_line_within_the_uncertainty_budget_while_tracking(tmp_path):
    """Seed 004 Tables 3-4: 0.085-0.12 deg of tracking uncertainty. Measured: each line's
    angle (the inclinometer-closed drive + Table 1's b_i) against the exact eqs. 3-4, at
    30x in the afternoon (the sun's transversal motion at its fastest of the window)."""
    config = nodeset.resolve_config(DAYS['seed004'][0])
    desc = load(nodeset.for_config(nodeset.load(), config).collector)
    text, day = run_sim(config, '17:00', '17:10', tmp_path / 'out', speed=30.0, timeout=200.0)
    s, ok = tracking(day)
    t = np.asarray(s.t)[ok]
    keep = t >= t[0] + 120.0                       # after the slew from the sleeping position
    t, measured = t[keep], np.asarray(s['measured'])[ok][keep]
    assert len(t) > 30, (len(t), text[-3000:])
    lat, lon = site_of(day)
    theta_t = np.asarray(reference(config, lat, lon, 30.0)(t).transversal, dtype=float)
    offsets = np.asarray(desc.movement('mirrors').law_params['offsets'])
    err = np.degrees(np.abs(measured[:, None] + offsets[None, :] - prototype.exact_lines(desc, theta_t)))
    per_line = np.percentile(err, 95, axis=0)
    assert np.all(per_line <= 0.12), per_line
    print('\nseed 004 at 30x: p95 |line - exact| per line [deg]: ' + ' '.join(f'{v:.3f}' for v in per_line)
          + ' (budget 0.085-0.12 deg, seed 004 Tables 3-4)')


def test_a_two_movement_collector_runs_from_its_description_alone(tmp_path):
    """A fourth collector (mirrors on a switchless stepper, a mobile structure under seed
    000 eq. 16, a fixed horizontal receiver; tests/collectors_testutil.py) from its
    description alone: the node set starts its two drivers, both follow their law to the
    drive's step, safety does not miss the boards it lacks, the report has both."""
    config = write_fourth_collector(tmp_path)
    desc = load(nodeset.for_config(nodeset.load(), config).collector)
    end = DAY0 + 11 * 3600.0 + 600.0
    text, day = run_sim(config, '11:00', '11:10', tmp_path / 'out', speed=30.0, timeout=200.0)
    assert 'simulated operator referenced mirrors' in text, text[-3000:]
    started = next(line for line in text.splitlines() if 'nodes started at' in line).split(': ', 1)[1].split(', ')
    assert sorted(n for n in started if n.endswith('_driver')) == ['mirrors_driver', 'mobile_structure_driver']
    assert 'gps' not in started, started
    assert {t for t in day.topics if t.startswith('/axes/')} == {'/axes/mirrors/status', '/axes/mobile_structure/status'}
    lat, lon = site_of(day)
    ref = reference(config, lat, lon, 12.0)
    settled = 0.0                  # when both axes are on their law (the start-up slew done)
    for axis in ('mirrors', 'mobile_structure'):
        s = day.axes[axis]
        phase_t, phase = np.asarray(day.phase.t), np.asarray(day.phase['phase'])
        k = np.searchsorted(phase_t, s.t, side='right') - 1
        # a status carries NaN for what its driver does not know yet (its first after the
        # activation: no board status or no trajectory sample yet; a fresh-clone run had one)
        known = np.isfinite(np.asarray(s['measured'])) & np.isfinite(np.asarray(s['setpoint']))
        ok = ((k >= 0) & (phase[np.clip(k, 0, None)] == TRACKING) & (np.asarray(s.t) < end - 2.0)
              & np.isin(np.asarray(s['state']), ('following', 'holding', 'waiting')) & known)
        assert ok.sum() > 60, (axis, ok.sum(), text[-3000:])
        t = np.asarray(s.t)[ok]
        table = ref(t)
        law = np.asarray(getattr(table, axis), dtype=float)
        if axis == 'mobile_structure':    # seed 000 eq. 16: the rows at theta_z / 2, facing the equator
            assert np.allclose(law, np.asarray(table.zenith) / 2.0, atol=1e-9)
            assert np.all(np.asarray(table.secondary_reflector) == 0.0)   # the receiver is fixed, horizontal
        step = desc.movement(axis).step
        measured, setpoint = np.asarray(s['measured'])[ok], np.asarray(s['setpoint'])[ok]
        # the planner's setpoints are the law's: its recorded trajectory points against the
        # reference at their own times (to the motor step it quantises to)
        pt, pv, _ = planned_steps(day, t[0], t[-1], joint=axis)
        assert len(pt) > 60, (axis, len(pt))
        off = np.abs(pv - np.asarray(getattr(ref(pt), axis), dtype=float))
        assert np.max(off) <= step + 1e-9, (axis, np.degrees(np.max(off)), np.degrees(step))
        # the drive holds it to its step (open-loop steppers: the position is the step count)
        err = np.abs(measured - setpoint)
        assert np.percentile(err, 95) <= step + 1e-9, (axis, np.degrees(np.percentile(err, 95)), np.degrees(step))
        # (a start-up slew is 'following' too: seen 10.5 deg away at its first status, and
        # a slew still under way when the other axis settled cost 2.3 % of the energy)
        settled = max(settled, t[np.flatnonzero(err <= step + 1e-9)[0]])
    # safety watches what the collector has: no reason names a board it lacks, and
    # nothing stops the run between the start-up and the end of the window
    st = np.asarray(day.safety.t)
    reasons = [r for rs in day.safety['reasons'] for r in rs]
    assert not any('secondary_reflector' in r for r in reasons), reasons
    first_ok = st[np.asarray(day.safety['level']) == 0][0]
    during = (st > first_ok) & (st < end - 2.0)       # (a start-up state may share its stamp)
    assert np.all(np.asarray(day.safety['level'])[during] == 0), \
        [r for r, d in zip(day.safety['reasons'], during) if d and r]
    rep = report.analyse(day, str(config))
    assert rep.collector == 'fourth_rooftop' and rep.joints == ('mirrors', 'mobile_structure'), rep.joints
    for axis in rep.joints:
        assert rep.tracking[axis]['ideal'].samples > 60 and rep.tracking[axis]['ideal'].p95 < math.radians(0.1)
    assert rep.energy['ideal_kwh'] > 0.05 and rep.energy['achieved_kwh'] > 0.0, rep.energy
    # once both are on their law (the start-up slews aside), the absorbed energy on the described
    # optics with the measured angles is the ideal's (the drives' errors are ~0.02 deg)
    bt, beam = np.asarray(day.beam.t), np.asarray(day.beam['g'], dtype=float)
    k = (bt >= settled) & (bt < end - 2.0)
    e = energy_estimate(rep.site, bt[k], beam[k], {a: (day.axes[a].t, day.axes[a].cols) for a in rep.joints},
                        str(config))
    off = {a: [(round(float(ti - DAY0), 1), st, round(math.degrees(mi - si), 2))
               for ti, st, mi, si in zip(day.axes[a].t, day.axes[a]['state'], day.axes[a]['measured'],
                                         day.axes[a]['setpoint'])
               if ti >= settled and not abs(mi - si) <= desc.movement(a).step] for a in rep.joints}
    assert e['ideal_kwh'] > 0.05 and e['achieved_kwh'] >= 0.99 * e['ideal_kwh'], (e, settled - DAY0, off)
