"""`sslfr up` with the real node executables against simulated axis boards on ptys
(the boards a Pi would have on /dev/sslfr/*): lifecycle driven to active, a killed
safety supervisor restarted and reported loudly, SIGTERM stops the axes first and
everything within 5 s."""
from __future__ import annotations

import os
import signal
import subprocess
import time

import psutil
import pytest
import yaml

from conftest import ROOT, NodeProcess, executable
from sslfr_common.contract import DIAGNOSTICS

AXES = ('mirrors', 'mobile_structure', 'secondary_reflector')


@pytest.fixture
def axis_boards(ros_env, tmp_path):
    exe = executable('sslfr_sim', 'sim_board')
    if not exe.exists():
        pytest.fail('sim_board is not installed: run make setup')
    boards = {}
    for axis in AXES:
        link = tmp_path / f'{axis}.pty'
        boards[axis] = (NodeProcess([str(exe), '--kind', 'axis', '--axis', axis, '--link', str(link),
                                     '--opt', f'initial_angle_deg={90 if axis == "mirrors" else 0}'],
                                    ros_env, tmp_path / f'sim_{axis}.log'), link)
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and not all(link.exists() for _, link in boards.values()):
        time.sleep(0.05)
    assert all(link.exists() for _, link in boards.values()), [p.output() for p, _ in boards.values()]
    yield {a: str(link) for a, (_, link) in boards.items()}
    for proc, _ in boards.values():
        proc.stop()


def test_up_activates_axes_reports_safety_restart_and_stops_axes_first(ros, ros_env, axis_boards, tmp_path):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from sslfr_drivers.axis.lifecycle_ctl import get_state

    site = tmp_path / 'site.yaml'
    site.write_text(yaml.safe_dump({
        '/**': {'ros__parameters': {'site': {'latitude_deg': 36.835, 'longitude_deg': -2.402, 'elevation': 22.0}}},
        **{f'{a}_driver': {'ros__parameters': {'port': axis_boards[a]}} for a in AXES}}))
    nodes = ['safety', *(f'{a}_driver' for a in AXES)]
    logs = tmp_path / 'logs'
    up = subprocess.Popen([str(ROOT / 'sslfr'), 'up', '--config', str(site), '--only', ','.join(nodes),
                           '--log-dir', str(logs)], env=ros_env, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, start_new_session=True)
    diags = ros.collect(DiagnosticArray, DIAGNOSTICS.name)
    try:
        states = {}

        def all_active():
            for a in AXES:
                if states.get(a) != 'active':
                    states[a] = get_state(ros.node, f'{a}_driver', timeout=1.0, executor=ros.executor)
            return all(states.get(a) == 'active' for a in AXES)
        assert ros.spin_until(all_active, 45), (states, (logs / 'mirrors_driver.log').read_text()
                                                if (logs / 'mirrors_driver.log').exists() else '')
        # kill the safety supervisor: restarted, reported loudly (stderr + diagnostics ERROR)
        children = psutil.Process(up.pid).children(recursive=True)
        safety = [p for p in children if any('__node:=safety' in a for a in p.cmdline())]
        assert len(safety) == 1, [p.cmdline() for p in children]
        os.kill(safety[0].pid, signal.SIGKILL)

        def safety_error_reported():
            return any(s.name == 'sslfr_supervisor: safety' and s.level == DiagnosticStatus.ERROR
                       for arr in diags for s in arr.status)
        assert ros.spin_until(safety_error_reported, 15)

        def safety_back():
            return len([p for p in psutil.Process(up.pid).children(recursive=True)
                        if any('__node:=safety' in a for a in p.cmdline())]) == 1
        assert ros.spin_until(safety_back, 15)
        kids = psutil.Process(up.pid).children(recursive=True)
        t0 = time.monotonic()
        os.kill(up.pid, signal.SIGTERM)
        out, _ = up.communicate(timeout=20)
        took = time.monotonic() - t0
    finally:
        if up.poll() is None:
            os.killpg(up.pid, signal.SIGKILL)
            up.wait(5)
    assert up.returncode == 0, out
    assert took < 5.0 + 1.0, (took, out)   # the supervisor's 5 s budget + its own start/exit
    assert 'CRITICAL: safety DIED (exit code -9' in out and 'safety restarted (#1' in out, out
    assert 'stopped in' in out
    assert not [k for k in kids if k.is_running() and k.status() != psutil.STATUS_ZOMBIE], 'children left behind'
    # the axes were stopped (deactivated: motor stopped) before the safety node got SIGINT
    for a in AXES:
        assert 'motor stopped' in (logs / f'{a}_driver.log').read_text()


def test_two_collectors_in_their_namespaces_share_a_domain_without_mixing(ros, ros_env, tmp_path):
    """Two `sslfr up --namespace` sets, each with its own site config whose node section
    is keyed by the bare node name `planner:` (as the shipped configs are): each planner
    gets its own section (rcl alone would give a bare key only to the root namespace)."""
    from sslfr_common.contract import TRACKER_PHASE
    from sslfr_common.node import qos
    from sslfr_interfaces.msg import TrackerPhase

    ups = []
    phases = {}
    tl1 = qos(TRACKER_PHASE)
    for ns, lat, temp in (('/c1', 10.0, 18.0), ('/c2', -20.0, 25.0)):
        site = tmp_path / f'{ns[1:]}.yaml'
        site.write_text(yaml.safe_dump({'planner': {'ros__parameters': {
            'site': {'latitude_deg': lat, 'longitude_deg': 5.0, 'temperature': temp},
            'state_dir': str(tmp_path / ns[1:])}}}))
        ups.append(subprocess.Popen([str(ROOT / 'sslfr'), 'up', '--config', str(site), '--only', 'planner',
                                     '--namespace', ns, '--log-dir', str(tmp_path / f'logs{ns[1:]}')],
                                    env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                    start_new_session=True))
        box = phases.setdefault(ns, [])
        ros.node.create_subscription(TrackerPhase, f'{ns}/tracker/phase', box.append, tl1)
    try:
        assert ros.spin_until(lambda: all(phases.values()), 60), [u.poll() for u in ups]
        assert phases['/c1'][-1].latitude == 10.0 and phases['/c2'][-1].latitude == -20.0
        for ns, temp in (('/c1', 18.0), ('/c2', 25.0)):
            assert _get_param(ros, f'{ns}/planner', 'site.temperature') == temp
    finally:
        for u in ups:
            u.send_signal(signal.SIGTERM)
        for u in ups:
            u.communicate(timeout=30)
    assert all(u.returncode == 0 for u in ups), [u.returncode for u in ups]


def _get_param(ros, node: str, name: str):
    from rcl_interfaces.srv import GetParameters
    res = ros.call(GetParameters, f'{node}/get_parameters', GetParameters.Request(names=[name]), timeout=30)
    return res.values[0].double_value
