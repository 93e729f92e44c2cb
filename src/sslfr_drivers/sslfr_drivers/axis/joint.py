"""Joint geometry of one axis (no rclpy): step calibration, soft limits, move speed.

Angles are joint angles in radians (REP-103, the axis conventions of
docs/architecture.md); motor positions are integer steps of the board's counter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from sslfr_common.contract import STEP_ANGLE


# --------------------------------------------------------------------------- calibration
@dataclass(frozen=True)
class Calibration:
    """Joint angle <-> motor step conversion.

    ``theta = offset + sign * steps * step_angle / gear_ratio``

    Parameters
    ----------
    step_angle : float
        Motor shaft rotation per step [rad/step], > 0. Seed 000 section 3.4: 0.006 deg
        (with ``gear_ratio`` 1 the seed's 0.006 deg is the joint resolution).
    gear_ratio : float
        Motor shaft angle per joint angle [-], > 0 (a 10:1 reducer is 10).
    offset : float
        Joint angle at step count 0 [rad] (where SET_ZERO / homing puts the counter).
    invert : bool
        True when positive steps turn the joint in the negative direction.
    """

    step_angle: float = STEP_ANGLE
    gear_ratio: float = 1.0
    offset: float = 0.0
    invert: bool = False

    def __post_init__(self):
        for name in ('step_angle', 'gear_ratio'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be finite and > 0, got {value!r}')
        if not math.isfinite(self.offset):
            raise ValueError(f'offset must be finite, got {self.offset!r}')

    @property
    def joint_per_step(self) -> float:
        """Joint rotation per motor step [rad/step] (signed by ``invert``)."""
        return (-1.0 if self.invert else 1.0) * self.step_angle / self.gear_ratio

    def steps(self, theta: float) -> int:
        """Nearest step count for joint angle ``theta`` [rad] -> [steps]."""
        return int(round((theta - self.offset) / self.joint_per_step))

    def angle(self, steps: float) -> float:
        """Joint angle [rad] for a step count [steps]."""
        return self.offset + steps * self.joint_per_step

    def step_rate(self, speed: float) -> float:
        """Motor step rate [steps/s] (>= 0) for a joint speed [rad/s]."""
        return abs(speed / self.joint_per_step)


# --------------------------------------------------------------------------- limits
@dataclass(frozen=True)
class SoftLimits:
    """Software joint limits ``lower <= theta <= upper`` [rad]."""

    lower: float
    upper: float

    def __post_init__(self):
        if not (math.isfinite(self.lower) and math.isfinite(self.upper) and self.lower < self.upper):
            raise ValueError(f'soft limits need finite lower < upper, got {self.lower!r}..{self.upper!r}')

    def contains(self, theta: float, tol: float = 1e-9) -> bool:
        """True when ``theta`` [rad] is inside the limits (``tol`` [rad] of slack)."""
        return self.lower - tol <= theta <= self.upper + tol

    def clamp(self, theta: float) -> float:
        """``theta`` [rad] clamped into the limits."""
        return min(self.upper, max(self.lower, theta))

    def steps(self, cal: Calibration, theta: float, margin: float = 0.0) -> int:
        """The step count [steps] nearest ``theta`` [rad] whose angle lies inside the
        limits narrowed by ``margin`` [rad] (>= 0) on each side: a target on a limit
        would otherwise round to the step just beyond it, which the board refuses
        (OUT_OF_RANGE) when the limit is its mechanical range."""
        lo, hi = self.lower + margin, self.upper - margin
        if lo > hi:
            lo = hi = 0.5 * (self.lower + self.upper)
        steps = cal.steps(min(hi, max(lo, theta)))
        inward = 1 if cal.steps(1.0) >= cal.steps(0.0) else -1     # steps grow with the angle?
        if cal.angle(steps) > hi + 1e-12:
            steps -= inward
        elif cal.angle(steps) < lo - 1e-12:
            steps += inward
        return steps


def move_speed(current: float, target: float, horizon: float, max_speed: float,
               min_speed: float) -> float:
    """Speed [rad/s] to send with a MOVE_TO so the axis reaches ``target`` in ``horizon``.

    ``v = clamp(|target - current| / horizon, min_speed, max_speed)``: commanding the
    setpoint one control period ahead at this speed keeps the motor moving
    continuously instead of stop-and-go, and never faster than ``max_speed``.

    Parameters
    ----------
    current, target : float
        Measured and target joint angles [rad].
    horizon : float
        Time to reach the target [s], > 0 (the control period).
    max_speed, min_speed : float
        Speed bounds [rad/s], 0 < min_speed <= max_speed.
    """
    if horizon <= 0:
        return max_speed
    return min(max_speed, max(min_speed, abs(target - current) / horizon))
