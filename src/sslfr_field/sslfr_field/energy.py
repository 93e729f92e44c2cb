"""Energy of the day at the field page (pure, no rclpy).

:class:`DayIntegral` integrates a power over one UTC day of ROS time (the day of the
collectors' bags, ``<id>_YYYY-MM-DD``) by trapezoids; a gap longer than ``max_gap``
adds nothing (the station did not hear the collector then) and an unknown (NaN) sample
ends the running trapezoid. The field page keeps two per collector:

- **absorbed** [kWh]: the power absorbed by the receiver as the day report computes it
  (sslfr_recording.report_energy: seed 000 eqs. 18, 20, 25 on the 3-D ray trace,
  :func:`sslfr_planner.analysis.optics.power`) from the collector's beam irradiance
  (``irradiance/beam``), the sun it publishes (``tracker/sun``) and its axes' measured
  angles (``axes/<axis>/status``), on the optical parameters of its site config
  (:func:`absorbed_model`);
- **thermal** [kWh]: the useful thermal energy delivered, the integral of
  ``absorber/thermal_power`` (m_dot c_p (T_out - T_in)), for a collector with a flow meter.

Both count only what the station heard: a station started at noon shows the energy since
noon, and a collector lost for a while misses that while.
"""
from __future__ import annotations

import math

#: [s] the longest gap between two samples that is still integrated across (the beam and
#: thermal power arrive at >= 1 Hz; the day report's gap rule is of the same order)
MAX_GAP = 10.0
#: [s] a UTC day
DAY = 86400.0


class DayIntegral:
    """The integral of a power [W] over the UTC day of its latest sample, in joules."""

    def __init__(self, max_gap: float = MAX_GAP):
        self.max_gap = float(max_gap)
        self.day: int | None = None
        self.joules = 0.0
        self._t: float | None = None
        self._y = 0.0

    def add(self, t: float, watts: float) -> None:
        """One sample: ``t`` [s, ROS time since the epoch], ``watts`` [W] (NaN: unknown).

        A new UTC day starts from zero; a sample older than the last one is ignored."""
        if not math.isfinite(t) or t <= 0.0:
            return
        day = int(t // DAY)
        if self.day is None or day > self.day:
            self.day, self.joules, self._t = day, 0.0, None
        elif day < self.day or (self._t is not None and t <= self._t):
            return
        if not math.isfinite(watts):
            self._t = None
            return
        if self._t is not None and t - self._t <= self.max_gap:
            self.joules += 0.5 * (watts + self._y) * (t - self._t)
        self._t, self._y = t, watts

    def kwh(self, now: float | None = None) -> float | None:
        """The day's energy [kWh]; None before any sample or (``now`` [s, ROS time] given)
        when ``now`` is already another day."""
        if self.day is None or (now is not None and math.isfinite(now) and now > 0 and int(now // DAY) != self.day):
            return None
        return self.joules / 3.6e6


def absorbed_model(config: str | None):
    """``power(beam, zenith, azimuth, mirrors, mobile_structure, secondary_reflector) -> W``
    for the collector of site config ``config`` (its planner's ``collector.*`` geometry and
    azimuth, as the day report takes them: :func:`sslfr_recording.day.reference`).

    ``beam`` [W/m^2], sun ``zenith`` and ``azimuth`` [rad] (clockwise from north), the
    three axes' measured angles [rad]. The sun below the horizon gives 0 W. Raises
    ValueError (or the node set's NodeSetError) for a config it cannot use."""
    import numpy as np
    from sslfr_planner import raytrace
    from sslfr_planner.analysis.optics import OpticalParameters
    from sslfr_planner.analysis.optics import power as optics_power
    from sslfr_planner.day_cycle import make_collector
    from sslfr_recording.day import planner_config

    c = make_collector(planner_config(config or None))
    params = OpticalParameters(geometry=c.geometry)

    def power(beam: float, zenith: float, azimuth: float, mirrors: float, mobile: float, secondary: float) -> float:
        if not all(math.isfinite(x) for x in (beam, zenith, azimuth, mirrors, mobile, secondary)):
            return math.nan
        if zenith >= math.pi / 2 or beam <= 0.0:
            return 0.0
        sun = raytrace.sun_vector(np.float64(zenith), np.float64(azimuth), c.azimuth)
        q = float(optics_power(np.float64(beam), sun, np.float64(mirrors), np.float64(mobile), np.float64(secondary),
                               params))
        return q if math.isfinite(q) else 0.0
    return power
