"""Bringup supervisor on real child processes (plain Python programs that log their
SIGINT): start order, restart with backoff, loud critical restart, ordered stop
(axes first) within 5 s even when a child ignores SIGINT, `sslfr up` on signals."""
from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import tempfile
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
    # each gap = the child's start-up + 0.2 s run + backoff (0.3, 0.6, 1.2): at least the
    # backoff of its rank, never a tight loop (a loaded machine only lengthens a gap)
    assert all(g >= 0.2 + b - 0.05 for g, b in zip(gaps, (0.3, 0.6, 1.2))), gaps
    text = out.getvalue()
    assert 'CRITICAL: safety DIED (exit code 3' in text and 'safety restarted' in text
    assert 'planner exited (code 3' in text and 'CRITICAL: planner' not in text
    assert sup.programs['safety'].restarts >= 2


def test_a_dead_node_process_waits_for_its_dds_lease_before_its_restart(tmp_path):
    """restart_wait (the DDS lease + 1 s, sslfr_bringup.dds_profile) overrides a
    shorter backoff: the others must have forgotten the dead participant first."""
    progs, journal = _programs(tmp_path, {'planner': 'crash'})
    out = io.StringIO()
    sup = Supervisor(progs, dict(os.environ), backoff=(0.1,), stable_after=30.0, out=out, restart_wait=1.0)
    sup.start()
    t_end = time.monotonic() + 3.5
    while time.monotonic() < t_end:
        sup.step()
        time.sleep(0.02)
    sup.stop()
    starts = [t for t, n, e in _events(journal) if n == 'planner' and e == 'start']
    assert len(starts) >= 2, starts
    # each gap = 0.2 s run + the wait (1 s), not the 0.1 s backoff
    assert all(b - a >= 1.15 for a, b in zip(starts, starts[1:])), starts
    assert 'planner exited (code 3, up 0.' in out.getvalue() and 'restart in 1 s' in out.getvalue()


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


# ---------------------------------------------------------------- executor liveness
BEATING = textwrap.dedent('''
    import os, signal, sys, time
    from sslfr_common.sdnotify import Notifier
    n = Notifier.from_environ()
    stop = []
    signal.signal(signal.SIGINT, lambda s, f: stop.append(s))
    signal.signal(signal.SIGTERM, lambda s, f: stop.append(s))
    if sys.argv[1] == 'mute':              # starts but never turns its executor
        while not stop:
            time.sleep(0.05)
        sys.exit(0)
    n.notify('READY=1', 'STATUS=executor turning: ' + sys.argv[1])
    while not stop:                        # the spin loop: one beat call per turn
        n.beat()
        time.sleep(0.02)
    n.notify('STOPPING=1')
''')


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_hung_process_is_killed_within_the_bound_and_restarted(tmp_path):
    """A SIGSTOPped node process (its executor stops as in a deadlock) is SIGKILLed once
    its beats have been missing for the bound (2 s), reaped and restarted, the cause in
    the log; the others are untouched; a process that never beats is killed after the
    start-up bound; the stop kills a stopped process at once."""
    from sslfr_bringup.liveness import LivenessWatch
    script = tmp_path / 'beating.py'
    script.write_text(BEATING)
    progs = [Program(name=n, argv=[sys.executable, str(script), n], start=i, stop=1, critical=(n == 'safety'))
             for i, n in enumerate(['planner', 'safety', 'gps'])]
    out = io.StringIO()
    sup = Supervisor(progs, dict(os.environ), backoff=(0.2,), stable_after=30.0, out=out,
                     liveness=LivenessWatch(timeout=2.0, startup_timeout=30.0))
    try:
        sup.start()
        pids = {p.name: p.pid for p in progs}

        def run_until(pred, timeout):
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline and not pred():
                sup.step()
                time.sleep(0.02)
            return pred()

        assert run_until(sup.node_set_ready, 30.0), out.getvalue()
        t_hang = time.monotonic()
        sup.hang('planner')
        assert run_until(lambda: not _alive(pids['planner']), 6.0), out.getvalue()
        t_kill = time.monotonic()
        # silent for the bound (2 s) since the last beat, which came at most one beat
        # period (0.5 s) before the hang; then one supervision pass (loaded machine: +1 s)
        assert 2.0 - 0.5 <= t_kill - t_hang <= 2.0 + 1.0, t_kill - t_hang
        assert run_until(lambda: sup.programs['planner'].alive() and sup.liveness.beats('planner') > 0, 30.0)
        text = out.getvalue()
        assert 'planner: no executor beat for 2.' in text and 'killing it (SIGKILL) to restart it' in text, text
        assert 'planner exited (killed: no executor beat for' in text, text
        assert sup.programs['planner'].restarts == 1 and sup.programs['planner'].pid != pids['planner']
        assert [p.restarts for p in progs[1:]] == [0, 0] and [p.pid for p in progs[1:]] == \
            [pids['safety'], pids['gps']]
        events = [ev for _, name, ev, _ in sup.events if name == 'planner']
        assert events[-6:] == ['hang', 'hung', 'exited', 'restart', 'started', 'turning'], events
        # a critical process hangs: the same, loudly
        sup.hang('safety')
        assert run_until(lambda: sup.programs['safety'].restarts == 1, 10.0), out.getvalue()
        assert '*** CRITICAL: safety DIED (killed: no executor beat for' in out.getvalue()
        # the stop: a stopped process is SIGKILLed at once, not after the budget
        sup.hang('gps')
        gps = pids['gps']
        took = sup.stop()
        assert took < 3.0, out.getvalue()
        assert 'gps is stopped (SIGSTOP): SIGKILL' in out.getvalue()
        assert not any(_alive(p) for p in [gps, *sup.pids()])
    finally:
        if not sup.stopping:
            sup.stop()
    for p in progs:                        # reaped: no zombie, no orphan
        assert p.proc.returncode is not None


def test_process_that_never_beats_is_killed_after_the_startup_bound(tmp_path):
    from sslfr_bringup.liveness import LivenessWatch
    script = tmp_path / 'beating.py'
    script.write_text(BEATING)
    prog = Program(name='web', argv=[sys.executable, str(script), 'mute'])
    out = io.StringIO()
    sup = Supervisor([prog], dict(os.environ), backoff=(30.0,), out=out,
                     liveness=LivenessWatch(timeout=2.0, startup_timeout=5.0))
    sup.start()
    try:
        deadline = time.monotonic() + 15.0
        while time.monotonic() < deadline and prog.last_exit is None:
            sup.step()
            time.sleep(0.05)
        assert prog.last_exit == -signal.SIGKILL, out.getvalue()
        assert 'web: no executor beat 5.' in out.getvalue() and 'after its start (start-up bound 5 s)' in out.getvalue()
        assert not sup.node_set_ready()
    finally:
        sup.stop()


def test_children_get_their_own_notify_socket_never_systemds(tmp_path):
    """Node processes get the supervisor's NOTIFY_SOCKET and its bound; simulated
    boards get neither; systemd's own variables reach no child."""
    from sslfr_bringup.liveness import LivenessWatch
    script = tmp_path / 'env.py'
    script.write_text('import os, sys, json\n'
                      'open(sys.argv[1], "w").write(json.dumps({k: os.environ.get(k) for k in '
                      '("NOTIFY_SOCKET", "WATCHDOG_USEC", "WATCHDOG_PID")}))\n')
    progs = [Program(name='node', argv=[sys.executable, str(script), str(tmp_path / 'node.json')], restart=False),
             Program(name='sim_x', argv=[sys.executable, str(script), str(tmp_path / 'board.json')], kind='board',
                     restart=False)]
    env = dict(os.environ, NOTIFY_SOCKET='/run/systemd/notify', WATCHDOG_USEC='15000000', WATCHDOG_PID='1')
    sup = Supervisor(progs, env, out=io.StringIO(), liveness=LivenessWatch(timeout=3.0))
    sup.start()
    for p in progs:
        p.proc.wait(30)
    sup.stop()
    import json
    node = json.loads((tmp_path / 'node.json').read_text())
    board = json.loads((tmp_path / 'board.json').read_text())
    assert node['NOTIFY_SOCKET'].endswith('notify.sock') and node['NOTIFY_SOCKET'] != env['NOTIFY_SOCKET']
    assert node['WATCHDOG_USEC'] == '3000000' and node['WATCHDOG_PID'] is None
    assert board == {'NOTIFY_SOCKET': None, 'WATCHDOG_USEC': None, 'WATCHDOG_PID': None}
    assert not os.path.exists(node['NOTIFY_SOCKET']), 'the socket is removed at close'


def test_sslfr_up_speaks_sd_notify_to_its_watcher(tmp_path, ros_env):
    """`sslfr up` as systemd runs it (Type=notify, WatchdogSec=): on a real
    NOTIFY_SOCKET it beats WATCHDOG=1 from its start, says READY=1 once every node
    process's executor turns, and STOPPING=1 at SIGTERM; every message comes from its
    own pid (the node processes have the supervisor's socket, not this one)."""
    from sslfr_common.sdnotify import NotifyListener
    site = tmp_path / 'site.yaml'
    site.write_text("/**:\n  ros__parameters:\n    site:\n      latitude_deg: 36.835\n")
    # a short directory: socket paths are <= 107 bytes, and tmp_path may be longer
    with tempfile.TemporaryDirectory(prefix='sslfr-sd-') as short, \
            NotifyListener(os.path.join(short, 'systemd-notify.sock')) as lis:
        env = dict(ros_env, NOTIFY_SOCKET=lis.path, WATCHDOG_USEC='4000000')    # beat every 1 s
        proc = subprocess.Popen([str(ROOT / 'sslfr'), 'up', '--config', str(site), '--only', 'safety,gps',
                                 '--log-dir', str(tmp_path / 'logs')],
                                env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        got = []
        try:
            deadline = time.monotonic() + 90
            while time.monotonic() < deadline and proc.poll() is None:
                got += [(time.monotonic(), n) for n in lis.receive()]
                if any(n.fields.get('READY') == '1' for _, n in got) and \
                        sum('WATCHDOG' in n.fields for _, n in got) >= 3:
                    break
                time.sleep(0.05)
            assert proc.poll() is None
            proc.send_signal(signal.SIGTERM)
            out, _ = proc.communicate(timeout=15)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate(timeout=15)
        got += [(time.monotonic(), n) for n in lis.receive()]
    assert proc.returncode == 0, out
    assert {n.pid for _, n in got} == {proc.pid}, 'only the unit\'s main process talks to systemd'
    ready = [n for _, n in got if n.fields.get('READY') == '1']
    assert len(ready) == 1 and ready[0].fields['STATUS'].startswith('node set up: 2 node processes'), got
    beats = [t for t, n in got if n.fields.get('WATCHDOG') == '1']
    assert len(beats) >= 3 and max(b - a for a, b in zip(beats, beats[1:])) < 2.0, beats
    assert got[-1][1].fields == {'STOPPING': '1'}, got[-3:]
    assert 'node set up: 2 node processes, every executor turning' in out


STUCK_NODE = textwrap.dedent('''
    import threading
    from rclpy.node import Node
    from sslfr_common.node import run_node

    def stuck_in_callback():
        threading.Event().wait()               # a callback that never returns

    class Stuck(Node):
        def __init__(self, **kw):
            super().__init__('stuck', **kw)
            self.create_timer(1.5, stuck_in_callback)

    raise SystemExit(run_node('stuck', Stuck))
''')


def test_a_hung_node_process_writes_its_stacks_to_its_log_before_the_kill(tmp_path, ros_env):
    """A real node process (sslfr_common.node.run_node) whose callback never returns stops
    beating; before the SIGKILL the supervisor asks it for every thread's stack
    (faulthandler on STACK_DUMP_SIGNAL), which lands in its log: the stuck call named."""
    from sslfr_bringup.liveness import LivenessWatch
    script = tmp_path / 'stuck.py'
    script.write_text(STUCK_NODE)
    prog = Program(name='stuck', argv=[sys.executable, str(script)], start=0, stop=1)
    out = io.StringIO()
    sup = Supervisor([prog], ros_env, backoff=(30.0,), stable_after=30.0, out=out, log_dir=tmp_path / 'logs',
                     liveness=LivenessWatch(timeout=2.0, startup_timeout=60.0))
    try:
        sup.start()
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and not any(ev == 'hung' for _, _, ev, _ in sup.events):
            sup.step()
            time.sleep(0.05)
        assert any(ev == 'hung' for _, _, ev, _ in sup.events), out.getvalue()
        log = (tmp_path / 'logs' / 'stuck.log').read_text(errors='replace')
        assert 'its stacks to its log, then killing it (SIGKILL)' in out.getvalue()
        assert 'stuck_in_callback' in log and 'spin_until_stopped' in log, log[-3000:]
    finally:
        sup.stop()
        sup.close()
