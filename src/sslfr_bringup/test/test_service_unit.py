"""The systemd unit's notify and watchdog lines, and the whole unit as systemd itself
reads it (``systemd-analyze verify``, where the machine has it)."""
from __future__ import annotations

import getpass
import shutil
import subprocess

import pytest

from sslfr_bringup import service


def _unit(**kw) -> str:
    return service.render_unit(root=service.repo_root(), config=str(service.repo_root() / 'site.yaml'),
                               user=getpass.getuser(), domain_id=42, discovery_range='LOCALHOST', **kw)


def test_unit_is_notify_with_a_watchdog():
    lines = _unit().splitlines()
    for line in ('Type=notify', 'NotifyAccess=main', f'WatchdogSec={service.SUPERVISOR_WATCHDOG_S}',
                 f'TimeoutStartSec={service.START_TIMEOUT_S}', 'Restart=on-failure', 'KillMode=mixed'):
        assert line in lines, line
    assert 'Type=simple' not in lines
    # the supervisor beats at least every MAX_BEAT_PERIOD: several beats fit in the bound
    from sslfr_common.sdnotify import MAX_BEAT_PERIOD
    assert service.SUPERVISOR_WATCHDOG_S >= 10 * MAX_BEAT_PERIOD


@pytest.mark.skipif(shutil.which('systemd-analyze') is None,
                    reason='systemd-analyze is not installed on this machine: the unit is checked by the '
                           'assertions above only')
def test_systemd_analyze_verify_accepts_the_unit(tmp_path):
    unit = tmp_path / service.UNIT_NAME
    unit.write_text(_unit(layout='composed', namespace='/sslfr1'))
    res = subprocess.run(['systemd-analyze', 'verify', '--man=no', str(unit)],
                         capture_output=True, text=True, timeout=60)
    # verify exits 0 even for a key it ignores ("Failed to parse ..., ignoring"): every
    # line it prints about this file is a failure
    ours = [ln for ln in (res.stdout + res.stderr).splitlines() if service.UNIT_NAME in ln]
    assert res.returncode == 0 and not ours, res.stdout + res.stderr


def test_verify_would_see_a_bad_watchdog_line(tmp_path):
    """The check above can fail: systemd-analyze names a line it cannot parse."""
    if shutil.which('systemd-analyze') is None:
        pytest.skip('systemd-analyze is not installed on this machine')
    unit = tmp_path / service.UNIT_NAME
    unit.write_text(_unit().replace(f'WatchdogSec={service.SUPERVISOR_WATCHDOG_S}', 'WatchdogSec=soon'))
    res = subprocess.run(['systemd-analyze', 'verify', '--man=no', str(unit)],
                         capture_output=True, text=True, timeout=60)
    assert any(service.UNIT_NAME in ln and 'WatchdogSec' not in ln and 'soon' in ln
               for ln in res.stderr.splitlines()), res.stderr
