"""The day's absorbed energy, ideal vs achieved: the optical model of seed 000
(eqs. 18, 20, 25; :func:`sslfr_planner.analysis.performance.day_energy`) fed with the
recorded beam irradiance, once with the ideal axis angles of the run's reference
(:func:`.day.reference`) and once with the measured ones."""
from __future__ import annotations

import numpy as np
from sslfr_common.contract import JOINTS

from .day import reference


def energy_estimate(site: dict, t: np.ndarray, beam: np.ndarray, measured: dict, config: str | None) -> dict:
    """Absorbed energy of the day [kWh], ideal vs achieved (seed 000 eqs. 18, 20, 25).

    ``beam`` [W/m^2] at ``t`` [s]; ``measured``: axis -> (t, {'measured': rad, ...}) from
    ``axes/<axis>/status``. The ideal angles and the sun come from
    :func:`sslfr_planner.tracking_table.evaluate`; an axis without status counts as ideal.
    """
    try:
        from sslfr_planner.analysis.optics import OpticalParameters
        from sslfr_planner.analysis.performance import day_energy
    except ImportError:
        return {'note': 'energy estimate unavailable (sslfr_planner not installed)'}
    if not site or not np.isfinite(site.get('latitude', np.nan)):
        return {'note': 'energy estimate unavailable (no site in the bag)'}
    ok = np.isfinite(beam)
    t, beam = t[ok], np.clip(beam[ok], 0.0, None)
    if t.size < 2:
        return {'note': 'energy estimate unavailable (no valid beam samples)'}
    ref = reference(config, site['latitude'], site['longitude'], site.get('altitude', 0.0))
    c = ref.collector
    table = ref(t)
    try:
        params = OpticalParameters(geometry=c.geometry)
    except ValueError as exc:
        return {'note': f'energy estimate unavailable ({exc})'}
    ideal = {a: np.asarray(getattr(table, a), dtype=float) for a in JOINTS}
    held = dict(ideal)
    for axis, (ta, va) in measured.items():
        good = np.isfinite(va['measured'])
        if good.sum() >= 2:
            held[axis] = np.interp(t, ta[good], va['measured'][good])
    args = (t, beam, table.zenith, table.azimuth)
    e_ideal = day_energy(*args, *(ideal[a] for a in JOINTS), params, c.azimuth) / 1000.0
    e_held = day_energy(*args, *(held[a] for a in JOINTS), params, c.azimuth) / 1000.0
    missing = [a for a in JOINTS if a not in measured]
    note = 'seed 000 optical model on the 3-D ray trace (docs/optics.md), recorded beam irradiance'
    if missing:
        note += '; no status for ' + ', '.join(missing) + ' (taken as ideal)'
    return {'ideal_kwh': e_ideal, 'achieved_kwh': e_held, 'note': note}
