"""Beam (direct normal) irradiance for the performance analysis (no rclpy).

Three sources, all returning DNI [W/m^2] at given UTC instants [s since the epoch]:

* :func:`clear_sky_dni`: the Ineichen-Perez clear-sky model (Ineichen & Perez 2002,
  as implemented by pvlib.clearsky.ineichen) with the monthly Linke turbidity
  climatology pvlib ships (Remund et al. 2003), interpolated to the day, and the
  Kasten-Young 1989 air mass. It is an upper bound of a real year (every day
  cloudless); the seeds used PVGIS monthly averages instead, which are not
  available offline (docs/optics.md).
* :func:`dni_from_csv`: measured DNI from a CSV file with columns ``utc`` (ISO 8601)
  and ``dni_w_m2``, linearly interpolated, 0 outside the file's span.
* :func:`dni_from_samples`: any (time, DNI) series, e.g. a recorded day's
  ``irradiance/beam`` read from a bag by the report.
"""
from __future__ import annotations

import csv
from datetime import datetime, timezone

import numpy as np


def clear_sky_dni(t, zenith, latitude_deg: float, longitude_deg: float, elevation: float = 0.0):
    """Clear-sky DNI, Ineichen-Perez model [W/m^2].

    Parameters
    ----------
    t : array_like
        UTC instants [s since 1970-01-01].
    zenith : array_like
        Apparent (refracted) solar zenith angle at ``t`` [rad].
    latitude_deg, longitude_deg : float
        Site [deg], north and east positive (used for the Linke turbidity map only).
    elevation : float
        Site altitude [m] (air pressure from the standard atmosphere).

    Returns
    -------
    numpy.ndarray
        DNI [W/m^2], 0 with the sun below the horizon.
    """
    import pandas as pd
    import pvlib

    t = np.atleast_1d(np.asarray(t, dtype=float))
    z = np.degrees(np.broadcast_to(np.asarray(zenith, dtype=float), t.shape))
    times = pd.DatetimeIndex(pd.to_datetime(t, unit='s', utc=True))
    linke = pvlib.clearsky.lookup_linke_turbidity(times, latitude_deg, longitude_deg).to_numpy()
    am_rel = pvlib.atmosphere.get_relative_airmass(z, model='kastenyoung1989')
    am_abs = pvlib.atmosphere.get_absolute_airmass(am_rel, pvlib.atmosphere.alt2pres(elevation))
    dni_extra = pvlib.irradiance.get_extra_radiation(times).to_numpy()
    out = pvlib.clearsky.ineichen(z, am_abs, linke, altitude=elevation, dni_extra=dni_extra)
    dni = np.nan_to_num(np.asarray(out['dni'], dtype=float), nan=0.0)
    return np.where(z < 90.0, np.clip(dni, 0.0, None), 0.0)


def dni_from_samples(t, sample_t, sample_dni):
    """DNI at ``t`` [W/m^2] from a measured series (linear interpolation, 0 outside it).

    Samples that are NaN or negative are dropped.
    """
    st = np.asarray(sample_t, dtype=float)
    sd = np.asarray(sample_dni, dtype=float)
    keep = np.isfinite(st) & np.isfinite(sd) & (sd >= 0)
    st, sd = st[keep], sd[keep]
    if st.size == 0:
        raise ValueError('no valid DNI samples')
    order = np.argsort(st)
    return np.interp(np.asarray(t, dtype=float), st[order], sd[order], left=0.0, right=0.0)


def read_dni_csv(path) -> tuple[np.ndarray, np.ndarray]:
    """Read a DNI CSV (columns ``utc`` ISO 8601 and ``dni_w_m2``) -> (t [s], DNI [W/m^2]).

    Raises ValueError naming the line of the first malformed row.
    """
    times, values = [], []
    with open(path, newline='') as fh:
        reader = csv.DictReader(fh)
        if reader.fieldnames is None or not {'utc', 'dni_w_m2'} <= set(reader.fieldnames):
            raise ValueError(f'{path}: expected a header with columns utc,dni_w_m2')
        for lineno, row in enumerate(reader, start=2):
            try:
                stamp = datetime.fromisoformat(row['utc'].strip().replace('Z', '+00:00'))
                if stamp.tzinfo is None:
                    stamp = stamp.replace(tzinfo=timezone.utc)
                times.append(stamp.timestamp())
                values.append(float(row['dni_w_m2']))
            except (ValueError, TypeError, AttributeError) as exc:
                raise ValueError(f'{path}:{lineno}: bad row {row!r}: {exc}') from None
    return np.asarray(times), np.asarray(values)


def dni_from_csv(t, path):
    """Measured DNI from a CSV file, interpolated at ``t`` [W/m^2]."""
    st, sd = read_dni_csv(path)
    return dni_from_samples(t, st, sd)
