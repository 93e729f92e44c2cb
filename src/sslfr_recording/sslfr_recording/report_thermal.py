"""The day report's thermal output: energy delivered and mean efficiency (pure).

From the recorded ``absorber/thermal_power`` (a collector with a flow meter; nothing
otherwise): the useful energy delivered over the recording, E = integral of
P dt [kWh] (trapezoids over gaps no longer than the report's gap limit; a negative
power, the water cooling in the tube, counts negative), and the mean efficiency while
tracking in the sense of seed 003 section 3.2: the useful energy over the beam energy
on the aperture, integral P dt / integral G_b A_a dt, over the samples in phase
TRACKING whose efficiency was computed (beam known and above the node's minimum).
"""
from __future__ import annotations

import math

import numpy as np

from .day import Day


def _integral(t: np.ndarray, y: np.ndarray, max_gap: float) -> float:
    """Trapezoid integral of y dt [unit x s] over the gaps <= ``max_gap`` [s]."""
    if len(t) < 2:
        return 0.0
    dt = np.diff(t)
    area = 0.5 * (y[1:] + y[:-1]) * dt
    return float(area[(dt > 0) & (dt <= max_gap)].sum())


def thermal_of(day: Day, max_gap: float) -> dict:
    """The thermal figures of ``day`` ({} without ``absorber/thermal_power``): 'kwh'
    delivered, 'efficiency' mean while tracking (NaN: no such sample), 'tracking_s'
    [s] covered by it, 'peak_w' and its time 't_peak', 'mean_lph' the mean flow [L/h],
    'samples', 'nan_samples' (power unknown: a thermocouple open)."""
    s = day.thermal
    if not len(s):
        return {}
    t, p = s.t, s['power'].astype(float)
    ok = np.isfinite(p)
    out = {'kwh': _integral(t[ok], p[ok], max_gap) / 3.6e6, 'samples': len(t), 'nan_samples': int((~ok).sum()),
           'mean_lph': float(np.nanmean(s['volume_flow'])) * 3.6e6,
           'peak_w': float(p[ok].max()) if ok.any() else math.nan,
           't_peak': float(t[ok][np.argmax(p[ok])]) if ok.any() else math.nan}
    pt = day.phase.t
    tracking = np.zeros(len(t), dtype=bool)
    if len(pt):
        ph = np.asarray(day.phase['phase'])[np.clip(np.searchsorted(pt, t, side='right') - 1, 0, None)]
        tracking = (ph == 2) & (t >= pt[0])
    k = tracking & ok & np.isfinite(s['efficiency'].astype(float))
    incident = _integral(t[k], (s['beam'] * s['aperture']).astype(float)[k], max_gap)
    out['efficiency'] = _integral(t[k], p[k], max_gap) / incident if incident > 0 else math.nan
    out['tracking_s'] = _integral(t[k], np.ones(int(k.sum())), max_gap)
    return out


def render(th: dict, utc) -> list[str]:
    """The report's lines of :func:`thermal_of`'s figures (none without a flow meter)."""
    if not th:
        return []
    eta = th['efficiency']
    peak = f'{th["peak_w"]:.0f} W at {utc(th["t_peak"])}' if math.isfinite(th['peak_w']) else '-'
    return [f'thermal output  {th["kwh"]:.3f} kWh delivered (m_dot c_p (T_out - T_in)), peak {peak}, '
            f'mean flow {th["mean_lph"]:.1f} L/h'
            + (f', {th["nan_samples"]} samples without power (thermocouple)' if th['nan_samples'] else ''),
            '  efficiency    ' + (f'{100.0 * eta:.2f} % mean while tracking (useful / beam on the aperture, '
                                  f'seed 003 section 3.2; over {th["tracking_s"] / 3600.0:.2f} h)'
                                  if math.isfinite(eta) else 'not computed: no tracking sample with a beam')]
