"""Unit tests of the planner's pure helpers: modes, site source, clock jumps, horizons."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sslfr_common.contract import Phase
from sslfr_planner import modes
from sslfr_planner.site_source import (PERSIST_FILE, SiteFix, SiteSelector, check_fix,
                                       distance_m, load_persisted, save_persisted)
from sslfr_planner.timejump import ClockJumpDetector
from sslfr_planner.trajectory import hold, horizon_times, ramp, velocities_from


# ----------------------------------------------------------------------------- modes
@pytest.mark.parametrize('cur', modes.MODES)
@pytest.mark.parametrize('want', modes.MODES)
def test_mode_transition_table(cur, want):
    res = modes.request_mode(cur, want)
    allowed = want == cur or want in modes.TRANSITIONS[cur]
    assert res.success is allowed
    assert res.mode == (want if allowed else cur)
    if not allowed:
        assert 'refused' in res.message and cur in res.message and want in res.message


def test_forbidden_transitions_are_the_documented_ones():
    forbidden = {(a, b) for a in modes.MODES for b in modes.MODES
                 if a != b and not modes.request_mode(a, b).success}
    assert forbidden == {('stow', 'manual'), ('maintenance', 'manual')}


def test_unknown_mode_refused_with_its_name():
    res = modes.request_mode('auto', 'fly')
    assert not res.success and res.mode == 'auto' and "'fly'" in res.message
    assert not modes.request_mode('auto', '').success


def test_mode_aliases_and_case():
    assert modes.request_mode('auto', ' STOW ').mode == 'stow'
    assert modes.request_mode('auto', 'hold').mode == 'manual'


@pytest.mark.parametrize('auto', sorted(modes.AUTO_PHASES))
def test_resolve_phase_priorities(auto):
    for mode in modes.MODES:
        d = modes.resolve_phase(mode, auto, True, ['outlet 152.3 degC > 150 degC'])
        assert d.phase == Phase.STOW and d.reason == 'safety: outlet 152.3 degC > 150 degC'
    assert modes.resolve_phase('auto', auto, False).phase == auto
    assert modes.resolve_phase('stow', auto, False).phase == Phase.STOW
    assert modes.resolve_phase('manual', auto, False).phase == Phase.MANUAL
    assert modes.resolve_phase('maintenance', auto, False).phase == Phase.MAINTENANCE


def test_resolve_phase_rejects_garbage():
    with pytest.raises(ValueError):
        modes.resolve_phase('fly', Phase.NIGHT, False)
    with pytest.raises(ValueError):
        modes.resolve_phase('auto', Phase.STOW, False)


# ------------------------------------------------------------------------ site source
ALMERIA = SiteFix(36 + 50 / 60 + 7 / 3600, -(2 + 24 / 60 + 8 / 3600), 22.0, 'parameters')
COV_GOOD = [4.0, 0, 0, 0, 4.0, 0, 0, 0, 16.0]


def test_check_fix_rules():
    assert check_fix(0, 36.8, -2.4, 22.0, COV_GOOD, 2, 500.0) is None
    assert check_fix(2, 36.8, -2.4, 22.0, COV_GOOD, 2, 500.0) is None      # GBAS fix
    assert 'STATUS_FIX' in check_fix(-1, 36.8, -2.4, 22.0, COV_GOOD, 2, 500.0)
    assert 'non-finite' in check_fix(0, math.nan, -2.4, 22.0, COV_GOOD, 2, 500.0)
    assert 'out of range' in check_fix(0, 91.0, -2.4, 22.0, COV_GOOD, 2, 500.0)
    assert 'std' in check_fix(0, 36.8, -2.4, 22.0, [1e6, 0, 0, 0, 1e6, 0, 0, 0, 1], 1, 500.0)
    assert check_fix(0, 36.8, -2.4, 22.0, [1e6] * 9, 0, 500.0) is None       # unknown cov
    assert 'covariance' in check_fix(0, 36.8, -2.4, 22.0, [math.nan] * 9, 2, 500.0)
    assert check_fix(0, 36.8, -2.4, math.nan, COV_GOOD, 2, 500.0) is None    # NaN: altitude unknown
    for alt in (math.inf, -math.inf, 1e300, 20000.0):
        assert 'altitude' in check_fix(0, 36.8, -2.4, alt, COV_GOOD, 2, 500.0)


def test_a_fix_with_an_infinite_altitude_is_refused_and_counted_not_the_site(tmp_path):
    sel = SiteSelector(SiteFix(36.8, -2.4, 22.0, 'parameters'), str(tmp_path), 500.0, 100.0)
    assert 'altitude' in sel.on_fix(0, 10.0, 10.0, math.inf, COV_GOOD, 2, 1.0)
    assert sel.rejected == 1 and sel.current().source == 'parameters'


def test_distance_reference():
    # one degree of latitude on the mean sphere
    a = SiteFix(0.0, 0.0, 0.0, 'x')
    assert distance_m(a, SiteFix(1.0, 0.0, 0.0, 'x')) == pytest.approx(111_195.08, abs=0.1)
    assert distance_m(a, a) == 0.0


def test_persist_round_trip_and_atomic_file(tmp_path):
    fix = SiteFix(36.8353, -2.4022, 22.0, 'gps', 1.7e9)
    path = save_persisted(tmp_path / 'state', fix)
    assert path.name == PERSIST_FILE
    assert [p.name for p in path.parent.iterdir()] == [PERSIST_FILE]       # no temp left
    got, err = load_persisted(tmp_path / 'state')
    assert err is None and got == SiteFix(36.8353, -2.4022, 22.0, 'persisted', 1.7e9)


@pytest.mark.parametrize('content', ['{', '[]', '{"version": 9}', '{"version": 1}',
                                     '{"version": 1, "latitude_deg": 95, "longitude_deg": 0, "elevation": 0}'])
def test_corrupt_persisted_file_is_reported_not_used(tmp_path, content):
    (tmp_path / PERSIST_FILE).write_text(content)
    got, err = load_persisted(tmp_path)
    assert got is None and err and PERSIST_FILE in err


def test_selector_preference_order(tmp_path):
    sel = SiteSelector(ALMERIA, tmp_path, 500.0, 50.0)
    assert sel.current() is ALMERIA
    assert sel.on_fix(-1, 10.0, 10.0, 5.0, COV_GOOD, 2, 1.0) is not None
    assert sel.current() is ALMERIA and sel.rejected == 1
    assert sel.on_fix(0, 7.1254, -73.1198, 959.0, COV_GOOD, 2, 2.0) is None
    cur = sel.current()
    assert cur.source == 'gps' and cur.latitude_deg == 7.1254 and cur.elevation == 959.0
    assert sel.writes == 1
    # jitter of a few metres is not written again
    assert sel.on_fix(0, 7.12541, -73.11981, 959.5, COV_GOOD, 2, 3.0) is None
    assert sel.writes == 1
    # a new run without GPS takes the persisted fix
    sel2 = SiteSelector(ALMERIA, tmp_path, 500.0, 50.0)
    cur2 = sel2.current()
    assert cur2.source == 'persisted' and cur2.latitude_deg == 7.1254
    assert cur2.longitude_deg == -73.1198 and cur2.elevation == 959.0


def test_selector_nan_altitude_keeps_known_elevation(tmp_path):
    sel = SiteSelector(ALMERIA, None)
    assert sel.on_fix(0, 36.0, -2.0, math.nan, COV_GOOD, 2, 1.0) is None
    assert sel.current().elevation == 22.0


def test_selector_unwritable_state_dir_is_an_error_not_a_crash(tmp_path):
    blocker = tmp_path / 'file'
    blocker.write_text('x')
    sel = SiteSelector(ALMERIA, blocker / 'sub')
    assert sel.on_fix(0, 36.0, -2.0, 10.0, COV_GOOD, 2, 1.0) is None
    assert sel.current().source == 'gps' and sel.errors and sel.writes == 0


# ----------------------------------------------------------------------- clock jumps
def test_clock_jump_detector():
    det = ClockJumpDetector(1.0)
    assert det.update(1000.0, 5.0) is None
    assert det.update(1001.0, 6.0) is None
    j = det.update(1002.0 + 3 * 3600, 7.0)
    assert j is not None and j.delta == pytest.approx(3 * 3600) and det.count == 1
    j = det.update(1003.0, 8.0)
    assert j is not None and j.delta == pytest.approx(-3 * 3600)
    assert det.update(1003.5, 8.6) is None                                   # 0.1 s jitter
    with pytest.raises(ValueError):
        ClockJumpDetector(0.0)


# -------------------------------------------------------------------------- horizons
@settings(max_examples=300, deadline=None)
@given(now=st.floats(1.0e9, 4.0e9), step=st.sampled_from([0.25, 0.5, 1.0, 2.0, 15.0]),
       horizon=st.sampled_from([1.0, 60.0, 120.0, 900.0]))
def test_horizon_is_strictly_in_the_future_on_the_grid(now, step, horizon):
    t = horizon_times(now, horizon, step)
    assert t[0] > now and t[0] - now <= step * (1 + 1e-9)
    assert t.size == int(round(horizon / step)) + 1
    assert np.allclose(np.diff(t), step)
    assert np.allclose(t / step, np.round(t / step), atol=1e-6)


def test_horizon_on_exact_grid_point_starts_at_the_next():
    t = horizon_times(1_700_000_000.0, 120.0, 1.0)
    assert t[0] == 1_700_000_001.0 and t[-1] == 1_700_000_121.0 and t.size == 121


def test_velocities_central_difference_exact_on_quadratic():
    step = 0.5
    t = np.arange(-1, 12) * step
    p = np.stack([t ** 2, 3 * t, np.zeros_like(t)], axis=1)
    v = velocities_from(p, step)
    assert np.allclose(v[:, 0], 2 * t[1:-1]) and np.allclose(v[:, 1], 3.0)
    assert np.all(v[:, 2] == 0)


def test_hold_and_ramp():
    t = np.arange(100.0, 221.0)
    h = hold(t, [0.1, 0.2, 0.3])
    assert h.positions.shape == (121, 3) and np.all(h.velocities == 0)
    assert np.all(h.positions == [0.1, 0.2, 0.3])
    r = ramp(t, 90.0, [-0.5, 0.3, 0.0], [math.pi / 2, 0.0, 0.0], [0.02, 0.01, 0.01])
    # mirrors: 10 s elapsed at t=100 -> -0.3; reaches pi/2 after (pi/2+0.5)/0.02 = 103.5 s
    assert r.positions[0, 0] == pytest.approx(-0.5 + 0.2)
    assert r.velocities[0, 0] == 0.02
    assert r.positions[50, 0] == pytest.approx(-0.5 + 0.02 * 60)            # t = 150
    assert r.positions[-1, 0] == math.pi / 2 and r.velocities[-1, 0] == 0.0   # t = 220
    # structure 0.3 -> 0 at 0.01 rad/s: done at t = 120
    k = int(np.searchsorted(t, 120.0))
    assert r.positions[k:, 1].tolist() == [0.0] * (121 - k) and np.all(r.velocities[k:, 1] == 0)
    assert r.velocities[0, 1] == -0.01 and np.all(r.velocities[:, 2] == 0)
    assert np.all(np.diff(r.positions[:, 0]) >= 0)
    with pytest.raises(ValueError):
        ramp(t, 0.0, [0, 0, 0], [1, 1, 1], [0.0, 1.0, 1.0])


def test_ramp_end_reaches_target_exactly():
    t = np.arange(0.0, 400.0)
    r = ramp(t, 0.0, [-math.pi / 4, 0.2, 0.4], [math.pi / 2, 0.0, 0.0], [0.0175] * 3)
    assert r.positions[-1].tolist() == [math.pi / 2, 0.0, 0.0]
