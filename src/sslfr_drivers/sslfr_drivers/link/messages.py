"""Message-type registry and payload codecs of the SSLFR board protocol.

Pure Python (no rclpy). Every message type is a frozen dataclass registered with
:func:`register` under a one-byte type code; :func:`encode` / :func:`decode` turn
them into / from :class:`~sslfr_drivers.link.protocol.Frame` payloads. All multi-byte
fields are little-endian.

Type code ranges (documented in docs/protocol.md; never reuse a code):

=============  ==============================================================
0x01 - 0x0F    common host -> board requests (PING, GET_INFO, GET_STATUS, RESET, GET_CONFIG, SET_CONFIG, HELLO, PROVISION)
0x10 - 0x3F    axis-board requests (MOVE_TO, STOP, HOME, SET_ZERO)
0x40 - 0x5F    RESERVED for sensor-board requests (sensor_messages module)
0x60 - 0x7F    reserved (future)
0x80 - 0x8F    common board -> host frames (ACK, NACK, INFO, STATUS, BOOT, CONFIG, HELLO_REPLY)
0x90 - 0xBF    axis-board unsolicited frames (none yet)
0xC0 - 0xDF    RESERVED for sensor-board frames (samples, NMEA passthrough)
0xE0 - 0xFF    reserved (future; 0xFF never used)
=============  ==============================================================

Units on the wire: positions in motor steps (i32), speeds in steps/s (f32),
angles in radians (f32), times in milliseconds (u32). Seed 000 default
resolution: 0.006 deg of joint per step (``DEFAULT_STEP_RAD``).
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass, fields
from enum import IntEnum, IntFlag
from typing import ClassVar

from sslfr_common.contract import JOINTS, STEP_ANGLE
from sslfr_drivers.link.protocol import FLAG_RESPONSE, Frame, PayloadError

DEFAULT_STEP_RAD = STEP_ANGLE      # [rad/step] seed 000: 0.006 deg

SENSOR_REQUEST_RANGE = range(0x40, 0x60)
SENSOR_REPLY_RANGE = range(0xC0, 0xE0)


class BoardKind(IntEnum):
    """INFO.board_kind. 0x10-0x1F are reserved for sensor boards."""

    UNKNOWN = 0x00
    AXIS_STEPPER = 0x01   # stepper, with limit switches or without (seeds 000, 003)
    AXIS_ACTUATOR = 0x02  # linear actuator closed on an inclinometer (seed 004)
    # sensor boards (models and messages in the sensor module):
    GPS = 0x10
    ABSORBER = 0x11       # MAX6675 thermocouples + five limit switches
    IRRADIANCE = 0x12     # VEML7700


class ErrorCode(IntEnum):
    """NACK.code: why a board refused a request."""

    UNKNOWN_TYPE = 1      # message type not implemented by this board
    BAD_PAYLOAD = 2       # payload does not decode
    OUT_OF_RANGE = 3      # value outside the board's limits (speed, steps, switch id)
    NOT_HOMED = 4         # MOVE_TO refused: position lost since boot/reset
    FAULT_ACTIVE = 5      # a latched fault forbids the request
    BUSY = 6              # another operation (e.g. HOME) is running
    LIMIT_ACTIVE = 7      # the move would go further into an active limit switch
    VERSION = 8           # protocol version not supported
    INTERNAL = 9
    AUTH = 10             # the frame's tag does not verify (forged, other key, old session)
    REPLAY = 11           # authenticated but stale in the session (a replayed or late frame)
    NO_SESSION = 12       # the board has no session (it rebooted): send HELLO
    LOCKED = 13           # PROVISION outside the provisioning window (only after an external reset)


class LimitBits(IntFlag):
    """STATUS.limit_bits; HOME.switch is the bit *index* (0, 1, 2)."""

    LOW = 1 << 0          # mechanical lower end
    HIGH = 1 << 1         # mechanical upper end
    SLEEP = 1 << 2        # sleeping (stow) position


class Switch(IntEnum):
    LOW = 0
    HIGH = 1
    SLEEP = 2


class StatusFlags(IntFlag):
    MOVING = 1 << 0
    HOMED = 1 << 1        # step counter is referenced (HOME or SET_ZERO since boot)
    HOMING = 1 << 2
    HAS_SENSOR = 1 << 3   # sensor_angle is meaningful


class FaultBits(IntFlag):
    """STATUS.fault_bits (latched until cleared by the named request)."""

    WATCHDOG = 1 << 0     # nothing heard for WATCHDOG_S: motor stopped (cleared by MOVE_TO/HOME)
    LIMIT = 1 << 1        # a limit switch stopped a move (cleared by a move away / HOME)
    STALL = 1 << 2        # the board itself detected a stall (drivers with feedback)
    SENSOR = 1 << 3       # position sensor not answering
    DRIVER = 1 << 4       # stepper driver fault pin
    RESET = 1 << 5        # the board booted since the host last referenced it


#: board-side watchdog period [s]: a board stops its motor when no valid frame
#: addressed to it arrives for this long (docs/protocol.md "Watchdog").
WATCHDOG_S = 1.0

_REGISTRY: dict[int, type] = {}


def register(cls):
    """Class decorator: register a message dataclass under ``cls.TYPE``.

    The class needs ``TYPE`` (int), ``FORMAT`` (struct format without byte order,
    fields in dataclass order) or its own ``pack``/``unpack``. Duplicated codes are
    refused (``ValueError``).
    """
    code = cls.TYPE
    if not 0 <= code <= 0xFE:
        raise ValueError(f'type code {code:#x} out of range')
    if code in _REGISTRY and _REGISTRY[code] is not cls:
        raise ValueError(f'type code {code:#04x} already used by {_REGISTRY[code].__name__}')
    _REGISTRY[code] = cls
    return cls


def registry() -> dict[int, type]:
    """Copy of the type-code -> message-class table."""
    return dict(_REGISTRY)


class Message:
    """Base of all registered messages (fixed-layout struct payloads)."""

    TYPE: ClassVar[int] = -1
    FORMAT: ClassVar[str] = ''
    #: True if the host expects an answer frame to this request
    RESPONSE: ClassVar[bool] = False

    def pack(self) -> bytes:
        try:
            return struct.pack('<' + self.FORMAT, *(getattr(self, f.name) for f in fields(self)))
        except struct.error as exc:
            raise PayloadError(f'{type(self).__name__}: {exc}') from None

    @classmethod
    def unpack(cls, payload: bytes):
        try:
            return cls(*struct.unpack('<' + cls.FORMAT, payload))
        except struct.error as exc:
            raise PayloadError(f'{cls.__name__}: {len(payload)} bytes do not match '
                               f'layout {cls.FORMAT!r}: {exc}') from None


def encode(msg: Message, seq: int, ref: int | None = None) -> Frame:
    """Build the :class:`Frame` carrying ``msg`` (``ref`` set makes it a response)."""
    if ref is None:
        return Frame(msg.TYPE, seq, msg.pack())
    return Frame(msg.TYPE, seq, msg.pack(), ref, FLAG_RESPONSE)


def decode(frame: Frame) -> Message:
    """Decode a frame's payload into its registered message.

    Raises
    ------
    PayloadError
        Unknown type code or a payload that does not fit the type's layout (the only
        exception this function raises).
    """
    cls = _REGISTRY.get(frame.type)
    if cls is None:
        raise PayloadError(f'unknown message type {frame.type:#04x}')
    msg = cls.unpack(frame.payload)
    if hasattr(msg, 'validate'):
        msg.validate()
    return msg


def _finite(name: str, *vals: float) -> None:
    for v in vals:
        if not math.isfinite(v):
            raise PayloadError(f'{name}: non-finite value {v!r}')


# ---------------------------------------------------------------- common requests
@register
@dataclass(frozen=True)
class Ping(Message):
    """Heartbeat (answered with ACK). ``host_ms``: host steady clock [ms] mod 2**32."""

    TYPE: ClassVar[int] = 0x01
    FORMAT: ClassVar[str] = 'I'
    RESPONSE: ClassVar[bool] = True
    host_ms: int = 0


@register
@dataclass(frozen=True)
class GetInfo(Message):
    """Ask for INFO."""

    TYPE: ClassVar[int] = 0x02
    RESPONSE: ClassVar[bool] = True


@register
@dataclass(frozen=True)
class GetStatus(Message):
    """Ask for STATUS."""

    TYPE: ClassVar[int] = 0x03
    RESPONSE: ClassVar[bool] = True


@register
@dataclass(frozen=True)
class Reset(Message):
    """Software reset of the board (ACKed, then the board reboots and sends BOOT)."""

    TYPE: ClassVar[int] = 0x04
    RESPONSE: ClassVar[bool] = True


@register
@dataclass(frozen=True)
class GetConfig(Message):
    """Ask for the board's configuration record (answered with CONFIG)."""

    TYPE: ClassVar[int] = 0x05
    RESPONSE: ClassVar[bool] = True


@dataclass(frozen=True)
class ConfigRecord:
    """The board configuration record (EEPROM address 0; docs/firmware.md "EEPROM
    configuration"). Units: baud [bit/s], max_speed [steps/s], accel [steps/s^2],
    min_steps / max_steps [steps] (the MOVE_TO range), sensor_zero [encoder counts].

    ``axis``: 0 mirrors, 1 mobile structure, 2 secondary reflector, 0xFF none;
    ``flags``: :data:`CFG_INVERT_DIR`, :data:`CFG_SWITCH_NC`, :data:`CFG_HAS_SENSOR`,
    :data:`CFG_SENSOR_INVERT`."""

    layout: int = 1
    kind: int = 0
    board_id: int = 0
    baud: int = 115200
    axis: int = 0xFF
    flags: int = 0
    max_speed: float = 0.0
    accel: float = 0.0
    min_steps: int = 0
    max_steps: int = 0
    sensor_zero: int = 0

    FORMAT: ClassVar[str] = '<BBIIBBffiiH'
    SIZE: ClassVar[int] = 30
    #: the ``axis`` byte indexes the contract's joints (0 mirrors, 1 mobile_structure, ...)
    AXES: ClassVar[tuple[str, ...]] = JOINTS

    def pack(self) -> bytes:
        """The 30-byte record (SET_CONFIG / CONFIG payload)."""
        try:
            return struct.pack(self.FORMAT, *(getattr(self, f.name) for f in fields(self)))
        except struct.error as exc:
            raise PayloadError(f'ConfigRecord: {exc}') from None

    @classmethod
    def unpack(cls, payload: bytes) -> 'ConfigRecord':
        """Record from its 30 bytes; PayloadError for another size."""
        if len(payload) != cls.SIZE:
            raise PayloadError(f'ConfigRecord: {len(payload)} bytes, not {cls.SIZE}')
        return cls(*struct.unpack(cls.FORMAT, payload))

    def eeprom_image(self) -> bytes:
        """What the firmware stores at EEPROM address 0: the record + its CRC-16."""
        from .protocol import crc16
        raw = self.pack()
        return raw + struct.pack('<H', crc16(raw))

    def check(self, kind: int) -> int:
        """0 when a board of ``kind`` accepts this record, else the NACK code
        (OUT_OF_RANGE): the firmware's rule (firmware/lib/msgs.c config_check)."""
        bad = ErrorCode.OUT_OF_RANGE
        if self.layout != 1 or self.kind != kind or self.baud not in (9600, 19200, 38400, 57600, 115200):
            return bad
        if kind != BoardKind.AXIS_STEPPER:
            return 0
        if self.axis > 2 or self.flags & ~0x0F:
            return bad
        f32 = struct.unpack('<ff', struct.pack('<ff', self.max_speed, self.accel))
        if not (1.0 <= f32[0] <= AXIS_MAX_STEP_RATE) or not (1.0 <= f32[1] <= 1.0e7):
            return bad
        if self.min_steps >= self.max_steps:
            return bad
        if self.flags & CFG_HAS_SENSOR and self.sensor_zero > 0x3FFF:
            return bad
        return 0

    @classmethod
    def defaults(cls, kind: int) -> 'ConfigRecord':
        """The firmware's defaults for a board of ``kind`` (blank EEPROM)."""
        if kind == BoardKind.AXIS_STEPPER:
            return cls(kind=kind, axis=0, max_speed=3000.0, accel=6000.0, min_steps=-(1 << 30),
                       max_steps=1 << 30)
        return cls(kind=kind)


CFG_INVERT_DIR = 0x01      #: DIR low for increasing steps
AXIS_MAX_STEP_RATE = 25000.0   #: [steps/s] highest max_speed an axis board accepts
CFG_SWITCH_NC = 0x02       #: normally-closed limit switches
CFG_HAS_SENSOR = 0x04      #: AS5048A absolute encoder on the joint
CFG_SENSOR_INVERT = 0x08   #: encoder counts decrease with the joint angle


@dataclass(frozen=True)
class _RecordMessage(Message):
    """A message whose payload is one configuration record (ConfigRecord.SIZE bytes)."""

    record: bytes = b''

    def pack(self) -> bytes:
        if len(self.record) != ConfigRecord.SIZE:
            raise PayloadError(f'{type(self).__name__}: {len(self.record)} bytes, not {ConfigRecord.SIZE}')
        return bytes(self.record)

    @classmethod
    def unpack(cls, payload: bytes):
        if len(payload) != ConfigRecord.SIZE:
            raise PayloadError(f'{cls.__name__}: {len(payload)} bytes, not {ConfigRecord.SIZE}')
        return cls(bytes(payload))

    @property
    def value(self) -> ConfigRecord:
        """The decoded record."""
        return ConfigRecord.unpack(self.record)


@register
@dataclass(frozen=True)
class SetConfig(_RecordMessage):
    """Store a configuration record (ACK; used from the next start, i.e. after RESET).
    NACK OUT_OF_RANGE for a record the board refuses, BUSY while the motor moves."""

    TYPE: ClassVar[int] = 0x06
    RESPONSE: ClassVar[bool] = True


@register
@dataclass(frozen=True)
class Hello(Message):
    """Start a session (docs/protocol.md "Authentication"): ``nonce`` = the host's fresh
    8-byte Nh. Sent in the null session; answered with HELLO_REPLY in the new one."""

    TYPE: ClassVar[int] = 0x07
    FORMAT: ClassVar[str] = '8s'
    RESPONSE: ClassVar[bool] = True
    nonce: bytes = bytes(8)


@register
@dataclass(frozen=True)
class Provision(Message):
    """Set the board's installation key (docs/deploy.md "Board keys"): tagged under the
    null key in the null session, accepted only during the provisioning window that an
    external reset opens (the USB adapter's DTR: never from the radio; else NACK
    LOCKED); answered ACK in the null session of the new key."""

    TYPE: ClassVar[int] = 0x08
    FORMAT: ClassVar[str] = '16s'
    RESPONSE: ClassVar[bool] = True
    key: bytes = bytes(16)


# ------------------------------------------------------------------ axis requests
@register
@dataclass(frozen=True)
class MoveTo(Message):
    """Move to absolute ``steps`` [steps] at up to ``speed`` [steps/s] (> 0).

    Answered with ACK (accepted; motion starts) or NACK (NOT_HOMED, OUT_OF_RANGE,
    LIMIT_ACTIVE, FAULT_ACTIVE). Clears the WATCHDOG and LIMIT faults.
    """

    TYPE: ClassVar[int] = 0x10
    FORMAT: ClassVar[str] = 'if'
    RESPONSE: ClassVar[bool] = True
    steps: int
    speed: float

    def validate(self):
        _finite('MoveTo.speed', self.speed)


@register
@dataclass(frozen=True)
class Stop(Message):
    """Decelerate to a stop now (always ACKed)."""

    TYPE: ClassVar[int] = 0x11
    RESPONSE: ClassVar[bool] = True


@register
@dataclass(frozen=True)
class Home(Message):
    """Drive toward limit switch ``switch`` (:class:`Switch` index) at ``speed``
    [steps/s, sign = direction, + increases steps] until it closes, then set the step
    counter to ``position`` [steps] and flag HOMED. ACKed when started; completion is
    seen in STATUS (HOMING cleared, HOMED set)."""

    TYPE: ClassVar[int] = 0x12
    FORMAT: ClassVar[str] = 'Bfi'
    RESPONSE: ClassVar[bool] = True
    switch: int
    speed: float
    position: int = 0

    def validate(self):
        _finite('Home.speed', self.speed)


@register
@dataclass(frozen=True)
class SetZero(Message):
    """Declare the current position to be ``position`` [steps]; flags HOMED and clears
    the RESET fault (use after re-establishing the position from the sensor)."""

    TYPE: ClassVar[int] = 0x13
    FORMAT: ClassVar[str] = 'i'
    RESPONSE: ClassVar[bool] = True
    position: int = 0


# ------------------------------------------------------------- board -> host
@register
@dataclass(frozen=True)
class Ack(Message):
    """Positive answer; ``request_type`` echoes the request's type code."""

    TYPE: ClassVar[int] = 0x80
    FORMAT: ClassVar[str] = 'B'
    request_type: int


@register
@dataclass(frozen=True)
class Nack(Message):
    """Refusal: ``request_type`` echoed, ``code`` an :class:`ErrorCode`."""

    TYPE: ClassVar[int] = 0x81
    FORMAT: ClassVar[str] = 'BB'
    request_type: int
    code: int


@register
@dataclass(frozen=True)
class Info(Message):
    """Board identity. ``board_kind`` :class:`BoardKind`; firmware version
    major.minor.patch; ``protocol`` version spoken; ``board_id`` a 32-bit serial;
    ``name`` up to 16 bytes ASCII (e.g. 'sim-axis', 'uno-axis')."""

    TYPE: ClassVar[int] = 0x82
    FORMAT: ClassVar[str] = 'BBBBBI16s'
    board_kind: int
    fw_major: int
    fw_minor: int
    fw_patch: int
    protocol: int
    board_id: int
    name: bytes = b''

    @property
    def firmware(self) -> str:
        """Firmware version 'major.minor.patch'."""
        return f'{self.fw_major}.{self.fw_minor}.{self.fw_patch}'

    @property
    def name_str(self) -> str:
        """Board name, trailing NULs removed."""
        return self.name.rstrip(b'\0').decode('ascii', 'replace')

    @property
    def is_simulator(self) -> bool:
        """True for simulated boards (name starting with 'sim')."""
        return self.name_str.startswith('sim')


@register
@dataclass(frozen=True)
class Status(Message):
    """Axis board state.

    position : steps counter [steps] (meaningless unless HOMED)
    target : current target [steps]
    speed : current speed [steps/s], signed
    flags : :class:`StatusFlags`
    limit_bits : :class:`LimitBits` (closed switches)
    fault_bits : :class:`FaultBits`
    sensor_angle : joint angle from the board's position sensor [rad] (NaN if none)
    uptime_ms : time since boot [ms] mod 2**32 (a decrease means a reset)
    """

    TYPE: ClassVar[int] = 0x83
    FORMAT: ClassVar[str] = 'iifBBHfI'
    position: int
    target: int
    speed: float
    flags: int
    limit_bits: int
    fault_bits: int
    sensor_angle: float
    uptime_ms: int

    @property
    def moving(self) -> bool:
        """MOVING flag: the motor turns or has not reached its target."""
        return bool(self.flags & StatusFlags.MOVING)

    @property
    def homed(self) -> bool:
        """HOMED flag: the step counter is referenced."""
        return bool(self.flags & StatusFlags.HOMED)

    @property
    def homing(self) -> bool:
        """HOMING flag: a HOME request is running."""
        return bool(self.flags & StatusFlags.HOMING)


@register
@dataclass(frozen=True)
class Config(_RecordMessage):
    """The board's configuration record (answer to GET_CONFIG); :attr:`value` decodes it."""

    TYPE: ClassVar[int] = 0x85


@register
@dataclass(frozen=True)
class HelloReply(Message):
    """Answer to HELLO, tagged in the new session: the board's nonce Nb and its boot
    count (kept in EEPROM, +1 per power-up or reset: a change tells the host the board
    rebooted)."""

    TYPE: ClassVar[int] = 0x86
    FORMAT: ClassVar[str] = '8sI'
    nonce: bytes
    boot_count: int


@register
@dataclass(frozen=True)
class Boot(Message):
    """Unsolicited, sent once after power-up/reset with sequence 0: the receiver
    restarts its sequence tracking and must re-read INFO/STATUS (position lost)."""

    TYPE: ClassVar[int] = 0x84
    FORMAT: ClassVar[str] = 'BB'
    board_kind: int
    protocol: int
