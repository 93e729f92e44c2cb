"""The day's absorbed energy: ideal, under the collector's law, and achieved.

The optical model of seed 000 (eqs. 18, 20, 25) on the 3-D ray trace, fed with the
recorded beam irradiance, on the run's own collector: with a collector description
(:func:`.day.run_description`) its optics (lines, widths, gaps, central line or not,
receiver height and width, tube, axis azimuth) and its law
(:mod:`sslfr_planner.analysis.ideal`): the ideal has every line at its exact angle
(seed 004 eqs. 3-4; seed 000: the central mirror at theta_t'/2 on the law's tilts), the
law's energy the lines on the reference's drive command (its linearisation, its
steps), the achieved energy the lines riding on the measured drive and the measured
tilts. Without a description (a config naming none): the planner's collector
parameters with the seed 000 model (:func:`sslfr_planner.analysis.performance.day_energy`).
"""
from __future__ import annotations

import numpy as np
from sslfr_common.contract import MIRRORS, MOBILE_STRUCTURE, SECONDARY_REFLECTOR

from .day import Reference, reference

#: instants traced at once (bounded memory on a whole day at 1 Hz)
CHUNK = 8192


def _integral(t: np.ndarray, q: np.ndarray) -> float:
    """Trapezoidal integral of the power ``q`` [W] over ``t`` [s], in kWh (NaN counts 0)."""
    q = np.nan_to_num(np.asarray(q, dtype=float), nan=0.0)
    return float(np.sum((q[1:] + q[:-1]) / 2.0 * np.diff(t)) / 3.6e6)


def _chunked(fn, n: int, *arrays) -> np.ndarray:
    """``fn`` over slices of :data:`CHUNK` instants of the (n,) ``arrays``, concatenated."""
    return np.concatenate([fn(*(a[k:k + CHUNK] for a in arrays)) for k in range(0, n, CHUNK)]) if n else np.zeros(0)


def energy_estimate(site: dict, t: np.ndarray, beam: np.ndarray, measured: dict, config: str | None,
                    ref: Reference | None = None) -> dict:
    """Absorbed energy of the day [kWh]: 'ideal_kwh', 'law_kwh' (with a description),
    'achieved_kwh' and a 'note' (or only a 'note' saying why there is no estimate).

    ``beam`` [W/m^2] at ``t`` [s]; ``measured``: axis -> (t, {'measured': rad, ...}) from
    ``axes/<axis>/status``; ``config`` the run's site config (or ``ref``, its
    :class:`.day.Reference`, already built). A movement of the collector without
    status counts as ideal (the note says which).
    """
    try:
        from sslfr_planner.analysis import ideal
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
    if ref is None:
        ref = reference(config, site['latitude'], site['longitude'], site.get('altitude', 0.0))
    table = ref(t)
    law = {a: np.asarray(getattr(table, a), dtype=float) for a in ref.joints}
    held = dict(law)
    for axis, (ta, va) in measured.items():
        good = np.isfinite(va['measured'])
        if axis in held and good.sum() >= 2:
            held[axis] = np.interp(t, ta[good], va['measured'][good])
    missing = [a for a in ref.joints if a not in measured]
    zen, azi = np.asarray(table.zenith, dtype=float), np.asarray(table.azimuth, dtype=float)
    desc = ref.description
    if desc is None:
        c = ref.collector
        try:
            params = OpticalParameters(geometry=c.geometry)
        except ValueError as exc:
            return {'note': f'energy estimate unavailable ({exc})'}
        args = (t, beam, zen, azi)        # every contract joint (ref.joints): the seed 000 model's three
        e_ideal = day_energy(*args, *(law[a] for a in ref.joints), params, c.azimuth) / 1000.0
        e_held = day_energy(*args, *(held[a] for a in ref.joints), params, c.azimuth) / 1000.0
        note = ('seed 000 optical model on the 3-D ray trace (docs/optics.md), the planner\'s collector '
                'parameters (no collector description), recorded beam irradiance')
        if missing:
            note += '; no status for ' + ', '.join(missing) + ' (taken as ideal)'
        return {'ideal_kwh': e_ideal, 'achieved_kwh': e_held, 'note': note}
    dni = np.where(zen < np.pi / 2, beam, 0.0)
    zeros = np.zeros(t.size)
    bm_law, ba_law = law.get(MOBILE_STRUCTURE, zeros), law.get(SECONDARY_REFLECTOR, zeros)
    bm, ba = held.get(MOBILE_STRUCTURE, zeros), held.get(SECONDARY_REFLECTOR, zeros)
    n = t.size
    q_ideal = _chunked(lambda z, a, g, m, r: ideal.ideal_absorbed_power(desc, z, a, g, m, r),
                       n, zen, azi, dni, bm_law, ba_law)
    q_law = _chunked(lambda z, a, g, d, m, r: ideal.held_absorbed_power(desc, z, a, g, d, m, r),
                     n, zen, azi, dni, law[MIRRORS], bm_law, ba_law)
    q_held = _chunked(lambda z, a, g, d, m, r: ideal.held_absorbed_power(desc, z, a, g, d, m, r),
                      n, zen, azi, dni, held[MIRRORS], bm, ba)
    note = (f'seed 000 optical model on the 3-D ray trace (docs/optics.md) on the collector {desc.name} '
            f'({desc.optics.lines} lines, {ideal.aperture_area(desc):g} m2 of mirrors), recorded beam irradiance')
    if missing:
        note += '; no status for ' + ', '.join(missing) + ' (taken as ideal)'
    return {'ideal_kwh': _integral(t, q_ideal), 'law_kwh': _integral(t, q_law),
            'achieved_kwh': _integral(t, q_held), 'note': note}
