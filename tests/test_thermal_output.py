"""Thermal output of seed 003's collector (issue 34 item 5) through `./sslfr sim` on its
own site config: the simulated absorber pumps 150 L/h (seed 003 section 3.2) through a
pulse flow meter on the absorber board's pulse input; ``absorber/flow`` and
``absorber/thermal_power`` (useful power m_dot c_p (T_out - T_in), seed 003's
efficiency against the beam on the 1 m^2 aperture) are published live, recorded in
the bag and summed in the day report."""
from __future__ import annotations

import math
import subprocess

import numpy as np
import pytest

from conftest import ROOT

from sslfr_bringup import nodeset
from sslfr_common.contract import ABSORBER_FLOW, THERMAL_POWER
from sslfr_recording.day import read_day
from sslfr_recording.report import gap_limit
from sslfr_recording.report_thermal import thermal_of
from sslfr_sim.sim_cli import day_epoch

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]
DATE = '2026-03-20'                       # 15:00-15:10 UTC: 10:00 local at Bucaramanga (UTC-5)
DAY0 = day_epoch(DATE)
LPH = 1.0 / 3.6e6                         # 1 L/h in m^3/s


def test_seed_003_flow_thermal_power_and_efficiency_published_recorded_reported(ros, ros_env, tmp_path):
    from sslfr_interfaces.msg import Flow, ThermalPower
    from sslfr_common.node import qos
    live_flow = ros.collect(Flow, ABSORBER_FLOW.name, qos(ABSORBER_FLOW))
    live_thermal = ros.collect(ThermalPower, THERMAL_POWER.name, qos(THERMAL_POWER))
    out = tmp_path / 'out'
    config = str(nodeset.resolve_config('bucaramanga_single_axis.yaml'))
    cmd = [str(ROOT / 'sslfr'), 'sim', '--config', config, '--date', DATE, '--start', '15:00', '--end', '15:10',
           '--speed', '20', '--out', str(out)]
    proc = subprocess.Popen(cmd, env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        ros.spin_until(lambda: proc.poll() is not None, 200.0)
    finally:
        if proc.poll() is None:
            proc.terminate()
    text, _ = proc.communicate(timeout=30)
    assert proc.returncode == 0, text
    # published: the flow of the meter on the board's clock, the power and efficiency
    assert len(live_flow) > 20 and len(live_thermal) > 20, (len(live_flow), len(live_thermal), text[-2000:])
    full = [m for m in live_flow if m.window >= 4.99]
    assert full and all(abs(m.volume_flow / LPH - 150.0) <= 3.0 for m in full), \
        [round(m.volume_flow / LPH, 1) for m in live_flow]
    # recorded: every message of both topics, with the numbers the node computed
    bag = sorted(p for p in (out / 'bags').iterdir() if (p / 'metadata.yaml').exists())[-1]
    day = read_day(bag)
    assert day.topics.get('/' + ABSORBER_FLOW.name, 0) > 20 and day.topics.get('/' + THERMAL_POWER.name, 0) > 20
    th = day.thermal.between(DAY0 + 15 * 3600 + 120, DAY0 + 15 * 3600 + 570)   # after the absorber warmed up
    assert len(th) > 20, len(th)
    p, g, eta, a = (th[k].astype(float) for k in ('power', 'beam', 'efficiency', 'aperture'))
    assert np.all(a == 1.0)                                            # 10 x 0.10 m x 1.0 m
    assert np.all(np.isfinite(p)) and np.median(p) > 100.0, p          # a clear morning: hundreds of W
    k = np.isfinite(eta)
    assert k.mean() > 0.9, 'efficiency computed while the beam is heard'
    assert np.allclose(eta[k], p[k] / (g[k] * a[k]))                   # seed 003's definition
    assert np.all((eta[k] > 0.05) & (eta[k] < 1.0)), eta               # below the beam on the aperture
    # the day report: energy delivered and mean efficiency while tracking
    report = (out / 'report' / 'report.md').read_text()
    line = next((s for s in report.splitlines() if s.startswith('thermal output')), None)
    assert line is not None, report
    figures = thermal_of(day, gap_limit(day.thermal.t))             # as the report computes them
    print('thermal output:', line)
    assert f'{figures["kwh"]:.3f} kWh delivered' in line, (line, figures)
    t_all, p_all = day.thermal.t, day.thermal['power'].astype(float)
    ok = np.isfinite(p_all)
    assert figures['kwh'] == pytest.approx(np.trapezoid(p_all[ok], t_all[ok]) / 3.6e6, rel=0.02)
    assert 0.05 < figures['efficiency'] < 1.0 and math.isfinite(figures['efficiency'])
    assert f'{100.0 * figures["efficiency"]:.2f} % mean while tracking' in report
