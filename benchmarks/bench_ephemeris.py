"""Benchmark: one whole day at 1 s (86,400 instants), all columns of ``sslfr plan``.

Issue 3 goals: <= 20 ms median in-process for the whole table (sun position, incidence
angles, phases, axis commands; ``tabulate_day``) and >= 20x faster than pvlib's
``spa_python`` on the same instants (sun position only, numpy back end). Also prints
the agreement with pvlib (max |difference| in zenith and azimuth), the distance of the
fast path from the exact SPA path, and how far the seeds' own low-accuracy formulas
(seed 000 eqs. 2-8, seed 003 eqs. 1-2) are from the SPA.

Run: . scripts/env.sh && python benchmarks/bench_ephemeris.py [--repeat N]
"""
from __future__ import annotations

import argparse
import datetime as dt
import math
import statistics
import time

import numpy as np

from sslfr_planner import solar_simple, spa
from sslfr_planner.collector import Collector
from sslfr_planner.tracking_table import day_grid, tabulate_day
from sslfr_planner.site import Site


def timings(fn, repeat, clock=time.perf_counter):
    out = []
    for _ in range(repeat):
        t0 = clock()
        fn()
        out.append(clock() - t0)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--repeat', type=int, default=21, help='runs of tabulate_day (median reported)')
    ap.add_argument('--pvlib-repeat', type=int, default=3, help='runs of pvlib spa_python')
    a = ap.parse_args(argv)

    import pandas as pd
    import pvlib.solarposition as pvsp

    day = dt.date(2026, 6, 21)
    lat, lon, elev = 36.8353, -2.4022, 22.0  # Almeria (seed 000)
    site = Site.from_degrees(lat, lon, elev, delta_t=69.2)
    collector = Collector()
    t = day_grid(day, 1.0)
    idx = pd.to_datetime(t, unit='s', utc=True)

    tabulate_day(day, site, collector, 1.0)  # warm-up
    ours = timings(lambda: tabulate_day(day, site, collector, 1.0), a.repeat)
    ours_cpu = timings(lambda: tabulate_day(day, site, collector, 1.0), a.repeat, time.process_time)
    sun_only = timings(lambda: spa.sun_position(t, site), a.repeat)
    theirs = timings(lambda: pvsp.spa_python(idx, lat, lon, elev, delta_t=69.2, how='numpy'), a.pvlib_repeat)
    theirs_cpu = timings(lambda: pvsp.spa_python(idx, lat, lon, elev, delta_t=69.2, how='numpy'), a.pvlib_repeat,
                         time.process_time)
    med_ours, med_sun, med_pv = statistics.median(ours), statistics.median(sun_only), statistics.median(theirs)

    table = tabulate_day(day, site, collector, 1.0)
    ref = pvsp.spa_python(idx, lat, lon, elev, delta_t=69.2, how='numpy')
    dz = np.abs(np.degrees(table.zenith) - ref['apparent_zenith'].to_numpy())
    da = np.abs((np.degrees(table.azimuth) - ref['azimuth'].to_numpy() + 180.0) % 360.0 - 180.0)
    ex = spa.sun_position(t, site, exact=True)
    fz = np.abs(np.degrees(table.zenith - ex.zenith))
    fa = np.abs(np.degrees((table.azimuth - ex.azimuth + math.pi) % (2 * math.pi) - math.pi))

    import os
    print(f'day table {day} at 1 s, {t.size} instants, Almeria (36.84 N, 2.40 W), all `sslfr plan` columns')
    print(f'  machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f} (1 min) at the end of the runs')
    print(f'  tabulate_day (ours, in-process)     median {med_ours * 1e3:8.2f} ms  '
          f'(min {min(ours) * 1e3:.2f}, max {max(ours) * 1e3:.2f}, n={len(ours)})   goal <= 20 ms: '
          f'{"OK" if med_ours <= 0.020 else "MISSED"}')
    print(f'  tabulate_day CPU time (process)     median {statistics.median(ours_cpu) * 1e3:8.2f} ms  '
          '(wall time above includes waiting for the shared CPUs)')
    print(f'  sun_position only (ours)        median {med_sun * 1e3:8.2f} ms')
    print(f'  pvlib spa_python (numpy)        median {med_pv * 1e3:8.2f} ms  (n={len(theirs)})')
    print(f'  ratio pvlib / tabulate_day          {med_pv / med_ours:8.1f} x   goal >= 20x: '
          f'{"OK" if med_pv / med_ours >= 20 else "MISSED"}')
    print(f'  ratio pvlib / sun_position      {med_pv / med_sun:8.1f} x')
    cpu_ratio = statistics.median(theirs_cpu) / statistics.median(ours_cpu)
    print(f'  ratio of CPU-time medians, pvlib / tabulate_day {cpu_ratio:8.1f} x '
          f'(pvlib CPU {statistics.median(theirs_cpu) * 1e3:.1f} ms)')
    print(f'  max |ours - pvlib|: zenith {dz.max():.2e} deg, azimuth {da.max():.2e} deg')
    print(f'  max |fast - exact SPA path|: zenith {fz.max():.2e} deg, azimuth {fa.max():.2e} deg')

    # random instants 1950-2100, random sites |lat| <= 85 (the test's check, bigger sample)
    rng = np.random.default_rng(1)
    t0 = dt.datetime(1950, 1, 1, tzinfo=dt.timezone.utc).timestamp()
    t1 = dt.datetime(2100, 12, 31, tzinfo=dt.timezone.utc).timestamp()
    worst_z = worst_a = 0.0
    n = 0
    for _ in range(100):
        la, lo = rng.uniform(-85, 85), rng.uniform(-180, 180)
        tt = np.sort(rng.uniform(t0, t1, 100))
        r = pvsp.spa_python(pd.to_datetime(tt, unit='s', utc=True), la, lo, 100.0, delta_t=67.0, how='numpy')
        z, az, _ = spa.solar_position(tt, la, lo, 100.0, 1013.25, 12.0, 67.0)
        worst_z = max(worst_z, np.max(np.abs(z - r['apparent_zenith'].to_numpy())))
        worst_a = max(worst_a, np.max(np.abs((az - r['azimuth'].to_numpy() + 180) % 360 - 180)))
        n += tt.size
    print(f'  {n} random instants 1950-2100, |lat| <= 85: max |ours - pvlib| zenith {worst_z:.2e} deg, '
          f'azimuth {worst_a:.2e} deg (goal < 1e-5)')

    # the seeds' own formulas against the SPA (a year at Almeria, sun above 5 deg)
    ty = dt.datetime(2026, 1, 1, tzinfo=dt.timezone.utc).timestamp() + np.arange(0, 365 * 86400.0, 600.0)
    s = spa.sun_position(ty, site)
    up = s.zenith < math.radians(85)
    for name, fn in (('seed 000 eqs. 2-6', solar_simple.seed000_position),
                     ('seed 003 eqs. 1-3', solar_simple.seed003_position)):
        for eot in (True, False):
            z, az = fn(ty, site.latitude, site.longitude, equation_of_time=eot)
            ez = np.degrees(np.abs(z - s.zenith))[up]
            ea = np.degrees(np.abs((az - s.azimuth + math.pi) % (2 * math.pi) - math.pi))[up]
            print(f'  {name} ({"with" if eot else "without"} equation of time) vs SPA over 2026: '
                  f'zenith max {ez.max():.3f} deg (mean {ez.mean():.3f}), azimuth max {ea.max():.3f} deg')


if __name__ == '__main__':
    main()
