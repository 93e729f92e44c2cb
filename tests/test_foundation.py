"""Foundation acceptance: interfaces build and round-trip between processes, every
console script is where `ros2 run` looks, the CLI works, set-up errors are clear."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import ROOT, NodeProcess, executable


def test_custom_interfaces_round_trip_between_processes(ros, ros_env, tmp_path):
    from sslfr_interfaces.msg import SafetyState
    from sslfr_interfaces.srv import SetMode

    peer = NodeProcess([sys.executable, str(ROOT / 'tests/support/interface_peer.py')],
                       ros_env, tmp_path / 'peer.log')
    try:
        assert peer.wait_for_output('peer ready', 20), peer.output()
        got = ros.collect(SafetyState, 'peer/out')
        pub = ros.node.create_publisher(SafetyState, 'peer/in', 10)
        msg = SafetyState(level=SafetyState.WARN, stow_required=True,
                          reasons=['outlet 151.0 degC > 150 degC'], stopped_axes=['mirrors'],
                          sequence=4_000_000_000)
        msg.since.sec = 1_700_000_000

        def sent_and_got():
            if not got:
                pub.publish(msg)
            return bool(got)
        assert ros.spin_until(sent_and_got, 15), peer.output()
        echo = got[0]
        assert echo.level == SafetyState.STOW
        assert echo.reasons == ['outlet 151.0 degC > 150 degC', 'echoed']
        assert echo.stopped_axes == ['mirrors']
        assert echo.sequence == 4_000_000_000 and echo.since.sec == 1_700_000_000
        assert echo.stow_required is True

        ok = ros.call(SetMode, 'peer/set_mode', SetMode.Request(mode='stow'))
        assert ok.success and ok.mode == 'stow'
        bad = ros.call(SetMode, 'peer/set_mode', SetMode.Request(mode='fly'))
        assert not bad.success and 'fly' in bad.message
    finally:
        assert peer.stop() == 0, peer.output()


def _installed_executables():
    sys.path.insert(0, str(ROOT / 'src/sslfr_bringup'))
    from sslfr_bringup.doctor import EXECUTABLES
    return [(pkg, exe, kind) for pkg, exes in EXECUTABLES.items() for exe, kind in exes.items()]


@pytest.mark.parametrize('package,exe,kind', _installed_executables())
def test_console_script_installed_where_ros2_run_looks(package, exe, kind, ros_env, ros, tmp_path):
    path = executable(package, exe)
    assert path.is_file() and os.access(path, os.X_OK), f'{path} missing: ros2 run {package} {exe} would fail'
    if kind == 'cli':
        out = subprocess.run([str(path), '--help'], env=ros_env, capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        assert 'usage' in out.stdout.lower()
    else:  # a node: starts, then stops cleanly on SIGINT
        # (the operator page and the gateways: any free port, not the default one that a
        # running tracker or station may hold)
        extra = ['--ros-args', '-p', 'port:=0', '-p', f'audit_file:={tmp_path / "audit"}'] if exe == 'web' else []
        if exe in ('modbus_gateway', 'foxglove_bridge'):
            extra = ['--ros-args', '-p', 'port:=0']
        proc = NodeProcess([str(path), *extra], ros_env, tmp_path / f'{exe}.log')
        # up = its node (default name = the executable's) is in the graph; start-up
        # takes longer on a loaded machine, so wait for it instead of a fixed sleep
        up = ros.spin_until(lambda: exe in ros.node.get_node_names() or not proc.running(), 60)
        assert up and proc.running(), f'{exe} exited early or never joined the graph:\n{proc.output()}'
        code = proc.stop(timeout=10)
        assert code == 0, f'{exe} exit code {code}:\n{proc.output()}'
        assert 'Traceback' not in proc.output(), proc.output()


def test_sslfr_wrapper_needs_no_sourcing():
    env = {k: v for k, v in os.environ.items()
           if k not in ('AMENT_PREFIX_PATH', 'PYTHONPATH', 'LD_LIBRARY_PATH', 'VIRTUAL_ENV', 'CMAKE_PREFIX_PATH')}
    env['PATH'] = '/usr/local/bin:/usr/bin:/bin'
    out = subprocess.run([str(ROOT / 'sslfr'), 'doctor'], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    assert 'interfaces    sslfr_interfaces imports' in out.stdout
    bad = subprocess.run([str(ROOT / 'sslfr'), 'no-such-command'], env=env, capture_output=True, text=True,
                         timeout=60)
    assert bad.returncode == 2 and "unknown subcommand 'no-such-command'" in bad.stderr


# --- set-up errors: run a copy of the bootstrap in a scratch tree ------------------

def _scratch_tree(tmp_path: Path) -> Path:
    tree = tmp_path / 'tree'
    (tree / 'scripts').mkdir(parents=True)
    for name in ('scripts/setup.sh', 'scripts/env.sh', 'requirements.txt'):
        shutil.copy(ROOT / name, tree / name)
    (tree / 'src').mkdir()
    return tree


def _run_setup(tree: Path, env_extra: dict, path: str | None = None):
    env = {k: v for k, v in os.environ.items() if not k.startswith(('PIP_', 'VIRTUAL_ENV'))}
    env.update(env_extra)
    if path is not None:
        env['PATH'] = path
    return subprocess.run([shutil.which('bash') or '/bin/bash', str(tree / 'scripts/setup.sh')], env=env, capture_output=True,
                          text=True, timeout=300)


def test_setup_refuses_missing_or_old_python(tmp_path):
    tree = _scratch_tree(tmp_path)
    out = _run_setup(tree, {'PYTHON': str(tmp_path / 'no-python')})
    assert out.returncode != 0 and 'does not run' in out.stderr
    old = tmp_path / 'python3.9'
    old.write_text('#!/bin/sh\necho 3.9\n')
    old.chmod(0o755)
    out = _run_setup(tree, {'PYTHON': str(old)})
    assert out.returncode != 0
    assert 'Python 3.9 found' in out.stderr and '3.10-3.13' in out.stderr


def test_setup_refuses_missing_compiler(tmp_path):
    tree = _scratch_tree(tmp_path)
    bindir = tmp_path / 'bin'
    bindir.mkdir()
    real = shutil.which('python3')
    os.symlink(real, bindir / 'python3')
    for tool in ('sed', 'grep', 'cat', 'rm', 'dirname', 'uname', 'cmp', 'mv', 'cp', 'touch', 'mkdir', 'head', 'tail'):
        if shutil.which(tool):
            os.symlink(shutil.which(tool), bindir / tool)
    out = _run_setup(tree, {}, path=str(bindir))
    assert out.returncode != 0
    assert "no 'cc' on PATH" in out.stderr and 'build-essential' in out.stderr


def test_setup_repairs_broken_venv_and_reports_unreachable_registry(tmp_path):
    tree = _scratch_tree(tmp_path)
    (tree / '.venv' / 'bin').mkdir(parents=True)
    os.symlink('/nonexistent/python3', tree / '.venv' / 'bin' / 'python')
    out = _run_setup(tree, {'PIP_CONFIG_FILE': os.devnull, 'PIP_INDEX_URL': 'http://127.0.0.1:9/simple',
                            'PIP_RETRIES': '0', 'PIP_TIMEOUT': '2'})
    assert '.venv/ is broken' in out.stdout
    assert out.returncode != 0
    assert 'package registry cannot be reached' in out.stderr, out.stderr


def test_a_test_stuck_in_native_code_holding_the_gil_ends_its_worker_with_stacks(tmp_path):
    """pytest-timeout's handler is Python and needs the GIL; a deadlock in native code
    that holds it (seen in a soak round: Fast DDS's event and receive threads of a test's
    own participant deadlocked, eProsima/Fast-DDS#6502, and the harness's destroy_node
    waited for them with the GIL held) hung the worker for good. The suite's pytest.ini
    arms faulthandler's C watchdog too: the stuck test's process ends with every
    thread's stack. Checked here with the suite's own pytest.ini, the timeout shortened."""
    case = tmp_path / 'test_stuck.py'
    case.write_text('import ctypes\n\n'
                    'def test_stuck_holding_the_gil():\n'
                    '    libc = ctypes.PyDLL(None)                # PyDLL: the GIL stays held\n'
                    '    mutex = ctypes.create_string_buffer(64)  # PTHREAD_MUTEX_INITIALIZER\n'
                    '    libc.pthread_mutex_lock(mutex)\n'
                    '    libc.pthread_mutex_lock(mutex)           # for ever; no signal ends it\n')
    t0 = time.monotonic()
    # pytest-timeout at 1 s cannot end it (its handler needs the GIL); the watchdog at 2 s must
    run = subprocess.run([sys.executable, '-m', 'pytest', '-c', str(ROOT / 'pytest.ini'),
                          '--rootdir', str(tmp_path), '-p', 'no:randomly', '-q', '-o', 'timeout=1',
                          '-o', 'faulthandler_timeout=2', str(case)],
                         capture_output=True, text=True, timeout=30)
    took = time.monotonic() - t0
    assert run.returncode != 0, run.stdout
    assert took < 20, took
    assert 'Timeout (0:00:02)!' in run.stderr, run.stderr
    assert 'test_stuck_holding_the_gil' in run.stderr, run.stderr
