"""Executor liveness watch (pure): who is overdue, when, and why."""
from __future__ import annotations

import pytest

from sslfr_bringup import nodeset
from sslfr_bringup.liveness import LivenessWatch, check_bounds


def test_running_process_overdue_after_the_bound():
    w = LivenessWatch(timeout=5.0, startup_timeout=60.0)
    w.watch('planner', 0.0)
    assert w.note('planner', {'READY': '1', 'STATUS': 'executor turning: planner'}, 2.0)
    for t in (3.0, 4.0, 5.0):
        w.note('planner', {'WATCHDOG': '1'}, t)
    assert w.beats('planner') == 4 and w.status('planner') == 'executor turning: planner'
    assert w.overdue(10.0) == []                         # exactly the bound: not yet
    late = w.overdue(10.5)
    assert [(o.key, o.silence, o.bound, o.starting) for o in late] == [('planner', 5.5, 5.0, False)]
    assert late[0].cause == 'no executor beat for 5.5 s (bound 5 s)'


def test_starting_process_has_its_own_bound():
    w = LivenessWatch(timeout=5.0, startup_timeout=30.0)
    w.watch('web', 100.0)
    assert w.overdue(129.0) == []                        # importing, building its nodes
    late = w.overdue(131.0)
    assert late[0].starting and late[0].cause == 'no executor beat 31.0 s after its start (start-up bound 30 s)'


def test_stopping_ends_the_watch_and_unknown_keys_are_ignored():
    w = LivenessWatch()
    w.watch('gps', 0.0)
    w.note('gps', {'WATCHDOG': '1'}, 1.0)
    assert w.note('gps', {'STOPPING': '1'}, 2.0)
    assert not w.watching('gps') and w.overdue(100.0) == []
    assert w.note('ghost', {'WATCHDOG': '1'}, 1.0) is False
    w.watch('gps', 200.0)                                # a restart: watched afresh
    assert w.beats('gps') == 0 and w.overdue(205.0) == []


def test_other_fields_are_not_beats():
    w = LivenessWatch(timeout=2.0)
    w.watch('x', 0.0)
    w.note('x', {'WATCHDOG': '1'}, 1.0)
    w.note('x', {'STATUS': 'still here'}, 3.5)
    assert [o.key for o in w.overdue(3.5)] == ['x']


@pytest.mark.parametrize('timeout,startup', [(1.0, 60.0), (301.0, 60.0), (5.0, 4.0), (5.0, 601.0),
                                             (float('nan'), 60.0)])
def test_bounds_outside_their_ranges_are_refused(timeout, startup):
    assert check_bounds(timeout, startup)
    with pytest.raises(ValueError):
        LivenessWatch(timeout, startup)


def test_node_set_carries_the_bounds(tmp_path):
    ns = nodeset.load()
    assert (ns.watchdog_timeout, ns.watchdog_startup) == (5.0, 60.0)
    src = ns.path.read_text()
    bad = tmp_path / 'nodeset.yaml'
    bad.write_text(src.replace('watchdog_timeout: 5.0', 'watchdog_timeout: 0.5'))
    with pytest.raises(nodeset.NodeSetError, match=r'defaults.watchdog_timeout 0.5 s outside 2..300 s'):
        nodeset.load(bad)
