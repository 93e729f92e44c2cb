"""A transparent serial tap between a driver and a simulated board, in a process of
its own: ``python tests/wiretap.py BOARD_PTY``.

It opens a pty pair, prints the slave's name (the port the driver opens) on its first
line, forwards every byte both ways and decodes the host -> board frames
(protocol.Framer). Each decoded message is one stdout line
``<monotonic s> <wall s> <message type> <steps or ->``: CLOCK_MONOTONIC is the same
in every process, the wall time compares with a message's ROS stamp.

Why a process: a tap thread inside the test process shares its GIL, and a garbage
collection of a large test process late in a run stalled every tap for seconds
(frames to and from the boards held back, the drivers' links "silent").
:class:`WireTap` is the test side: it starts the tap and collects its lines.
"""
from __future__ import annotations

import os
import select
import subprocess
import sys
import threading
import time
import tty


def _forward(src: int, dst: int) -> bytes:
    """Move what ``src`` holds to ``dst``; return it (b'' when nothing)."""
    try:
        data = os.read(src, 4096)
    except (BlockingIOError, OSError):
        return b''
    view = memoryview(data)
    while view:
        try:
            n = os.write(dst, view)
        except BlockingIOError:
            time.sleep(0.001)
            continue
        view = view[n:]
    return data


def serve(board_path: str) -> None:
    """The tap's loop (the child process): until stdin closes."""
    from sslfr_drivers.link import messages, protocol
    master, slave = os.openpty()
    tty.setraw(slave)
    board = os.open(board_path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    tty.setraw(board)
    os.set_blocking(master, False)
    framer = protocol.Framer()
    out = sys.stdout
    out.write(os.ttyname(slave) + '\n')
    out.flush()
    stdin = sys.stdin.fileno()
    while True:
        ready, _, _ = select.select([master, board, stdin], [], [], 1.0)
        if stdin in ready and not os.read(stdin, 1):
            return                                   # the test closed our stdin: done
        if board in ready:
            _forward(board, master)
        if master in ready:
            data = _forward(master, board)
            mono, wall = time.monotonic(), time.time()
            for frame in framer.feed(data):
                try:
                    msg = messages.decode(frame)
                except protocol.ProtocolError:
                    continue
                out.write(f'{mono:.6f} {wall:.6f} {type(msg).__name__} {getattr(msg, "steps", "-")}\n')
            out.flush()


class WireTap:
    """The test side of a tap on ``board_path``: ``port`` for the driver, the decoded
    host -> board messages in :attr:`events` as ``(monotonic, wall, type, steps)``."""

    def __init__(self, board_path: str, env: dict | None = None):
        self.proc = subprocess.Popen([sys.executable, __file__, board_path], env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.port = self.proc.stdout.readline().strip()
        if not self.port:
            raise RuntimeError(f'wire tap on {board_path} did not start (exit {self.proc.poll()})')
        self.events: list[tuple[float, float, str, int | None]] = []
        self._thread = threading.Thread(target=self._collect, daemon=True)
        self._thread.start()

    def _collect(self) -> None:
        for line in self.proc.stdout:
            mono, wall, kind, steps = line.split()
            self.events.append((float(mono), float(wall), kind, None if steps == '-' else int(steps)))

    def moves(self, since: float = 0.0):
        """[(monotonic t, steps)] of MOVE_TO frames sent after monotonic ``since``."""
        return [(t, s) for t, _, k, s in list(self.events) if t >= since and k == 'MoveTo']

    def stops(self, since: float = 0.0):
        """Monotonic times of STOP frames sent after monotonic ``since``."""
        return [t for t, _, k, _ in list(self.events) if t >= since and k == 'Stop']

    def stops_wall(self, since: float):
        """Wall times [s since the epoch] of STOP frames sent after wall ``since``."""
        return [w for _, w, k, _ in list(self.events) if w >= since and k == 'Stop']

    def close(self) -> None:
        try:
            self.proc.stdin.close()
            self.proc.wait(5)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait(5)
        self._thread.join(2)


if __name__ == '__main__':
    serve(sys.argv[1])
