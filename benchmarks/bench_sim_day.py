"""Benchmark: a whole simulated summer day at Almeria (`./sslfr sim`, = `make demo`).

Prints the wall time of the simulated day (goal: <= 180 s on the project's 2-core
machine, start-up and report included), the start-up and stop times, and the peak
memory of the node set as separate processes (goal: <= 400 MB so a 1 GB Raspberry Pi 3
can run it): the sum of RSS (shared libraries counted once per process, an upper
bound) and the sum of PSS (shared pages divided among the processes sharing them).

    python benchmarks/bench_sim_day.py [--speed X] [--start HH:MM] [--end HH:MM]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--speed', default=None)
    ap.add_argument('--start', default=None)
    ap.add_argument('--end', default=None)
    args = ap.parse_args()
    out = Path(tempfile.mkdtemp(prefix='bench-sim-'))
    cmd = [str(ROOT / 'sslfr'), 'sim', '--out', str(out)]
    for k in ('speed', 'start', 'end'):
        if getattr(args, k):
            cmd += [f'--{k}', getattr(args, k)]
    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', str(200 + os.getpid() % 30))
    t0 = time.monotonic()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.monotonic() - t0
    if proc.returncode != 0:
        print(proc.stdout[-3000:], proc.stderr[-3000:], file=sys.stderr)
        return 1
    s = json.loads((out / 'sim.json').read_text())
    window_h = (s['end_utc'] - s['start_utc']) / 3600
    print(f'simulated day {s["date"]}: {window_h:.2f} h at {s["speed"]:g}x')
    print(f'wall time (whole command, report included): {wall:.1f} s   (goal <= 180 s)')
    print(f'  sim part {s["wall_time_s"]:.1f} s, start-up {s["startup_s"]:.1f} s, ordered stop {s["stop_s"]:.2f} s')
    print(f'peak memory of the node set ({len([k for k in s["rss_pss_at_peak_mb"] if not k.startswith("sim_")])} '
          f'processes): RSS sum {s["peak_rss_nodes_mb"]:.0f} MB, PSS sum {s["peak_pss_nodes_mb"]:.0f} MB '
          f'(goal <= 400 MB)')
    print(f'simulated boards (not on the Pi): RSS sum {s["peak_rss_sim_boards_mb"]:.0f} MB')
    for name, (rss, pss) in sorted(s['rss_pss_at_peak_mb'].items()):
        print(f'  {name:<28} RSS {rss:6.1f} MB  PSS {pss:6.1f} MB')
    if s.get('missing'):
        print('MISSING: ' + '; '.join(s['missing']))
    print(f'output: {out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
