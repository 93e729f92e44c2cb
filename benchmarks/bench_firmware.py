#!/usr/bin/env python3
"""Firmware-in-the-loop figures (docs/firmware.md, docs/measurements.md):

1. harness speed: simulated seconds per wall second of each board's exact firmware in
   simavr, free-running (``--pace 0``), idle and (axis) stepping at 20 000 steps/s;
   and the CPU a board costs when paced to real time (``--pace 1``);
2. setpoint-to-step latency inside the board: from the last byte of a MOVE_TO frame
   reaching the AVR's UART to the first STEP edge (simulated time, cycle-exact), with
   the simulation's acceleration (400 000 steps/s^2) and the default (6 000);
3. flash / static RAM per board (avr-size).

Usage: python benchmarks/bench_firmware.py [--seconds 3] [--n 40]
The machine's load average is printed with the figures (other processes slow simavr).
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'tests'))
from fw_support import RawHost  # noqa: E402

from sslfr_drivers import firmware as fw, messages as m  # noqa: E402
from sslfr_sim.fw_board import config_record  # noqa: E402
from sslfr_sim.fw_harness import Harness, axis_mech  # noqa: E402


def cpu_of(pid: int) -> float:
    with open(f'/proc/{pid}/stat') as fh:
        f = fh.read().rsplit(')', 1)[1].split()
    return (int(f[11]) + int(f[12])) / os.sysconf('SC_CLK_TCK')


def harness(board, tmp, pace, **opts):
    rec = config_record(board, {'axis': 'mirrors', **opts}, 1)
    return Harness(board, eeprom=rec.eeprom_image(), link=f'{tmp}/{board}', pace=pace,
                   mech=axis_mech('mirrors', 0.0) if board == 'axis' else None).start()


def speed(board, tmp, seconds, stepping=False):
    h = harness(board, tmp, 0.0, max_speed=20000, accel=400000)
    host = RawHost(h.path)
    try:
        if stepping:
            host.request(m.SetZero(0))
        s0, c0, t0 = h.status()['sim_time'], cpu_of(h.proc.pid), time.monotonic()
        k = 0
        while time.monotonic() - t0 < seconds:
            if stepping:      # keep it moving (and the host-silence watchdog fed)
                k += 1
                host.send(m.MoveTo(2000 if k % 2 else -2000, 20000.0))
            time.sleep(0.05)
        st = h.status()
        wall, cpu = time.monotonic() - t0, cpu_of(h.proc.pid) - c0
        steps = st.get('steps_total', 0)
        return (st['sim_time'] - s0) / wall, (st['sim_time'] - s0) / max(cpu, 1e-9), steps
    finally:
        host.close()
        h.stop()


def paced_cpu(board, tmp, seconds):
    h = harness(board, tmp, 1.0)
    try:
        time.sleep(0.5)
        c0, t0 = cpu_of(h.proc.pid), time.monotonic()
        time.sleep(seconds)
        return (cpu_of(h.proc.pid) - c0) / (time.monotonic() - t0)
    finally:
        h.stop()


def latency(tmp, n, accel):
    h = harness('axis', tmp, 1.0, max_speed=20000, accel=accel)
    host = RawHost(h.path)
    out = []
    try:
        host.request(m.SetZero(0))
        for k in range(n):
            h.cmd('mark')
            host.request(m.MoveTo(10 * (k % 2 + 1), 20000.0))
            st = h.wait(lambda s: s['speed'] == 0.0 and s['first_step_after_mark_s'] > 0, 5, 0.01)
            out.append(st['first_step_after_mark_s'] - st['last_rx_s'])
    finally:
        host.close()
        h.stop()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=3.0)
    ap.add_argument('--n', type=int, default=40)
    a = ap.parse_args()
    fw.build()
    tmp = f'/tmp/sslfr-bench-fw-{os.getpid()}'
    os.makedirs(tmp, exist_ok=True)
    print(f'load average before: {os.getloadavg()[0]:.2f}')
    print('board        free-run [x real time, wall]  [x per CPU second]   paced 1x: CPU [% of a core]')
    for board in fw.BOARDS:
        wall, per_cpu, _ = speed(board, tmp, a.seconds)
        cpu = paced_cpu(board, tmp, a.seconds)
        print(f'{board:12s} {wall:10.1f} {per_cpu:28.1f} {100 * cpu:22.1f}')
    wall, per_cpu, steps = speed('axis', tmp, a.seconds, stepping=True)
    print(f'{"axis moving":12s} {wall:10.1f} {per_cpu:28.1f}   ({steps} steps at up to 20000 steps/s)')
    for accel in (400000.0, 6000.0):
        lat = sorted(latency(tmp, a.n, accel))
        print(f'MOVE_TO last byte -> first STEP edge, accel {accel:g} steps/s^2: median '
              f'{1000 * statistics.median(lat):.2f} ms, max {1000 * lat[-1]:.2f} ms (n={len(lat)}, simulated time)')
    print('board        flash [B]   static RAM [B]   (limits 30720 / 1536)')
    for board in fw.BOARDS:
        out = subprocess.run(['avr-size', '-A', str(fw.elf(board))], capture_output=True, text=True).stdout
        sec = {ln.split()[0]: int(ln.split()[1]) for ln in out.splitlines() if ln.startswith('.')}
        print(f'{board:12s} {sec.get(".text", 0) + sec.get(".data", 0):9d} '
              f'{sec.get(".data", 0) + sec.get(".bss", 0) + sec.get(".noinit", 0):16d}')
    print(f'load average after: {os.getloadavg()[0]:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
