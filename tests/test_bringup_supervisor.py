"""Bringup supervisor on real child processes (plain Python programs that log their
SIGINT): start order, restart with backoff, loud critical restart, ordered stop
(axes first) within 5 s even when a child ignores SIGINT, `sslfr up` on signals."""
from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import textwrap
import time

from conftest import ROOT

sys.path.insert(0, str(ROOT / 'src/sslfr_bringup'))
from sslfr_bringup.supervisor import Program, Supervisor  # noqa: E402

CHILD = textwrap.dedent('''
    import os, signal, sys, time
    name, journal, mode = sys.argv[1], sys.argv[2], sys.argv[3]
    def log(event):
        with open(journal, 'a') as f:
            f.write(f'{time.monotonic():.4f} {name} {event}\\n')
    def on_int(signum, frame):
        log('sigint')
        time.sleep(0.3 if name.startswith('axis') else 0.05)   # the axes take a while to stop
        log('exit')
        sys.exit(0)
    # like the tracker's nodes (sslfr_common.node.run_node): SIGINT and SIGTERM handled
    # alike once started; the stubborn child ignores both
    handler = on_int if mode != 'stubborn' else (lambda signum, frame: None)
    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    log('start')
    if mode == 'crash':
        time.sleep(0.2)
        sys.exit(3)
    while True:
        time.sleep(0.05)
''')


def _programs(tmp_path, modes: dict[str, str]):
    script = tmp_path / 'child.py'
    script.write_text(CHILD)
    journal = tmp_path / 'journal.txt'
    layout = {  # name: (start, stop, critical)
        'recorder': (0, 2, False), 'safety': (1, 1, True), 'planner': (3, 1, False),
        'axis_a': (4, 0, False), 'axis_b': (4, 0, False)}
    progs = [Program(name=n, argv=[sys.executable, str(script), n, str(journal), modes.get(n, 'run')],
                     start=s, stop=g, critical=c) for n, (s, g, c) in layout.items()]
    return progs, journal


def _events(journal):
    out = []
    for line in journal.read_text().splitlines():
        t, name, ev = line.split()
        out.append((float(t), name, ev))
    return out


def test_ordered_stop_axes_first_within_5_s(tmp_path):
    progs, journal = _programs(tmp_path, {'planner': 'stubborn'})
    out = io.StringIO()
    sup = Supervisor(progs, dict(os.environ), backoff=(0.2,), stop_timeout=5.0, out=out)
    sup.start()
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and len([e for e in (_events(journal) if journal.exists() else [])
                                                if e[2] == 'start']) < 5:
        sup.step()
        time.sleep(0.05)
    took = sup.stop()
    assert took < 5.0, out.getvalue()
    ev = _events(journal)
    first_int = {n: t for t, n, e in ev if e == 'sigint'}
    exited = {n: t for t, n, e in ev if e == 'exit'}
    assert set(exited) >= {'axis_a', 'axis_b', 'safety', 'recorder'}
    assert max(exited['axis_a'], exited['axis_b']) <= first_int['safety'], 'axes stop before the rest'
    assert first_int['recorder'] >= exited['safety'], 'the recorder stops last'
    assert 'planner still running: SIGKILL' in out.getvalue() or 'planner did not stop' in out.getvalue()
    assert not any(p.alive() for p in progs)


def test_restart_with_backoff_and_loud_critical_restart(tmp_path):
    progs, journal = _programs(tmp_path, {'safety': 'crash', 'planner': 'crash'})
    out = io.StringIO()
    sup = Supervisor(progs, dict(os.environ), backoff=(0.3, 0.6, 1.2), stable_after=30.0, out=out)
    sup.start()
    t_end = time.monotonic() + 4.0
    while time.monotonic() < t_end:
        sup.step()
        time.sleep(0.02)
    sup.stop()
    starts = [t for t, n, e in _events(journal) if n == 'planner' and e == 'start']
    assert len(starts) >= 3, starts
    gaps = [b - a for a, b in zip(starts, starts[1:])]
    # each gap = 0.2 s run + backoff (0.3, 0.6, 1.2): growing, never a tight loop
    assert gaps[0] >= 0.45 and gaps[1] >= gaps[0] + 0.2, gaps
    text = out.getvalue()
    assert 'CRITICAL: safety DIED (exit code 3' in text and 'safety restarted' in text
    assert 'planner exited (code 3' in text and 'CRITICAL: planner' not in text
    assert sup.programs['safety'].restarts >= 2


def test_fault_kill_holds_until_released(tmp_path):
    progs, journal = _programs(tmp_path, {})
    sup = Supervisor(progs, dict(os.environ), backoff=(0.1,), out=io.StringIO())
    sup.start()
    time.sleep(0.5)
    pid = sup.programs['planner'].pid
    sup.kill('planner', hold=True)
    t_end = time.monotonic() + 0.6
    while time.monotonic() < t_end:
        sup.step()
        time.sleep(0.02)
    assert not sup.programs['planner'].alive(), 'a held program is not restarted'
    sup.release('planner')
    sup.step()
    assert sup.programs['planner'].alive() and sup.programs['planner'].pid != pid
    sup.stop()


def test_sslfr_up_on_sigterm_stops_everything_it_started(tmp_path, ros_env):
    """`sslfr up --only` with whatever node executables are installed; SIGTERM ->
    ordered stop, exit 0, no process left."""
    from sslfr_bringup import nodeset, up
    ns = nodeset.load()
    installed = [n.name for n in ns.nodes if up.find_executable(n.package, n.executable)
                 and not n.lifecycle]
    if not installed:
        installed = []
    site = tmp_path / 'site.yaml'
    site.write_text("/**:\n  ros__parameters:\n    site:\n      latitude_deg: 36.835\n")
    env = ros_env
    args = [str(ROOT / 'sslfr'), 'up', '--config', str(site), '--log-dir', str(tmp_path / 'logs')]
    if installed:
        args += ['--only', ','.join(installed[:3])]
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if not installed:
        out, _ = proc.communicate(timeout=60)
        assert proc.returncode == 1 and 'MISSING executable' in out and 'nothing to run' in out
        return
    import psutil
    deadline = time.monotonic() + 60      # every node process started (slow when loaded)
    kids = []
    while time.monotonic() < deadline and proc.poll() is None:
        kids = psutil.Process(proc.pid).children(recursive=True)
        logs = [tmp_path / 'logs' / f'{name}.log' for name in installed[:3]]
        if len(kids) >= len(installed[:3]) and all(p.exists() and p.stat().st_size for p in logs):
            break
        time.sleep(0.1)
    assert proc.poll() is None
    assert len(kids) >= len(installed[:3]), [k.cmdline() for k in kids]
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    out, _ = proc.communicate(timeout=15)
    assert time.monotonic() - t0 < 6.0, out
    assert proc.returncode == 0, out
    assert 'stopped in' in out
    # every child is gone
    assert not [k for k in kids if k.is_running() and k.status() != psutil.STATUS_ZOMBIE]
    for name in installed[:3]:
        log = (tmp_path / 'logs' / f'{name}.log')
        assert log.exists()


def test_stop_signal_is_sigterm_while_a_node_starts_and_sigint_once_it_handles_stops(tmp_path):
    """SIGINT inside a starting interpreter is a KeyboardInterrupt in Python's own start-up
    (a "Fatal Python error" traceback on the console); until a node has installed its
    stop handlers (it then catches SIGTERM) the ordered stop sends SIGTERM instead."""
    from sslfr_bringup.supervisor import catches, stop_signal
    ready = tmp_path / 'ready'
    code = ('import signal, sys, time\n'
            'time.sleep(1.0)\n'
            'signal.signal(signal.SIGINT, lambda s, f: sys.exit(0))\n'
            'signal.signal(signal.SIGTERM, lambda s, f: sys.exit(0))\n'
            f'open({str(ready)!r}, "w").close()\n'
            'time.sleep(30)\n')
    p = Program(name='n', argv=[sys.executable, '-c', code])
    p.proc = subprocess.Popen(p.argv)
    try:
        time.sleep(0.2)                 # past the exec (the forked child has pytest's handlers)
        assert not catches(p.proc.pid, signal.SIGTERM)
        assert stop_signal(p) == signal.SIGTERM
        deadline = time.monotonic() + 20
        while not ready.exists():
            assert time.monotonic() < deadline and p.proc.poll() is None
            time.sleep(0.02)
        assert catches(p.proc.pid, signal.SIGTERM)
        assert stop_signal(p) == signal.SIGINT
        board = Program(name='b', argv=[], kind='board')
        board.proc = p.proc
        assert stop_signal(board) == signal.SIGINT
        p.proc.send_signal(stop_signal(p))
        assert p.proc.wait(10) == 0
    finally:
        if p.proc.poll() is None:
            p.proc.kill()
            p.proc.wait()
