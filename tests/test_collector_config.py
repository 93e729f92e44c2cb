"""A site config names its collector description (docs/collectors.md): `sslfr doctor
--config`, `sslfr sim`, `sslfr up` and the launch file refuse a broken description (or
collector.* values contradicting it) before any process starts, naming the file and
the key; a namespaced copy of the config still finds the description."""
from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys

import pytest
import yaml

from conftest import ROOT

sys.path.insert(0, str(ROOT / 'src/sslfr_bringup'))
from sslfr_bringup import nodeset  # noqa: E402

pytestmark = pytest.mark.timeout(120)
CONFIG = ROOT / 'src/sslfr_bringup/config'
LAUNCH = ROOT / 'src/sslfr_bringup/launch/tracker.launch.py'


def _copy(tmp_path, change=None, site='florianopolis_lepten.yaml'):
    """The site config and its description copied to tmp_path, the description edited."""
    (tmp_path / 'collectors').mkdir(exist_ok=True)
    shutil.copy(CONFIG / site, tmp_path / site)
    desc = yaml.safe_load((CONFIG / 'collectors' / site).read_text())
    if change:
        change(desc)
    (tmp_path / 'collectors' / site).write_text(yaml.safe_dump(desc))
    return tmp_path / site, tmp_path / 'collectors' / site


def _run(args, ros_env):
    return subprocess.run([str(ROOT / 'sslfr'), *args], env=ros_env, capture_output=True, text=True, timeout=90)


def test_shipped_site_configs_name_a_valid_collector():
    ns = nodeset.load()
    named = {'almeria_sslfr.yaml': 'almeria_three_movement.yaml',
             'bucaramanga_single_axis.yaml': 'bucaramanga_single_axis.yaml',
             'florianopolis_lepten.yaml': 'florianopolis_lepten.yaml'}
    for site, desc in named.items():
        params = nodeset.read_params(CONFIG / site)
        assert nodeset.node_params(params, 'planner')['collector.description'] == f'collectors/{desc}'
        assert nodeset.check_config(ns, params, where=str(CONFIG / site)) == []


def test_wind_supervision_needs_an_anemometer_in_the_description(tmp_path):
    """Almeria's description lists the cup anemometer the site added (seed 000 has none);
    without it the config's anemometer_pin and wind.enabled are refused."""
    ns = nodeset.load()
    desc = yaml.safe_load((CONFIG / 'collectors' / 'almeria_three_movement.yaml').read_text())
    added = [s for s in desc['sensors'] if s['kind'] == 'anemometer']
    assert len(added) == 1 and added[0]['site_addition'] is True
    (tmp_path / 'collectors').mkdir()
    site = tmp_path / 'almeria_sslfr.yaml'
    shutil.copy(CONFIG / site.name, site)
    (tmp_path / 'collectors' / 'almeria_three_movement.yaml').write_text(yaml.safe_dump(
        {**desc, 'sensors': [s for s in desc['sensors'] if s['kind'] != 'anemometer']}))
    errors = nodeset.check_config(ns, nodeset.read_params(site), where=str(site))
    assert any('absorber_board: anemometer_pin: 7 but the collector description' in e for e in errors), errors
    assert any('safety: wind.enabled: true but the collector description' in e for e in errors), errors
    text = site.read_text().replace('anemometer_pin: 7 ', 'anemometer_pin: -1 ').replace(
        'wind.enabled: true ', 'wind.enabled: false ')
    site.write_text(text)
    assert nodeset.check_config(ns, nodeset.read_params(site), where=str(site)) == []


def test_a_flow_meter_needs_one_in_the_description_and_its_aperture(tmp_path):
    """Seed 003's description lists the flow meter of its 150 L/h tests and its config
    counts it with the description's aperture (1 m^2); without the sensor, with another
    aperture, or with an anemometer on the same (one) pulse input: refused."""
    ns = nodeset.load()
    desc = yaml.safe_load((CONFIG / 'collectors' / 'bucaramanga_single_axis.yaml').read_text())
    assert [s['name'] for s in desc['sensors'] if s['kind'] == 'flow_meter'] == ['flow']
    site, _ = _copy(tmp_path, lambda d: d.update(sensors=[s for s in d['sensors'] if s['kind'] != 'flow_meter']),
                    site='bucaramanga_single_axis.yaml')
    errors = nodeset.check_config(ns, nodeset.read_params(site), where=str(site))
    assert any('absorber_board: flow_meter_pin: 8 but the collector description' in e for e in errors), errors
    site, _ = _copy(tmp_path, site='bucaramanga_single_axis.yaml')
    assert nodeset.check_config(ns, nodeset.read_params(site), where=str(site)) == []
    site.write_text(site.read_text().replace('aperture_area: 1.0 ', 'aperture_area: 1.5 ').replace(
        'flow_meter_pin: 8 ', 'flow_meter_pin: 8\n    anemometer_pin: 7 '))
    errors = nodeset.check_config(ns, nodeset.read_params(site), where=str(site))
    assert any('aperture_area: 1.5 contradicts the collector description' in e and '1.0 m^2' in e
               for e in errors), errors
    assert any('counts one pulse input' in e for e in errors), errors


@pytest.mark.parametrize('command', ['doctor', 'sim', 'up'])
def test_a_broken_description_starts_nothing(command, ros_env, tmp_path):
    site, desc = _copy(tmp_path, lambda d: d['movements']['mirrors'].update(drive='hydraulic_ram'))
    args = {'doctor': ['doctor', '--config', str(site)],
            'sim': ['sim', '--config', str(site), '--date', '2026-06-21', '--start', '12:00', '--end', '12:01',
                    '--no-report', '--out', str(tmp_path / 'out')],
            'up': ['up', '--config', str(site)]}[command]
    proc = _run(args, ros_env)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 2, out
    assert f'{desc}: movements.mirrors.drive: unknown drive kind' in out, out
    assert 'started ' not in out and 'Traceback' not in out, out
    assert not (tmp_path / 'out').exists() or not any((tmp_path / 'out').iterdir())


def test_site_values_contradicting_the_description_are_refused(ros_env, tmp_path):
    site, desc = _copy(tmp_path)
    text = site.read_text().replace('collector.gap: 0.0597', 'collector.gap: 0.065')
    site.write_text(text)
    proc = _run(['doctor', '--config', str(site)], ros_env)
    assert proc.returncode == 2
    assert f'planner: collector.gap: 0.065 contradicts the collector description {desc}' in proc.stderr, proc.stderr


def test_a_law_needing_a_missing_movement_is_refused_by_the_launch_file(tmp_path):
    site, desc = _copy(tmp_path, lambda d: d['movements'].update(mobile_structure={
        'drive': 'stepper_switches', 'feedback': 'steps', 'law': 'continuous', 'range_deg': [-90, 90],
        'sleep_deg': 0, 'stow_deg': 0, 'step_deg': 0.006, 'switches_deg': {'longitudinal_1': 0.0}}))
    spec = importlib.util.spec_from_file_location('tracker_launch', LAUNCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    with pytest.raises(nodeset.NodeSetError) as err:
        mod._entries(str(site), '', str(tmp_path))
    assert f'{desc}: movements.mobile_structure.law: the continuous law needs the secondary_reflector' \
        in str(err.value), err.value
    # a valid one under a namespace: the moved copy names the description by its absolute path
    site, desc = _copy(tmp_path)
    entries = {e['name']: e for e in mod._entries(str(site), '/lepten', str(tmp_path))}
    moved = nodeset.read_params(entries['planner']['parameters'][0])
    assert nodeset.node_params(moved, 'planner', '/lepten')['collector.description'] == str(desc.resolve())
