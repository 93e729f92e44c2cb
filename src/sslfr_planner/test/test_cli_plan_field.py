"""``sslfr plan`` and ``sslfr field`` (in-process and through ./sslfr)."""
import csv
import io
import math
import os
import subprocess
from pathlib import Path

import pytest

from sslfr_planner import cli_field, cli_plan, lepten

ROOT = Path(__file__).resolve().parents[3]
HEADER = ('utc,phase,zenith_deg,azimuth_deg,transversal_deg,longitudinal_deg,mirrors_deg,'
          'mobile_structure_deg,secondary_reflector_deg')


def test_plan_writes_the_whole_day(tmp_path):
    out = tmp_path / 'day.csv'
    assert cli_plan.main(['--lat', '36.8353', '--lon', '-2.4022', '--elevation', '22', '--date', '2026-06-21',
                          '--step', '60', '--out', str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0] == HEADER and len(lines) == 1 + 1440
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    assert rows[0]['utc'] == '2026-06-21T00:00:00Z' and rows[-1]['utc'] == '2026-06-21T23:59:00Z'
    assert {r['phase'] for r in rows} == {'NIGHT', 'PRE_DAWN', 'TRACKING', 'STOWING'}
    night = [r for r in rows if r['phase'] == 'NIGHT']
    assert all(float(r['mirrors_deg']) == 90.0 for r in night)
    noon = min(rows, key=lambda r: float(r['zenith_deg']))
    assert abs(float(noon['zenith_deg']) - (36.8353 - 23.44)) < 0.1
    # the default 'continuous' law at noon: theta_z/2 for the central mirror, a little more so that
    # the outer mirrors' longer rays land centred too (docs/optics.md)
    excess = float(noon['mobile_structure_deg']) - float(noon['zenith_deg']) / 2
    assert 0.0 < excess < 0.5
    assert cli_plan.main(['--lat', '36.8353', '--lon', '-2.4022', '--date', '2026-06-21', '--step', '60',
                          '--mode', 'eq16', '--out', str(out)]) == 0
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    noon = min(rows, key=lambda r: float(r['zenith_deg']))
    assert abs(float(noon['mobile_structure_deg']) - float(noon['zenith_deg']) / 2) < 1e-5   # seed 000 eq. 16


def test_plan_modes_and_options_to_stdout(capsys):
    assert cli_plan.main(['--lat', '52.52', '--lon', '13.4', '--date', '2026-03-20', '--step', '3600',
                          '--mode', 'optimum_fixed', '--collector-azimuth', '4.6', '--pressure', '950',
                          '--temperature', '20', '--delta-t', '69.2']) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == HEADER and len(out) == 25
    assert all(r.split(',')[7] == '26.260000' for r in out[1:])  # beta_M = latitude/2
    assert all(r.split(',')[8] == '52.520000' for r in out[1:])  # beta_a = latitude


@pytest.mark.parametrize('args,needle', [
    (['--lat', '91', '--lon', '0'], 'latitude'),
    (['--lat', '10', '--lon', '0', '--date', '2023-02-30'], 'date'),
    (['--lat', '10', '--lon', '0', '--step', '0'], 'step'),
    (['--lat', '10', '--lon', '0', '--mode', 'diagonal'], 'mode'),
    (['--lat', 'nan', '--lon', '0'], 'lat'),
    (['--lon', '0'], '--lat'),
    (['--lat', '10', '--lon', '0', '--out', '/nonexistent/dir/x.csv'], 'nonexistent'),
])
def test_plan_bad_input_one_clear_line(args, needle, capsys):
    assert cli_plan.main(args) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('sslfr plan: error:') and needle in err[0]


def test_field_reproduces_seed004_table1(capsys):
    b = [15.8311, 12.8113, 9.4542, 5.8066, 1.9593, -1.9594, -5.8066, -9.4543, -12.8113, -15.8312]
    a = [0.4966, 0.4963, 0.4961, 0.4959, 0.4958, 0.4958, 0.4959, 0.4961, 0.4963, 0.4966]
    xs = [lepten.position_from_offset(math.radians(v), 3.75, 0.065) for v in b]
    assert cli_field.main(['--positions', ','.join(f'{x:.9f}' for x in xs), '--height', '3.75',
                           '--radius', '0.065', '--fit', '-80:80']) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert list(rows[0]) == ['x_m', 'a', 'b', 'max_error_deg'] and len(rows) == 10
    for r, aa, bb in zip(rows, a, b):
        assert abs(float(r['b']) - bb) < 5e-5 and abs(float(r['a']) - aa) < 1e-4
        assert 0 < float(r['max_error_deg']) < 0.03


@pytest.mark.parametrize('args', [
    ['--positions', '1,x', '--height', '3', '--radius', '0.05'],
    ['--positions', '1', '--height', '0', '--radius', '0.05'],
    ['--positions', '1', '--height', '3', '--radius', '2'],
    ['--positions', '1', '--height', '3', '--radius', '0.05', '--fit', '80:-80'],
])
def test_field_bad_input(args, capsys):
    assert cli_field.main(args) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('sslfr field: error:')


def test_through_the_sslfr_dispatcher():
    env = dict(os.environ)
    r = subprocess.run([str(ROOT / 'sslfr'), 'plan', '--lat', '-27.6', '--lon', '-48.5', '--date', '2026-12-21',
                        '--step', '3600'], capture_output=True, text=True, timeout=60, env=env)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == HEADER and len(r.stdout.splitlines()) == 25
    r = subprocess.run([str(ROOT / 'sslfr'), 'plan', '--lat', '91', '--lon', '0'], capture_output=True, text=True,
                       timeout=60, env=env)
    assert r.returncode != 0 and len(r.stderr.strip().splitlines()) == 1
