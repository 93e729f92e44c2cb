"""Sensor-board messages of the SSLFR board protocol (pure Python, no rclpy).

Registered in the ranges :mod:`sslfr_drivers.link.messages` reserves for sensor boards
(0x40-0x5F host -> board, 0xC0-0xDF board -> host). Importing this module registers
them. Wire layout little-endian; documented in docs/protocol.md, "Sensor boards".

Sensor boards stream their samples unsolicited (no request needed) and answer the
common requests PING, GET_INFO (INFO.board_kind = BoardKind.GPS / ABSORBER /
IRRADIANCE) and RESET; GET_STATUS is NACKed with UNKNOWN_TYPE (no axis status).
``board_ms`` is the board's millisecond tick (mod 2**32) when the sample was taken.

=====  ======================  ================================================
code   message                 payload
=====  ======================  ================================================
0xC0   NmeaChunk               1..88 bytes of the receiver's NMEA stream, as is
0xC1   ThermocoupleSample      u32 board_ms, u16 inlet word, u16 outlet word
                               (raw MAX6675 words: D2 = open thermocouple)
0xC2   SwitchSample            u32 board_ms, u8 raw switch bits (bit 0 initial,
                               1 last, 2 sleeping, 3 longitudinal_1,
                               4 longitudinal_2; 1 = closed), u8 reserved 0
0xC3   AlsSample               u32 board_ms, u16 ALS count, u8 ALS_GAIN code,
                               u8 ALS_IT code (VEML7700 register codes)
0xC4   PulseSample             u32 board_ms, u32 pulse count (falling edges
                               since the input was set, wraps), u8 pin
0x40   SetPulseInput           u8 pin (Arduino number; 0xFF = off) -> ACK /
                               NACK OUT_OF_RANGE (a pin the board uses)
=====  ======================  ================================================
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from sslfr_drivers.link.messages import SENSOR_REPLY_RANGE, SENSOR_REQUEST_RANGE, Message, register
from sslfr_drivers.link.protocol import MAX_PAYLOAD, PayloadError


@register
@dataclass(frozen=True)
class NmeaChunk(Message):
    """A piece of the GPS receiver's NMEA byte stream (sentences may be split across
    chunks; the host reassembles them with :class:`sslfr_drivers.sensors.nmea.NmeaStream`)."""

    TYPE: ClassVar[int] = 0xC0
    data: bytes = b''

    def pack(self) -> bytes:
        """The NMEA bytes as they are (1..MAX_PAYLOAD); PayloadError otherwise."""
        if not 1 <= len(self.data) <= MAX_PAYLOAD:
            raise PayloadError(f'NmeaChunk: {len(self.data)} bytes (1..{MAX_PAYLOAD})')
        return bytes(self.data)

    @classmethod
    def unpack(cls, payload: bytes):
        """A chunk from a payload of 1..MAX_PAYLOAD bytes; PayloadError otherwise."""
        if not 1 <= len(payload) <= MAX_PAYLOAD:
            raise PayloadError(f'NmeaChunk: {len(payload)} bytes (1..{MAX_PAYLOAD})')
        return cls(bytes(payload))


@register
@dataclass(frozen=True)
class ThermocoupleSample(Message):
    """Raw MAX6675 words of the inlet and outlet thermocouples (decode with
    :func:`sslfr_drivers.sensors.max6675.decode`)."""

    TYPE: ClassVar[int] = 0xC1
    FORMAT: ClassVar[str] = 'IHH'
    board_ms: int
    inlet: int
    outlet: int


@register
@dataclass(frozen=True)
class SwitchSample(Message):
    """Raw (not debounced) limit switch bits, sent periodically and on every change."""

    TYPE: ClassVar[int] = 0xC2
    FORMAT: ClassVar[str] = 'IBB'
    board_ms: int
    bits: int
    reserved: int = 0

    def validate(self):
        """PayloadError when bits beyond the five switches are set."""
        if self.bits > 0x1F:
            raise PayloadError(f'SwitchSample: bits {self.bits:#x} use more than 5 switches')


@register
@dataclass(frozen=True)
class AlsSample(Message):
    """VEML7700 raw ALS count with the gain and integration-time codes it was taken
    with (decode with :func:`sslfr_drivers.sensors.veml7700.decode`)."""

    TYPE: ClassVar[int] = 0xC3
    FORMAT: ClassVar[str] = 'IHBB'
    board_ms: int
    count: int
    gain_code: int
    it_code: int


@register
@dataclass(frozen=True)
class PulseSample(Message):
    """The running count of the pulse input (cup anemometer, absorber board), sent
    at 4 Hz while the input is set (convert with :mod:`sslfr_drivers.sensors.anemometer`)."""

    TYPE: ClassVar[int] = 0xC4
    FORMAT: ClassVar[str] = 'IIB'
    board_ms: int
    count: int
    pin: int


#: SetPulseInput.pin value that switches the pulse input off.
PULSE_PIN_OFF = 0xFF


@register
@dataclass(frozen=True)
class SetPulseInput(Message):
    """Count falling edges on Arduino pin ``pin`` from now on (count restarts at 0),
    or stop counting (:data:`PULSE_PIN_OFF`). Not stored: the host sends it whenever
    its link comes up. ACK, or NACK OUT_OF_RANGE for a pin the board uses otherwise."""

    TYPE: ClassVar[int] = 0x40
    FORMAT: ClassVar[str] = 'B'
    RESPONSE: ClassVar[bool] = True
    pin: int = PULSE_PIN_OFF


assert all(c.TYPE in SENSOR_REPLY_RANGE for c in (NmeaChunk, ThermocoupleSample, SwitchSample,
                                                    AlsSample, PulseSample))
assert SetPulseInput.TYPE in SENSOR_REQUEST_RANGE
