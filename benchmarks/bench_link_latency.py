#!/usr/bin/env python3
"""Setpoint-to-frame-on-the-wire latency of the board link (issue 5 goal: p99 < 10 ms).

Measured interval: from ``BoardLink.submit(MoveTo(...))`` being called (the driver
hands a setpoint to the link API) to the complete frame having been read and
CRC-checked by a reader blocked on the OTHER end of a real pty (the board side).
Also printed: the full request round trip (MOVE_TO submitted -> ACK future done),
and the same for the XBee path (digi-xbee coordinator on a pty -> simulated
coordinator reading the escaped API TX64 frame; the round trip includes digi-xbee's
wait for the TX status).

Usage: python benchmarks/bench_link_latency.py [--n 2000] [--rate 200] [--xbee-n 300]
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
from sslfr_drivers.link.board_link import BoardLink
from sslfr_drivers.link.protocol import Framer, encode_frame
from sslfr_drivers.sim.xbee import ApiParser, api_frame
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


class BoardEnd(threading.Thread):
    """Board side of a pty: blocking reads, deframing, timestamps, ACK answers."""

    def __init__(self, master: int, xbee: bool = False):
        super().__init__(daemon=True)
        self.master = master
        self.xbee = xbee
        self.arrivals: dict[int, float] = {}
        self.running = True

    @staticmethod
    def answer(frame) -> m.Message:
        if frame.type == m.GetInfo.TYPE:
            return m.Info(m.BoardKind.AXIS_STEPPER, 1, 0, 0, 1, 99, b'bench-end')
        if frame.type == m.GetStatus.TYPE:
            return m.Status(0, 0, 0.0, 0, 0, 0, float('nan'), 0)
        return m.Ack(frame.type)

    def run(self) -> None:
        framer, api = Framer(), ApiParser()
        seq = 0
        while self.running:
            try:
                data = os.read(self.master, 4096)
            except OSError:
                return
            now = time.perf_counter()
            if self.xbee:
                for fd in api.feed(data):
                    if fd[0] == 0x08 or fd[0] == 0x09:       # AT command at digi-xbee open
                        from sslfr_drivers.sim.xbee import DEFAULT_AT
                        cmd = fd[2:4].decode()
                        val = DEFAULT_AT.get(cmd)
                        os.write(self.master, api_frame(bytes((0x88, fd[1])) + fd[2:4] +
                                                        (bytes((0,)) + val if val else b'\x02')))
                    elif fd[0] == 0x00:                       # TX64: status, then the ACK
                        os.write(self.master, api_frame(bytes((0x89, fd[1], 0))))
                        for f in framer.feed(fd[11:]):
                            self.arrivals[f.seq] = now
                            seq += 1
                            ack = encode_frame(m.encode(self.answer(f), seq, f.seq))
                            os.write(self.master, api_frame(b'\x80' + fd[2:10] + b'\x28\x00' + ack))
            else:
                for f in framer.feed(data):
                    self.arrivals[f.seq] = now
                    seq += 1
                    os.write(self.master, encode_frame(m.encode(self.answer(f), seq, f.seq)))


def run(link: BoardLink, end: BoardEnd, n: int, rate: float) -> tuple[list[float], list[float]]:
    wire, rtt = [], []
    period = 1.0 / rate
    for i in range(n):
        seq = link._seq.peek()
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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--n', type=int, default=2000, help='MOVE_TO samples over a pty')
    ap.add_argument('--rate', type=float, default=200.0, help='setpoints per second [Hz]')
    ap.add_argument('--xbee-n', type=int, default=300, help='samples over the XBee path (0: skip)')
    args = ap.parse_args(argv)

    print(f'python {sys.version.split()[0]}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}')
    master, slave = os.openpty()
    tty.setraw(slave)
    end = BoardEnd(master)
    end.start()
    link = BoardLink(SerialTransport(os.ttyname(slave)), name='bench').start()
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
                       name='bench-xbee').start()
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
