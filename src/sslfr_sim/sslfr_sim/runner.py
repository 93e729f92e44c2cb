"""``sim_board``: run simulated boards as their own process on a real pty.

Two wirings:

* plain (default): one board on one pty, the host opens the pty slave path with
  pyserial (``SerialTransport``), exactly as it would open ``/dev/ttyUSB0``;
* ``--xbee``: a simulated XBee 802.15.4 coordinator (API mode AP=2, escaped) on one
  pty with several remote boards behind it, each with its 64-bit address
  (``--board KIND[:AXIS]@ADDR``, repeatable). The host uses digi-xbee
  (``xbee:<pty>?addr=<ADDR>`` ports).

The slave path is printed on stdout as ``SIM_PTY <path>`` (one line, flushed; again
after every ``unplug``), written to ``--path-file`` and, with ``--link PATH``,
published as a symlink (like /dev/serial/by-id; it disappears while unplugged).

Run-time fault injection through a UNIX socket (``--control PATH``): one text line
per command, one JSON line back. Commands (``@ADDR`` or ``@INDEX`` selects one board
of an XBee sim, default all)::

    status                  board states, counters
    drop P | corrupt P      byte drop / bit-flip probability, both directions
    corrupt_frames P        probability that a board->host frame gets one bit flipped
    disconnect S            radio cut: nothing passes either way for S seconds
    unplug S                close the pty for S seconds (port disappears), then a new one
    stall on|off            steps are counted but the joint does not move
    reset                   power-cycle the board (position lost, BOOT sent)
    set_angle DEG           move the joint by hand (board not told) [deg]
    anchor T                start a sensor board's held clock (``anchor=hold``): simulated
                            UTC = start_utc at T [s of CLOCK_MONOTONIC] (sim.sensors)
    slip DEG SECONDS        the coupling slips: the joint turns DEG away from the motor
                            over SECONDS (wall) and stays there
    {"cmd": ...}            a JSON object: passed to the board model's control()
                            (sensor boards, see sim.sensors), "board": ADDR|INDEX
    quit                    exit

``python -m sslfr_sim.runner --help`` lists the options.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import selectors
import socket
import sys
import time

from sslfr_common.contract import JOINTS, MIRRORS
from sslfr_drivers.link.endpoint import (PtyEndpoint, close_control, listen_control,
                                         serve_until_signalled)
from sslfr_sim.base import FaultInjector, SimBoard
from sslfr_sim import board_class


class PlainHost:
    """One board directly on the pty."""

    def __init__(self, board: SimBoard, faults: FaultInjector):
        self.boards = [(None, board, faults)]

    def from_wire(self, data: bytes, now: float) -> None:
        """Host bytes -> the board, through the fault injector (``now`` [s, monotonic])."""
        _, board, faults = self.boards[0]
        board.receive(faults.bytes(data, now))

    def to_wire(self, now: float) -> bytes:
        """The board's pending output, through the fault injector (``now`` [s, monotonic])."""
        _, board, faults = self.boards[0]
        return faults.board_frames(board.take_output(), now)


def _parse_board_spec(spec: str) -> tuple[str, dict, str | None]:
    """``KIND[:AXIS][,key=value...][@ADDR]`` -> (kind, options, address hex)."""
    addr = None
    if '@' in spec:
        spec, addr = spec.rsplit('@', 1)
    parts = spec.split(',')
    kind, _, axis = parts[0].partition(':')
    opts: dict = {}
    if axis:
        opts['axis'] = axis
    for p in parts[1:]:
        k, _, v = p.partition('=')
        opts[k] = v
    return kind, opts, addr


class Runner:
    """Select loop: pty bytes <-> boards, ticks, control socket."""

    def __init__(self, endpoint: PtyEndpoint, host, control: str | None = None,
                 tick: float = 0.005, idle_tick: float = 0.02):
        self.endpoint = endpoint
        self.host = host
        self.tick = tick
        self.idle_tick = idle_tick
        self.sel = selectors.DefaultSelector()
        self.control_path = control
        self._ctl = None
        self._clients: dict[socket.socket, bytearray] = {}
        self.running = True
        # shared world file (sim.sensors): axis angles for the absorber's focus model
        world = os.environ.get('SSLFR_SIM_WORLD')
        if world:
            from sslfr_sim.sensors import WorldPublisher
            self.world = WorldPublisher(world)
        else:
            self.world = None
        if control:
            self._ctl = listen_control(control)
            self.sel.register(self._ctl, selectors.EVENT_READ, 'accept')
        self._register_master()

    def _register_master(self) -> None:
        if self.endpoint.plugged:
            self.sel.register(self.endpoint.master, selectors.EVENT_READ, 'pty')

    def step(self, timeout: float | None = None) -> None:
        """One select round (pty, control socket) of at most ``timeout`` [s] (default:
        ``tick`` while a board is busy, else ``idle_tick``), then tick the boards and
        send their output."""
        if timeout is None:
            busy = any(b.busy() for _, b, _ in self.host.boards)
            timeout = self.tick if busy else self.idle_tick
        for key, _ in self.sel.select(timeout):
            if key.data == 'pty':
                data = self.endpoint.read()
                if data:
                    self.host.from_wire(data, time.monotonic())
            elif key.data == 'accept':
                conn, _ = self._ctl.accept()
                conn.setblocking(False)
                self._clients[conn] = bytearray()
                self.sel.register(conn, selectors.EVENT_READ, 'client')
            elif key.data == 'client':
                self._client_read(key.fileobj)
        now = time.monotonic()
        ep = self.endpoint
        if not ep.plugged and now >= ep.unplugged_until:
            ep.plug()
            self._register_master()
        for _, board, _ in self.host.boards:
            board.tick(now)
        if self.world is not None:
            self.world.update([b for _, b, _ in self.host.boards], now)
        out = self.host.to_wire(now)
        if ep.plugged:
            ep.write(out)

    def serve(self) -> None:
        """Step until ``running`` is cleared (``quit`` command or a signal)."""
        while self.running:
            self.step()

    def close(self) -> None:
        """Close the control socket and the pty, removing their files."""
        for conn in list(self._clients):
            conn.close()
        close_control(self._ctl, self.control_path)
        if self.endpoint.plugged:
            self.sel.unregister(self.endpoint.master)
        self.endpoint.close()   # also removes the --link symlink

    # ---------------------------------------------------------------- control
    def _client_read(self, conn: socket.socket) -> None:
        try:
            data = conn.recv(4096)
        except OSError:
            data = b''
        if not data:
            self.sel.unregister(conn)
            self._clients.pop(conn, None)
            conn.close()
            return
        buf = self._clients[conn]
        buf += data
        while b'\n' in buf:
            line, _, rest = bytes(buf).partition(b'\n')
            buf[:] = rest
            try:
                reply = self.command(line.decode('utf-8', 'replace').strip())
            except Exception as exc:  # noqa: BLE001 - report any bad command to the client
                reply = {'ok': False, 'error': f'{type(exc).__name__}: {exc}'}
            try:
                conn.setblocking(True)
                conn.sendall((json.dumps(reply) + '\n').encode())
                conn.setblocking(False)
            except OSError:
                pass

    def _select(self, selector: str | None):
        boards = self.host.boards
        if selector is None:
            return boards
        for i, entry in enumerate(boards):
            addr = entry[0]
            if selector == str(i) or (addr is not None and selector.lower() == addr.hex()):
                return [entry]
        raise ValueError(f'no board {selector!r}')

    def command(self, line: str) -> dict:
        """Execute one control command (see module docstring) -> JSON-able reply."""
        if line.lstrip().startswith('{'):
            # a JSON object: a board-model command (sensor boards: sim.sensors, control())
            req = json.loads(line)
            boards = [b for _, b, _ in self._select(req.pop('board', None)) if hasattr(b, 'control')]
            if not boards:
                return {'ok': False, 'error': f'no board accepts model commands: {line!r}'}
            replies = [b.control(dict(req)) for b in boards]
            bad = [r for r in replies if not r.get('ok')]
            return bad[0] if bad else {'ok': True}
        words = line.split()
        if not words:
            return {'ok': False, 'error': 'empty command'}
        selector = None
        if words[-1].startswith('@'):
            selector = words.pop()[1:]
        cmd, args = words[0], words[1:]
        now = time.monotonic()
        targets = self._select(selector)
        if cmd == 'status':
            return {'ok': True, 'path': self.endpoint.path, 'plugged': self.endpoint.plugged,
                    'boards': [board_state(a, b, f) for a, b, f in targets]}
        if cmd == 'quit':
            self.running = False
            return {'ok': True}
        if cmd == 'unplug':
            if self.endpoint.plugged:
                self.sel.unregister(self.endpoint.master)
            self.endpoint.unplug(float(args[0]), now)
            return {'ok': True}
        if cmd == 'anchor':            # the sensor boards among the targets (an XBee sim mixes kinds)
            clocked = [b for _, b, _ in targets if hasattr(b, 'set_anchor')]
            if not clocked:
                return {'ok': False, 'error': 'no board with a simulated clock to anchor'}
            for board in clocked:
                board.set_anchor(float(args[0]))
            return {'ok': True, 'anchored': len(clocked)}
        for _, board, faults in targets:
            if cmd in ('drop', 'corrupt', 'corrupt_frames'):
                setattr(faults, cmd, float(args[0]))
            elif cmd == 'disconnect':
                faults.silent_until = now + float(args[0])
            elif cmd == 'stall':
                board.stalled = args[0] in ('on', '1', 'true')
            elif cmd == 'reset':
                board.reset()
            elif cmd == 'slip':
                import math
                if not hasattr(board, 'slip'):
                    return {'ok': False, 'error': f'board {board.name} has no coupling to slip'}
                board.slip(math.radians(float(args[0])), float(args[1]))
            elif cmd == 'set_angle':
                import math
                board.angle = math.radians(float(args[0]))
            else:
                return {'ok': False, 'error': f'unknown command {cmd!r}'}
        return {'ok': True}


def board_state(addr, board: SimBoard, faults: FaultInjector) -> dict:
    """JSON-able state of one board for the ``status`` command: counters of the
    board and its fault injector; axis boards add angle [rad], counter, target
    [steps], speed [steps/s], homed, stalled, fault bits and home_angle (the joint
    angle [rad] where the last HOME since boot ended, None before)."""
    d = {
        'address': addr.hex() if addr else None,
        'kind': board.kind.name, 'name': board.name,
        'resets': board.resets, 'frames_in': board.frames_in, 'frames_out': board.frames_out,
        'requests_stale': board.requests_stale, 'requests_duplicate': board.requests_duplicate,
        'watchdog_trips': board.watchdog_trips, 'watchdog_tripped': board.watchdog_tripped,
        'bytes_dropped': faults.bytes_dropped, 'bytes_corrupted': faults.bytes_corrupted,
        'frames_corrupted': faults.frames_corrupted, 'frames_silenced': faults.frames_silenced,
    }
    for attr in ('angle', 'counter', 'target', 'speed', 'homed', 'stalled', 'faults', 'home_angle'):
        if hasattr(board, attr):
            v = getattr(board, attr)
            d[attr] = int(v) if attr == 'faults' else v
    if hasattr(board, 'extra_state'):      # e.g. firmware boards: the harness's state
        d.update(board.extra_state())
    return d


class SimControl:
    """Client of a runner's control socket: ``SimControl(path).cmd('reset')``."""

    def __init__(self, path: str, timeout: float = 5.0):
        self.path = path
        self.timeout = timeout

    def cmd(self, line: str) -> dict:
        """Send one control command line; return the JSON reply, RuntimeError if it
        is not ok."""
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.settimeout(self.timeout)
            s.connect(self.path)
            s.sendall(line.encode() + b'\n')
            buf = b''
            while not buf.endswith(b'\n'):
                chunk = s.recv(65536)
                if not chunk:
                    break
                buf += chunk
        reply = json.loads(buf)
        if not reply.get('ok'):
            raise RuntimeError(f'sim control {line!r}: {reply.get("error")}')
        return reply


def build_parser() -> argparse.ArgumentParser:
    """The ``sim_board`` command line."""
    p = argparse.ArgumentParser(
        prog='sim_board', description='Simulated SSLFR board(s) on a real pty.',
        epilog='Control commands (one line on --control): status, drop P, corrupt P, '
               'corrupt_frames P, disconnect S, unplug S, stall on|off, reset, '
               'set_angle DEG, slip DEG SECONDS, quit; suffix @ADDR selects one XBee board.')
    p.add_argument('--kind', default='axis', help='board kind (plain mode): axis, ...')
    p.add_argument('--axis', default=MIRRORS, help=f'axis name for kind axis: {"|".join(JOINTS)}')
    p.add_argument('--opt', action='append', default=[], metavar='KEY=VALUE',
                   help='board model option (axis: max_speed, accel [steps/s, steps/s^2], '
                        'sensor_noise_deg, initial_angle_deg, no_sensor=1)')
    p.add_argument('--xbee', action='store_true',
                   help='simulate an XBee 802.15.4 coordinator (API AP=2) with --board boards')
    p.add_argument('--board', action='append', default=[], metavar='KIND[:AXIS][,k=v]@ADDR',
                   help='XBee mode: a remote board and its 64-bit address (16 hex digits)')
    p.add_argument('--link', help='maintain a symlink PATH -> current pty slave')
    p.add_argument('--path-file', help='write the pty slave path to this file')
    p.add_argument('--control', help='UNIX socket path for run-time fault injection')
    p.add_argument('--drop', type=float, default=0.0, help='byte drop probability')
    p.add_argument('--corrupt', type=float, default=0.0, help='byte bit-flip probability')
    p.add_argument('--corrupt-frames', type=float, default=0.0,
                   help='board->host frame corruption probability')
    p.add_argument('--seed', type=int, default=None, help='random seed (noise and faults)')
    p.add_argument('--protocol-version', type=int, default=None,
                   help='speak another protocol version (to test refusal)')
    p.add_argument('--key-file', default=None,
                   help='boards provisioned with the installation key of this key file (sslfr keys new); '
                        'default: unprovisioned boards (the null key)')
    return p


def board_key(args, prog: str) -> tuple[bool, bytes | None]:
    """(ok, key) of ``--key-file`` (the message printed when the file cannot be used)."""
    if not args.key_file:
        return True, None
    from sslfr_drivers.link.keys import KeyFileError, load_key
    try:
        return True, load_key(args.key_file)
    except KeyFileError as exc:
        print(f'{prog}: {exc}', file=sys.stderr)
        return False, None


def make_board(kind: str, options: dict, rng: random.Random, board_id: int,
               protocol_version: int | None, key: bytes | None = None) -> SimBoard:
    """A board model of ``kind`` from its options, provisioned with ``key`` (None:
    unprovisioned); ``protocol_version`` (if given) replaces the version it speaks, for
    refusal tests."""
    board = board_class(kind).from_options(options, rng, board_id=board_id)
    if key is not None:
        board.take_output()              # its first BOOT (unprovisioned) never reaches the wire
        board.provision(key)
    if protocol_version is not None:
        board.protocol_version = protocol_version
        board.reset()
        board.resets = 0
    return board


def xbee_host(specs: list[str], opts: dict, make, injector, prog: str):
    """The simulated XBee coordinator with a board per ``--board KIND[:AXIS][,k=v]@ADDR``
    spec: ``make(kind, options, board_id)`` builds each board, ``injector()`` its fault
    injector. None (the reason printed) when a spec is incomplete."""
    from .xbee import XBeeSimCoordinator
    if not specs:
        print(f'{prog}: --xbee needs at least one --board KIND[:AXIS]@ADDR', file=sys.stderr)
        return None
    host = XBeeSimCoordinator()
    for i, spec in enumerate(specs):
        kind, bopts, addr = _parse_board_spec(spec)
        if addr is None:
            print(f'{prog}: --board {spec!r} needs @ADDR', file=sys.stderr)
            return None
        host.add_board(bytes.fromhex(addr), make(kind, {**opts, **bopts}, i + 1), injector())
    return host


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``sim_board``; exit status 0, 2 on a bad ``--board``."""
    args = build_parser().parse_args(argv)
    rng = random.Random(args.seed)

    def announce(path):
        print(f'SIM_PTY {path}', flush=True)

    def injector():
        return FaultInjector(drop=args.drop, corrupt=args.corrupt,
                             corrupt_frames=args.corrupt_frames,
                             rng=random.Random(rng.random()))

    opts = dict(o.split('=', 1) for o in args.opt)
    ok, key = board_key(args, 'sim_board')
    if not ok:
        return 2
    if args.xbee:
        host = xbee_host(args.board, opts, lambda kind, o, board_id: make_board(
            kind, o, rng, board_id, args.protocol_version, key), injector, 'sim_board')
        if host is None:
            return 2
    else:
        opts.setdefault('axis', args.axis)
        host = PlainHost(make_board(args.kind, opts, rng, 1, args.protocol_version, key), injector())
    endpoint = PtyEndpoint(args.link, args.path_file, announce)
    return serve_until_signalled(Runner(endpoint, host, control=args.control))


if __name__ == '__main__':
    sys.exit(main())


class SimThread:
    """Run simulated board(s) on a real pty in a background thread (for tests and
    benchmarks in one process). ``host`` is a :class:`PlainHost` or an
    ``XBeeSimCoordinator``; ``path`` is the pty slave to open.

    >>> with SimThread.plain(AxisSim()) as sim:          # doctest: +SKIP
    ...     link = BoardLink(SerialTransport(sim.path)).start()
    """

    def __init__(self, host, link: str | None = None, control: str | None = None):
        import threading
        self.host = host
        self.endpoint = PtyEndpoint(link)
        self.runner = Runner(self.endpoint, host, control=control)
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._serve, name='sim-board', daemon=True)

    @classmethod
    def plain(cls, board: SimBoard, faults: FaultInjector | None = None, **kw) -> 'SimThread':
        """One board directly on a pty (no XBee)."""
        return cls(PlainHost(board, faults or FaultInjector()), **kw)

    @property
    def path(self) -> str:
        """The pty slave path to give the host."""
        return self.endpoint.path

    @property
    def board(self) -> SimBoard:
        """The (first) board model."""
        return self.host.boards[0][1]

    @property
    def faults(self) -> FaultInjector:
        """The fault injector of the (first) board."""
        return self.host.boards[0][2]

    def _serve(self) -> None:
        while self.runner.running:
            with self._lock:
                self.runner.step()

    def command(self, line: str) -> dict:
        """Run a control command (same syntax as the socket) in the sim thread's lock."""
        with self._lock:
            return self.runner.command(line)

    def locked(self):
        """Context manager: hold the sim still while a test inspects/changes it."""
        return self._lock

    def start(self) -> 'SimThread':
        """Start serving in the background thread."""
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the thread (within 2 s) and close the pty and control socket."""
        self.runner.running = False
        self._thread.join(timeout=2)
        self.runner.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
