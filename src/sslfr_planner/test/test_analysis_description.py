"""``sslfr analyse`` on a described collector (issue 34): the geometry, receiver and
azimuth of the collector description the site config names; seed 000's figures
unchanged; a broken description refused with one line naming the file and key."""
import math
import shutil
from pathlib import Path

import pytest

from sslfr_planner.analysis import cli

CONFIG = Path(__file__).resolve().parents[2] / 'sslfr_bringup' / 'config'


def test_lepten_config_takes_the_description_geometry():
    site, optic, params = cli.load_config(str(CONFIG / 'florianopolis_lepten.yaml'))
    g = optic.geometry
    assert g.n_mirrors == 10 and not g.central_mirror
    assert g.mirror_width == 0.45 and g.mirror_length == 12.0 and g.aim_height == pytest.approx(3.75)
    assert optic.cavity_aperture == 0.15                      # the 150 mm receiver
    assert math.degrees(site.collector_azimuth) == pytest.approx(4.6)
    assert cli.law_tube('horizontal', params) == (-6.0, 6.0)  # its 12 m receiver, centred
    assert cli.law_tube('continuous', params) == (-6.0, 6.0)


def test_seed000_description_keeps_the_seed_placements():
    _, optic, params = cli.load_config(str(CONFIG / 'almeria_sslfr.yaml'))
    assert optic.geometry.n_mirrors == 25 and optic.geometry.mirror_length == 2.0
    assert cli.law_tube('continuous', params) == cli.SEED_TUBES['tilting']
    assert cli.law_tube('horizontal', params) == cli.SEED_TUBES['horizontal']


def test_error_table_of_a_described_collector_has_its_lines(capsys):
    assert cli.main(['error', '--config', str(CONFIG / 'bucaramanga_single_axis.yaml'), '--errors', '0.36',
                     '--days', '2026-03-21', '--hours', '12']) == 0
    header, row = capsys.readouterr().out.strip().splitlines()
    assert header.split(',')[5:] == ['5L', '4L', '3L', '2L', '1L', '1R', '2R', '3R', '4R', '5R']
    assert 0 < float(row.split(',')[4]) < 20                  # loss [%] of 0.36 deg on seed 003's rows


def test_a_broken_description_is_refused_naming_the_key(tmp_path, capsys):
    shutil.copy(CONFIG / 'florianopolis_lepten.yaml', tmp_path / 'site.yaml')
    (tmp_path / 'collectors').mkdir()
    text = (CONFIG / 'collectors' / 'florianopolis_lepten.yaml').read_text()
    (tmp_path / 'collectors' / 'florianopolis_lepten.yaml').write_text(text.replace('lines: 10', 'lines: 9'))
    assert cli.main(['error', '--config', str(tmp_path / 'site.yaml')]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'optics.lines' in err and 'florianopolis_lepten.yaml' in err
