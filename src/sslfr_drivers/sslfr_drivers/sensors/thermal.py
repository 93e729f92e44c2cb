"""Flow meter and thermal output: pulse counts -> volume flow, useful power, efficiency.

The absorber board counts a pulse flow meter on its pulse input (the input the cup
anemometer uses on other collectors; one of the two per board, docs/firmware.md) and
reports the running count at 4 Hz (``PulseSample``). Here, in pure Python:

* :func:`volume_flow` - the meter's calibration: ``Q = f / K`` with the K-factor ``K``
  [pulses per litre] of its data sheet (a turbine / Hall meter is linear in its range).
* :class:`FlowStats` - the mean flow over a window of the board's clock (a 2.5 L/min
  flow on a 450 pulse/L meter is 19 pulses per second: one 0.25 s sample counts 4 or
  5, a 5 s window averages that quantisation down to about 1 %). The window runs on
  the pulses' own time base, as their frequency is measured: a simulation at 400x
  measures its flow over the same 5 real seconds as the board does.
* :func:`water_density`, :func:`water_cp` - liquid water at saturation, 0-150 degC
  (IAPWS-95 as tabulated by the NIST Chemistry WebBook; linear between 10 K points,
  within 0.1 % of the formulation), NaN outside: ice or steam is not this model.
* :func:`useful_power` - ``P = m_dot c_p (T_out - T_in)`` [W].
* :func:`efficiency` - seed 003 section 3.2 (the efficiency "equation 6" of its
  section 2.3.4): useful power over the beam irradiance on the aperture,
  ``eta = P / (G_b A_a)``; ``A_a`` = lines x line width x line length of the
  collector description (``sslfr_planner.analysis.ideal.aperture_area``, the node's
  ``aperture_area`` parameter; seed 003: 10 x 0.1 m x 1 m = 1 m^2).
  The seed's printed fraction also divides by a factor 0.77 (``Hdp eta_0``, not
  defined in the paper) and its two results are the bare ratios written as percent
  (docs/collectors.md, "Thermal output"); this module keeps the definition the text
  states: useful power against the beam on the aperture.
* :func:`thermal_output` - all of it for one sample (the ``absorber/thermal_power``
  message's fields).

Units: SI (m^3/s, kg/s, W, W/m^2, m^2) except temperatures in degC as on the
thermocouple topics; the K-factor is per litre, as data sheets give it.
"""
from __future__ import annotations

import bisect
import collections
import math
from dataclasses import dataclass

#: K-factor of a common Hall-effect flow meter (YF-S201 type: f [Hz] = 7.5 Q [L/min],
#: 450 pulses per litre, 1-30 L/min); a site sets its own meter's value.
K_FACTOR = 450.0
#: Default window of the mean flow [s].
FLOW_WINDOW = 5.0
#: Below this beam irradiance [W/m^2] the efficiency is not computed (NaN): the ratio
#: of two small numbers says nothing (dawn, dusk, a cloud).
MIN_BEAM = 100.0

#: Saturated liquid water, IAPWS-95 (NIST Chemistry WebBook): temperature [degC],
#: density [kg/m^3], isobaric specific heat c_p [J/(kg K)].
WATER_T = (0.01, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0, 100.0,
           110.0, 120.0, 130.0, 140.0, 150.0)
WATER_RHO = (999.79, 999.65, 998.16, 995.61, 992.18, 988.00, 983.16, 977.73, 971.77,
             965.30, 958.35, 950.95, 943.11, 934.83, 926.13, 917.01)
WATER_CP = (4219.9, 4195.5, 4184.4, 4180.1, 4179.6, 4181.5, 4185.1, 4190.2, 4196.9,
            4205.3, 4215.7, 4228.3, 4243.5, 4261.5, 4282.6, 4307.1)


def _interp(t: float, ys: tuple) -> float:
    if not (math.isfinite(t) and 0.0 <= t <= WATER_T[-1]):
        return math.nan
    t = max(t, WATER_T[0])
    i = min(bisect.bisect_right(WATER_T, t), len(WATER_T) - 1)
    t0, t1 = WATER_T[i - 1], WATER_T[i]
    return ys[i - 1] + (ys[i] - ys[i - 1]) * (t - t0) / (t1 - t0)


def water_density(t: float) -> float:
    """Density of liquid water [kg/m^3] at ``t`` [degC] (0-150; NaN outside)."""
    return _interp(t, WATER_RHO)


def water_cp(t: float) -> float:
    """Isobaric specific heat of liquid water [J/(kg K)] at ``t`` [degC] (0-150; NaN outside)."""
    return _interp(t, WATER_CP)


def check_k_factor(k: float) -> None:
    """Raise ValueError unless the K-factor [pulses/L] is finite and > 0."""
    if not (math.isfinite(k) and k > 0.0):
        raise ValueError(f'flow meter K-factor must be > 0 pulses per litre, got {k!r}')


def volume_flow(pulse_rate: float, k_factor: float = K_FACTOR) -> float:
    """Volume flow [m^3/s] of a meter giving ``pulse_rate`` [Hz] with ``k_factor``
    [pulses per litre]."""
    return pulse_rate / k_factor / 1000.0


def pulse_rate(flow: float, k_factor: float = K_FACTOR) -> float:
    """Inverse of :func:`volume_flow`: the pulse frequency [Hz] at ``flow`` [m^3/s]."""
    return flow * 1000.0 * k_factor


def litres_per_hour(flow: float) -> float:
    """[m^3/s] -> [L/h] (for people: the seeds give flows in L/h)."""
    return flow * 3.6e6


def useful_power(mass_flow: float, cp: float, t_in: float, t_out: float) -> float:
    """Useful thermal power [W] = ``mass_flow`` [kg/s] x ``cp`` [J/(kg K)] x
    (``t_out`` - ``t_in``) [K] (seed 003 section 3.2, the numerator of its efficiency)."""
    return mass_flow * cp * (t_out - t_in)


def efficiency(power: float, beam: float, aperture: float, min_beam: float = MIN_BEAM) -> float:
    """Seed 003's efficiency [-] = ``power`` [W] / (``beam`` [W/m^2] x ``aperture``
    [m^2]); NaN when any input is unknown, the aperture is not > 0 or the beam is below
    ``min_beam``."""
    if not (math.isfinite(power) and math.isfinite(beam) and aperture > 0.0) or beam < min_beam:
        return math.nan
    return power / (beam * aperture)


@dataclass(frozen=True)
class ThermalReading:
    """One sample of the thermal output (the fields of sslfr_interfaces/ThermalPower)."""

    volume_flow: float     # [m^3/s]
    mass_flow: float       # [kg/s]
    inlet: float           # [degC]
    outlet: float          # [degC]
    cp: float              # [J/(kg K)]
    power: float           # [W]
    beam: float            # [W/m^2]
    aperture: float        # [m^2]
    efficiency: float      # [-]


def thermal_output(flow: float, t_in: float, t_out: float, beam: float, aperture: float,
                   min_beam: float = MIN_BEAM) -> ThermalReading:
    """Thermal output of volume ``flow`` [m^3/s] heated from ``t_in`` to ``t_out``
    [degC] under ``beam`` [W/m^2] on ``aperture`` [m^2]. The meter is on the inlet
    line (the density is the inlet's); c_p at the mean temperature. An unknown
    temperature (NaN) gives NaN power and efficiency, never a number."""
    m_dot = flow * water_density(t_in)
    cp = water_cp(0.5 * (t_in + t_out))
    p = useful_power(m_dot, cp, t_in, t_out)
    return ThermalReading(flow, m_dot, t_in, t_out, cp, p, beam, aperture,
                          efficiency(p, beam, aperture, min_beam))


@dataclass(frozen=True)
class FlowReading:
    """What :class:`FlowStats` says after a sample (the fields of sslfr_interfaces/Flow)."""

    volume_flow: float    # mean over the window [m^3/s]
    window: float         # time the mean covers [s]
    pulse_rate: float     # mean pulse frequency over the window [Hz]


class FlowStats:
    """Mean flow over the last ``window`` [s] from pulse intervals (``dt`` [s of the
    board's clock], ``pulses``); a gap (the caller calls :meth:`restart`) or time going
    back empties the window."""

    def __init__(self, k_factor: float = K_FACTOR, window: float = FLOW_WINDOW):
        check_k_factor(k_factor)
        if not (math.isfinite(window) and window > 0.0):
            raise ValueError(f'flow window must be > 0 s, got {window!r}')
        self.k_factor, self.window = k_factor, window
        self.restart()

    def restart(self) -> None:
        """Forget every sample."""
        self._t: float | None = None
        self._origin = 0.0
        self._q: collections.deque = collections.deque()    # (t_end, dt, pulses)
        self._sum = [0.0, 0]                                 # sum dt, sum pulses

    def add(self, dt: float, pulses: int, t: float | None = None) -> FlowReading:
        """One interval of ``dt`` [s] with ``pulses`` counted, ending at ``t`` [s; None:
        the previous end + ``dt``, the board's clock]; the reading after it."""
        if t is None:
            t = dt if self._t is None else self._t + dt
        elif self._t is not None and t < self._t:
            self.restart()
        if self._t is None:
            self._origin = t - dt
        self._t = t
        self._q.append((t, dt, pulses))
        self._sum[0] += dt
        self._sum[1] += pulses
        while self._q and self._q[0][0] <= t - self.window:
            _, odt, on = self._q.popleft()
            self._sum[0] -= odt
            self._sum[1] -= on
        rate = self._sum[1] / self._sum[0] if self._sum[0] > 0.0 else 0.0
        return FlowReading(volume_flow(rate, self.k_factor), min(t - self._origin, self.window), rate)


class ThermalTracker:
    """The absorber board node's flow meter and thermal output, without rclpy: the
    board's pulse samples -> :class:`FlowReading` and :class:`ThermalReading` with the
    last inlet and outlet temperatures [degC] and the last beam irradiance [W/m^2]
    (older than ``beam_max_age`` [s of the caller's steady clock]: unknown)."""

    def __init__(self, k_factor: float = K_FACTOR, window: float = FLOW_WINDOW, aperture: float = 0.0,
                 min_beam: float = MIN_BEAM, beam_max_age: float = 5.0):
        from sslfr_drivers.sensors.anemometer import PulseCounter
        self.flow = FlowStats(k_factor, window)
        self.pulses = PulseCounter()
        self.aperture, self.min_beam, self.beam_max_age = aperture, min_beam, beam_max_age
        self.temperatures = {'inlet': math.nan, 'outlet': math.nan}
        self._beam = (math.nan, -math.inf)          # (W/m^2, steady time)
        self.counts = {'samples': 0, 'restarts': 0}
        self.last: tuple[FlowReading, ThermalReading] | None = None

    def set_temperature(self, which: str, value: float) -> None:
        """The last reading of thermocouple ``which`` (NaN: unknown)."""
        self.temperatures[which] = value

    def set_beam(self, beam: float, steady: float) -> None:
        """The last beam irradiance [W/m^2], heard at ``steady`` [s]."""
        self._beam = (beam, steady)

    def beam(self, steady: float) -> float:
        """The beam irradiance to use at ``steady`` [s] (NaN: none recent)."""
        value, at = self._beam
        return value if steady - at <= self.beam_max_age else math.nan

    def add(self, board_ms: int, count: int, steady: float):
        """One pulse sample (board tick [ms], running count; the flow window runs on
        the board's clock) received at steady time ``steady`` [s] -> (flow, thermal)
        readings, or None for
        the first sample after a start, a board reset or a gap (the window restarts)."""
        self.counts['samples'] += 1
        interval = self.pulses.add(board_ms, count)
        if interval is None:
            self.counts['restarts'] += 1
            self.flow.restart()
            return None
        f = self.flow.add(*interval)            # the window on the board's clock
        r = thermal_output(f.volume_flow, self.temperatures['inlet'], self.temperatures['outlet'],
                           self.beam(steady), self.aperture, self.min_beam)
        self.last = (f, r)
        return self.last
