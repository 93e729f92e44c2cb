"""``sslfr sim``'s own rules (no ROS): the window of a run on the system clock."""
from __future__ import annotations

import pytest

from sslfr_sim.sim_cli import _hhmm, day_epoch, wall_clock_window

DAY = day_epoch('2026-11-26')


def test_wall_clock_window_runs_across_midnight_utc():
    """``--end`` not after now is tomorrow's (a field sim started at 23:54 with
    --end 00:09 was refused, and the field tests with it, near midnight)."""
    date, start, end = wall_clock_window(DAY + 23 * 3600 + 54 * 60, '00:09')
    assert date == '2026-11-26' and start == pytest.approx(86040.0) and end == pytest.approx(86400.0 + 540.0)
    assert _hhmm(end) == '00:09:00 (+1 d)' and _hhmm(start) == '23:54:00'
    _, start, end = wall_clock_window(DAY + 12 * 3600, '12:30')          # later today: today's
    assert end - start == pytest.approx(1800.0)
    _, start, end = wall_clock_window(DAY + 23 * 3600 + 55 * 60, None)    # default: 10 minutes, across too
    assert end - start == pytest.approx(600.0) and _hhmm(end) == '00:05:00 (+1 d)'
