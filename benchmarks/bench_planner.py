"""Benchmark: the planner's work (issue 4 goal: planning a day < 50 ms of CPU).

Figures printed (CPU time of this process, ``time.process_time``; median and worst
of N runs):

- plan a day: the local solar day's per-second table (86,401 instants: SPA, incidence
  angles, phases, three axis commands, sunrise/noon/sunset) for each seed site, as the
  node does at start-up, at 0:00 local solar time and after a clock jump;
- one rolling horizon (121 points with rates) from the table, and from the core
  directly (instants off the table grid);
- one tick's phase lookup and the 1 Hz sun position.

Run: . scripts/env.sh && python benchmarks/bench_planner.py [--runs N]
"""
from __future__ import annotations

import argparse
import datetime as dt
import statistics
import time
from pathlib import Path

import yaml

from sslfr_planner.day_cycle import DayCycle
from sslfr_planner.planner_params import PLANNER_PARAMS
from sslfr_planner.site_source import SiteFix
from sslfr_planner.trajectory import horizon_times

CONFIG = Path(__file__).resolve().parents[1] / 'src' / 'sslfr_bringup' / 'config'
GOAL_MS = 50.0


def cfg_from(name: str) -> dict:
    data = yaml.safe_load((CONFIG / name).read_text())
    cfg = PLANNER_PARAMS.defaults()
    for section in ('/**', 'planner'):
        cfg.update(data[section]['ros__parameters'])
    return PLANNER_PARAMS.coerce(cfg)


def cpu_ms(fn, runs: int) -> tuple[float, float]:
    """(median, worst) CPU milliseconds of ``fn()`` over ``runs`` calls."""
    out = []
    for _ in range(runs):
        t0 = time.process_time()
        fn()
        out.append((time.process_time() - t0) * 1e3)
    return statistics.median(out), max(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--runs', type=int, default=15)
    args = ap.parse_args()
    now = dt.datetime(2026, 6, 21, 10, 0, 0, tzinfo=dt.timezone.utc).timestamp() + 0.37
    polar = PLANNER_PARAMS.defaults()
    polar.update({'site.latitude_deg': 78.22, 'site.longitude_deg': 15.65})
    sites = [('almeria_sslfr.yaml', cfg_from('almeria_sslfr.yaml')),
             ('bucaramanga_single_axis.yaml', cfg_from('bucaramanga_single_axis.yaml')),
             ('florianopolis_lepten.yaml', cfg_from('florianopolis_lepten.yaml')),
             ('polar 78.22N (polar day)', polar)]
    ok = True
    print(f'planning a day (86,401 per-second rows), CPU ms over {args.runs} runs; goal < {GOAL_MS:.0f} ms')
    for name, cfg in sites:
        p = DayCycle(cfg, SiteFix(cfg['site.latitude_deg'], cfg['site.longitude_deg'],
                                    cfg['site.elevation'], 'parameters'))
        p.plan(now)                                   # warm-up (imports, caches)
        med, worst = cpu_ms(lambda: p.plan(now), args.runs)
        ok &= med < GOAL_MS
        print(f'  {name:32s} median {med:6.1f}  worst {worst:6.1f}  '
              f'{"ok" if med < GOAL_MS else "OVER GOAL"}')
    cfg = cfg_from('almeria_sslfr.yaml')
    p = DayCycle(cfg, SiteFix(cfg['site.latitude_deg'], cfg['site.longitude_deg'],
                                cfg['site.elevation'], 'parameters'))
    p.plan(now)
    t = horizon_times(now, 120.0, 1.0)
    med, worst = cpu_ms(lambda: p.auto_horizon(t), 200)
    print(f'horizon 121 points from the table:      median {med:6.3f} ms  worst {worst:6.3f} ms')
    t2 = horizon_times(now, 60.0, 0.5)
    med, worst = cpu_ms(lambda: p.auto_horizon(t2), 50)
    print(f'horizon 121 points off-grid (core):     median {med:6.3f} ms  worst {worst:6.3f} ms')
    med, worst = cpu_ms(lambda: p.auto_phase(now), 500)
    print(f'phase lookup (each tick):               median {med:6.3f} ms  worst {worst:6.3f} ms')
    med, worst = cpu_ms(lambda: p.sun(now), 500)
    print(f'sun position (1 Hz):                    median {med:6.3f} ms  worst {worst:6.3f} ms')
    print('verdict: ' + ('ok' if ok else 'a day plan is over the goal'))
    return 0 if ok else 1


if __name__ == '__main__':
    raise SystemExit(main())
