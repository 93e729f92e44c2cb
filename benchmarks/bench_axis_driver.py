#!/usr/bin/env python3
"""Axis driver control tick: decision cost and tick-to-frame latency (no ROS).

Measured, with the driver's own classes (``AxisSupervisor`` + ``AxisBoardSession``)
against the simulated axis board on a real pty (``sim.runner.SimThread``):

1. ``AxisSupervisor.tick`` alone (trajectory interpolation, safety, stall, limits,
   speed): pure Python cost per call;
2. one full control tick as the node runs it (read -> update -> write): STATUS
   (request -> answer over the pty) + decision + MOVE_TO (request -> ACK);
3. setpoint-to-frame: from the start of the decision (setpoint interpolated) to the
   MOVE_TO frame having been read and CRC-checked by the board side of the pty.

Usage: python benchmarks/bench_axis_driver.py [--n 1000]
"""
from __future__ import annotations

import argparse
import math
import random
import statistics
import time

from sslfr_common.contract import JOINT_RANGE, STOW_POSITION
from sslfr_drivers.axis.board_session import AxisBoardSession
from sslfr_drivers.axis.commands import BoardState
from sslfr_drivers.axis.supervisor import AxisSupervisor, AxisTuning
from sslfr_drivers.axis.joint import Calibration, SoftLimits
from sslfr_drivers.axis.trajectory import TrajectoryMsg
from sslfr_sim.axis import AxisConfig as SimConfig
from sslfr_sim.axis import AxisSim
from sslfr_sim.runner import SimThread


def pct(values, q):
    s = sorted(values)
    return s[min(len(s) - 1, int(round(q / 100 * (len(s) - 1))))]


def report(name, values_s):
    ms = [v * 1e3 for v in values_s]
    print(f'{name:<46} n={len(ms):5d}  p50={pct(ms, 50):8.4f} ms  p99={pct(ms, 99):8.4f} ms  '
          f'max={max(ms):8.4f} ms  mean={statistics.fmean(ms):8.4f} ms')


def make_supervisor(rate: float) -> AxisSupervisor:
    cfg = AxisTuning('mirrors', Calibration(), SoftLimits(*JOINT_RANGE['mirrors']), 0.3, 1e-4,
                     1.0 / rate, STOW_POSITION['mirrors'], 'sleep', math.pi / 2, 0.3)
    sup = AxisSupervisor(cfg)
    now = time.time()
    ts = [now + k for k in range(0, 3600, 1)]              # one hour, one point per second
    msg = TrajectoryMsg.for_joint('mirrors', ts, [0.2 + 0.1 * math.sin(k / 600) for k in range(len(ts))])
    assert sup.store.offer(msg, 'mirrors', now, cfg.limits) is None
    return sup


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--n', type=int, default=1000)
    ap.add_argument('--rate', type=float, default=20.0, help='control rate [Hz]')
    args = ap.parse_args()

    sup = make_supervisor(args.rate)
    sup.safety.timeout = 1e9
    sup.safety.receive(time.monotonic(), 0, False, [], 1)
    cal = sup.cfg.calibration
    board = BoardState(cal.steps(0.2), cal.steps(0.2), False, True, False, 0.2)
    t_pure = []
    for k in range(args.n * 10):
        t = time.perf_counter()
        sup.tick(time.time(), time.monotonic(), board, True)
        t_pure.append(time.perf_counter() - t)
    report('AxisSupervisor.tick (pure decision)', t_pure)

    sim = AxisSim(SimConfig.for_axis('mirrors', initial_angle=0.2), rng=random.Random(1))
    with SimThread.plain(sim) as st:
        # timestamp every MOVE_TO the board decodes (its handler runs in the sim thread)
        seen: list[float] = []
        orig = sim.handle

        def handle(msg, frame):
            if type(msg).__name__ == 'MoveTo':
                seen.append(time.perf_counter())
            return orig(msg, frame)
        sim.handle = handle
        session = AxisBoardSession(st.path, request_timeout=0.25)
        session.open()
        sup = make_supervisor(args.rate)
        sup.safety.timeout = 1e9
        sup.safety.receive(time.monotonic(), 0, False, [], 1)
        period = 1.0 / args.rate
        t_tick, t_frame = [], []
        # re-reference once from the sensor (SET_ZERO), as the node does
        while True:
            b = session.read(time.monotonic(), period).board
            act = sup.tick(time.time(), time.monotonic(), b, True)
            if act.kind != 'none':
                session.write(act)
            if b is not None and b.homed:
                break
            time.sleep(period / 4)
        k = 0
        while len(t_tick) < args.n:
            t0 = time.perf_counter()
            b = session.read(time.monotonic(), period).board          # read
            t_dec = time.perf_counter()
            # a fresh setpoint every tick (the trajectory moves ~0.5 step per tick here)
            sup._cmd_steps = None
            act = sup.tick(time.time() + k * 0.5 / args.rate, time.monotonic(), b, True)   # update
            n_seen = len(seen)
            if act.kind != 'none':
                sup.record_write(act, *session.write(act))                     # write
            t1 = time.perf_counter()
            t_tick.append(t1 - t0)
            if act.kind == 'move' and len(seen) > n_seen:
                t_frame.append(seen[n_seen] - t_dec)
            k += 1
        session.close()
    report('control tick: read STATUS + update + write MOVE_TO', t_tick)
    report('setpoint decided -> MOVE_TO decoded by the board', t_frame)
    print(f'(control period at {args.rate:.0f} Hz = {1e3 / args.rate:.0f} ms; goal p99 < 10 ms)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
