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


def test_rows_tilting_alone_over_a_fixed_receiver(tmp_path):
    """The two-movement test collector (rows under seed 000 eq. 16, receiver fixed
    horizontal; docs/collectors.md "Longitudinal movements"), 21 June at Barcelona, 900
    W/m^2, ideal mirror angles: near solar noon the rows' tilt gains over horizontal rows
    and a receiver tilted with them gains a little more (seed 001 section 4); at 08:00 UTC
    eq. 16's rows face away from the sun and lose."""
    import calendar

    import numpy as np
    from collectors_testutil import write_fourth_collector
    from sslfr_planner.analysis import ideal
    from sslfr_planner.day_cycle import make_collector
    from sslfr_planner.description import load
    from sslfr_planner.planner_params import PLANNER_PARAMS
    from sslfr_planner.site import Site
    from sslfr_planner.tracking_table import evaluate

    write_fourth_collector(tmp_path)
    desc = load(tmp_path / 'fourth.yaml')
    t = calendar.timegm((2026, 6, 21, 0, 0, 0)) + np.array([8.0, 11.9]) * 3600.0
    tab = evaluate(t, Site.from_degrees(41.39, 2.17, 12.0), make_collector(PLANNER_PARAMS.defaults(), desc))
    assert np.all(tab.secondary_reflector == 0.0)
    assert np.allclose(tab.mobile_structure, tab.zenith / 2.0)
    zero = np.zeros(2)

    def q(bm, ba):
        return ideal.ideal_absorbed_power(desc, tab.zenith, tab.azimuth, np.full(2, 900.0), bm, ba)
    rows, flat, both = q(tab.mobile_structure, zero), q(zero, zero), q(tab.mobile_structure, tab.mobile_structure)
    assert rows == pytest.approx([439.1, 1183.3], abs=1.0)
    assert flat == pytest.approx([1290.5, 957.6], abs=1.0)
    assert both == pytest.approx([700.9, 1266.5], abs=1.0)
    assert flat[1] < rows[1] < both[1] and rows[0] < both[0] < flat[0]
    # the report's default (a movement the collector lacks: 0) is the table's fixed receiver
    assert ideal.ideal_absorbed_power(desc, tab.zenith, tab.azimuth, np.full(2, 900.0), tab.mobile_structure,
                                      tab.secondary_reflector) == pytest.approx(rows)


def test_the_loss_table_of_rows_over_a_fixed_receiver(tmp_path):
    """The accuracy alarms' loss table (seed 000 section 5.2) of the two-movement collector
    is studied with its receiver where it is (fixed, horizontal), not tilted by the law."""
    import numpy as np
    from collectors_testutil import write_fourth_collector
    from sslfr_planner.analysis import ideal, performance
    from sslfr_planner.description import load

    write_fourth_collector(tmp_path)
    desc = load(tmp_path / 'fourth.yaml')
    assert desc.receiver_fixed
    site = performance.AnalysisSite(41.39, 2.17, 12.0, 0.0)
    t = np.array([1782043200.0 - 3600.0])       # 2026-06-21 11:00 UTC
    zen, azi = performance.sun_positions(t, site)
    moving = performance.commands('eq16', zen, azi, t, site)
    fixed = performance.commands('eq16', zen, azi, t, site, receiver_fixed=True)
    assert moving[2][0] == pytest.approx(zen[0] / 2.0) and fixed[2][0] == 0.0
    np.testing.assert_array_equal(moving[1], fixed[1])
    from datetime import date
    table = ideal.loss_table(desc, 41.39, 2.17, 12.0)
    err = table[-1][0]
    for fixed_rcv in (True, False):
        rows = performance.error_table(site, ideal.optical_parameters(desc), [err],
                                       [date.fromisoformat(d) for d in ideal.LOSS_DAYS], list(ideal.LOSS_HOURS),
                                       law='eq16', receiver_fixed=fixed_rcv)
        low = round(max(0.0, min(r.loss_total for r in rows)), 2)
        high = round(min(100.0, max(r.loss_total for r in rows)), 2)
        assert ((low, high) == table[-1][1:]) is fixed_rcv, (fixed_rcv, low, high, table[-1])
