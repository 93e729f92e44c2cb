"""Process supervisor of the node set (used by ``./sslfr up`` and ``./sslfr sim``).

Every node runs as its own process (its own session, so a terminal's Ctrl-C reaches
only the supervisor, which then stops the set in order). The supervisor

- starts the programs in the node set's start order;
- restarts a program that exits with backoff (``restart_backoff`` seconds, the index
  advancing with each consecutive failure and reset once a program stayed up
  ``stable_after`` seconds), a node process never sooner than ``restart_wait`` after
  its death (its DDS participant lease + a margin, :mod:`sslfr_bringup.dds_profile`:
  until the others have forgotten the dead participant they still write to its
  shared-memory port, and a process restarted on that port may never hear them); the restart of a *critical* program (the safety
  supervisor) is reported loudly: a banner on stderr at journal priority ``err`` and
  an ERROR status on ``diagnostics``;
- watches lifecycle programs (the axis drivers) after every (re)start until they
  report ``active``: the drivers activate themselves (``autostart``, configure
  retried with back-off while a board is not reachable), the supervisor never
  requests a transition on the way up, so it cannot fight them; a driver not active
  after 20 s is reported (and watched again 3 s later);
- watches that every node process's executor turns (with a
  :class:`~sslfr_bringup.liveness.LivenessWatch`): each node process gets its own
  ``NOTIFY_SOCKET`` (one datagram socket of the supervisor, the sender told apart by
  the pid the kernel attaches) and ``WATCHDOG_USEC``, and beats ``WATCHDOG=1`` from
  its spin loop (:func:`sslfr_common.node.run_nodes`). A process silent for longer
  than the bound (``defaults.watchdog_timeout``; before its first beat
  ``defaults.watchdog_startup``) is killed with SIGKILL (a stopped or deadlocked
  process does not act on SIGTERM), reaped and restarted like a crashed one; the
  log line and the ``diagnostics`` status say why ("no executor beat for N s");
- speaks sd_notify to its own watcher (systemd, ``Type=notify``): ``WATCHDOG=1`` from
  its loop, ``READY=1`` once every node process has beaten, ``STOPPING=1`` at stop;
- on :meth:`Supervisor.stop` stops the set in stop groups within ``stop_timeout``
  seconds: the axes first (lifecycle ``deactivate``, then SIGINT), then the rest,
  the recorder last; a stopped (SIGSTOP) process is killed at once; whatever is
  still alive at the end is killed.

The ROS side (lifecycle calls, diagnostics, the simulation's /clock) lives in one
thread (:class:`RosSide`) that owns the rclpy context; the process bookkeeping is
plain Python in the caller's thread. All waits are on ``time.monotonic``.
"""
from __future__ import annotations

import os
import queue
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, TextIO

from sslfr_common.cliargs import CliError, one_line
from sslfr_common.contract import CLOCK, DIAGNOSTICS
from sslfr_common.sdnotify import STACK_DUMP_SIGNAL, Notifier, NotifyListener

from sslfr_bringup.liveness import LivenessWatch


class Interrupted(Exception):
    """A stop signal arrived; raised at a safe point (never inside a spawn)."""


class StopSignals:
    """SIGINT, SIGTERM and SIGHUP -> a flag, from the moment ``sslfr up`` / ``sslfr
    sim`` start until they end (use as a context manager around the whole command).

    The handler only sets :attr:`requested`; start-up waits call :meth:`check` (which
    raises :class:`Interrupted`) and the supervision loop watches the flag, so a
    signal can never cut a spawn in half and leave an untracked child. Further
    signals while stopping are ignored.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)

    def __init__(self) -> None:
        self.requested = threading.Event()
        self.name = ''
        self._old: dict = {}

    def __enter__(self) -> 'StopSignals':
        for sig in self.SIGNALS:
            self._old[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)

    def _handler(self, signum, frame) -> None:  # noqa: ARG002 - signal API
        if not self.requested.is_set():
            self.name = signal.Signals(signum).name
            self.requested.set()

    def check(self) -> None:
        """Raise :class:`Interrupted` when a stop signal has arrived."""
        if self.requested.is_set():
            raise Interrupted(self.name)

    def wait(self, seconds: float) -> None:
        """Sleep up to ``seconds``, then :meth:`check`."""
        self.requested.wait(seconds)
        self.check()


def supervised_main(prog: str, body: Callable[[StopSignals, Path], int]) -> int:
    """Run ``body(stop, run_dir)``, a command that starts processes (``sslfr up``,
    ``sslfr station``): stop signals caught throughout, ``run_dir`` a fresh directory
    removed afterwards; a :class:`CliError` is one line and exit 2, a stop signal exit 0."""
    with StopSignals() as stop:
        run_dir = Path(tempfile.mkdtemp(prefix=f'sslfr-{prog}-'))
        try:
            return body(stop, run_dir)
        except CliError as exc:
            print(f'sslfr {prog}: error: {one_line(exc)}', file=sys.stderr)
            return 2
        except Interrupted:
            return 0
        finally:
            shutil.rmtree(run_dir, ignore_errors=True)


def _orphan_guard(argv: list[str]) -> list[str]:
    """``argv`` run so that the kernel sends it SIGTERM if the supervisor dies, even
    by SIGKILL (``setpriv --pdeathsig``, util-linux, on every Debian/Ubuntu): no node
    or simulated board outlives ``sslfr up`` / ``sslfr sim``. The spawn happens in
    the supervisor's main thread (the death signal follows the spawning thread)."""
    import shutil
    setpriv = shutil.which('setpriv')
    return [setpriv, '--pdeathsig', 'TERM', '--', *argv] if setpriv else list(argv)


#: A node exiting with this code refused its configuration (sslfr_common.node): it
#: would refuse it again, so the set stops instead of restarting it forever.
EXIT_CONFIG_REFUSED = 2
#: [s] longest wait for the stack dumps of the processes found hung in one pass
STACK_DUMP_WAIT = 0.3


def catches(pid: int, sig: int) -> bool:
    """Whether process ``pid`` has a handler installed for ``sig`` (Linux
    /proc/PID/status ``SigCgt``; False when it cannot be read)."""
    try:
        with open(f'/proc/{pid}/status') as f:
            for line in f:
                if line.startswith('SigCgt:'):
                    return bool(int(line.split()[1], 16) >> (sig - 1) & 1)
    except (OSError, ValueError, IndexError):
        pass
    return False


def is_stopped(pid: int) -> bool:
    """Whether process ``pid`` is stopped (SIGSTOP; Linux /proc/PID/stat state T)."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            return f.read().rsplit(')', 1)[1].split()[0] in ('T', 't')
    except (OSError, IndexError):
        return False


#: environment variables of the sd_notify protocol (sslfr_common.sdnotify)
NOTIFY_ENV = ('NOTIFY_SOCKET', 'WATCHDOG_USEC', 'WATCHDOG_PID')


@dataclass
class Program:
    """A supervised process."""

    name: str
    argv: list[str]
    start: int = 0
    stop: int = 1
    critical: bool = False
    lifecycle: bool = False
    restart: bool = True
    kind: str = 'node'            # 'node' or 'board' (simulated board)
    nodes: tuple = ()             # ROS nodes it runs (several: a composed process); () = (name,)
    lifecycle_nodes: tuple = ()   # its lifecycle nodes; () = (name,) when lifecycle
    # runtime state
    proc: subprocess.Popen | None = None
    started_at: float = 0.0
    failures: int = 0             # consecutive failures (backoff index)
    restarts: int = 0             # total restarts
    next_start: float | None = None
    held: bool = False            # killed on purpose (fault injection): no restart
    lifecycle_state: str = ''     # '', 'activating', 'active', 'failed'
    lifecycle_retry: float | None = None
    lifecycle_pending: set = field(default_factory=set)   # lifecycle nodes not yet active
    last_exit: int | None = None
    hang_cause: str = ''          # why the liveness watch killed it ('' = it was not)
    log_file: object = None
    history: list = field(default_factory=list)   # (monotonic, event, detail)

    @property
    def node_names(self) -> tuple:
        return self.nodes or (self.name,)

    @property
    def lifecycle_names(self) -> tuple:
        return self.lifecycle_nodes or ((self.name,) if self.lifecycle else ())

    @property
    def pid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None


def _journal_prefix(priority: int) -> str:
    """sd-daemon priority prefix when stderr goes to the journal (systemd)."""
    return f'<{priority}>' if os.environ.get('JOURNAL_STREAM') else ''


def stop_signal(p: 'Program') -> int:
    """The signal of the ordered stop for program ``p``: SIGINT (the ROS convention)
    once a node has installed its stop handlers - every node of the tracker handles
    SIGINT and SIGTERM alike from :func:`sslfr_common.node.run_node` on, so it catches
    SIGTERM from then - and SIGTERM while its interpreter is still starting: SIGINT
    there raises KeyboardInterrupt inside Python's own start-up ("Fatal Python error:
    init_import_site" and a traceback on the console), SIGTERM ends it quietly before
    it has opened anything. Simulated boards always get SIGINT."""
    if p.kind == 'node' and p.proc is not None and not catches(p.proc.pid, signal.SIGTERM):
        return signal.SIGTERM
    return signal.SIGINT


class Supervisor:
    """Start, watch, restart and stop a set of :class:`Program` (see module doc)."""

    def __init__(self, programs: list[Program], env: dict, *, backoff=(1.0, 2.0, 4.0, 8.0, 16.0, 30.0),
                 stable_after: float = 60.0, stop_timeout: float = 5.0, log_dir: Path | None = None,
                 out: TextIO | None = None, ros: 'RosSide | None' = None,
                 liveness: LivenessWatch | None = None, notifier: Notifier | None = None,
                 restart_wait: float = 0.0):
        names = [p.name for p in programs]
        if len(set(names)) != len(names):
            raise ValueError(f'duplicate program names: {names}')
        self.programs = {p.name: p for p in sorted(programs, key=lambda p: p.start)}
        self.env = env
        self.backoff = tuple(backoff)
        #: [s] shortest time from a node process's death to its restart (0: no wait)
        self.restart_wait = float(restart_wait)
        self.stable_after = stable_after
        self.stop_timeout = stop_timeout
        self.log_dir = Path(log_dir) if log_dir else None
        self.out = out or sys.stderr
        self.ros = ros
        self.stopping = False
        self.stop_took = 0.0   # [s] how long the ordered stop took
        self.fatal = ''        # why the set cannot run (a node refused its configuration)
        self.events: list[tuple[float, str, str, str]] = []   # (mono, program, event, detail)
        #: the executor-liveness watch of the node processes (None: not watched)
        self.liveness = liveness
        #: sd_notify towards this supervisor's own watcher (systemd); sends nothing without one
        self.notifier = notifier or Notifier(None)
        self.ready_sent = False
        self._notify_dir = self._listener = None
        if liveness is not None:
            self._notify_dir = tempfile.mkdtemp(prefix='sslfr-notify-')   # short: socket paths <= 107 bytes
            self._listener = NotifyListener(os.path.join(self._notify_dir, 'notify.sock'))

    # ------------------------------------------------------------------ reporting
    def say(self, text: str, priority: int = 6) -> None:
        self.out.write(f'{_journal_prefix(priority)}[sslfr up] {text}\n')
        self.out.flush()

    def _event(self, p: Program, event: str, detail: str = '') -> None:
        now = time.monotonic()
        self.events.append((now, p.name, event, detail))
        p.history.append((now, event, detail))
        if self.ros is not None:
            self.ros.note(p.name, event, detail, p.critical)

    # ------------------------------------------------------------------ processes
    def _spawn(self, p: Program) -> None:
        stdout = None
        if self.log_dir is not None:
            self.log_dir.mkdir(parents=True, exist_ok=True)
            if p.log_file is None:
                p.log_file = open(self.log_dir / f'{p.name}.log', 'ab')  # noqa: SIM115 - closed in close()
                for node in p.node_names:     # a composed process: each node's log is the process's
                    link = self.log_dir / f'{node}.log'
                    if node != p.name and not link.exists():
                        link.symlink_to(f'{p.name}.log')
            stdout = p.log_file
        watched = self._listener is not None and p.kind == 'node'
        env = {k: v for k, v in self.env.items() if k not in NOTIFY_ENV}   # never systemd's socket
        if watched:
            env.update(NOTIFY_SOCKET=self._listener.path, WATCHDOG_USEC=str(int(self.liveness.timeout * 1e6)))
        try:
            p.proc = subprocess.Popen(_orphan_guard(p.argv), env=env, stdout=stdout,
                                      stderr=subprocess.STDOUT if stdout else None,
                                      stdin=subprocess.DEVNULL, start_new_session=True)
        except OSError as exc:
            p.proc = None
            p.failures += 1
            p.next_start = time.monotonic() + self._delay(p)
            self.say(f'{p.name}: cannot start {p.argv[0]}: {exc}; retry in {self._delay(p):.0f} s', 3)
            self._event(p, 'spawn-failed', str(exc))
            return
        p.started_at = time.monotonic()
        p.next_start = None
        p.lifecycle_state = ''
        p.lifecycle_retry = None
        p.hang_cause = ''
        if watched:
            self.liveness.watch(p.name, p.started_at)
        self._event(p, 'started', f'pid {p.proc.pid}')
        if p.lifecycle:
            self._activate(p)

    def _delay(self, p: Program) -> float:
        delay = self.backoff[min(max(p.failures - 1, 0), len(self.backoff) - 1)]
        return max(delay, self.restart_wait) if p.kind == 'node' else delay

    def start(self) -> None:
        """Start every program in start order."""
        for p in self.programs.values():
            self._spawn(p)
        self.say('started ' + ', '.join(f'{p.name}[{p.pid}]' for p in self.programs.values()))

    def _activate(self, p: Program) -> None:
        if self.ros is None:
            return
        p.lifecycle_state = 'activating'
        p.lifecycle_pending = set(p.lifecycle_names)
        for name in p.lifecycle_names:
            self.ros.request_active(name)

    def program_of(self, node: str) -> Program | None:
        """The program running ROS node ``node`` (its own, or the composed one)."""
        return self.programs.get(node) or next(
            (p for p in self.programs.values() if node in p.node_names), None)

    def _check_liveness(self, now: float) -> None:
        """Take the node processes' beats; kill those past their bound (the exit is
        then handled as any other: restart with backoff)."""
        by_pid = {p.proc.pid: p for p in self.programs.values() if p.proc is not None and p.kind == 'node'}
        for n in self._listener.receive():
            p = by_pid.get(n.pid)
            if p is not None:
                first = self.liveness.beats(p.name) == 0
                if self.liveness.note(p.name, n.fields, now) and first and self.liveness.beats(p.name):
                    self._event(p, 'turning', f'first executor beat {now - p.started_at:.1f} s after its start')
        hung = []
        for late in self.liveness.overdue(now):
            p = self.programs[late.key]
            self.liveness.forget(p.name)
            if not p.alive() or p.held:
                continue
            p.hang_cause = late.cause
            # a process that has beaten runs run_nodes' stack dump handler: its threads'
            # stacks to its log first (a stopped process cannot write them)
            dump = not late.starting
            self.say(f'{p.name}: {late.cause}: ' + ('its stacks to its log, then ' if dump else '')
                     + 'killing it (SIGKILL) to restart it', 2 if p.critical else 3)
            self._event(p, 'hung', late.cause)          # when found (the dump takes up to 0.3 s)
            if dump:
                try:
                    os.kill(p.proc.pid, STACK_DUMP_SIGNAL)
                except ProcessLookupError:
                    pass
            hung.append(p)
        # the dumps of every process found in this pass written at once: one wait of at
        # most STACK_DUMP_WAIT for all (several hung at once are not killed one by one)
        deadline = time.monotonic() + STACK_DUMP_WAIT
        for p in hung:
            try:
                p.proc.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
        for p in hung:
            try:
                os.killpg(p.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        for p in hung:
            p.proc.wait(5)

    def node_set_ready(self) -> bool:
        """Every node process runs and (when watched) has beaten at least once."""
        nodes = [p for p in self.programs.values() if p.kind == 'node']
        return bool(nodes) and all(p.alive() and (self.liveness is None or self.liveness.beats(p.name) > 0)
                                   for p in nodes)

    def _notify_systemd(self) -> None:
        self.notifier.beat()
        if not self.ready_sent and self.node_set_ready():
            self.ready_sent = True
            n = sum(1 for p in self.programs.values() if p.kind == 'node')
            self.notifier.notify('READY=1', f'STATUS=node set up: {n} node processes, every executor turning')
            self.say(f'node set up: {n} node processes, every executor turning')

    def step(self) -> None:
        """One supervision pass: reap exits, schedule/perform restarts, lifecycle,
        executor liveness."""
        now = time.monotonic()
        if self._listener is not None and not self.stopping:
            self._check_liveness(now)
        if self.ros is not None:
            for name, ok, msg in self.ros.results():
                p = self.program_of(name)
                if p is None or not p.alive():
                    continue
                who = p.name if name == p.name else f'{p.name}/{name}'
                if ok:
                    p.lifecycle_pending.discard(name)
                    if not p.lifecycle_pending and p.lifecycle_state != 'failed':
                        p.lifecycle_state = 'active'
                    self._event(p, 'active', msg)
                    self.say(f'{who}: lifecycle active')
                else:
                    p.lifecycle_state = 'failed'
                    p.lifecycle_retry = now + 3.0
                    self._event(p, 'activate-failed', msg)
                    self.say(f'{who}: {msg}; checking again in 3 s', 4)
        for p in self.programs.values():
            if self.stopping:
                return
            if p.proc is not None and p.proc.poll() is not None and p.next_start is None and not p.held:
                code = p.proc.returncode
                p.last_exit = code
                up_for = now - p.started_at
                if up_for >= self.stable_after:
                    p.failures = 0
                p.failures += 1
                p.lifecycle_state = ''
                how = f'killed: {p.hang_cause}' if p.hang_cause else f'code {code}'
                self._event(p, 'exited', f'{how} after {up_for:.1f} s')
                if code == EXIT_CONFIG_REFUSED and p.kind == 'node':
                    p.next_start = float('inf')
                    self.fatal = f'{p.name} refused its configuration (exit code {code}): {self.last_error(p)}'
                    self.say(self.fatal, 2)
                    continue
                if not p.restart:
                    p.next_start = float('inf')
                    self.say(f'{p.name} exited (code {code}); not restarted', 3)
                    continue
                delay = self._delay(p)
                p.next_start = now + delay
                if p.critical:
                    self.say('*' * 72, 2)
                    self.say(f'*** CRITICAL: {p.name} DIED ({how if p.hang_cause else f"exit code {code}"}, '
                             f'up {up_for:.1f} s). '
                             f'Restart #{p.restarts + 1} in {delay:g} s. Until it is back the axis '
                             f'drivers see no safety heartbeat and stow/hold.', 2)
                    self.say('*' * 72, 2)
                else:
                    self.say(f'{p.name} exited ({how}, up {up_for:.1f} s); restart in {delay:g} s', 4)
            if p.next_start is not None and now >= p.next_start and not p.held:
                p.restarts += 1
                self._event(p, 'restart', f'#{p.restarts}')
                self._spawn(p)
                level = 2 if p.critical else 5
                self.say(f'{p.name} restarted (#{p.restarts}, pid {p.pid})', level)
            if (p.lifecycle and p.alive() and p.lifecycle_state == 'failed'
                    and p.lifecycle_retry is not None and now >= p.lifecycle_retry):
                self._activate(p)

    def last_error(self, p: Program) -> str:
        """The last line a program printed that looks like an error (its log file), or
        a pointer to its output."""
        if self.log_dir is None or not (self.log_dir / f'{p.name}.log').exists():
            return 'see its output above'
        if p.log_file is not None:
            p.log_file.flush()
        lines = [ln.strip() for ln in (self.log_dir / f'{p.name}.log').read_text(errors='replace').splitlines()
                 if ln.strip()]
        for ln in reversed(lines):
            if any(w in ln.lower() for w in ('error', 'invalid', 'refused', 'not starting', 'exception', 'fatal')):
                return ln
        return lines[-1] if lines else 'it printed nothing'

    # ------------------------------------------------------------------ fault injection
    def kill(self, name: str, hold: bool = True) -> None:
        """SIGKILL program ``name`` (a fault; a node name kills the process running it,
        all of a composed process); with ``hold`` it stays down until :meth:`release`,
        otherwise the normal restart policy applies."""
        p = self.program_of(name)
        if p is None:
            raise KeyError(name)
        p.held = hold
        if p.alive():
            os.killpg(p.proc.pid, signal.SIGKILL)
            p.proc.wait(5)
        self._event(p, 'killed', 'fault injection')
        self.say(f'{name} killed (fault injection){"; held down" if hold else ""}', 4)

    def hang(self, name: str) -> None:
        """SIGSTOP the process running node ``name`` (a fault: the process stops as if
        deadlocked; the liveness watch has to find and restart it)."""
        p = self.program_of(name)
        if p is None:
            raise KeyError(name)
        if not p.alive():
            raise RuntimeError(f'{p.name} is not running')
        os.killpg(p.proc.pid, signal.SIGSTOP)
        self._event(p, 'hang', 'fault injection: SIGSTOP')
        self.say(f'{p.name} stopped with SIGSTOP (fault injection: hang of {name})', 4)

    def release(self, name: str) -> None:
        """Let a held program start again now."""
        p = self.program_of(name)
        if p is None:
            raise KeyError(name)
        if p.held:
            p.held = False
            p.failures = 0
            p.next_start = time.monotonic()

    # ------------------------------------------------------------------ stop
    def stop(self) -> float:
        """Ordered stop (axes first, recorder last) within ``stop_timeout``; return the
        wall time it took [s]."""
        self.stopping = True
        self.notifier.notify('STOPPING=1')
        t0 = time.monotonic()
        deadline = t0 + self.stop_timeout - 0.4
        self._kill_stopped(self.programs.values())
        groups: dict[int, list[Program]] = {}
        for p in self.programs.values():
            groups.setdefault(p.stop, []).append(p)
        order = sorted(groups)
        for i, g in enumerate(order):
            progs = [p for p in groups[g] if p.alive()]
            lifecycle = [n for p in progs for n in p.lifecycle_names]     # active or about to be
            if lifecycle and self.ros is not None:
                # stop the motors through the drivers' own deactivate (bounded wait)
                self.ros.deactivate(lifecycle, timeout=min(1.0, max(0.1, deadline - time.monotonic() - 1.5)))
            for p in progs:
                try:
                    os.killpg(p.proc.pid, stop_signal(p))
                except ProcessLookupError:
                    pass
            # the first groups get a share, the last one what is left
            left = len(order) - i
            group_deadline = time.monotonic() + max(0.2, (deadline - time.monotonic()) / left * (1.5 if left > 1 else 1))
            group_deadline = min(group_deadline, deadline)
            while time.monotonic() < group_deadline and any(p.alive() for p in progs):
                time.sleep(0.02)
                self._kill_stopped(progs)
            for p in progs:
                if p.alive():
                    self.say(f'{p.name} did not stop on SIGINT in time: SIGTERM', 4)
                    try:
                        os.killpg(p.proc.pid, signal.SIGTERM)
                    except ProcessLookupError:
                        pass
        end = t0 + self.stop_timeout - 0.1
        while time.monotonic() < end and any(p.alive() for p in self.programs.values()):
            time.sleep(0.02)
        for p in self.programs.values():
            if p.alive():
                self._sigkill(p, 'still running', 3)
        took = time.monotonic() - t0
        for p in self.programs.values():
            if p.proc is not None:
                self._event(p, 'stopped', f'code {p.proc.returncode}')
        self.say(f'stopped in {took:.2f} s (axes first)')
        self.close()
        self.stop_took = took
        return took

    def _kill_stopped(self, progs) -> None:
        """SIGKILL (and reap) the stopped ones among ``progs``: a stopped process acts on
        no signal but SIGKILL (SIGINT and SIGTERM wait for a SIGCONT), so it is killed
        at once, not at the end of the stop budget."""
        for p in progs:
            if p.alive() and is_stopped(p.proc.pid):
                self._sigkill(p, 'is stopped (SIGSTOP)', 4)

    def _sigkill(self, p, why: str, level: int) -> None:
        """SIGKILL program ``p``'s process group, saying ``why``, and reap it (2 s at most)."""
        self.say(f'{p.name} {why}: SIGKILL', level)
        try:
            os.killpg(p.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        p.proc.wait(2)

    def close(self) -> None:
        for p in self.programs.values():
            if p.log_file is not None:
                p.log_file.close()
                p.log_file = None
        if self._listener is not None:
            self._listener.close()
            shutil.rmtree(self._notify_dir, ignore_errors=True)
            self._listener = None

    def rss(self, full: bool = False) -> dict[str, tuple[int, int]]:
        """Memory of every running program with its children: ``(rss, pss)`` [bytes].

        RSS counts the shared libraries (rclpy, DDS, numpy) once per process, so
        their sum overstates the total; PSS shares them out and sums to what the set
        really occupies. ``pss`` is 0 unless ``full`` (reading smaps is slower).
        """
        import psutil
        out = {}
        for p in self.programs.values():
            if not p.alive():
                continue
            try:
                root = psutil.Process(p.pid)
                rss = pss = 0
                for proc in [root, *root.children(recursive=True)]:
                    try:
                        if full:
                            info = proc.memory_full_info()
                            rss, pss = rss + info.rss, pss + getattr(info, 'pss', 0)
                        else:
                            rss += proc.memory_info().rss
                    except psutil.Error:
                        pass
                out[p.name] = (rss, pss)
            except psutil.Error:
                pass
        return out

    def pids(self) -> list[int]:
        return [p.pid for p in self.programs.values() if p.alive()]

    def run(self, stop: StopSignals, until: Callable[[], bool] | None = None,
            tick: Callable[[], None] | None = None, period: float = 0.05) -> str:
        """Supervise until a stop signal (``stop``), ``until()`` or a node that refused
        its configuration (:attr:`fatal`); then stop in order. ``tick()`` is called
        every pass (the simulation's fault timer). Returns why it stopped: 'signal',
        'until' or 'fatal'."""
        why = 'signal'
        try:
            if not any(p.proc is not None for p in self.programs.values()):
                self.start()
            while not stop.requested.is_set():
                self.step()
                self._notify_systemd()
                if self.fatal:
                    why = 'fatal'
                    break
                if tick is not None:
                    tick()
                if until is not None and until():
                    why = 'until'
                    break
                stop.requested.wait(period)
        finally:
            if not self.stopping:
                self.stop()
        return why


# ---------------------------------------------------------------------------------
class RosSide(threading.Thread):
    """The supervisor's rclpy side, in one thread owning its own context.

    - lifecycle: watches requested nodes until ``active`` (results via
      :meth:`results`; ``lifecycle_ctl.ActiveWatch``), deactivates the axes at stop;
    - ``diagnostics``: one DiagnosticStatus per supervised process at 1 Hz, ERROR after
      a critical program's restart (so the monitoring laptop sees it too);
    - optional ``/clock`` (simulation): ``clock_fn()`` -> sim time [s since epoch],
      published every ``1/clock_rate`` wall seconds on a steady timer.
    """

    #: [s] shutdown's waits: the thread's own end, the context's shutdown, the end after it
    SHUTDOWN_BOUNDS = (1.0, 5.0, 10.0)

    def __init__(self, domain_id: int, namespace: str = '', clock_fn: Callable[[], float | None] | None = None,
                 clock_rate: float = 20.0, node_name: str = 'sslfr_supervisor', watch: dict | None = None):
        super().__init__(daemon=True, name='ros-side')
        self.domain_id = domain_id
        self.namespace = namespace
        self.node_name = node_name
        self.clock_fn = clock_fn
        self.clock_rate = clock_rate
        self._jobs: queue.Queue = queue.Queue()
        self._results: queue.Queue = queue.Queue()
        self._notes: queue.Queue = queue.Queue()
        self._halt = threading.Event()
        self.ready = threading.Event()
        self.error: BaseException | None = None
        self.clock_published = 0
        self.watch = dict(watch or {})          # topic -> message type: count arrivals
        self.seen: dict[str, int] = {}
        self.last: dict[str, object] = {}      # topic -> its last message
        self.graph_nodes: set[str] = set()      # node names in the ROS graph (refreshed ~2 Hz)
        self._ctx = None

    # called from the supervisor thread
    def _heard(self, topic: str, msg) -> None:
        self.seen[topic] = self.seen.get(topic, 0) + 1
        self.last[topic] = msg

    def wait_ready(self, stop: StopSignals, tick: Callable[[], None] | None = None) -> str | None:
        """Wait (started thread) until the ROS side is ready: None, or why it failed.
        ``tick()`` is called every 0.05 s meanwhile (the supervisor's own beat)."""
        while not self.ready.is_set() and self.is_alive():
            if tick is not None:
                tick()
            stop.wait(0.05)
        if self.error is not None or not self.ready.is_set():
            return str(self.error or 'its thread ended before it was ready')
        return None

    def request_active(self, name: str) -> None:
        self._jobs.put(('active', name))

    def results(self) -> list[tuple[str, bool, str]]:
        out = []
        while True:
            try:
                out.append(self._results.get_nowait())
            except queue.Empty:
                return out

    def note(self, name: str, event: str, detail: str, critical: bool) -> None:
        self._notes.put((name, event, detail, critical))

    def trigger(self, service: str, timeout: float) -> tuple[bool, str]:
        """Call the std_srvs/Trigger ``service`` (waiting for it within ``timeout`` [s]):
        (success, message); (False, why) when it was not answered in time."""
        done, answer = threading.Event(), []
        self._jobs.put(('trigger', (service, timeout, answer, done)))
        done.wait(timeout + 0.5)
        return tuple(answer[0]) if answer else (False, f'{service}: no answer within {timeout:g} s')

    def deactivate(self, names: list[str], timeout: float) -> None:
        done = threading.Event()
        self._jobs.put(('deactivate', (names, timeout, done)))
        done.wait(timeout + 0.5)

    def shutdown(self) -> bool:
        """End the thread (idempotent); True when it has ended. A lifecycle call under
        way (up to 20 s) is cut short by shutting its context down. Bounded: at most
        about 16 s, whatever rclpy does (the context's shutdown runs in a helper thread,
        so a shutdown that blocks cannot block the caller). A thread still running then
        is left to :func:`exit_if_stuck`, so the interpreter never tears down under a
        running rclpy thread (which aborts or hangs it)."""
        self._halt.set()
        if not self.is_alive():
            return True
        self.join(self.SHUTDOWN_BOUNDS[0])
        if self.is_alive() and self._ctx is not None:
            import rclpy
            helper = threading.Thread(target=rclpy.try_shutdown, kwargs={'context': self._ctx},
                                      daemon=True, name='ros-side-shutdown')
            helper.start()
            helper.join(self.SHUTDOWN_BOUNDS[1])
        self.join(self.SHUTDOWN_BOUNDS[2])
        if self.is_alive():
            _STUCK.append(self)
            return False
        return True

    # the thread
    def run(self) -> None:
        try:
            self._run()
        except BaseException as exc:  # noqa: BLE001 - reported to the supervisor, never a silent death
            if self.error is None:
                self.error = exc
        finally:
            self.ready.set()            # whoever waits for it is released, ready or failed

    def _run(self) -> None:  # noqa: C901 - one loop owning every rclpy object
        # a failure setting up ends the thread through run(): error set, waiters released
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
        from lifecycle_msgs.msg import Transition
        from sslfr_common.contract import collector_id
        from lifecycle_msgs.srv import ChangeState
        from rclpy.clock import Clock, ClockType
        from rclpy.executors import SingleThreadedExecutor
        from sslfr_common.node import qos
        from sslfr_drivers.axis.lifecycle_ctl import ActiveWatch

        ctx = self._ctx = rclpy.Context()
        from sslfr_common.contract import namespace_remaps
        remap = [a for src, dst in namespace_remaps(self.namespace).items() for a in ('-r', f'{src}:={dst}')]
        rclpy.init(context=ctx, domain_id=self.domain_id,
                   args=['sslfr_supervisor', *(['--ros-args', *remap] if remap else [])])
        node = rclpy.create_node(self.node_name, namespace=self.namespace or None, context=ctx)
        executor = SingleThreadedExecutor(context=ctx)
        executor.add_node(node)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        status: dict[str, dict] = {}
        clients: dict = {}
        diag_pub = node.create_publisher(DiagnosticArray, DIAGNOSTICS.name, qos(DIAGNOSTICS))

        def publish_diag():
            while True:
                try:
                    name, event, detail, critical = self._notes.get_nowait()
                except queue.Empty:
                    break
                s = status.setdefault(name, {'restarts': 0, 'critical': critical, 'event': '', 'detail': ''})
                s['event'], s['detail'] = event, detail
                if event == 'restart':
                    s['restarts'] += 1
                if event in ('hung', 'exited', 'killed'):
                    s['cause'] = f'{event} {detail}'.strip()   # why it went, kept past the restart
            arr = DiagnosticArray()
            arr.header.stamp = node.get_clock().now().to_msg()
            for name, s in sorted(status.items()):
                level = DiagnosticStatus.OK
                if s['event'] in ('exited', 'killed', 'hung', 'hang', 'spawn-failed', 'activate-failed'):
                    level = DiagnosticStatus.ERROR if s['critical'] else DiagnosticStatus.WARN
                elif s['restarts'] and s['critical']:
                    level = DiagnosticStatus.ERROR
                elif s['restarts']:
                    level = DiagnosticStatus.WARN
                msg = f"{s['event']} {s['detail']}".strip()
                if s['restarts'] and s.get('cause') and s['event'] not in ('hung', 'exited', 'killed'):
                    msg += f"; restarted after: {s['cause']}"
                if s['restarts'] and s['critical']:
                    msg = f"CRITICAL process restarted {s['restarts']}x; last: {msg}"
                arr.status.append(DiagnosticStatus(
                    level=level, name=f'sslfr_supervisor: {name}', message=msg, hardware_id=collector_id(self.namespace),
                    values=[KeyValue(key='restarts', value=str(s['restarts'])),
                            KeyValue(key='critical', value=str(s['critical']).lower())]))
            diag_pub.publish(arr)

        node.create_timer(1.0, publish_diag, clock=steady)

        def refresh_graph():
            self.graph_nodes = set(node.get_node_names())
        node.create_timer(0.5, refresh_graph, clock=steady)
        for topic, msg_type in self.watch.items():
            node.create_subscription(msg_type, topic, lambda m, t=topic: self._heard(t, m), 10)
        if self.clock_fn is not None:
            from rosgraph_msgs.msg import Clock as ClockMsg
            from sslfr_common.timeconv import stamp

            clock_pub = node.create_publisher(ClockMsg, CLOCK.name, qos(CLOCK))

            def publish_clock():
                t = self.clock_fn()
                if t is None:   # clock held back: nothing published yet
                    return
                clock_pub.publish(ClockMsg(clock=stamp(t)))
                self.clock_published += 1

            node.create_timer(1.0 / self.clock_rate, publish_clock, clock=steady)
        watch = ActiveWatch(node, timeout=20.0)
        self.ready.set()
        try:
            while not self._halt.is_set() and ctx.ok():
                for result in watch.poll():
                    self._results.put(result)
                try:
                    kind, arg = self._jobs.get_nowait()
                except queue.Empty:
                    executor.spin_once(timeout_sec=0.02)
                    continue
                if kind == 'trigger':
                    from std_srvs.srv import Trigger
                    service, timeout, answer, done = arg
                    deadline = time.monotonic() + timeout
                    client, future = node.create_client(Trigger, service), None
                    while time.monotonic() < deadline and not (future and future.done()):
                        if future is None and client.service_is_ready():
                            future = client.call_async(Trigger.Request())
                        executor.spin_once(timeout_sec=0.02)
                    if future is not None and future.done() and future.result() is not None:
                        answer.append((bool(future.result().success), str(future.result().message)))
                    node.destroy_client(client)
                    done.set()
                    continue
                if kind == 'active':
                    if arg not in clients:  # kept for a quick deactivate at stop
                        clients[arg] = node.create_client(ChangeState, f'{arg}/change_state')
                    watch.add(arg)
                elif kind == 'deactivate':
                    names, timeout, done = arg
                    deadline = time.monotonic() + timeout
                    futures, waiting = [], list(names)
                    # a service not discovered yet (a process that just started, or one
                    # with many nodes) is waited for within the deadline, never skipped
                    while time.monotonic() < deadline:
                        for name in list(waiting):
                            client = clients.get(name)
                            if client is None:
                                client = clients[name] = node.create_client(ChangeState, f'{name}/change_state')
                            if client.service_is_ready():
                                req = ChangeState.Request()
                                req.transition.id = Transition.TRANSITION_DEACTIVATE
                                futures.append(client.call_async(req))
                                waiting.remove(name)
                        if not waiting and all(f.done() for f in futures):
                            break
                        executor.spin_once(timeout_sec=0.02)
                    done.set()
        except BaseException as exc:  # noqa: BLE001
            if not self._halt.is_set():
                self.error = exc
        finally:
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=ctx)


#: RosSide threads that did not end within their shutdown's bound
_STUCK: list[RosSide] = []


def exit_if_stuck(code: int, prog: str) -> None:
    """After a command's work is done (bags closed, summary written): when a RosSide
    thread did not end, say so and leave at once with ``code`` instead of tearing the
    interpreter down under a running rclpy thread."""
    if any(t.is_alive() for t in _STUCK):
        print(f'{prog}: the ROS side did not end within 16 s of the stop: leaving without '
              f'interpreter teardown (exit {code})', file=sys.stderr)
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
