"""A userspace link emulator: delay, jitter and loss where the kernel has no ``tc netem``.

Test and benchmark support (the field's network-namespace tests, benchmarks/bench_field.py),
not product code. One emulator process owns one TAP device per port (``/dev/net/tun``,
``IFF_TAP | IFF_NO_PI``; the caller moves a port's device into its network namespace with
``ip link set DEV netns NS``, the emulator keeps the file descriptor) and switches Ethernet
frames between the ports as a learning switch (broadcast, multicast and unknown
destinations flooded), like a Wi-Fi access point with a wired uplink:

- a *shaped* port is a radio link: each frame from it (uplink) and each frame to it
  (downlink) is lost with probability ``loss``, else delayed by ``delay +- jitter``
  (uniform, as netem's ``delay D J`` without a distribution table). A frame never
  overtakes an earlier frame of the same link direction (802.11 delivers in order; its
  retransmissions hold the queue): a frame leaves at ``max(arrival + draw, previous
  departure)``, so frames closer together than the jitter's spread come out a little
  later than drawn, never reordered (netem with jitter does reorder). Between two
  shaped ports a frame crosses both links (up, then down), as through an access point;
- a *wired* port (the station) adds nothing;
- a port can be cut (``cut NAME``: every frame from or to it dropped, those in flight
  included; the device stays up, as a collector out of radio range) and joined again.

The emulator runs with a low real-time priority (SCHED_FIFO 10; else nice -10) where
allowed, so that its own scheduling adds little to the drawn delays on a loaded machine
(it sleeps in ``select`` between frames and uses little CPU); ``stats`` reports how late
it delivered. Control: one
command a line on its stdin (``cut NAME``, ``join NAME``, ``stats``), one answer a line on
its stdout; it exits when its stdin closes (the devices vanish with it).

    python tests/linkemu.py --delay 0.02 --jitter 0.005 --loss 0.01 --wired station \\
        station=tapS c1=tap1 c2=tap2
"""
from __future__ import annotations

import argparse
import ctypes
import errno
import fcntl
import heapq
import json
import os
import random
import select
import socket
import struct
import subprocess
import sys
import time
from dataclasses import dataclass, field

TUNSETIFF = 0x400454CA
IFF_TAP = 0x0002
IFF_NO_PI = 0x1000
CLONE_NEWNET = 0x40000000
#: SCHED_FIFO priority of the emulator (lowest real-time band; the kernel's real-time
#: throttling still leaves others 5 % of each second should it ever spin)
RT_PRIORITY = 10


@dataclass(frozen=True)
class Shaping:
    """One radio link, each direction: ``delay_s`` +- ``jitter_s`` (uniform) [s], ``loss`` (0..1)."""

    delay_s: float = 0.020
    jitter_s: float = 0.005
    loss: float = 0.01

    def __post_init__(self):
        if not (0.0 <= self.jitter_s <= self.delay_s and 0.0 <= self.loss < 1.0):
            raise ValueError(f'link shaping out of range: {self}')

    def describe(self) -> str:
        return f'{self.delay_s * 1e3:g} ms +- {self.jitter_s * 1e3:g} ms, {self.loss * 100:g} % loss each way'


#: the field tests' Wi-Fi link (the netem line ``delay 20ms 5ms loss 1%`` on each direction)
WIFI = Shaping()


@dataclass
class PortStats:
    rx_frames: int = 0        # frames the port's host sent into the emulator
    rx_bytes: int = 0
    tx_frames: int = 0        # frames delivered to the port's host
    tx_bytes: int = 0
    lost: int = 0             # dropped by the loss draw on this port's link (either direction)
    cut: int = 0              # dropped because the port was cut


@dataclass
class Switch:
    """The emulator's core, without devices: learning switch, per-link shaping, schedule.

    ``ingress(port, frame, now)`` takes a frame from a port at ``now`` [s, any monotonic
    clock]; ``due(now)`` returns the ``(port, frame, due_time)`` deliveries whose time has
    come, in time order; ``next_due()`` the earliest pending time (None: nothing pending).
    """

    ports: list[str]
    shaping: dict[str, Shaping | None]          # port -> its radio link (None: wired)
    rng: random.Random = field(default_factory=random.Random)

    def __post_init__(self):
        self.up = {p: True for p in self.ports}
        self.table: dict[bytes, str] = {}
        self.heap: list[tuple[float, int, str, bytes]] = []
        self.last: dict[tuple[str, str], float] = {}
        self.stats = {p: PortStats() for p in self.ports}
        self._seq = 0

    def set_up(self, port: str, up: bool) -> None:
        if port not in self.up:
            raise KeyError(f'no port {port!r} (ports: {", ".join(self.ports)})')
        self.up[port] = up

    def _hop(self, port: str, direction: str, t: float) -> float | None:
        """Departure time from ``port``'s link in ``direction`` ('up'/'down') of a frame
        entering it at ``t``; None when the loss draw drops it."""
        s = self.shaping.get(port)
        if s is None:
            return t
        if s.loss and self.rng.random() < s.loss:
            self.stats[port].lost += 1
            return None
        out = max(t + s.delay_s + self.rng.uniform(-s.jitter_s, s.jitter_s), self.last.get((port, direction), 0.0))
        self.last[(port, direction)] = out
        return out

    def ingress(self, port: str, frame: bytes, now: float) -> None:
        st = self.stats[port]
        st.rx_frames += 1
        st.rx_bytes += len(frame)
        if not self.up[port]:
            st.cut += 1
            return
        if len(frame) < 14:
            return
        dst, src = frame[0:6], frame[6:12]
        if not src[0] & 1:
            self.table[src] = port
        if dst[0] & 1 or dst not in self.table:
            outs = [p for p in self.ports if p != port]
        else:
            outs = [self.table[dst]] if self.table[dst] != port else []
        if not outs:
            return
        t = self._hop(port, 'up', now)
        if t is None:
            return
        for q in outs:
            if not self.up[q]:
                self.stats[q].cut += 1
                continue
            tq = self._hop(q, 'down', t)
            if tq is not None:
                self._seq += 1
                heapq.heappush(self.heap, (tq, self._seq, q, frame))

    def next_due(self) -> float | None:
        return self.heap[0][0] if self.heap else None

    def due(self, now: float) -> list[tuple[str, bytes, float]]:
        out = []
        while self.heap and self.heap[0][0] <= now:
            t, _, q, frame = heapq.heappop(self.heap)
            if not self.up[q]:
                self.stats[q].cut += 1
                continue
            st = self.stats[q]
            st.tx_frames += 1
            st.tx_bytes += len(frame)
            out.append((q, frame, t))
        return out


def open_tap(name: str) -> int:
    """A new TAP device ``name`` (down, no address) and its non-blocking file descriptor."""
    fd = os.open('/dev/net/tun', os.O_RDWR | os.O_NONBLOCK)
    try:
        fcntl.ioctl(fd, TUNSETIFF, struct.pack('16sH', name.encode(), IFF_TAP | IFF_NO_PI))
    except OSError:
        os.close(fd)
        raise
    return fd


def serve(devices: dict[str, str], shaping: dict[str, Shaping | None], seed: int | None,
          cmd_in=None, cmd_out=None) -> int:
    """The emulator's loop: TAP devices ``devices`` (port -> device name), until stdin closes."""
    cmd_in = cmd_in if cmd_in is not None else sys.stdin.buffer
    cmd_out = cmd_out if cmd_out is not None else sys.stdout
    try:                                            # a radio does not wait for a CPU: see the module's text
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    except (OSError, AttributeError):
        try:
            os.nice(-10)
        except OSError:
            pass
    fds = {p: open_tap(dev) for p, dev in devices.items()}
    port_of = {fd: p for p, fd in fds.items()}
    sw = Switch(list(devices), shaping, random.Random(seed))
    late = {'n': 0, 'sum_s': 0.0, 'max_s': 0.0, 'over_1ms': 0}
    write_errors = 0
    inp = cmd_in.fileno()
    os.set_blocking(inp, False)
    buf = b''
    print('ready', file=cmd_out, flush=True)
    while True:
        nd = sw.next_due()
        timeout = None if nd is None else max(0.0, nd - time.monotonic())
        readable, _, _ = select.select([inp, *fds.values()], [], [], timeout)
        for fd in readable:
            if fd == inp:
                try:
                    chunk = os.read(inp, 4096)
                except BlockingIOError:
                    continue
                if not chunk:
                    for f in fds.values():
                        os.close(f)
                    return 0
                buf += chunk
                while b'\n' in buf:
                    line, buf = buf.split(b'\n', 1)
                    print(_command(sw, line.decode().split(), late, write_errors), file=cmd_out, flush=True)
                continue
            port = port_of[fd]
            for _ in range(64):                     # a burst, then the other ports get their turn
                try:
                    frame = os.read(fd, 65536)
                except BlockingIOError:
                    break
                except OSError as e:                # EIO while the device is being moved or is down
                    if e.errno not in (errno.EIO, errno.EAGAIN):
                        raise
                    break
                sw.ingress(port, frame, time.monotonic())
        now = time.monotonic()
        for q, frame, t in sw.due(now):
            try:
                os.write(fds[q], frame)
            except OSError:
                write_errors += 1                   # the device is down or being moved: the frame is gone
                continue
            lag = now - t
            late['n'] += 1
            late['sum_s'] += lag
            late['max_s'] = max(late['max_s'], lag)
            late['over_1ms'] += lag > 1e-3


def _command(sw: Switch, words: list[str], late: dict, write_errors: int) -> str:
    try:
        if len(words) == 2 and words[0] in ('cut', 'join'):
            sw.set_up(words[1], words[0] == 'join')
            return 'ok'
        if words == ['stats']:
            return json.dumps({'ports': {p: vars(s) for p, s in sw.stats.items()},
                               'late': {**late, 'mean_s': late['sum_s'] / max(1, late['n'])},
                               'write_errors': write_errors, 'pending': len(sw.heap),
                               'cpu_s': sum(os.times()[:2])})
    except KeyError as e:
        return f'error {e}'
    return f'error unknown command {" ".join(words)!r} (cut NAME, join NAME, stats)'


class LinkEmulator:
    """The emulator as a child process: ``start()`` creates the TAP devices (then move and
    configure them), ``set_link(port, up)``, ``stats()``, ``stop()`` (the devices vanish)."""

    def __init__(self, devices: dict[str, str], shaping: Shaping = WIFI, wired: tuple[str, ...] = (),
                 seed: int | None = None):
        self.devices = dict(devices)
        self.shaping = shaping
        self.wired = tuple(wired)
        self.seed = seed
        self.proc: subprocess.Popen | None = None

    def start(self, timeout: float = 10.0) -> None:
        argv = [sys.executable, os.path.abspath(__file__), '--delay', repr(self.shaping.delay_s),
                '--jitter', repr(self.shaping.jitter_s), '--loss', repr(self.shaping.loss)]
        argv += [a for w in self.wired for a in ('--wired', w)]
        if self.seed is not None:
            argv += ['--seed', str(self.seed)]
        argv += [f'{p}={d}' for p, d in self.devices.items()]
        self.proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, bufsize=1)
        line = self._line(timeout)
        if line != 'ready':
            err = self.proc.stderr.read() if self.proc.poll() is not None else ''
            self.stop()
            raise RuntimeError(f'link emulator did not start: {line!r} {err.strip()[-2000:]}')

    def _line(self, timeout: float) -> str:
        r, _, _ = select.select([self.proc.stdout], [], [], timeout)
        if not r:
            raise TimeoutError(f'link emulator silent for {timeout} s')
        return self.proc.stdout.readline().strip()

    def _ask(self, cmd: str) -> str:
        if self.proc is None or self.proc.poll() is not None:
            raise RuntimeError('link emulator not running')
        self.proc.stdin.write(cmd + '\n')
        self.proc.stdin.flush()
        answer = self._line(10.0)
        if answer.startswith('error'):
            raise ValueError(f'link emulator: {answer}')
        return answer

    def set_link(self, port: str, up: bool) -> None:
        self._ask(f'{"join" if up else "cut"} {port}')

    def stats(self) -> dict:
        return json.loads(self._ask('stats'))

    def stop(self) -> None:
        if self.proc is None:
            return
        try:
            self.proc.stdin.close()
        except OSError:
            pass
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)
        self.proc = None


def netns_socket(ns: str, *args) -> socket.socket:
    """``socket.socket(*args)`` created inside network namespace ``ns`` (``ip netns`` name;
    root). The calling thread enters the namespace for the creation and comes back."""
    libc = ctypes.CDLL(None, use_errno=True)
    own = os.open(f'/proc/thread-self/ns/net', os.O_RDONLY)
    target = os.open(f'/run/netns/{ns}', os.O_RDONLY)
    try:
        if libc.setns(target, CLONE_NEWNET) != 0:
            raise OSError(ctypes.get_errno(), f'setns into {ns}')
        try:
            return socket.socket(*args)
        finally:
            if libc.setns(own, CLONE_NEWNET) != 0:
                raise OSError(ctypes.get_errno(), 'setns back')
    finally:
        os.close(own)
        os.close(target)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('ports', nargs='+', metavar='PORT=DEVICE')
    ap.add_argument('--delay', type=float, default=WIFI.delay_s, help='[s] mean one-way delay of a shaped link')
    ap.add_argument('--jitter', type=float, default=WIFI.jitter_s, help='[s] +- uniform around the delay')
    ap.add_argument('--loss', type=float, default=WIFI.loss, help='loss probability per frame and link direction')
    ap.add_argument('--wired', action='append', default=[], help='a port without shaping (repeatable)')
    ap.add_argument('--seed', type=int, default=None)
    a = ap.parse_args(argv)
    devices = dict(p.split('=', 1) for p in a.ports)
    s = Shaping(a.delay, a.jitter, a.loss)
    return serve(devices, {p: None if p in a.wired else s for p in devices}, a.seed)


if __name__ == '__main__':
    sys.exit(main())
