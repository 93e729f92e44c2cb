"""SunSpec register image of one collector (pure: no rclpy, no sockets).

A SunSpec device is a chain of models in holding registers from base 40000: the
marker 'SunS', then each model as (ID, L, L registers of points), then the end model
(0xFFFF, 0). The points, their types and order come from the SunSpec model
definitions that `pysunspec2` ships (models/json/model_<id>.json), read here, never
retyped. The image served per collector:

- model 1 (common): Mn, Md, Opt, Vr, SN = the collector id, DA = the Modbus unit id;
- model 601 (tracker controller): one repeating `tracker` block per tracker, Typ
  Horizontal (rows turned about one horizontal N-S axis). Elevation points carry the
  mirrors' drive angle beta_0 in degrees (docs/conventions.md: counter-clockwise
  from the horizontal seen from the south, +90 = the sleeping/stow pose), NOT a sun
  elevation; azimuth points are "not implemented" (the rows do not turn in azimuth).
  Ctl: Automatic (0) while the planner's mode is `auto`, Manual (1) otherwise.
  Alm: SetPoint (bit 0) when |measured - setpoint| exceeds the alarm threshold,
  ObsEl (bit 1) when the mirrors' axis is in fault (stall, lost steps: an
  obstruction), ObsAz never;
- model 302 (irradiance): one repeating block, DNI = `irradiance/beam` [W/m^2]
  rounded; the other irradiances are not implemented.

Writes: only Ctl (per tracker) and GlblCtl: 0 -> planner mode `auto`, 1 -> `stow`
(the one manual command a plant gives a tracker: go to the stow pose and hold).
Anything else is refused (:class:`WriteRefused` with the Modbus exception code).
"""
from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

BASE = 40000                       # SunSpec base address (protocol address, 0-based)
MARKER = (0x5375, 0x6E53)          # 'SunS'
END = (0xFFFF, 0)
DEG_SF = -3                        # Dgr_SF: 0.001 deg per count (a motor step is 0.006 deg)

#: 'not implemented' value per SunSpec point type (SunSpec Information Model spec).
UNIMPL = {'uint16': 0xFFFF, 'enum16': 0xFFFF, 'bitfield16': 0xFFFF, 'int16': 0x8000,
          'sunssf': 0x8000, 'pad': 0x8000, 'int32': 0x80000000, 'uint32': 0xFFFFFFFF,
          'acc16': 0, 'acc32': 0, 'count': 0}

CTL_AUTO, CTL_MANUAL = 0, 1
ALM_SETPOINT, ALM_OBS_EL = 1 << 0, 1 << 1
#: Modbus exception codes used for refused writes.
ILLEGAL_FUNCTION, ILLEGAL_ADDRESS, ILLEGAL_VALUE, DEVICE_FAILURE = 1, 2, 3, 4


class WriteRefused(Exception):
    """A write the image does not accept; ``code`` is the Modbus exception code."""

    def __init__(self, code: int, reason: str):
        super().__init__(reason)
        self.code = code


@functools.lru_cache(maxsize=None)
def model_definition(model_id: int) -> dict:
    """The SunSpec definition of ``model_id`` as pysunspec2 ships it (its JSON)."""
    import sunspec2
    path = Path(sunspec2.__file__).parent / 'models' / 'json' / f'model_{model_id}.json'
    return json.loads(path.read_text())


@dataclass
class Tracker:
    """One tracker (collector) in physical units; None = not known (not implemented)."""

    name: str
    el_target_deg: float | None = None
    el_pos_deg: float | None = None
    auto: bool | None = None
    alarm: int = 0


@dataclass
class Unit:
    """What one Modbus unit serves: identification, trackers, beam irradiance."""

    serial: str
    unit_id: int
    trackers: list[Tracker] = field(default_factory=list)
    beam_wm2: float | None = None
    manufacturer: str = 'SSLFR tracker'
    model: str = 'SSLFR collector'
    version: str = '0.1.0'


def _points(group: dict) -> list[dict]:
    return [p for p in group.get('points', []) if p['name'] not in ('ID', 'L')]


def _encode_point(p: dict, value) -> list[int]:
    """Registers of one point (big-endian words); None = the type's 'not implemented'."""
    t, size = p['type'], int(p['size'])
    if t == 'string':
        raw = (value or '').encode('utf-8')[:2 * size].ljust(2 * size, b'\0')
        return [int.from_bytes(raw[i:i + 2], 'big') for i in range(0, 2 * size, 2)]
    v = UNIMPL[t] if value is None else int(value)
    if size == 2:
        v &= 0xFFFFFFFF
        return [v >> 16, v & 0xFFFF]
    return [v & 0xFFFF]


def _scaled(deg: float | None) -> int | None:
    if deg is None or not math.isfinite(deg):
        return None
    return int(round(deg / 10.0 ** DEG_SF))


def _model(model_id: int, fixed: dict, repeats: list[dict]) -> list[int]:
    """ID, L and the points of one model; ``repeats``: values of each repeating block."""
    top = model_definition(model_id)['group']
    regs: list[int] = []
    for p in _points(top):
        regs += _encode_point(p, fixed.get(p['name']))
    for sub in top.get('groups', []):
        for values in repeats:
            for p in _points(sub):
                regs += _encode_point(p, values.get(p['name']))
    return [model_id, len(regs)] + regs


def encode(unit: Unit) -> list[int]:
    """The holding registers of ``unit`` from BASE: marker, models 1, 601, 302, end.

    Angles: degrees x 10^-DEG_SF as int32 (ElPos, ElTrgt); beam [W/m^2] as uint16,
    clamped to 0..65534."""
    common = {'Mn': unit.manufacturer, 'Md': unit.model, 'Opt': '', 'Vr': unit.version,
              'SN': unit.serial, 'DA': unit.unit_id}
    alarms = 0
    blocks = []
    for t in unit.trackers:
        alarms |= t.alarm
        blocks.append({'Id': t.name, 'ElTrgt': _scaled(t.el_target_deg), 'ElPos': _scaled(t.el_pos_deg),
                       'Ctl': None if t.auto is None else (CTL_AUTO if t.auto else CTL_MANUAL),
                       'Alm': t.alarm})
    autos = {t.auto for t in unit.trackers}
    glbl = None if None in autos or len(autos) != 1 else (CTL_AUTO if autos == {True} else CTL_MANUAL)
    tracker = {'Nam': 'SSLFR', 'Typ': 2, 'GlblCtl': glbl, 'GlblAlm': alarms, 'Dgr_SF': DEG_SF,
               'N': len(unit.trackers)}
    beam = None
    if unit.beam_wm2 is not None and math.isfinite(unit.beam_wm2):
        beam = min(max(int(round(unit.beam_wm2)), 0), 65534)
    return (list(MARKER) + _model(1, common, []) + _model(601, tracker, blocks)
            + _model(302, {}, [{'DNI': beam}]) + list(END))


def point_addresses(n_trackers: int) -> dict[str, int]:
    """Protocol address of every point of the image (``name`` for model 1 and the fixed
    points of 601/302 as ``<model>.<name>``, ``601.tracker[i].<name>`` for a block)."""
    addr = BASE + len(MARKER)
    out: dict[str, int] = {}
    for mid, reps in ((1, 0), (601, n_trackers), (302, 1)):
        top = model_definition(mid)['group']
        out[f'{mid}.ID'] = addr
        addr += 2
        for p in _points(top):
            out[f'{mid}.{p["name"]}'] = addr
            addr += int(p['size'])
        for sub in top.get('groups', []):
            for i in range(reps):
                for p in _points(sub):
                    out[f'{mid}.{sub["name"]}[{i}].{p["name"]}'] = addr
                    addr += int(p['size'])
    out['end'] = addr
    return out


def decode_write(n_trackers: int, address: int, values: list[int]) -> list[tuple[int | None, str]]:
    """The commands a write of ``values`` at ``address`` asks for: ``[(tracker index
    or None for every tracker, mode)]`` with mode 'auto' or 'stow'.

    Raises :class:`WriteRefused` (ILLEGAL_ADDRESS) when the write touches any register
    but the Ctl / GlblCtl points, (ILLEGAL_VALUE) for a value other than 0 / 1."""
    addrs = point_addresses(n_trackers)
    writable = {addrs['601.GlblCtl']: None}
    writable.update({addrs[f'601.tracker[{i}].Ctl']: i for i in range(n_trackers)})
    commands = []
    for k, v in enumerate(values):
        a = address + k
        if a not in writable:
            raise WriteRefused(ILLEGAL_ADDRESS, f'register {a} is not writable (only Ctl / GlblCtl)')
        if v not in (CTL_AUTO, CTL_MANUAL):
            raise WriteRefused(ILLEGAL_VALUE, f'Ctl value {v}: 0 (automatic) or 1 (manual: stow) only')
        commands.append((writable[a], 'auto' if v == CTL_AUTO else 'stow'))
    return commands


def tracker_alarm(measured: float | None, setpoint: float | None, threshold: float,
                  fault: bool) -> int:
    """Alm bits of one tracker: SetPoint when |measured - setpoint| > ``threshold``
    [rad, both angles in rad], ObsEl when the axis is in fault."""
    bits = ALM_OBS_EL if fault else 0
    if measured is not None and setpoint is not None and math.isfinite(measured) \
            and math.isfinite(setpoint) and abs(measured - setpoint) > threshold:
        bits |= ALM_SETPOINT
    return bits
