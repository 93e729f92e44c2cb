"""``xbee_hub``: one process owns the XBee coordinator UART and gives every remote
board its own local pty (pure Python, no rclpy).

Several driver processes (three ``axis_driver`` instances, the sensor nodes) cannot
open one serial port. The hub opens the local XBee (802.15.4, API mode AP=2) through
:class:`~sslfr_drivers.link.transport.XBeeCoordinator` and, for each remote board
``ADDR=PATH``, creates a raw pty and a symlink ``PATH`` to it. Each driver then uses
``PATH`` as an ordinary serial port (``SerialTransport``), exactly as with a
USB-connected board or a ``sim_board`` pty:

* bytes a driver writes to its pty are deframed; every complete valid frame is sent to
  that board's 64-bit address as one TX64 packet and its TX status checked (failures
  counted per board; the driver's link sees the missing answer and retries);
* data received from a board (RX64) is written to that board's pty as is.

If the coordinator UART disappears, the hub reopens it with the link's back-off
(:class:`~sslfr_drivers.link.reader.Backoff`: 0.1 s doubling to 2 s) while the ptys
stay up. ``--control PATH`` answers ``status`` (per-board
counters, JSON) like ``sim_board``.

Example (three axis boards behind one coordinator)::

    xbee_hub --port /dev/ttyUSB0 --baud 9600 \\
        --board 0013A20040A1B2C3=/run/sslfr/mirrors \\
        --board 0013A20040A1B2C4=/run/sslfr/mobile_structure \\
        --board 0013A20040A1B2C5=/run/sslfr/secondary_reflector
"""
from __future__ import annotations

import argparse
import json
import queue
import selectors
import sys
import threading
import time

from sslfr_drivers.link.endpoint import PtyEndpoint, close_control, listen_control, serve_until_signalled
from sslfr_drivers.link.protocol import Framer, encode_frame
from sslfr_drivers.link.reader import Backoff
from sslfr_drivers.link.transport import TransmitError, TransportError, XBeeBoardTransport, XBeeCoordinator


class _Board:
    def __init__(self, hub: 'XBeeHub', address: str, link: str):
        self.address = address.upper()
        self.endpoint = PtyEndpoint(link)
        self.transport = XBeeBoardTransport(hub.coordinator, address)
        self.transport._deliver = self._from_radio          # RX64 data -> our pty
        self.framer = Framer()
        self.queue: queue.Queue[bytes] = queue.Queue(maxsize=64)
        self.frames_sent = 0
        self.tx_failures = 0
        self.frames_dropped = 0
        self.bytes_received = 0

    def _from_radio(self, data: bytes) -> None:
        self.bytes_received += len(data)
        self.endpoint.write(data)

    def status(self) -> dict:
        return {'address': self.address, 'path': self.endpoint.path,
                'link': self.endpoint.link, 'frames_sent': self.frames_sent,
                'tx_failures': self.tx_failures, 'frames_dropped': self.frames_dropped,
                'bytes_received': self.bytes_received,
                'crc_errors': self.framer.crc_errors}


class XBeeHub:
    """See module docstring. ``boards``: {64-bit address hex: symlink path}."""

    def __init__(self, port: str, boards: dict[str, str], baudrate: int = 9600,
                 control: str | None = None):
        self.coordinator = XBeeCoordinator(port, baudrate)
        self.boards = [_Board(self, a, p) for a, p in boards.items()]
        self.running = True
        self.coordinator_opens = 0
        self.last_error = ''
        self.sel = selectors.DefaultSelector()
        for b in self.boards:
            self.sel.register(b.endpoint.master, selectors.EVENT_READ, b)
        self.control_path = control
        self._ctl = None
        if control:
            self._ctl = listen_control(control)
            self.sel.register(self._ctl, selectors.EVENT_READ, 'control')
        self._senders = [threading.Thread(target=self._sender, args=(b,), daemon=True,
                                          name=f'xbee-tx-{b.address}') for b in self.boards]
        self._radio = threading.Thread(target=self._keep_radio, daemon=True, name='xbee-radio')

    def status(self) -> dict:
        """The ``status`` control reply: coordinator state and counters, per-board counters."""
        c = self.coordinator
        return {'ok': True, 'port': c.port, 'open': c.is_open, 'opens': self.coordinator_opens,
                'tx_ok': c.tx_ok, 'tx_failures': c.tx_failures, 'rx_frames': c.rx_frames,
                'rx_unknown': c.rx_unknown, 'last_error': self.last_error,
                'boards': [b.status() for b in self.boards]}

    def _keep_radio(self) -> None:
        backoff = Backoff()
        while self.running:
            if not self.coordinator.is_open:
                try:
                    self.coordinator.open()
                    for b in self.boards:
                        self.coordinator.attach(b.transport)
                        b.transport._open = True
                    self.coordinator_opens += 1
                    backoff.reset()
                except TransportError as exc:
                    self.last_error = str(exc)
                    time.sleep(backoff.next())
                    continue
            time.sleep(0.2)

    def _sender(self, board: _Board) -> None:
        while self.running:
            try:
                data = board.queue.get(timeout=0.2)
            except queue.Empty:
                continue
            try:
                self.coordinator.send(board.transport.address, data)
                board.frames_sent += 1
            except TransmitError as exc:
                board.tx_failures += 1
                self.last_error = str(exc)
            except TransportError as exc:
                board.frames_dropped += 1
                self.last_error = str(exc)

    def step(self, timeout: float = 0.05) -> None:
        """One select round of at most ``timeout`` [s]: frames from the ptys go to
        the per-board send queues; a control connection gets its reply."""
        for key, _ in self.sel.select(timeout):
            if key.data == 'control':
                conn, _ = self._ctl.accept()
                with conn:
                    conn.settimeout(2)
                    try:
                        line = conn.recv(4096).decode().strip()
                        reply = self.status() if line == 'status' else \
                            {'ok': False, 'error': f'unknown command {line!r}'}
                        if line == 'quit':
                            self.running, reply = False, {'ok': True}
                        conn.sendall((json.dumps(reply) + '\n').encode())
                    except OSError:
                        pass
                continue
            board: _Board = key.data
            data = board.endpoint.read()
            for frame in board.framer.feed(data):
                try:
                    board.queue.put_nowait(encode_frame(frame))
                except queue.Full:
                    board.frames_dropped += 1

    def serve(self) -> None:
        """Start the radio and sender threads and step until ``running`` is cleared."""
        self._radio.start()
        for t in self._senders:
            t.start()
        while self.running:
            self.step()

    def close(self) -> None:
        """Stop, close the ptys (removing their symlinks), the coordinator and the
        control socket."""
        self.running = False
        for b in self.boards:
            b.endpoint.close()   # also removes the board's symlink
        self.coordinator.close()
        close_control(self._ctl, self.control_path)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``xbee_hub``; exit status 0, 2 on bad arguments."""
    p = argparse.ArgumentParser(prog='xbee_hub', description=__doc__.split('\n')[0])
    p.add_argument('--port', required=True, help='serial device of the coordinator XBee')
    p.add_argument('--baud', type=int, default=9600, help='coordinator UART speed [bit/s]')
    p.add_argument('--board', action='append', required=True, metavar='ADDR=PATH',
                   help='remote board 64-bit address (16 hex digits) and its pty symlink')
    p.add_argument('--control', help='UNIX socket answering "status"')
    args = p.parse_args(argv)
    boards = {}
    for spec in args.board:
        addr, sep, path = spec.partition('=')
        if not sep or len(addr) != 16:
            p.error(f'--board {spec!r}: expected ADDR=PATH with a 16-hex-digit address')
        boards[addr] = path
    hub = XBeeHub(args.port, boards, args.baud, args.control)
    for b in hub.boards:
        print(f'HUB_PTY {b.address} {b.endpoint.path} {b.endpoint.link}', flush=True)
    return serve_until_signalled(hub)


if __name__ == '__main__':
    sys.exit(main())
