"""Local endpoints of a helper process (no rclpy): a raw pty a host opens as its serial
port (with a stable symlink, unplug and re-plug), a UNIX control socket answering one
command per line, and the serve-until-SIGTERM loop.

Used by the production tool ``xbee_hub`` (one pty per remote board) and by the
simulated boards (``sim_board``, :mod:`sslfr_sim.runner`); production code
imports them from here, never from the simulators.
"""
from __future__ import annotations

import os
import signal
import socket
import termios
import tty


def open_pty() -> tuple[int, int, str]:
    """Open a raw pty pair: (master fd non-blocking, slave fd, slave path). The
    runner keeps the slave open itself so a host closing its side is harmless."""
    master, slave = os.openpty()
    tty.setraw(slave)
    attrs = termios.tcgetattr(slave)
    attrs[3] &= ~termios.ECHO
    termios.tcsetattr(slave, termios.TCSANOW, attrs)
    os.set_blocking(master, False)
    return master, slave, os.ttyname(slave)


def listen_control(path: str) -> socket.socket:
    """A non-blocking UNIX stream socket listening at ``path`` (a stale socket file
    there is replaced): the ``--control`` socket of ``sim_board`` and ``xbee_hub``."""
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.bind(path)
    sock.listen(4)
    sock.setblocking(False)
    return sock


def close_control(sock: socket.socket | None, path: str | None) -> None:
    """Close a :func:`listen_control` socket and remove its file."""
    if sock is None:
        return
    sock.close()
    try:
        os.unlink(path)
    except OSError:
        pass


def serve_until_signalled(server) -> int:
    """Run ``server.serve()`` until SIGTERM or SIGINT clears ``server.running``,
    then ``server.close()``; returns the exit status 0."""
    def _stop(*_):
        server.running = False

    signal.signal(signal.SIGTERM, _stop)
    signal.signal(signal.SIGINT, _stop)
    try:
        server.serve()
    finally:
        server.close()
    return 0


class PtyEndpoint:
    """A pty the host connects to, with optional stable symlink and unplug."""

    def __init__(self, link: str | None = None, path_file: str | None = None,
                 announce=None):
        self.link = link
        self.path_file = path_file
        self.announce = announce or (lambda path: None)
        self.master = self.slave = -1
        self.path = ''
        self.unplugged_until = 0.0
        self.bytes_unwritable = 0
        self.plug()

    def plug(self) -> None:
        """Open a new pty, point the symlink and the path file at it, announce it."""
        self.master, self.slave, self.path = open_pty()
        if self.link:
            tmp = f'{self.link}.tmp{os.getpid()}'
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass
            os.symlink(self.path, tmp)
            os.replace(tmp, self.link)
        if self.path_file:
            with open(self.path_file + '.tmp', 'w') as fh:
                fh.write(self.path + '\n')
            os.replace(self.path_file + '.tmp', self.path_file)
        self.announce(self.path)

    def unplug(self, seconds: float, now: float) -> None:
        """Close the pty and remove the symlink; the runner plugs a new one at
        ``now + seconds`` [s, monotonic]."""
        if self.link:
            try:
                os.unlink(self.link)
            except FileNotFoundError:
                pass
        for fd in (self.master, self.slave):
            if fd >= 0:
                os.close(fd)
        self.master = self.slave = -1
        self.unplugged_until = now + seconds

    @property
    def plugged(self) -> bool:
        """True while a pty is open."""
        return self.master >= 0

    def read(self) -> bytes:
        """Bytes the host wrote (b'' when none; never blocks)."""
        try:
            return os.read(self.master, 4096)
        except (BlockingIOError, InterruptedError):
            return b''
        except OSError:   # EIO: no slave open (cannot happen: we hold the slave)
            return b''

    def write(self, data: bytes) -> None:
        """Send ``data`` to the host; bytes the pty cannot take now are dropped and
        counted in ``bytes_unwritable``."""
        if not data or not self.plugged:
            return
        try:
            n = os.write(self.master, data)
            self.bytes_unwritable += len(data) - n
        except (BlockingIOError, OSError):
            self.bytes_unwritable += len(data)

    def close(self) -> None:
        """Close the pty and remove the symlink."""
        self.unplug(0, 0)
