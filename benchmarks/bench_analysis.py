"""Benchmark: a year of the SSLFR performance analysis at 10-minute steps for one site
(issue goal: < 5 s), split into its parts, plus seed 001's tilt search on an 11x11 grid.

Run: . scripts/env.sh && python benchmarks/bench_analysis.py
"""
from __future__ import annotations

import os
import time

import numpy as np

from sslfr_planner.analysis import performance
from sslfr_planner.analysis.optics import OpticalParameters
from sslfr_planner.analysis.performance import AnalysisSite, Costs, YearSky


def timed(fn, repeat=3):
    """Best wall time [s] and CPU time [s] of ``repeat`` runs, and the last result."""
    best, cpu, out = float('inf'), float('inf'), None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return best, cpu, out


def main():
    site = AnalysisSite(36 + 50 / 60 + 7 / 3600, -(2 + 24 / 60 + 8 / 3600), 22.0)
    p = OpticalParameters()
    t_sky, c_sky, sky = timed(lambda: YearSky.compute(site, 2023, 600.0))
    three = performance.with_tube(p, (-1.005, 1.005))
    flat_p = performance.with_tube(p, (-2.037, -0.037))
    t_eq16, c_eq16, eq16 = timed(lambda: performance.annual_energy(sky, site, three, 'eq16', model='eq18',
                                                                   costs=Costs(5865.98)))
    t_flat, c_flat, flat = timed(lambda: performance.annual_energy(sky, site, flat_p, 'horizontal', model='eq18',
                                                                   costs=Costs(5299.53)))
    t_cont, c_cont, cont = timed(lambda: performance.annual_energy(sky, site, three, 'continuous'))
    total = t_sky + t_eq16
    print(f'load average {os.getloadavg()[0]:.1f} (timings on a loaded machine are upper bounds)')
    print(f'year at 10-min steps, Almeria: {sky.t.size} daylight instants x {p.geometry.n_mirrors} mirrors')
    print(f'  sun (SPA) + clear-sky DNI: {t_sky * 1e3:8.1f} ms wall, {c_sky * 1e3:8.1f} ms CPU')
    print(f'  annual energy (3-D trace), eq16:       {t_eq16 * 1e3:8.1f} ms wall, {c_eq16 * 1e3:8.1f} ms CPU')
    print(f'  annual energy (3-D trace), horizontal: {t_flat * 1e3:8.1f} ms wall, {c_flat * 1e3:8.1f} ms CPU')
    print(f'  annual energy (3-D trace), continuous: {t_cont * 1e3:8.1f} ms wall, {c_cont * 1e3:8.1f} ms CPU')
    print(f'  one year for one site and law, total: {total:.3f} s (goal < 5 s): {"OK" if total < 5 else "MISSED"}')
    print(f'  seed 000 comparison (eq18 model): energy {100 * (eq16.energy_wh / flat.energy_wh - 1):+.2f} % '
          f'(paper +16.64 %), EAR {100 * (eq16.ear / flat.ear - 1):+.2f} % (+78.46 %), '
          f'LCOE {100 * (eq16.lcoe / flat.lcoe - 1):+.2f} % (-4.62 %)')
    t_tilt, c_tilt, res = timed(lambda: performance.tilt_search(sky, site, p, grid=11), repeat=1)
    bm, ba = np.degrees(res.optimum)
    print(f'tilt search 11x11 (seed 001): {t_tilt:.2f} s wall, {c_tilt:.2f} s CPU, optimum beta_M = {bm:.2f} deg, '
          f'beta_a = {ba:.2f} deg (latitude/2 = {site.latitude_deg / 2:.2f}, latitude = {site.latitude_deg:.2f})')


if __name__ == '__main__':
    main()
