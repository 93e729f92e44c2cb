"""``liveness_watchdog``: the executor-liveness watch of a node set started by
``ros2 launch`` (launch/tracker.launch.py starts it as one more process of the launch).

Launch restarts a process only when it exits (``respawn=True``). This process binds
the ``NOTIFY_SOCKET`` that the launch file gives every node process (with
``WATCHDOG_USEC``); each node process beats ``WATCHDOG=1`` from its spin loop
(:func:`sslfr_common.node.run_nodes`) and is told apart by the pid the kernel attaches
to its datagrams. A process is watched from its first message (launch starts the
processes, so their pids are learnt, not given); when its beats stop for longer than
``--timeout`` it is killed with SIGKILL (a stopped or deadlocked process does not act
on SIGTERM), which launch sees as an exit and respawns. The kill is printed with the
cause and the node names the process reported (``STATUS=``, else those on its
command line: a respawned watchdog hears no ``STATUS=``). ``STOPPING=1`` (an
orderly stop) ends the watch of a process; so does its exit.

Pure core: :class:`sslfr_bringup.liveness.LivenessWatch`. Plain Python, no rclpy.
"""
from __future__ import annotations

import argparse
import os
import select
import signal
import sys
import time

from sslfr_common.sdnotify import NotifyListener

from sslfr_bringup.liveness import DEFAULT_TIMEOUT, STARTUP_RANGE, TIMEOUT_RANGE, LivenessWatch

PROG = 'sslfr watchdog'


def node_names(pid: int) -> str:
    """The node names on the process's command line (its ``-r __node:=NAME`` remaps:
    one for a single node, several for a composed process), comma-separated; '' when
    none or the process is gone. Used when the process's ``STATUS=`` (sent once, at
    its start) was not heard: a watchdog respawned by launch learns the running
    processes from their next beat, which carries no names."""
    try:
        with open(f'/proc/{pid}/cmdline', 'rb') as f:
            argv = f.read().decode(errors='replace').split('\0')
    except OSError:
        return ''
    names = [a.partition('__node:=')[2] for a in argv if '__node:=' in a]
    return ', '.join(dict.fromkeys(n for n in names if n))


def start_time(pid: int) -> int | None:
    """The process's start time [clock ticks since boot] (/proc/PID/stat field 22): a
    pid reused by another process has another one. None when the process is gone."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            return int(f.read().rsplit(')', 1)[1].split()[19])
    except (OSError, IndexError, ValueError):
        return None


class PidWatch:
    """:class:`LivenessWatch` over pids learnt from their first message; kills the
    overdue ones (see the module docstring). ``kill`` and ``now`` are injectable."""

    def __init__(self, timeout: float, out=None, kill=os.kill, now=time.monotonic):
        self.watch = LivenessWatch(timeout, STARTUP_RANGE[1])   # adopted at a beat: never "starting"
        self.out = out or sys.stderr
        self._kill = kill
        self._now = now
        self._start: dict[int, int] = {}
        self._names: dict[int, str] = {}                   # from the command line (node_names)
        self.killed: list[tuple[int, str, str]] = []       # (pid, names, cause)

    def say(self, text: str) -> None:
        self.out.write(f'[{PROG}] {text}\n')
        self.out.flush()

    def take(self, notifications) -> None:
        now = self._now()
        for n in notifications:
            if not self.watch.watching(n.pid):
                started = start_time(n.pid)
                if n.fields.get('STOPPING') == '1' or started is None:   # stopping, or gone already
                    continue
                self.watch.watch(n.pid, now)
                self._start[n.pid] = started
                self._names[n.pid] = node_names(n.pid)
                status = n.fields.get('STATUS') or (f'nodes {self._names[n.pid]}' if self._names[n.pid]
                                                    else 'no status')
                self.say(f'watching pid {n.pid} ({status})')
            self.watch.note(n.pid, n.fields, now)
            if not self.watch.watching(n.pid):
                self._start.pop(n.pid, None)                   # STOPPING=1
                self._names.pop(n.pid, None)

    def check(self) -> None:
        """Forget processes that are gone; kill the overdue ones."""
        for pid in list(self._start):
            if start_time(pid) != self._start[pid]:          # exited (None) or pid reused
                self.watch.forget(pid)
                del self._start[pid]
                self._names.pop(pid, None)
        for late in self.watch.overdue(self._now()):
            pid = late.key
            names = late.status.removeprefix('executor turning: ') or self._names.get(pid) or 'unknown nodes'
            self.watch.forget(pid)
            self._start.pop(pid, None)
            self._names.pop(pid, None)
            try:
                self._kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                continue
            self.killed.append((pid, names, late.cause))
            self.say(f'{names} (pid {pid}): {late.cause}: killed (SIGKILL); launch respawns it')


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='liveness_watchdog', description=__doc__.split('\n\n')[0])
    p.add_argument('--socket', required=True, help='the NOTIFY_SOCKET path the node processes were given')
    p.add_argument('--timeout', type=float, default=DEFAULT_TIMEOUT,
                   help=f'longest silence of a process\'s executor [s], {TIMEOUT_RANGE[0]:g}..{TIMEOUT_RANGE[1]:g} '
                        f'(default {DEFAULT_TIMEOUT:g}; the launch file passes the node set\'s watchdog_timeout)')
    return p


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if '--ros-args' in argv:                      # launch_ros may append them: not ours
        argv = argv[:argv.index('--ros-args')]
    args = parser().parse_args(argv)
    if not TIMEOUT_RANGE[0] <= args.timeout <= TIMEOUT_RANGE[1]:
        print(f'{PROG}: --timeout {args.timeout:g} s outside {TIMEOUT_RANGE[0]:g}..{TIMEOUT_RANGE[1]:g} s',
              file=sys.stderr)
        return 2
    stop = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda s, f: stop.append(s))
    try:
        listener = NotifyListener(args.socket)
    except OSError as exc:
        print(f'{PROG}: cannot bind {args.socket}: {exc}', file=sys.stderr)
        return 1
    watch = PidWatch(args.timeout)
    watch.say(f'listening on {args.socket}; a node process silent for {args.timeout:g} s is killed')
    try:
        while not stop:
            try:
                select.select([listener], [], [], 0.25)
            except InterruptedError:
                pass
            watch.take(listener.receive())
            watch.check()
    finally:
        listener.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
