"""MAX6675 type-K thermocouple converter: decode and encode its 16-bit word.

The temperature PCB of seed 000 section 3.5.3 reads two type-K thermocouples (absorber
tube inlet and outlet) through MAX6675 converters. The board forwards the raw 16-bit
SPI word, so the host sees the converter's own fault bit. Word layout (MAX6675
datasheet, "Serial Interface Protocol"):

====  =========================================================
bit   meaning
====  =========================================================
D15   dummy sign bit, always 0
D14-3 12-bit temperature, LSB = 0.25 degC (0 .. 1023.75 degC)
D2    1 = thermocouple input open (no thermocouple attached)
D1    device ID, always 0
D0    three-state (reads 0 with the line pulled down)
====  =========================================================

A word with D15 or D1 set cannot come from a working MAX6675 (0xFFFF is what a
floating MISO line reads): it is reported as an invalid word, also a fault.

Pure Python, no rclpy. Temperatures are degrees Celsius (sensor_msgs/Temperature's
unit), variances degC^2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

RESOLUTION = 0.25          #: LSB of the temperature field [degC]
MAX_CODE = 0x0FFF          #: 12-bit full scale (1023.75 degC)
OPEN_BIT = 0x0004          #: D2, thermocouple input open
_INVALID_BITS = 0x8002     #: D15 and D1 must read 0

FAULT_NONE = 'ok'
FAULT_OPEN = 'open thermocouple'
FAULT_INVALID = 'invalid word (converter missing or SPI fault)'


@dataclass(frozen=True)
class ErrorModel:
    """Uncertainty of a MAX6675 + type-K reading.

    Tolerance limits are treated as bounds of uniform distributions (variance
    a^2 / 3) and the 0.25 degC quantization as uniform (variance q^2 / 12); the
    three are independent and add.

    Attributes
    ----------
    converter_error : float
        MAX6675 total error bound for 0..700 degC [degC] (datasheet: +-8 LSB = 2 degC
        at T_A = 25 degC; larger over the full ambient range).
    thermocouple_abs : float
        Type-K standard tolerance, absolute part [degC] (IEC 60584 class 2: 2.5 degC).
    thermocouple_rel : float
        Type-K standard tolerance, relative part [-] (class 2: 0.0075 |T|).
    """

    converter_error: float = 2.0
    thermocouple_abs: float = 2.5
    thermocouple_rel: float = 0.0075

    def variance(self, temperature: float) -> float:
        """Variance of a reading at ``temperature`` [degC] -> [degC^2]."""
        tc = max(self.thermocouple_abs, self.thermocouple_rel * abs(temperature))
        return RESOLUTION ** 2 / 12.0 + self.converter_error ** 2 / 3.0 + tc ** 2 / 3.0


@dataclass(frozen=True)
class Reading:
    """A decoded MAX6675 word.

    Attributes
    ----------
    word : int
        The raw 16-bit word.
    temperature : float
        [degC]; NaN when ``fault`` is not FAULT_NONE.
    variance : float
        [degC^2]; NaN with a fault.
    fault : str
        FAULT_NONE, FAULT_OPEN or FAULT_INVALID.
    """

    word: int
    temperature: float
    variance: float
    fault: str

    @property
    def ok(self) -> bool:
        """True when the reading is a temperature."""
        return self.fault == FAULT_NONE


def decode(word: int, model: ErrorModel | None = None) -> Reading:
    """Decode a MAX6675 16-bit word.

    Parameters
    ----------
    word : int
        The word as read MSB first (0..0xFFFF); other values are invalid.
    model : ErrorModel, optional
        Used for the variance.

    Returns
    -------
    Reading
        Temperature = ((word >> 3) & 0xFFF) * 0.25 degC. An open thermocouple (D2) or
        an impossible word gives NaN and a fault, never a number.
    """
    if not isinstance(word, int) or word < 0 or word > 0xFFFF or word & _INVALID_BITS:
        return Reading(int(word) if isinstance(word, int) else -1, math.nan, math.nan,
                       FAULT_INVALID)
    if word & OPEN_BIT:
        return Reading(word, math.nan, math.nan, FAULT_OPEN)
    temperature = ((word >> 3) & MAX_CODE) * RESOLUTION
    return Reading(word, temperature, (model or ErrorModel()).variance(temperature), FAULT_NONE)


def encode(temperature: float, open_circuit: bool = False) -> int:
    """The word a MAX6675 would send for ``temperature`` [degC] (simulated boards).

    Rounds to the 0.25 degC LSB and clamps to 0..1023.75 degC (the converter cannot
    report below 0 degC). ``open_circuit`` sets D2 (the datasheet leaves the temperature
    bits undefined then; they are sent as zero).
    """
    if open_circuit:
        return OPEN_BIT
    if not math.isfinite(temperature):
        temperature = 0.0
    code = int(round(min(max(temperature, 0.0), MAX_CODE * RESOLUTION) / RESOLUTION))
    return (code & MAX_CODE) << 3
