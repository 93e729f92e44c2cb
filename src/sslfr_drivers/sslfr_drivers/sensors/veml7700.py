"""VEML7700 ambient light sensor: raw count -> illuminance -> beam irradiance.

The irradiance PCB of seed 000 section 3.5.5 uses a VEML7700 (16-bit, 0 to
120,000 lx, best resolution 0.0036 lx/count) and converts illuminance to beam solar
irradiance with a luminous efficacy of 104 lm/W. The board sends the raw ALS count
together with the gain and integration-time register codes it used, so the host
computes lux itself and sees saturation.

Resolution (VEML7700 datasheet / Vishay application note "Designing the VEML7700
into an application"): 0.0036 lx/count at gain x2 and 800 ms, scaling inversely with
gain and integration time::

    resolution(g, T) = 0.0036 lx * (2 / g) * (800 ms / T)

so gain x1/8 and 25 ms give 1.8432 lx/count and 65535 counts = 120,796 lx.
The conversion here is linear (no high-lux non-linearity correction).

Auto-ranging (:func:`next_setting`) follows the application note's strategy: prefer
low gain, step sensitivity up while the count is at or below 100, and down (shorter
integration) above 10,000 counts, one step per measurement as the board's firmware
does. Pure Python, no rclpy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

#: ALS_GAIN register code -> gain [-]
GAINS = {0b00: 1.0, 0b01: 2.0, 0b10: 0.125, 0b11: 0.25}
#: ALS_IT register code -> integration time [s]
INTEGRATION_TIMES = {0b1100: 0.025, 0b1000: 0.050, 0b0000: 0.100, 0b0001: 0.200,
                     0b0010: 0.400, 0b0011: 0.800}
BEST_RESOLUTION = 0.0036   #: [lx/count] at gain 2, 800 ms (seed 000 section 3.5.5)
FULL_SCALE = 0xFFFF        #: 16-bit ALS counter
RANGE_MAX = 120000.0       #: sensor range [lx] (seed 000 section 3.5.5)
LUMINOUS_EFFICACY = 104.0  #: [lm/W] seed 000 section 3.5.5

#: Settings ordered from least to most sensitive: (gain code, IT code).
LADDER = [(0b10, 0b1100), (0b10, 0b1000), (0b10, 0b0000), (0b11, 0b0000), (0b00, 0b0000),
          (0b01, 0b0000), (0b01, 0b0001), (0b01, 0b0010), (0b01, 0b0011)]
LOW_COUNT = 100        #: step up in sensitivity at or below this count
HIGH_COUNT = 10000     #: step down above this count


def resolution(gain_code: int, it_code: int) -> float:
    """Illuminance per count [lx/count] for register codes; KeyError if unknown."""
    gain = GAINS[gain_code]
    it = INTEGRATION_TIMES[it_code]
    return BEST_RESOLUTION * (2.0 / gain) * (0.800 / it)


@dataclass(frozen=True)
class Sample:
    """A decoded VEML7700 sample.

    Attributes
    ----------
    count : int
        Raw ALS count (0..65535).
    gain : float
        Gain [-].
    integration_time : float
        [s].
    illuminance : float
        [lx] (a lower bound when ``saturated``); NaN if ``valid`` is False.
    variance : float
        Variance of illuminance [lx^2].
    saturated : bool
        Counter at full scale or illuminance above the 120,000 lx range.
    valid : bool
        False for unknown register codes or an out-of-range count.
    """

    count: int
    gain: float
    integration_time: float
    illuminance: float
    variance: float
    saturated: bool
    valid: bool


def decode(count: int, gain_code: int, it_code: int, relative_uncertainty: float = 0.1) -> Sample:
    """Raw count + register codes -> illuminance.

    Parameters
    ----------
    count : int
        ALS counter value (0..65535).
    gain_code, it_code : int
        ALS_GAIN (2 bits) and ALS_IT (4 bits) register codes used for the sample.
    relative_uncertainty : float
        1-sigma relative error of the sensor's lux calibration [-].

    Returns
    -------
    Sample
        illuminance = count * resolution(gain, IT) [lx]; variance =
        (relative_uncertainty * E)^2 + resolution^2 / 12 [lx^2].
    """
    if (gain_code not in GAINS or it_code not in INTEGRATION_TIMES or not isinstance(count, int)
            or count < 0 or count > FULL_SCALE):
        return Sample(int(count) if isinstance(count, int) else -1, math.nan, math.nan, math.nan,
                      math.nan, False, False)
    res = resolution(gain_code, it_code)
    lux = count * res
    saturated = count >= FULL_SCALE or lux > RANGE_MAX
    var = (relative_uncertainty * lux) ** 2 + res * res / 12.0
    return Sample(count, GAINS[gain_code], INTEGRATION_TIMES[it_code], lux, var, saturated, True)


def encode(illuminance: float, gain_code: int, it_code: int) -> int:
    """Count a VEML7700 would report for ``illuminance`` [lx] (simulated boards).

    Rounds to the nearest count and clips at 0..65535 (saturation).
    """
    if not math.isfinite(illuminance) or illuminance <= 0.0:
        return 0
    return int(min(FULL_SCALE, round(illuminance / resolution(gain_code, it_code))))


def next_setting(count: int, gain_code: int, it_code: int) -> tuple[int, int]:
    """Auto gain / integration time: the setting for the next measurement.

    One step along :data:`LADDER` per call: more sensitive when ``count`` <= 100, less
    sensitive when ``count`` > 10,000 (or saturated), unchanged otherwise. An unknown
    setting restarts at the application note's start point (gain 1/8, 100 ms).

    Returns
    -------
    (gain_code, it_code)
    """
    try:
        i = LADDER.index((gain_code, it_code))
    except ValueError:
        return LADDER[2]
    if count > HIGH_COUNT and i > 0:
        return LADDER[i - 1]
    if count <= LOW_COUNT and i < len(LADDER) - 1:
        return LADDER[i + 1]
    return LADDER[i]


def beam_irradiance(illuminance: float, variance: float = 0.0,
                    efficacy: float = LUMINOUS_EFFICACY) -> tuple[float, float]:
    """Beam irradiance from illuminance (seed 000 section 3.5.5: 104 lm/W).

    Parameters
    ----------
    illuminance : float
        [lx] = [lm/m^2].
    variance : float
        Its variance [lx^2].
    efficacy : float
        Luminous efficacy of beam sunlight [lm/W], > 0.

    Returns
    -------
    (beam [W/m^2], variance [(W/m^2)^2])
    """
    return illuminance / efficacy, variance / (efficacy * efficacy)
