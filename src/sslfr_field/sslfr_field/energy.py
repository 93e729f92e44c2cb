"""Energy of the day at the field page (pure, no rclpy).

:class:`DayIntegral` integrates a power over one UTC day of ROS time (the day of the
collectors' bags, ``<id>_YYYY-MM-DD``) by trapezoids; a gap longer than ``max_gap``
adds nothing (the station did not hear the collector then) and an unknown (NaN) sample
ends the running trapezoid. The field page keeps two per collector:

- **absorbed** [kWh]: the power absorbed by the receiver as the day report computes its
  achieved energy (sslfr_recording.report_energy: seed 000 eqs. 18, 20, 25 on the 3-D
  ray trace, on the collector description its site config names) from the collector's
  beam irradiance (``irradiance/beam``), the sun it publishes (``tracker/sun``) and its
  axes' measured angles (``axes/<axis>/status``): :class:`AbsorbedModel`;
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


class AbsorbedModel:
    """The absorbed power [W] of one collector, as the day report computes its achieved
    energy (sslfr_recording.report_energy): with the collector description its site
    config names, the described optics with every line riding on the measured mirror
    drive and the measured longitudinal tilts (0 for a movement it does not have:
    :func:`sslfr_planner.analysis.ideal.held_absorbed_power`); without one, seed 000's
    model on the planner's collector parameters (:func:`sslfr_planner.analysis.optics.power`).

    ``joints``: the axes whose measured angle it needs."""

    def __init__(self, config: str | None):
        from sslfr_common.contract import JOINTS
        from sslfr_planner.analysis.optics import OpticalParameters
        from sslfr_planner.day_cycle import make_collector
        from sslfr_recording.day import planner_config, run_description

        self.description = run_description(config or None)
        c = make_collector(planner_config(config or None), self.description)
        self.azimuth = c.azimuth
        if self.description is None:
            self.params = OpticalParameters(geometry=c.geometry)
            self.joints = tuple(JOINTS)
        else:
            self.joints = tuple(j for j in JOINTS if j in self.description.movements)

    def __call__(self, beam: float, zenith: float, azimuth: float, angles: dict) -> float:
        """``beam`` [W/m^2], sun ``zenith`` and ``azimuth`` [rad] (clockwise from north),
        ``angles`` axis -> measured angle [rad] (each of :attr:`joints`); NaN when one is
        unknown, 0 W with the sun below the horizon."""
        import numpy as np
        from sslfr_common.contract import MIRRORS, MOBILE_STRUCTURE, SECONDARY_REFLECTOR
        values = [beam, zenith, azimuth] + [angles.get(j) for j in self.joints]
        if not all(x is not None and math.isfinite(x) for x in values):
            return math.nan
        if zenith >= math.pi / 2 or beam <= 0.0:
            return 0.0
        z, a, g = np.float64(zenith), np.float64(azimuth), np.float64(beam)
        bm, ba = np.float64(angles.get(MOBILE_STRUCTURE, 0.0)), np.float64(angles.get(SECONDARY_REFLECTOR, 0.0))
        if self.description is None:
            from sslfr_planner import raytrace
            from sslfr_planner.analysis.optics import power
            q = power(g, raytrace.sun_vector(z, a, self.azimuth), np.float64(angles[MIRRORS]), bm, ba, self.params)
        else:
            from sslfr_planner.analysis import ideal
            q = ideal.held_absorbed_power(self.description, z, a, g, np.float64(angles[MIRRORS]), bm, ba)
        q = float(q)
        return q if math.isfinite(q) else 0.0


def absorbed_model(config: str | None) -> AbsorbedModel:
    """The :class:`AbsorbedModel` of the collector of site config ``config``; raises
    ValueError (a DescriptionError, the node set's NodeSetError) for a config it cannot use."""
    return AbsorbedModel(config)
