"""Benchmark: a year of the SSLFR performance analysis at 10-minute steps for one site
(issue goal: < 5 s), split into its parts, plus seed 001's tilt search on an 11x11 grid.

Run: . scripts/env.sh && python benchmarks/bench_analysis.py
"""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from sslfr_planner import analysis
from sslfr_planner.analysis import AnalysisSite, Costs, YearSky
from sslfr_planner.optics import OpticalParameters


def timed(fn, repeat=3):
    best, out = float('inf'), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main():
    site = AnalysisSite(36 + 50 / 60 + 7 / 3600, -(2 + 24 / 60 + 8 / 3600), 22.0)
    p = OpticalParameters()
    t_sky, sky = timed(lambda: YearSky.compute(site, 2023, 600.0))
    t_cont, cont = timed(lambda: analysis.annual_energy(sky, site, replace(p, tube_right=-1.005, tube_left=1.005),
                                                        'continuous', costs=Costs(5865.98)))
    t_flat, flat = timed(lambda: analysis.annual_energy(sky, site, replace(p, tube_right=-2.037, tube_left=-0.037),
                                                        'horizontal', costs=Costs(5299.53)))
    total = t_sky + t_cont
    print(f'year at 10-min steps, Almeria: {sky.t.size} daylight instants x {p.n_mirrors} mirrors')
    print(f'  sun (SPA) + clear-sky DNI: {t_sky * 1e3:8.1f} ms')
    print(f'  annual energy, continuous: {t_cont * 1e3:8.1f} ms   E = {cont.energy_wh / 1e6:.3f} MWh, '
          f'A = {cont.area_m2:.3f} m2, EAR = {cont.ear / 1e6:.3f} MWh/m2, LCOE = {cont.lcoe:.4f} EUR/kWh')
    print(f'  annual energy, horizontal: {t_flat * 1e3:8.1f} ms   E = {flat.energy_wh / 1e6:.3f} MWh, '
          f'A = {flat.area_m2:.3f} m2, EAR = {flat.ear / 1e6:.3f} MWh/m2, LCOE = {flat.lcoe:.4f} EUR/kWh')
    print(f'  one year for one site, total: {total:.3f} s (goal < 5 s): {"OK" if total < 5 else "MISSED"}')
    print(f'  three movements vs horizontal: energy {100 * (cont.energy_wh / flat.energy_wh - 1):+.2f} % '
          f'(seed 000: +16.64 %), EAR {100 * (cont.ear / flat.ear - 1):+.2f} % (+78.46 %), '
          f'LCOE {100 * (cont.lcoe / flat.lcoe - 1):+.2f} % (-4.62 %)')
    t_tilt, res = timed(lambda: analysis.tilt_search(sky, site, p, grid=11), repeat=1)
    bm, ba = np.degrees(res.optimum)
    print(f'tilt search 11x11 (seed 001): {t_tilt:.2f} s, optimum beta_M = {bm:.2f} deg, beta_a = {ba:.2f} deg '
          f'(latitude/2 = {site.latitude_deg / 2:.2f}, latitude = {site.latitude_deg:.2f})')


if __name__ == '__main__':
    main()
