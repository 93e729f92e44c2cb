"""Rolling-horizon setpoint trajectories for the three axes (pure numpy, no rclpy).

The planner publishes, every few seconds, the setpoints of the next ``horizon``
seconds at ``step`` spacing (default 120 s at 1 s) so the axis drivers can keep
following the plan for the rest of the horizon if the planner dies (seed 000 Step
1.3: "the tracking system aligns the mirrors, the mobile structure and the secondary
reflector system using the tabulated database").

Axis order everywhere: :data:`sslfr_common.contract.JOINTS` = (mirrors, mobile_structure,
secondary_reflector). Positions in radians (mirrors = beta_0 = theta_t / 2, seed 000
eq. 11, +pi/2 sleeping; beta_M and beta_a, seed 000 eq. 16), velocities in rad/s,
times in float seconds since the Unix epoch (UTC).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class Horizon:
    """Setpoints of the coming horizon.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Instants [s since the Unix epoch, UTC], strictly increasing, t[0] > now.
    positions : ndarray, shape (N, 3)
        Setpoints [rad] in :data:`sslfr_common.contract.JOINTS` order.
    velocities : ndarray, shape (N, 3)
        Setpoint rates [rad/s].
    """

    t: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray

    def __len__(self) -> int:
        return int(self.t.size)


def horizon_times(now: float, horizon: float, step: float) -> np.ndarray:
    """Instants of the next horizon, on the ``step`` grid, all strictly after ``now``.

    The grid is anchored at the Unix epoch (with step = 1 s: whole UTC seconds, the
    instants of the per-second day table of seed 000 Step 1.2), so successive
    horizons share their points.

    Parameters
    ----------
    now : float
        Current ROS time [s since the Unix epoch].
    horizon : float
        Horizon length [s], > 0; ``floor(horizon / step) + 1`` points are returned
        (120 s at 1 s: 121 points spanning 120 s).
    step : float
        Point spacing [s], > 0.

    Returns
    -------
    ndarray
        t[0] = the first grid instant strictly after ``now``.
    """
    if not (step > 0 and horizon > 0):
        raise ValueError('step and horizon must be > 0')
    k0 = math.floor(now / step) + 1
    n = int(math.floor(horizon / step + 1e-9)) + 1
    t = (k0 + np.arange(n, dtype=np.float64)) * step
    # guard against floating-point rounding of k0 * step
    if t[0] <= now:
        t = t + step
    return t


def velocities_from(positions_ext: np.ndarray, step: float) -> np.ndarray:
    """Central-difference rates of a sampled setpoint path.

    Parameters
    ----------
    positions_ext : ndarray, shape (N + 2, 3)
        Positions [rad] at t[0] - step, t[0], ..., t[N-1], t[N-1] + step.
    step : float
        Spacing [s].

    Returns
    -------
    ndarray, shape (N, 3)
        (p[k+1] - p[k-1]) / (2 step) [rad/s] at the N inner instants.
    """
    return (positions_ext[2:] - positions_ext[:-2]) / (2.0 * step)


def hold(t: np.ndarray, pose) -> Horizon:
    """Hold trajectory (MANUAL phase): every point at ``pose`` [rad], zero rate."""
    pose = np.asarray(pose, dtype=np.float64).reshape(1, 3)
    pos = np.repeat(pose, t.size, axis=0)
    return Horizon(t, pos, np.zeros_like(pos))


def ramp(t: np.ndarray, start_time: float, start_pose, target_pose, speeds) -> Horizon:
    """Move every axis from ``start_pose`` to ``target_pose`` at constant speed.

    Used for the STOW phase (seed 000 Step 4.1: mirrors back to the sleeping
    position). Each axis leaves ``start_pose`` at ``start_time`` and moves at its own
    ``speeds`` rate until it reaches the target, then holds it. Anchoring the ramp to
    the instant the stow began makes successive republished horizons agree.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Instants [s].
    start_time : float
        When the ramp starts [s].
    start_pose, target_pose : array_like, shape (3,)
        [rad].
    speeds : array_like, shape (3,)
        Axis rates [rad/s], > 0.

    Returns
    -------
    Horizon
    """
    p0 = np.asarray(start_pose, dtype=np.float64)
    p1 = np.asarray(target_pose, dtype=np.float64)
    v = np.asarray(speeds, dtype=np.float64)
    if np.any(~(v > 0)):
        raise ValueError('ramp speeds must be > 0')
    dist = p1 - p0
    sign = np.sign(dist)
    dur = np.abs(dist) / v                                  # time each axis needs [s]
    el = np.clip(t - start_time, 0.0, None)[:, None]        # elapsed [s], (N, 1)
    moving = el < dur[None, :]
    pos = np.where(moving, p0 + sign * v * el, p1)
    vel = np.where(moving & (t[:, None] >= start_time), sign * v, 0.0)
    return Horizon(t, pos, vel)


def finite_or_none(h: Horizon) -> str | None:
    """Return None when every position and rate is finite, else a reason."""
    if not np.all(np.isfinite(h.positions)):
        return 'non-finite setpoint in horizon'
    if not np.all(np.isfinite(h.velocities)):
        return 'non-finite rate in horizon'
    return None
