"""Pure models of the two drives without limit switches (issue 34 item 3; no rclpy).

* **Linear actuator closed on an inclinometer** (seed 004 section 2.1: one linear
  actuator with PWM speed control moves ten lever arms through an actuator bar; the
  inclinometer on line 2 measures the lines' angle):

  - :class:`LeverGeometry`: actuator length <-> line angle by the law of cosines on
    the triangle (lever pivot P, lever pin, actuator base mount A). Not linear.
  - :func:`duty_for_speed` / :func:`speed_for_duty`: PWM duty of the speed controller
    for an actuator speed (a DC motor does not start below ``min_duty``).
  - :class:`ActuatorLoop`: the board's closed loop (target angle, measured angle ->
    signed duty) with a deadband and hysteresis, slowing down near the target.
  - :class:`MotionWatch`: stall (no inclinometer change while driving) and time-out
    (a move lasting too long) detection.
  - :class:`Inclinometer`: reading = angle + mounting offset + Gaussian noise,
    quantised; :meth:`Inclinometer.correct` removes the calibrated offset.

* **Stepper without switches** (seed 003: TB6600 + NEMA23, no switches): the axis is
  referenced by an operator at a known angle; :class:`ReferenceStore` keeps that
  reference in a file (atomic write) with the board's boot count, so a board reset
  (a new boot count, or the board no longer HOMED) marks it lost.

Angles [rad] (line angle, positive as the joint angle of docs/conventions.md),
lengths [m], speeds [m/s] or [rad/s], times [s] on the steady clock.
"""
from __future__ import annotations

import json
import math
import os
import random
from dataclasses import asdict, dataclass
from pathlib import Path

from sslfr_common.files import atomic_write


# ------------------------------------------------------------ lever geometry
@dataclass(frozen=True)
class LeverGeometry:
    """Actuator length <-> line angle of one lever arm (law of cosines).

    The lever of length ``lever`` [m] turns about the line's pivot P; the actuator
    joins the lever pin to a fixed base mount A at ``mount_distance`` [m] from P.
    ``mount_angle`` [rad] is the angle at P between the lever and PA when the line
    angle is 0; the angle at P is ``gamma = mount_angle + theta``, and

        L(theta)^2 = d^2 + r^2 - 2 d r cos(mount_angle + theta)       (d: mount, r: lever)

    so L grows with theta while 0 < gamma < pi (the only branch used: validate with
    :meth:`problems`). ``stroke`` = (L_min, L_max) [m] of the actuator.
    """

    lever: float
    mount_distance: float
    mount_angle: float
    stroke: tuple[float, float]

    def gamma(self, theta: float) -> float:
        """Angle at the pivot between lever and base mount [rad] for line angle ``theta`` [rad]."""
        return self.mount_angle + theta

    def length(self, theta: float) -> float:
        """Actuator length [m] at line angle ``theta`` [rad] (law of cosines)."""
        d, r = self.mount_distance, self.lever
        return math.sqrt(d * d + r * r - 2.0 * d * r * math.cos(self.gamma(theta)))

    def angle(self, length: float) -> float:
        """Line angle [rad] at actuator length ``length`` [m] (inverse law of cosines);
        ValueError outside the triangle (|d - r| <= L <= d + r)."""
        d, r = self.mount_distance, self.lever
        c = (d * d + r * r - length * length) / (2.0 * d * r)
        if not -1.0 <= c <= 1.0:
            raise ValueError(f'actuator length {length} m: no lever position (|d - r| <= L <= d + r)')
        return math.acos(c) - self.mount_angle

    def rate(self, theta: float) -> float:
        """dL/dtheta [m/rad] at line angle ``theta`` [rad]: d r sin(gamma) / L (> 0 on the branch)."""
        return self.mount_distance * self.lever * math.sin(self.gamma(theta)) / self.length(theta)

    def problems(self, angle_range: tuple[float, float]) -> list[str]:
        """What makes this geometry unusable over ``angle_range`` [rad] (empty: usable):
        sizes, the single-valued branch (gamma within (5 deg, 175 deg): near 0 or pi the
        actuator barely moves the lever) and the stroke covering the range."""
        out = []
        if not (self.lever > 0 and self.mount_distance > 0):
            return ['lever_m and mount_distance_m must be > 0']
        lo, hi = self.stroke
        if not 0 < lo < hi:
            return [f'stroke_m [{lo}, {hi}]: must be 0 < min < max']
        margin = math.radians(5.0)
        g_lo, g_hi = self.gamma(angle_range[0]), self.gamma(angle_range[1])
        if g_lo < margin or g_hi > math.pi - margin:
            out.append(f'the lever-to-mount angle spans [{math.degrees(g_lo):.1f}, {math.degrees(g_hi):.1f}] deg '
                       'over range_deg: it must stay within (5, 175) deg (mount_angle_deg + range)')
            return out
        need = (self.length(angle_range[0]), self.length(angle_range[1]))
        if need[0] < lo or need[1] > hi:
            out.append(f'range_deg needs the actuator from {need[0]:.4f} to {need[1]:.4f} m, '
                       f'outside stroke_m [{lo}, {hi}]')
        return out


# ------------------------------------------------------------------ PWM speed
def speed_for_duty(duty: float, max_speed: float, min_duty: float) -> float:
    """Actuator speed [m/s] (signed as ``duty``) at PWM duty ``duty`` in [-1, 1]: 0 below
    ``min_duty`` (the motor does not start), then linear up to ``max_speed`` [m/s] at 1."""
    a = min(abs(duty), 1.0)
    if a < min_duty:
        return 0.0
    return math.copysign(max_speed * (a - min_duty) / (1.0 - min_duty), duty)


def duty_for_speed(speed: float, max_speed: float, min_duty: float) -> float:
    """PWM duty in [-1, 1] (signed as ``speed``) for actuator speed ``speed`` [m/s]: the
    inverse of :func:`speed_for_duty`, clamped to 1; 0 for speed 0 and at least
    ``min_duty`` otherwise (the slowest the actuator moves is just above its start)."""
    if speed == 0.0:
        return 0.0
    a = min(abs(speed) / max_speed, 1.0)
    return math.copysign(min_duty + (1.0 - min_duty) * a, speed)


@dataclass
class ActuatorLoop:
    """The actuator board's position loop on the measured line angle.

    Settles when |error| <= ``deadband`` / 2 and starts again only when |error| >
    ``deadband`` [rad] (hysteresis: inclinometer noise does not make it hunt). While
    driving, the angular speed is min(``speed`` of the move [rad/s], ``gain`` |error|)
    [1/s] (slows down on the way in: no overshoot past the deadband), but at least
    ``gain`` x ``deadband`` / 2 (a tracking move asks for a crawl the actuator cannot
    make below its start duty: it moves visibly, then rests inside the band), converted
    to the actuator speed through the lever (``LeverGeometry.rate``) and to a PWM duty.
    """

    geometry: LeverGeometry
    deadband: float
    max_speed: float          # [m/s] actuator at duty 1
    min_duty: float
    gain: float = 2.0         # [1/s]
    driving: bool = False

    def duty(self, target: float, measured: float, speed: float) -> float:
        """Signed PWM duty for ``target`` and ``measured`` line angles [rad] and the move's
        speed limit ``speed`` [rad/s] (> 0); + lengthens the actuator (increases the angle)."""
        err = target - measured
        if self.driving and abs(err) <= self.deadband / 2:
            self.driving = False
        elif not self.driving and abs(err) > self.deadband:
            self.driving = True
        if not self.driving:
            return 0.0
        omega = max(min(speed, self.gain * abs(err)), self.gain * self.deadband / 2)
        v = omega * self.geometry.rate(measured)
        return math.copysign(abs(duty_for_speed(v, self.max_speed, self.min_duty)), err)


@dataclass
class MotionWatch:
    """Stall and time-out detection of a drive measured by an angle sensor.

    *Stall*: driving for ``window`` [s] with the measured angle changing by less than
    ``min_change`` [rad] over that window: the change is the difference of the means of
    the first and last quarters of the window's samples (noise averages out; choose
    ``min_change`` above a few noise sigmas of one reading all the same).
    *Time-out*: one move (driving without a pause toward one target) lasting longer
    than ``timeout`` [s]; a new target starts a new move (:meth:`new_target`: a loop
    tracking a target that moves on every control period may drive without a pause).
    """

    window: float
    min_change: float
    timeout: float
    _since: float | None = None
    _hist: list | None = None

    def reset(self) -> None:
        """Forget the current move (the drive stopped)."""
        self._since = None
        self._hist = None

    def new_target(self) -> None:
        """A new target while driving: the time-out counts again, the stall window
        keeps its samples."""
        self._since = None

    def update(self, now: float, driving: bool, angle: float) -> str | None:
        """Feed one sample (steady ``now`` [s], whether the drive is powered, measured
        ``angle`` [rad]); a fault reason or None."""
        if not driving:
            self.reset()
            return None
        if self._since is None:
            self._since = now
        if self._hist is None:
            self._hist = []
        hist = self._hist
        hist.append((now, angle))
        while len(hist) > 1 and now - hist[1][0] >= self.window:
            hist.pop(0)
        if now - self._since > self.timeout:
            return f'time-out: driving for {now - self._since:.1f} s (> {self.timeout:.1f} s) without reaching the target'
        if now - hist[0][0] >= self.window:
            k = max(1, len(hist) // 4)
            span = abs(sum(a for _, a in hist[-k:]) / k - sum(a for _, a in hist[:k]) / k)
            if span < self.min_change:
                return (f'stall: driving for {now - hist[0][0]:.1f} s with the inclinometer changing '
                        f'{math.degrees(span):.3f} deg (< {math.degrees(self.min_change):.3f} deg)')
        return None


@dataclass(frozen=True)
class Inclinometer:
    """An inclinometer on a line: reading = angle + ``offset`` + N(0, ``noise``),
    quantised to ``resolution`` [rad] (0: none)."""

    offset: float = 0.0
    noise: float = 0.0
    resolution: float = 0.0

    def read(self, angle: float, rng: random.Random) -> float:
        """One reading [rad] of the true line ``angle`` [rad]."""
        v = angle + self.offset + (rng.gauss(0.0, self.noise) if self.noise > 0 else 0.0)
        if self.resolution > 0:
            v = round(v / self.resolution) * self.resolution
        return v

    def correct(self, reading: float) -> float:
        """The line angle [rad] from a ``reading`` [rad]: the calibrated offset removed."""
        return reading - self.offset


# ------------------------------------------------- switchless reference store
@dataclass(frozen=True)
class Reference:
    """An operator's reference of a switchless axis: the joint was at ``angle`` [rad]
    when the board's counter read ``steps``, during the board's boot ``boot_count``;
    ``stamp`` [s since the epoch, UTC]; ``lost``: a board reset since (reason in ``why``)."""

    axis: str
    angle: float
    steps: int
    boot_count: int
    stamp: float
    lost: bool = False
    why: str = ''


class ReferenceStore:
    """One axis's reference in ``<state_dir>/reference_<axis>.json``, written with
    :func:`sslfr_common.files.atomic_write`: a power cut leaves the old file or the new
    one, never half of one."""

    def __init__(self, state_dir: str | os.PathLike, axis: str):
        self.axis = axis
        self.path = Path(state_dir) / f'reference_{axis}.json'

    def save(self, ref: Reference) -> None:
        """Write ``ref`` (atomic); OSError when the directory is not writable."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(self.path, json.dumps(asdict(ref), sort_keys=True))

    def load(self) -> Reference | None:
        """The stored reference, None when there is none; ValueError naming the file when
        it is unreadable or malformed (never a silently wrong reference)."""
        try:
            text = self.path.read_text(encoding='utf-8')
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise ValueError(f'{self.path}: cannot read the reference: {exc}') from None
        try:
            d = json.loads(text)
            ref = Reference(axis=str(d['axis']), angle=float(d['angle']), steps=int(d['steps']),
                            boot_count=int(d['boot_count']), stamp=float(d['stamp']),
                            lost=bool(d.get('lost', False)), why=str(d.get('why', '')))
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f'{self.path}: malformed reference: {exc}') from None
        if ref.axis != self.axis or not math.isfinite(ref.angle):
            raise ValueError(f'{self.path}: a reference of axis {ref.axis!r} (angle {ref.angle}), not of {self.axis!r}')
        return ref

    def record(self, angle: float, steps: int, boot_count: int, stamp: float) -> Reference:
        """The operator referenced the axis at ``angle`` [rad] (counter ``steps``, board
        boot ``boot_count``): store and return it."""
        ref = Reference(self.axis, float(angle), int(steps), int(boot_count), float(stamp))
        self.save(ref)
        return ref

    def check(self, boot_count: int | None, homed: bool) -> tuple[str, Reference | None]:
        """Validity of the stored reference against the board as it is now:
        ``('valid', ref)`` when the board runs the same boot and is still referenced
        (HOMED); ``('lost', ref)`` after a board reset (another boot count, or not
        HOMED), the file then marked lost once; ``('none', None)`` without a reference;
        ``('unknown', ref)`` while the board's boot count is not known yet."""
        ref = self.load()
        if ref is None:
            return 'none', None
        if ref.lost:
            return 'lost', ref
        if boot_count is None:
            return 'unknown', ref
        if boot_count != ref.boot_count or not homed:
            why = (f'board reset: boot {boot_count} since the reference in boot {ref.boot_count}'
                   if boot_count != ref.boot_count else 'the board no longer reports HOMED')
            ref = Reference(**{**asdict(ref), 'lost': True, 'why': why})
            self.save(ref)
            return 'lost', ref
        return 'valid', ref
