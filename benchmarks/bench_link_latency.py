#!/usr/bin/env python3
"""Setpoint-to-frame-on-the-wire latency of the board link (issue 5 goal: p99 < 10 ms).

Protocol version 2 (issue 19): every frame is tagged (SipHash-2-4, 8 bytes) in a session;
the board end is the simulators' SimBoard with the installation key. Also printed: the
bytes a frame gains, the MAC's time on the host (seal + verify of a MOVE_TO and a
STATUS), and with ``--avr`` the MAC's cost on the ATmega328P in cycles (firmware/bench,
run in simavr).

Measured interval: from ``BoardLink.submit(MoveTo(...))`` being called (the driver
hands a setpoint to the link API) to the complete frame having been read and
CRC-checked by a reader blocked on the OTHER end of a real pty (the board side).
Also printed: the full request round trip (MOVE_TO submitted -> ACK future done),
and the same for the XBee path (digi-xbee coordinator on a pty -> simulated
coordinator reading the escaped API TX64 frame; the round trip includes digi-xbee's
wait for the TX status).

Usage: python benchmarks/bench_link_latency.py [--n 2000] [--rate 200] [--xbee-n 300] [--avr]
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import threading
import time
import tty

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.auth import BOARD_TO_HOST, HOST_TO_BOARD, Session
from sslfr_drivers.link.board_link import BoardLink
from sslfr_drivers.link.protocol import Framer, encode_frame
from sslfr_sim.base import SimBoard
from sslfr_sim.xbee import ApiParser, api_frame
from sslfr_drivers.link.transport import SerialTransport, make_transport


def pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, int(round(q / 100 * (len(s) - 1))))]


def report(name: str, values_s: list[float]) -> float:
    ms = [v * 1e3 for v in values_s]
    p99 = pct(ms, 99)
    print(f'{name:<44} n={len(ms):5d}  p50={pct(ms, 50):7.3f} ms  p90={pct(ms, 90):7.3f} ms  '
          f'p99={p99:7.3f} ms  max={max(ms):7.3f} ms  mean={statistics.fmean(ms):7.3f} ms')
    return p99


KEY = bytes(range(16))


class EndBoard(SimBoard):
    """The board protocol (sessions, tags, caches) answering STATUS and ACKing motion."""

    kind = m.BoardKind.AXIS_STEPPER
    REQUESTS = SimBoard.REQUESTS | {m.GetStatus.TYPE, m.MoveTo.TYPE}

    def handle(self, msg, frame):
        if isinstance(msg, m.GetStatus):
            return m.Status(0, 0, 0.0, 0, 0, 0, float('nan'), 0)
        if isinstance(msg, m.MoveTo):
            return m.Ack(frame.type)
        return super().handle(msg, frame)


class BoardEnd(threading.Thread):
    """Board side of a pty: blocking reads, deframing, timestamps, a v2 board's answers."""

    def __init__(self, master: int, xbee: bool = False):
        super().__init__(daemon=True)
        self.master = master
        self.xbee = xbee
        self.arrivals: dict[int, float] = {}
        self.running = True
        self.board = EndBoard(key=KEY)
        self.board.take_output()          # its BOOT: the link starts a session anyway

    def answer(self, raw: bytes) -> bytes:
        self.board.tick(time.monotonic())
        self.board.receive(raw)
        return self.board.take_output()

    def run(self) -> None:
        framer, api = Framer(), ApiParser()
        while self.running:
            try:
                data = os.read(self.master, 4096)
            except OSError:
                return
            now = time.perf_counter()
            if self.xbee:
                for fd in api.feed(data):
                    if fd[0] == 0x08 or fd[0] == 0x09:       # AT command at digi-xbee open
                        from sslfr_sim.xbee import DEFAULT_AT
                        cmd = fd[2:4].decode()
                        val = DEFAULT_AT.get(cmd)
                        os.write(self.master, api_frame(bytes((0x88, fd[1])) + fd[2:4] +
                                                        (bytes((0,)) + val if val else b'\x02')))
                    elif fd[0] == 0x00:                       # TX64: status, then the ACK
                        os.write(self.master, api_frame(bytes((0x89, fd[1], 0))))
                        for f in framer.feed(fd[11:]):
                            self.arrivals[f.seq] = now
                            out = self.answer(encode_frame(f))
                            if out:
                                os.write(self.master, api_frame(b'\x80' + fd[2:10] + b'\x28\x00' + out))
            else:
                for f in framer.feed(data):
                    self.arrivals[f.seq] = now
                    out = self.answer(encode_frame(f))
                    if out:
                        os.write(self.master, out)


def run(link: BoardLink, end: BoardEnd, n: int, rate: float) -> tuple[list[float], list[float]]:
    wire, rtt = [], []
    period = 1.0 / rate
    for i in range(n):
        seq = link.auth.seq.peek()
        t0 = time.perf_counter()
        fut = link.submit(m.MoveTo(1000 + i, 500.0), timeout=0.5, retries=0)
        try:
            fut.result(2.0)
        except Exception as exc:  # noqa: BLE001 - counted below
            print(f'request {i} failed: {exc}', file=sys.stderr)
            continue
        t2 = time.perf_counter()
        t1 = end.arrivals.get(seq)
        if t1 is not None:
            wire.append(t1 - t0)
            rtt.append(t2 - t0)
        time.sleep(max(0.0, period - (time.perf_counter() - t0)))
    return wire, rtt


def before(rev: str, n: int, rate: float) -> None:
    """Run ``rev``'s own benchmarks/bench_link_latency.py on ``rev``'s code (git archive
    into a temporary directory, first on PYTHONPATH) and print its figures."""
    import subprocess
    import tempfile
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory(prefix='sslfr-bench-') as tmp:
        arch = subprocess.run(['git', '-C', str(root), 'archive', rev, 'src', 'benchmarks'], capture_output=True,
                              check=True).stdout
        subprocess.run(['tar', '-x', '-C', tmp], input=arch, check=True)
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [f'{tmp}/src/{pkg}' for pkg in ('sslfr_drivers', 'sslfr_sim', 'sslfr_common', 'sslfr_interfaces')]
            + [os.environ.get('PYTHONPATH', '')]))
        out = subprocess.run([sys.executable, f'{tmp}/benchmarks/bench_link_latency.py', '--n', str(n), '--rate',
                              str(rate), '--xbee-n', '0'], capture_output=True, text=True, env=env, timeout=600)
        for line in (out.stdout + out.stderr).splitlines():
            print(f'before ({rev}): {line}')


def mac_cost(avr: bool) -> None:
    """Bytes the tag adds, the MAC's time on the host, and (``avr``) its cycles on the AVR."""
    s = Session(KEY, bytes(range(8)), bytes(range(8, 16)))
    move, status = m.encode(m.MoveTo(1000, 500.0), 0), m.encode(m.Status(0, 0, 0.0, 0, 0, 0, 0.0, 0), 0, 1)
    v1 = len(encode_frame(move.__class__(move.type, 0, move.payload, version=1, tag=b'')))
    sealed = s.seal(HOST_TO_BOARD, 5, move)
    print(f'frame size: MOVE_TO {v1} -> {len(encode_frame(sealed))} bytes (+8: the tag; a HELLO per session '
          f'{len(encode_frame(s.seal(HOST_TO_BOARD, 1, m.encode(m.Hello(bytes(8)), 0))))} B, HELLO_REPLY 32 B)')
    n = 20000
    t0 = time.perf_counter()
    for i in range(n):
        s.seal(HOST_TO_BOARD, i, move)
    t1 = time.perf_counter()
    for i in range(n):
        s.verify(HOST_TO_BOARD, 5, sealed)
    t2 = time.perf_counter()
    st = s.seal(BOARD_TO_HOST, 3, status)
    for i in range(n):
        s.verify(BOARD_TO_HOST, 3, st)
    t3 = time.perf_counter()
    print(f'host MAC (pure Python SipHash-2-4): seal MOVE_TO {(t1 - t0) / n * 1e6:.1f} us, verify MOVE_TO '
          f'{(t2 - t1) / n * 1e6:.1f} us, verify STATUS {(t3 - t2) / n * 1e6:.1f} us per frame')
    if avr:
        import re
        import subprocess
        from sslfr_drivers import firmware as fw
        fw.build('bench')
        out = subprocess.run(['simavr', '-m', 'atmega328p', '-f', '16000000', str(fw.build_dir() / 'macbench.elf')],
                             capture_output=True, text=True, timeout=60)
        line = next(ln for ln in (out.stdout + out.stderr).splitlines() if 'MACBENCH' in ln)
        fig = {k: int(v) for k, v in re.findall(r'(\w+)=(\d+)', line)}
        print('AVR MAC (ATmega328P 16 MHz, simavr cycle-exact): ' + ', '.join(
            f'{k} {v} cycles = {v / 16:.0f} us' for k, v in fig.items() if k != 'n'))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--n', type=int, default=2000, help='MOVE_TO samples over a pty')
    ap.add_argument('--rate', type=float, default=200.0, help='setpoints per second [Hz]')
    ap.add_argument('--xbee-n', type=int, default=300, help='samples over the XBee path (0: skip)')
    ap.add_argument('--avr', action='store_true', help='also the MAC cycles on the ATmega328P (simavr)')
    ap.add_argument('--before', metavar='REV', help='first run this benchmark of git revision REV (e.g. the '
                    'last protocol-1 commit 62305c9) on its own code, same --n/--rate: the before/after pair')
    args = ap.parse_args(argv)
    if args.before:
        before(args.before, args.n, args.rate)

    print(f'python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}')
    mac_cost(args.avr)
    master, slave = os.openpty()
    tty.setraw(slave)
    end = BoardEnd(master)
    end.start()
    link = BoardLink(SerialTransport(os.ttyname(slave)), name='bench', key=KEY).start()
    if not link.wait_up(5):
        print('link did not come up', file=sys.stderr)
        return 1
    wire, rtt = run(link, end, args.n, args.rate)
    link.stop()
    p99 = report('serial pty: MOVE_TO -> frame read on board end', wire)
    report('serial pty: MOVE_TO -> ACK received (round trip)', rtt)
    print(f'GOAL p99 < 10 ms: {"MET" if p99 < 10 else "NOT MET"} ({p99:.3f} ms)')

    if args.xbee_n:
        master2, slave2 = os.openpty()
        tty.setraw(slave2)
        end2 = BoardEnd(master2, xbee=True)
        end2.start()
        xl = BoardLink(make_transport(f'xbee:{os.ttyname(slave2)}?addr=0013A20040000001'),
                       name='bench-xbee', key=KEY).start()
        if not xl.wait_up(10):
            print('xbee link did not come up', file=sys.stderr)
            return 1
        wire2, rtt2 = run(xl, end2, args.xbee_n, min(args.rate, 20.0))
        xl.stop()
        c = xl.counters()
        print(f'xbee: tx_failures={c["tx_failures"]} timeouts={c["timeouts"]} '
              f'frames_lost={c["frames_lost"]}')
        report('xbee (digi-xbee): MOVE_TO -> TX64 read by coordinator', wire2)
        report('xbee (digi-xbee): MOVE_TO -> ACK received', rtt2)
    return 0


if __name__ == '__main__':
    sys.exit(main())
