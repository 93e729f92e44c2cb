"""The launch path's liveness watchdog (``liveness_watchdog``): pids learnt from their
first beat, a silent one SIGKILLed with its cause, gone or stopping ones forgotten;
run for real against a child process on a real NOTIFY_SOCKET; the launch file gives
the nodes and the watchdog the same socket and bound."""
from __future__ import annotations

import configparser
import importlib.util
import io
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

from sslfr_common.sdnotify import Notification

from sslfr_bringup import nodeset
from sslfr_bringup.watchdog import PidWatch, node_names, start_time

ROOT = Path(__file__).resolve().parents[3]

BEATING = textwrap.dedent('''
    import time
    from sslfr_common.sdnotify import Notifier
    n = Notifier.from_environ()
    n.notify('READY=1', 'STATUS=executor turning: planner, web, recorder')
    while True:
        n.beat()
        time.sleep(0.02)
''')


def test_pid_watch_learns_kills_and_forgets():
    clock = [0.0]
    killed = []
    out = io.StringIO()
    w = PidWatch(2.0, out=out, kill=lambda pid, sig: killed.append((pid, sig)), now=lambda: clock[0])
    me = os.getpid()                       # a live pid, so the watch keeps it
    w.take([Notification(me, {'READY': '1', 'STATUS': 'executor turning: gps'})])
    clock[0] = 1.5
    w.take([Notification(me, {'WATCHDOG': '1'})])
    w.check()
    clock[0] = 3.4
    w.check()
    assert killed == []
    clock[0] = 3.6
    w.check()
    assert killed == [(me, signal.SIGKILL)]
    assert 'gps (pid %d): no executor beat for 2.1 s (bound 2 s): killed (SIGKILL); launch respawns it' % me \
        in out.getvalue()
    clock[0] = 10.0
    w.check()                              # forgotten after the kill: not killed twice
    assert len(killed) == 1
    # an orderly stop ends the watch; a STOPPING=1 from an unknown pid starts none
    w.take([Notification(me, {'WATCHDOG': '1'}), Notification(me, {'STOPPING': '1'}),
            Notification(me + 1, {'STOPPING': '1'})])
    clock[0] = 20.0
    w.check()
    assert len(killed) == 1


def test_process_heard_without_status_is_named_from_its_command_line():
    """A watchdog respawned by launch hears the running processes' beats but never
    their STATUS= (sent once at their start): the kill names the nodes of the
    process's ``__node:=`` remaps (one, or several for a composed process)."""
    child = subprocess.Popen([sys.executable, '-c', 'import time; print("up", flush=True); time.sleep(60)',
                              '--ros-args', '-r', '__node:=gps', '--params-file', '/x.yaml', '-r', '__node:=irradiance'],
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline() == 'up\n'      # its own command line from here (exec done)
        assert node_names(child.pid) == 'gps, irradiance'
        clock = [0.0]
        killed = []
        out = io.StringIO()
        w = PidWatch(2.0, out=out, kill=lambda pid, sig: killed.append(pid), now=lambda: clock[0])
        w.take([Notification(child.pid, {'WATCHDOG': '1'})])
        assert f'watching pid {child.pid} (nodes gps, irradiance)' in out.getvalue()
        clock[0] = 2.5
        w.check()
        assert killed == [child.pid]
        assert f'gps, irradiance (pid {child.pid}): no executor beat for 2.5 s' in out.getvalue()
    finally:
        child.kill()
        child.wait(10)
        child.stdout.close()
    assert node_names(child.pid) == '' and node_names(os.getpid()) == ''


def test_gone_process_is_forgotten_not_killed():
    child = subprocess.Popen([sys.executable, '-c', 'pass'])
    child.wait(30)
    killed = []
    w = PidWatch(2.0, out=io.StringIO(), kill=lambda pid, sig: killed.append(pid), now=lambda: 0.0)
    w.take([Notification(child.pid, {'WATCHDOG': '1'})])
    w._now = lambda: 100.0
    w.check()
    assert killed == [] and start_time(child.pid) is None


def test_watchdog_process_kills_a_stopped_node_process(tmp_path):
    """The real thing: the watchdog on a real socket, a child that beats, SIGSTOP; the
    child is SIGKILLed once its beats have been missing for the bound (2 s)."""
    sock = str(tmp_path / 'notify.sock')
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    dog = subprocess.Popen([sys.executable, '-m', 'sslfr_bringup.watchdog', '--socket', sock, '--timeout', '2',
                            '--ros-args', '-r', '__node:=x'],
                           env=env, stderr=subprocess.PIPE, text=True)
    child = None
    try:
        line = dog.stderr.readline()
        assert 'listening on' in line, line
        script = tmp_path / 'beating.py'
        script.write_text(BEATING)
        child = subprocess.Popen([sys.executable, str(script)],
                                 env=dict(env, NOTIFY_SOCKET=sock, WATCHDOG_USEC='2000000'))
        assert f'watching pid {child.pid}' in dog.stderr.readline()
        time.sleep(0.5)                    # a few beats (nothing to wait for: it must NOT be killed)
        assert child.poll() is None
        os.kill(child.pid, signal.SIGSTOP)
        t0 = time.monotonic()
        code = child.wait(10)
        took = time.monotonic() - t0
        assert code == -signal.SIGKILL and 1.5 <= took <= 2.0 + 1.5, (code, took)
        line = dog.stderr.readline()
        assert f'planner, web, recorder (pid {child.pid}): no executor beat for' in line and 'SIGKILL' in line, line
    finally:
        if child is not None and child.poll() is None:
            child.kill()
            child.wait(10)
        dog.send_signal(signal.SIGINT)
        assert dog.wait(10) == 0
    assert not os.path.exists(sock)


def test_watchdog_refuses_a_bound_outside_its_range(tmp_path):
    res = subprocess.run([sys.executable, '-m', 'sslfr_bringup.watchdog', '--socket', str(tmp_path / 's'),
                          '--timeout', '0.5'], capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and 'outside 2..300 s' in res.stderr


def test_launch_file_gives_nodes_and_watchdog_one_socket_and_bound(tmp_path):
    path = ROOT / 'src/sslfr_bringup/launch/tracker.launch.py'
    spec = importlib.util.spec_from_file_location('tracker_launch', path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    args, env = mod._liveness(str(tmp_path))
    ns = nodeset.load()
    sock = str(tmp_path / 'notify.sock')
    assert args == ['--socket', sock, '--timeout', f'{ns.watchdog_timeout:g}']
    assert env == {'NOTIFY_SOCKET': sock, 'WATCHDOG_USEC': str(int(ns.watchdog_timeout * 1e6))}
    text = path.read_text()
    assert text.count('additional_env=notify_env') == 2, 'every node entry (single and composed)'
    assert "executable='liveness_watchdog'" in text
    assert 'OnShutdown(' in text and 'rmtree(write_dir' in text, 'the run directory (socket) goes with the launch'
    cfg = configparser.ConfigParser()
    cfg.read(ROOT / 'src/sslfr_bringup/setup.cfg')
    scripts = cfg['options.entry_points']['console_scripts'].split('\n')
    assert 'liveness_watchdog = sslfr_bringup.watchdog:main' in scripts
