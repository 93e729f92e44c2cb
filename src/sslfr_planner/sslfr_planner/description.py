"""Collector description: what a prototype HAS, read from one YAML file (pure, no rclpy).

One file per prototype (``sslfr_bringup/config/collectors/*.yaml``, format in
docs/collectors.md): its movements (for each: drive kind, position feedback, law,
mechanical range, sleep and stow positions, motor step or deadband), the boards and
sensors present, and the optical geometry (lines, widths, gaps, central line or not,
receiver height and size, axis azimuth). A site config names its collector with the
``collector.description`` parameter.

:func:`load` validates everything before any process starts and raises
:class:`DescriptionError` listing every problem, each line naming the file and the key
(``movements.mirrors.drive``): unknown keys, wrong types, unknown drive kinds, a law
that needs a movement the collector lacks (:data:`LAW_NEEDS`), ranges outside the mechanics, positions
outside a range, duplicate names. Angles are degrees in the file (``*_deg`` keys, for
people) and radians in :class:`Description` (SI inside the code).
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml
from sslfr_common.files import user_path

from sslfr_common.contract import DRIVE_KINDS, JOINT_LIMITS, DriveKind, JOINTS, LONGITUDINAL_JOINTS, SWITCHES
from sslfr_common.drives import LeverGeometry

#: drive kinds (issue 34 item 3): (a) stepper with limit switches, optional encoder or
#: laser sensor (seed 000); (b) linear actuator closed on an inclinometer (seed 004);
#: (c) stepper without switches, referenced by an operator at a known angle (seed 003)
#: position feedback each drive kind accepts ('steps': open loop, the step count)
FEEDBACK_FOR_DRIVE = {
    DriveKind.STEPPER_SWITCHES.value: ('steps', 'encoder', 'laser_sensor'),
    DriveKind.LINEAR_ACTUATOR_INCLINOMETER.value: ('inclinometer',),
    DriveKind.STEPPER_NO_SWITCHES.value: ('steps', 'encoder'),
}
#: movement laws -> the movements each may move (a movement's law must list it).
#: Mirror laws: half_transversal (seed 000 eq. 13, beta_0 = theta_t'/2), lepten_linear
#: (seed 004 eq. 5 with Table 1's pace and offsets), seed003_linkage (seed 003 eqs. 5-6,
#: 15-minute steps, never beyond its maximum inclination). Longitudinal laws
#: (:mod:`sslfr_planner.laws`) move the mobile structure and the secondary reflector together.
LAW_MOVEMENTS: dict[str, tuple[str, ...]] = {
    'half_transversal': (JOINTS[0],),
    'lepten_linear': (JOINTS[0],),
    'seed003_linkage': (JOINTS[0],),
    **{law: LONGITUDINAL_JOINTS for law in ('continuous', 'eq16', 'optimum_fixed', 'daily')},
}
#: movement laws -> the movements each needs (all of them must be in the collector).
#: 'continuous' centres the rays on a tube tilted with the rows (both move); 'eq16',
#: 'optimum_fixed' and 'daily' set the rows' tilt beta_M, which alone makes the reflected
#: rays vertical in the longitudinal plane at solar noon (seed 001 eq. 3, mu = 2 beta_M -
#: theta_z = 0): they need the mobile structure and move the secondary reflector with it
#: when the collector has one; without it the receiver is fixed (:data:`FIXED_TILT`).
LAW_NEEDS: dict[str, tuple[str, ...]] = {
    **{law: movements for law, movements in LAW_MOVEMENTS.items()},
    **{law: LONGITUDINAL_JOINTS[:1] for law in ('eq16', 'optimum_fixed', 'daily')},
}
#: tilt [rad] of a longitudinal part the collector does not move: the rows and receiver
#: of a collector without longitudinal movements (seeds 003, 004), the receiver of one
#: without a secondary_reflector movement. Horizontal: beta = 0 (docs/conventions.md).
FIXED_TILT = 0.0
#: kinematic limits of each movement [deg] (contract JOINT_LIMITS)
MOVEMENT_LIMITS_DEG = {j: (math.degrees(lo), math.degrees(hi)) for j, (lo, hi) in JOINT_LIMITS.items()}
#: board kinds the node set knows (sslfr_bringup/config/nodeset.yaml ``boards``)
BOARD_KINDS = ('axis', 'gps', 'absorber', 'irradiance')
#: sensor kinds
SENSOR_KINDS = ('thermocouple', 'limit_switch', 'light_sensor', 'pyrheliometer', 'inclinometer',
                'laser_sensor', 'encoder', 'flow_meter', 'rtc', 'gps', 'anemometer')


class DescriptionError(ValueError):
    """A collector description that cannot be used; ``problems`` lists each one."""

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        super().__init__('invalid collector description:\n  ' + '\n  '.join(self.problems))


@dataclass(frozen=True)
class Movement:
    """One movement (joint) of the collector. Angles [rad].

    ``step``: axis rotation per motor step (stepper drives) [rad], else None;
    ``deadband``: position deadband of the closed loop (linear actuator) [rad], else
    None; ``switches``: switch name -> angle where it closes [rad] (stepper_switches);
    ``reference``: the known angle at which an operator references a drive without
    switches [rad]; ``feedback_line``: the mirror line (1-based) carrying the
    inclinometer; ``law_params``: the law's own constants (radians, see the law);
    ``actuator``, ``inclinometer`` (linear actuator drives, SI and radians: the
    ``_deg`` / ``_m`` / ``_s`` suffixes of the file dropped): lever geometry, PWM
    speed, stall and time-out limits; inclinometer offset, noise, resolution
    (:mod:`sslfr_common.drives`, :func:`lever_geometry`).
    """

    name: str
    drive: str
    feedback: str
    law: str
    range: tuple[float, float]
    sleep: float
    stow: float
    step: float | None = None
    gear_ratio: float = 1.0
    deadband: float | None = None
    switches: dict = field(default_factory=dict)
    reference: float | None = None
    feedback_line: int | None = None
    law_params: dict = field(default_factory=dict)
    actuator: dict = field(default_factory=dict)
    inclinometer: dict = field(default_factory=dict)


def lever_geometry(mv: Movement) -> LeverGeometry:
    """The :class:`LeverGeometry` of a linear actuator movement (its ``actuator`` block)."""
    a = mv.actuator
    return LeverGeometry(lever=a['lever'], mount_distance=a['mount_distance'],
                         mount_angle=a['mount_angle'], stroke=tuple(a['stroke']))


@dataclass(frozen=True)
class Board:
    """A board present: ``name`` (the node set's board name), ``kind`` (BOARD_KINDS),
    ``hardware`` (free text: the seed's parts), ``movement`` (axis boards)."""

    name: str
    kind: str
    hardware: str = ''
    movement: str | None = None


@dataclass(frozen=True)
class Sensor:
    """A sensor present: ``name``, ``kind`` (SENSOR_KINDS), the ``board`` it is on, ``part``;
    ``site_addition``: fitted by the site, not part of the prototype the seed describes."""

    name: str
    kind: str
    board: str
    part: str = ''
    site_addition: bool = False


@dataclass(frozen=True)
class Optics:
    """Optical geometry (lengths [m], angles [rad]); frame and signs: docs/conventions.md.

    ``lines``: number of mirror lines; ``receiver_height``: height of the aim
    point (the tube axis, seed 000 f + D/2) above the line pivots; ``central_line``: one line on the axis (odd
    count, seed 000) or none (even count, seeds 003 and 004); ``line_width``,
    ``line_length``, ``gap`` between consecutive lines; ``receiver_width``: the receiver's aperture (cavity opening);
    ``tube_diameter``, ``tube_count``; ``receiver_length`` (centred on the rows unless
    ``tube_ends`` (L_a^r, L_a^l) are given); ``azimuth`` of the collector axis,
    clockwise from north; ``rotation_radius``: distance of the mirror surface from
    its rotation axis (seed 004 eq. 3's r; 0 for flat mirrors on their axis).
    """

    lines: int
    central_line: bool
    line_width: float
    line_length: float
    gap: float
    receiver_height: float
    receiver_width: float
    tube_diameter: float
    tube_count: int
    receiver_length: float
    azimuth: float
    rotation_radius: float = 0.0
    tube_ends: tuple[float, float] | None = None

    @property
    def n_per_side(self) -> int:
        """Lines on each side of the axis (without the central one) [-]."""
        return (self.lines - 1) // 2 if self.central_line else self.lines // 2


@dataclass(frozen=True)
class Description:
    """A validated collector description (:func:`load`). Angles [rad], lengths [m]."""

    name: str
    source: str
    path: str
    movements: dict
    boards: dict
    sensors: dict
    optics: Optics

    def movement(self, name: str) -> Movement | None:
        """The movement ``name`` or None when the collector lacks it."""
        return self.movements.get(name)

    @property
    def joints(self) -> tuple[str, ...]:
        """The collector's movements in the contract's joint order."""
        return tuple(j for j in JOINTS if j in self.movements)

    @property
    def longitudinal_law(self) -> str:
        """The planner's ``collector.law`` this description means: the longitudinal
        movements' law, or 'horizontal' when the collector has none (seeds 003, 004)."""
        m = self.movements.get(LONGITUDINAL_JOINTS[0])
        return m.law if m is not None else 'horizontal'

    @property
    def receiver_fixed(self) -> bool:
        """True when the collector does not move its receiver (no secondary_reflector
        movement): it stays at :data:`FIXED_TILT` whatever the longitudinal law."""
        return LONGITUDINAL_JOINTS[1] not in self.movements


# ------------------------------------------------------------------- schema
# key -> (type, required); types: 'str', 'int', 'num', 'bool', 'range', 'map', 'list'
_TOP = {'name': ('str', True), 'source': ('str', True), 'movements': ('map', True),
        'boards': ('list', True), 'sensors': ('list', True), 'optics': ('map', True)}
_MOVEMENT = {'drive': ('str', True), 'feedback': ('str', True), 'law': ('str', True),
             'range_deg': ('range', True), 'sleep_deg': ('num', True), 'stow_deg': ('num', True),
             'step_deg': ('num', False), 'gear_ratio': ('num', False), 'deadband_deg': ('num', False),
             'switches_deg': ('map', False), 'reference_deg': ('num', False),
             'feedback_line': ('int', False), 'law_params': ('map', False),
             'actuator': ('map', False), 'inclinometer': ('map', False)}
#: a linear actuator drive's mechanics (seed 004 section 2.1; docs/collectors.md): lever
#: pivot-to-pin length, pivot-to-base-mount distance, the angle between them at line
#: angle 0, the actuator's stroke, its speed at full PWM duty and the duty below which
#: it does not start, the stall window and least inclinometer change, the move time-out
_ACTUATOR = {'lever_m': ('num', True), 'mount_distance_m': ('num', True), 'mount_angle_deg': ('num', True),
             'stroke_m': ('range', True), 'max_speed_m_s': ('num', True), 'min_duty': ('num', True),
             'stall_window_s': ('num', True), 'stall_min_deg': ('num', True), 'move_timeout_s': ('num', True)}
#: the inclinometer: mounting offset (reading - line angle), noise 1-sigma, resolution
_INCLINOMETER = {'offset_deg': ('num', True), 'noise_deg': ('num', True), 'resolution_deg': ('num', True)}
_BOARD = {'name': ('str', True), 'kind': ('str', True), 'hardware': ('str', False), 'movement': ('str', False)}
_SENSOR = {'name': ('str', True), 'kind': ('str', True), 'board': ('str', True), 'part': ('str', False),
           'site_addition': ('bool', False)}
_OPTICS = {'lines': ('int', True), 'central_line': ('bool', True), 'line_width': ('num', True),
           'line_length': ('num', True), 'gap': ('num', True), 'receiver_height': ('num', True),
           'receiver_width': ('num', True), 'tube_diameter': ('num', True), 'tube_count': ('int', True),
           'receiver_length': ('num', True), 'azimuth_deg': ('num', True), 'rotation_radius': ('num', False),
           'tube_ends': ('range', False)}
#: the law constants each law takes (radians inside; ``_deg`` keys in the file)
_LAW_PARAMS = {
    'lepten_linear': {'pace': ('num', True), 'offsets_deg': ('list', True), 'transversal_limit_deg': ('num', True)},
    'seed003_linkage': {'max_inclination_deg': ('num', True), 'step_s': ('num', True)},
}


def _type_ok(kind: str, v: Any) -> bool:
    if kind == 'str':
        return isinstance(v, str) and v.strip() != ''
    if kind == 'int':
        return isinstance(v, int) and not isinstance(v, bool)
    if kind == 'num':
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    if kind == 'bool':
        return isinstance(v, bool)
    if kind == 'range':
        return (isinstance(v, list) and len(v) == 2 and all(_type_ok('num', x) for x in v))
    if kind == 'map':
        return isinstance(v, Mapping)
    return isinstance(v, list)


_TYPE_TEXT = {'str': 'a non-empty string', 'int': 'an integer', 'num': 'a finite number',
              'bool': 'true or false', 'range': 'a list [low, high] of two numbers', 'map': 'a mapping',
              'list': 'a list'}


class _Checker:
    """Collects problems, each prefixed with the file and the dotted key."""

    def __init__(self, where: str):
        self.where = where
        self.problems: list[str] = []

    def add(self, key: str, text: str) -> None:
        self.problems.append(f'{self.where}: {key}: {text}')

    def section(self, data: Any, schema: dict, key: str) -> dict:
        """The keys of ``data`` that have the right type (others reported); unknown keys refused."""
        if not isinstance(data, Mapping):
            self.add(key or '(top)', f'must be a mapping, got {type(data).__name__}')
            return {}
        out = {}
        prefix = f'{key}.' if key else ''
        for k in data:
            if k not in schema:
                import difflib
                close = difflib.get_close_matches(str(k), list(schema), n=1)
                hint = f' (did you mean {close[0]}?)' if close else ''
                self.add(f'{prefix}{k}', f'unknown key{hint}; known: {", ".join(schema)}')
        for k, (kind, required) in schema.items():
            if k not in data:
                if required:
                    self.add(f'{prefix}{k}', f'missing (required, {_TYPE_TEXT[kind]})')
                continue
            if not _type_ok(kind, data[k]):
                self.add(f'{prefix}{k}', f'must be {_TYPE_TEXT[kind]}, got {data[k]!r}')
                continue
            out[k] = data[k]
        return out


def _rad(v):
    return math.radians(float(v))


def _movement(c: _Checker, name: str, raw: Any) -> Movement | None:
    key = f'movements.{name}'
    if name not in JOINTS:
        c.add(key, f'unknown movement; known: {", ".join(JOINTS)}')
        return None
    m = c.section(raw, _MOVEMENT, key)
    if not {'drive', 'feedback', 'law', 'range_deg', 'sleep_deg', 'stow_deg'} <= set(m):
        return None
    ok = True
    drive, law = m['drive'], m['law']
    if drive not in DRIVE_KINDS:
        c.add(f'{key}.drive', f'unknown drive kind {drive!r}; known: {", ".join(DRIVE_KINDS)}')
        return None
    if m['feedback'] not in FEEDBACK_FOR_DRIVE[drive]:
        c.add(f'{key}.feedback', f'{m["feedback"]!r} is not a position feedback of a {drive} drive; '
                                 f'allowed: {", ".join(FEEDBACK_FOR_DRIVE[drive])}')
        ok = False
    if law not in LAW_MOVEMENTS:
        c.add(f'{key}.law', f'unknown law {law!r}; known: {", ".join(LAW_MOVEMENTS)}')
        ok = False
    elif name not in LAW_MOVEMENTS[law]:
        c.add(f'{key}.law', f'{law!r} is a law of {" and ".join(LAW_MOVEMENTS[law])}, not of {name}')
        ok = False
    lo, hi = m['range_deg']
    klo, khi = MOVEMENT_LIMITS_DEG[name]
    if not lo < hi:
        c.add(f'{key}.range_deg', f'[{lo}, {hi}]: the low end must be below the high end')
        ok = False
    elif lo < klo or hi > khi:
        c.add(f'{key}.range_deg', f'[{lo}, {hi}] deg is outside the mechanics of {name} '
                                  f'([{klo:g}, {khi:g}] deg)')
        ok = False

    def inside(k: str, v: float) -> None:
        nonlocal ok
        if not lo <= v <= hi:
            c.add(f'{key}.{k}', f'{v} deg is outside range_deg [{lo}, {hi}]')
            ok = False
    inside('sleep_deg', m['sleep_deg'])
    inside('stow_deg', m['stow_deg'])
    need = {DriveKind.STEPPER_SWITCHES.value: ('step_deg', 'switches_deg'),
            DriveKind.STEPPER_NO_SWITCHES.value: ('step_deg', 'reference_deg'),
            DriveKind.LINEAR_ACTUATOR_INCLINOMETER.value: ('deadband_deg', 'feedback_line', 'actuator', 'inclinometer')}[drive]
    banned = {'step_deg', 'gear_ratio', 'deadband_deg', 'switches_deg', 'reference_deg', 'feedback_line',
              'actuator', 'inclinometer'} - set(need)
    if drive != DriveKind.LINEAR_ACTUATOR_INCLINOMETER.value:
        banned -= {'gear_ratio'}
    for k in need:
        if k not in m and k not in (raw or {}):
            c.add(f'{key}.{k}', f'missing (a {drive} drive needs it)')
            ok = False
    for k in sorted(banned):
        if k in m:
            c.add(f'{key}.{k}', f'not a property of a {drive} drive')
            ok = False
    for k in ('step_deg', 'deadband_deg', 'gear_ratio'):
        if k in m and not m[k] > 0:
            c.add(f'{key}.{k}', f'must be > 0, got {m[k]}')
            ok = False
    switches = {}
    if 'switches_deg' in m:
        for sw, v in m['switches_deg'].items():
            if sw not in SWITCHES:
                c.add(f'{key}.switches_deg.{sw}', f'unknown switch; known: {", ".join(SWITCHES)}')
                ok = False
            elif not _type_ok('num', v):
                c.add(f'{key}.switches_deg.{sw}', f'must be a finite number, got {v!r}')
                ok = False
            else:
                inside(f'switches_deg.{sw}', v)
                switches[sw] = _rad(v)
    if 'reference_deg' in m:
        inside('reference_deg', m['reference_deg'])
    if 'feedback_line' in m and m['feedback_line'] < 1:
        c.add(f'{key}.feedback_line', f'must be a line number >= 1, got {m["feedback_line"]}')
        ok = False
    params = _law_params(c, key, law, m.get('law_params'))
    if params is None:
        ok = False
    actuator, inclinometer = {}, {}
    if 'actuator' in m:
        actuator = _actuator(c, key, m['actuator'], (_rad(lo), _rad(hi)) if lo < hi else None)
        ok = ok and actuator is not None
    if 'inclinometer' in m:
        inclinometer = _inclinometer(c, key, m['inclinometer'], m.get('deadband_deg'))
        ok = ok and inclinometer is not None
    if not ok:
        return None
    return Movement(name=name, drive=drive, feedback=m['feedback'], law=law,
                    range=(_rad(lo), _rad(hi)), sleep=_rad(m['sleep_deg']), stow=_rad(m['stow_deg']),
                    step=_rad(m['step_deg']) if 'step_deg' in m else None,
                    gear_ratio=float(m.get('gear_ratio', 1.0)),
                    deadband=_rad(m['deadband_deg']) if 'deadband_deg' in m else None,
                    switches=switches, reference=_rad(m['reference_deg']) if 'reference_deg' in m else None,
                    feedback_line=m.get('feedback_line'), law_params=params,
                    actuator=actuator, inclinometer=inclinometer)


def _si(block: dict) -> dict:
    """File units to SI: ``_deg`` keys to radians, ``_m`` / ``_s`` / ``_m_s`` suffixes dropped."""
    out = {}
    for k, v in block.items():
        if k.endswith('_deg'):
            out[k[:-4]] = _rad(v)
        else:
            name = k[:-4] if k.endswith('_m_s') else k[:-2] if k.endswith(('_m', '_s')) else k
            out[name] = tuple(float(x) for x in v) if isinstance(v, list) else float(v)
    return out


def _actuator(c: _Checker, key: str, raw: Any, rng: tuple[float, float] | None) -> dict | None:
    """The ``actuator`` block of a linear actuator movement, validated (None: reported)."""
    n = len(c.problems)
    a = c.section(raw, _ACTUATOR, f'{key}.actuator')
    if len(c.problems) > n:
        return None
    for k in ('lever_m', 'mount_distance_m', 'max_speed_m_s', 'stall_window_s', 'stall_min_deg', 'move_timeout_s'):
        if not a[k] > 0:
            c.add(f'{key}.actuator.{k}', f'must be > 0, got {a[k]}')
    if not 0 <= a['min_duty'] < 1:
        c.add(f'{key}.actuator.min_duty', f'must be in [0, 1), got {a["min_duty"]}')
    if not a['move_timeout_s'] > a['stall_window_s']:
        c.add(f'{key}.actuator.move_timeout_s', 'must exceed stall_window_s')
    if len(c.problems) > n:
        return None
    out = _si(a)
    if rng is not None:
        geo = LeverGeometry(out['lever'], out['mount_distance'], out['mount_angle'], out['stroke'])
        for text in geo.problems(rng):
            c.add(f'{key}.actuator', text)
    return out if len(c.problems) == n else None


def _inclinometer(c: _Checker, key: str, raw: Any, deadband_deg: float | None) -> dict | None:
    """The ``inclinometer`` block, validated: noise and resolution >= 0 and below the
    deadband (a loop cannot hold a band narrower than its sensor's noise)."""
    n = len(c.problems)
    i = c.section(raw, _INCLINOMETER, f'{key}.inclinometer')
    if len(c.problems) > n:
        return None
    for k in ('noise_deg', 'resolution_deg'):
        if not i[k] >= 0:
            c.add(f'{key}.inclinometer.{k}', f'must be >= 0, got {i[k]}')
        elif deadband_deg is not None and not i[k] < deadband_deg / 2:
            c.add(f'{key}.inclinometer.{k}', f'{i[k]} deg: must be below half the deadband '
                                             f'({deadband_deg} deg) or the loop hunts')
    if abs(i['offset_deg']) > 90:
        c.add(f'{key}.inclinometer.offset_deg', f'must be within [-90, 90] deg, got {i["offset_deg"]}')
    return _si(i) if len(c.problems) == n else None


def _law_params(c: _Checker, key: str, law: str, raw: Any) -> dict | None:
    schema = _LAW_PARAMS.get(law, {})
    if raw is None:
        if schema:
            c.add(f'{key}.law_params', f'missing (the {law} law needs {", ".join(schema)})')
            return None
        return {}
    if not schema:
        c.add(f'{key}.law_params', f'the {law} law takes no constants')
        return None
    n = len(c.problems)
    p = c.section(raw, schema, f'{key}.law_params')
    if len(c.problems) > n:
        return None
    out: dict = {}
    for k, v in p.items():
        if k.endswith('_deg'):
            if isinstance(v, list):
                if not v or not all(_type_ok('num', x) for x in v):
                    c.add(f'{key}.law_params.{k}', f'must be a non-empty list of finite numbers, got {v!r}')
                    return None
                out[k[:-4]] = tuple(_rad(x) for x in v)
            else:
                out[k[:-4]] = _rad(v)
        else:
            out[k] = float(v)
    if law == 'lepten_linear' and not 0.0 < out['pace'] <= 1.0:
        c.add(f'{key}.law_params.pace', f'must be in (0, 1], got {out["pace"]}')
        return None
    if law == 'seed003_linkage':
        if not 0 < out['max_inclination'] <= math.pi / 2:
            c.add(f'{key}.law_params.max_inclination_deg', 'must be in (0, 90] deg')
            return None
        if not 0 < out['step_s'] <= 21600:
            c.add(f'{key}.law_params.step_s', 'must be in (0, 21600] s')
            return None
    return out


def _named_list(c: _Checker, items: Any, schema: dict, key: str) -> dict:
    out: dict = {}
    for i, raw in enumerate(items):
        k = f'{key}[{i}]'
        d = c.section(raw, schema, k)
        name = d.get('name')
        if name is None:
            continue
        if name in out:
            c.add(f'{k}.name', f'duplicate name {name!r} (also {key}[{list(out).index(name)}])')
            continue
        out[name] = (k, d)
    return out



def _kinded(c: _Checker, items: Any, schema: dict, key: str, what: str, kinds: tuple[str, ...]):
    """Yield ``(name, key, section)`` of the named entries whose ``kind`` is one of ``kinds``;
    an unknown kind is reported (a missing one already is, by the schema) and the entry skipped."""
    for name, (k, d) in _named_list(c, items, schema, key).items():
        if d.get('kind') in kinds:
            yield name, k, d
        elif 'kind' in d:
            c.add(f'{k}.kind', f'unknown {what} kind {d["kind"]!r}; known: {", ".join(kinds)}')

def _optics(c: _Checker, raw: Any) -> Optics | None:
    n0 = len(c.problems)
    o = c.section(raw, _OPTICS, 'optics')
    if len(c.problems) > n0:
        return None
    checks = [
        ('lines', o['lines'] >= 1, 'must be >= 1'),
        ('lines', o['lines'] % 2 == (1 if o['central_line'] else 0),
         f'{o["lines"]} lines {"with" if o["central_line"] else "without"} a central line: the count must be '
         f'{"odd" if o["central_line"] else "even"} (lines are symmetric about the receiver)'),
        ('line_width', o['line_width'] > 0, 'must be > 0 m'),
        ('line_length', o['line_length'] > 0, 'must be > 0 m'),
        ('gap', o['gap'] >= 0, 'must be >= 0 m'),
        ('receiver_height', o['receiver_height'] > 0, 'must be > 0 m'),
        ('tube_diameter', o['tube_diameter'] > 0, 'must be > 0 m'),
        ('receiver_width', o['receiver_width'] >= o['tube_diameter'], 'must be >= tube_diameter (the aperture holds the tube)'),
        ('tube_count', o['tube_count'] >= 1, 'must be >= 1'),
        ('receiver_length', o['receiver_length'] > 0, 'must be > 0 m'),
        ('azimuth_deg', -90 <= o['azimuth_deg'] <= 90, 'must be within [-90, 90] deg'),
        ('rotation_radius', 0 <= o.get('rotation_radius', 0.0) < o['receiver_height'] / 2,
         'must be in [0, receiver_height / 2) m'),
    ]
    if 'tube_ends' in o:
        right, left = o['tube_ends']
        checks.append(('tube_ends', right < left and math.isclose(left - right, o['receiver_length'], rel_tol=1e-6),
                       '[L_a^r, L_a^l] must be increasing and span receiver_length'))
    ok = True
    for k, good, text in checks:
        if not good:
            c.add(f'optics.{k}', f'{o[k]!r}: {text}')
            ok = False
    if not ok:
        return None
    return Optics(lines=o['lines'], central_line=o['central_line'], line_width=float(o['line_width']),
                  line_length=float(o['line_length']), gap=float(o['gap']),
                  receiver_height=float(o['receiver_height']), receiver_width=float(o['receiver_width']),
                  tube_diameter=float(o['tube_diameter']), tube_count=o['tube_count'],
                  receiver_length=float(o['receiver_length']), azimuth=_rad(o['azimuth_deg']),
                  rotation_radius=float(o.get('rotation_radius', 0.0)),
                  tube_ends=tuple(float(x) for x in o['tube_ends']) if 'tube_ends' in o else None)


def parse(data: Any, where: str = 'description') -> Description:
    """Validate a parsed YAML document; :class:`DescriptionError` lists every problem."""
    c = _Checker(where)
    top = c.section(data, _TOP, '')
    movements: dict = {}
    for name, raw in (top.get('movements') or {}).items():
        mv = _movement(c, str(name), raw)
        if mv is not None:
            movements[mv.name] = mv
    if 'movements' in top and JOINTS[0] not in top['movements']:
        c.add('movements', f'a collector needs the {JOINTS[0]} movement')
    # a law needs the movements of LAW_NEEDS; those of LAW_MOVEMENTS it has move together
    for mv in movements.values():
        for needed in LAW_NEEDS[mv.law]:
            if needed not in (top.get('movements') or {}):
                c.add(f'movements.{mv.name}.law', f'the {mv.law} law needs the {needed} movement, '
                                                  f'which this collector lacks')
        for other in LAW_MOVEMENTS[mv.law]:
            if other in movements and movements[other].law != mv.law:
                c.add(f'movements.{mv.name}.law', f'{mv.law!r} differs from movements.{other}.law '
                                                  f'{movements[other].law!r}: the two move together')
    boards = {}
    for name, k, d in _kinded(c, top.get('boards') or [], _BOARD, 'boards', 'board', BOARD_KINDS):
        mv = d.get('movement')
        if d['kind'] == 'axis' and mv not in (top.get('movements') or {}):
            c.add(f'{k}.movement', f'an axis board drives a movement of this collector; got {mv!r}')
            continue
        if d['kind'] != 'axis' and mv is not None:
            c.add(f'{k}.movement', f'only an axis board drives a movement ({d["kind"]} board)')
            continue
        boards[name] = Board(name=name, kind=d['kind'], hardware=d.get('hardware', ''), movement=mv)
    driven = [b.movement for b in boards.values() if b.movement]
    for name in (top.get('movements') or {}):
        if name in JOINTS and driven.count(name) != 1:
            c.add(f'movements.{name}', f'needs exactly one axis board (boards with movement: {name}); '
                                       f'found {driven.count(name)}')
    sensors = {}
    for name, k, d in _kinded(c, top.get('sensors') or [], _SENSOR, 'sensors', 'sensor', SENSOR_KINDS):
        named = {i.get('name') for i in top.get('boards') or [] if isinstance(i, Mapping)}
        if d.get('board') not in named:     # a board named but refused above is reported there
            c.add(f'{k}.board', f'{d.get("board")!r} is not a board of this collector')
            continue
        sensors[name] = Sensor(name=name, kind=d['kind'], board=d['board'], part=d.get('part', ''),
                               site_addition=bool(d.get('site_addition', False)))
    optics = _optics(c, top['optics']) if 'optics' in top else None
    # cross-checks with the optics
    m = movements.get(JOINTS[0])
    if m is not None and optics is not None:
        if m.feedback_line is not None and m.feedback_line > optics.lines:
            c.add(f'movements.{JOINTS[0]}.feedback_line', f'line {m.feedback_line} of {optics.lines} lines')
        if m.law == 'lepten_linear':
            reach = m.law_params['pace'] * m.law_params['transversal_limit']
            if not (m.range[0] <= -reach and reach <= m.range[1]):
                c.add(f'movements.{JOINTS[0]}.range_deg',
                      f'the law needs the drive at +/-{math.degrees(reach):.2f} deg (pace x transversal_limit), '
                      'outside the range')
        offsets = m.law_params.get('offsets')
        if offsets is not None and len(offsets) != optics.lines:
            c.add(f'movements.{JOINTS[0]}.law_params.offsets_deg',
                  f'{len(offsets)} offsets for {optics.lines} lines (one per line)')
    if c.problems:
        raise DescriptionError(c.problems)
    return Description(name=top['name'], source=top['source'], path=where, movements=movements,
                       boards=boards, sensors=sensors, optics=optics)


def resolve(name: str, base: str | os.PathLike | None = None) -> Path:
    """The description file ``name``: absolute, or relative to ``base`` (the directory of
    the site config that names it)."""
    p = user_path(name)
    if not p.is_absolute() and base is not None:
        p = Path(base) / p
    return p


def find(name: str, params_files=(), cwd: str | os.PathLike | None = None) -> Path:
    """The description file a node was given as ``name``: absolute as is; relative, beside
    the last of ``params_files`` (the node's ``--params-file`` arguments, later wins, as
    rcl) that has it, else in ``cwd`` (the current directory). When none has it, the
    path beside the last params file (or in cwd): :func:`load` then says it is missing."""
    p = user_path(name)
    if p.is_absolute():
        return p
    candidates = [Path(f).parent / p for f in reversed(list(params_files))]
    candidates.append(Path(cwd if cwd is not None else os.getcwd()) / p)
    for cand in candidates:
        try:
            if cand.is_file():
                return cand
        except (OSError, ValueError):   # an unreadable directory, a NUL in the name
            continue
    return candidates[0]


def params_files(args) -> list[str]:
    """The ``--params-file`` paths of a ROS command line (``args``: argv or cli_args)."""
    args = list(args or ())
    return [args[i + 1] for i, a in enumerate(args[:-1]) if a == '--params-file']


def for_node(name: str, ros_args=()) -> Description | None:
    """The description a node's ``collector.description`` parameter names (None for ''),
    relative to the params file that names it (:func:`find`): DescriptionError (a
    ValueError) saying what is wrong."""
    if not name:
        return None
    return load(find(name, params_files(ros_args)))


def load(path: str | os.PathLike) -> Description:
    """Read and validate one description file (:func:`parse`): DescriptionError naming
    the file (and the key) when it is unreadable, not YAML or invalid."""
    p = Path(path)
    try:
        text = p.read_text(encoding='utf-8')
    except (OSError, UnicodeDecodeError, ValueError) as exc:   # ValueError: a NUL in the name
        raise DescriptionError([f'{p}: cannot read the collector description: {exc}']) from None

    class _UniqueKeys(yaml.SafeLoader):
        pass

    def _mapping(loader, node, deep=False):
        seen = set()
        for k, _ in node.value:
            key = loader.construct_object(k, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(None, None, f'duplicate key {key!r}', k.start_mark)
            seen.add(key)
        return yaml.SafeLoader.construct_mapping(loader, node, deep)
    _UniqueKeys.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping)
    try:
        data = yaml.load(text, Loader=_UniqueKeys)  # noqa: S506 - a SafeLoader subclass
    except RecursionError:
        raise DescriptionError([f'{p}: YAML nested too deeply']) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        what = getattr(exc, 'problem', None) or 'invalid YAML'
        raise DescriptionError([f'{p}: {what}' + (f' at line {mark.line + 1}' if mark else '')]) from None
    return parse(data, str(p))
