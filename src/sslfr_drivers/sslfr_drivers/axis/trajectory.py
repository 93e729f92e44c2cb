"""The axis driver's trajectory (no rclpy): one joint's setpoints, ONE validation.

As in ros2_controllers' joint_trajectory_controller, the driver keeps a trajectory
class of its own and a single validation function that decides, for a received
``trajectory_msgs/JointTrajectory`` (given here as plain numbers, a
:class:`TrajectoryMsg`), whether it is for this joint, whether it is well formed and
whether its numbers are acceptable:

- not for this joint (its name is not in ``joint_names``): ignored, nothing counted;
- refused (:class:`TrajectoryRejected`, the reason is logged and counted), the last
  good trajectory stays: duplicate joint names; a point whose positions, velocities
  or accelerations do not have one value per joint (velocities/accelerations may be
  empty, but then on every point); no points; a NaN/inf time, position or velocity;
  times not strictly increasing; a position outside the soft limits; every point in
  the past;
- accepted: a :class:`Trajectory` of this joint, sampled by cubic Hermite
  interpolation when velocities are given, else linearly.

Times are float seconds since the Unix epoch (ROS time, UTC): point time =
``start`` (the header stamp; 0 = "now", the ROS convention) + ``time_from_start``.
Positions are joint angles [rad], velocities [rad/s] (REP-103).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sslfr_drivers.axis.joint import SoftLimits


class TrajectoryRejected(ValueError):
    """A trajectory was refused; ``str(exc)`` is the reason to log."""


@dataclass(frozen=True)
class TrajectoryPoint:
    """One ``JointTrajectoryPoint`` in numbers: ``time_from_start`` [s], one value per
    joint of positions [rad], velocities [rad/s] and accelerations [rad/s^2] (the
    last two may be empty)."""

    time_from_start: float
    positions: tuple[float, ...]
    velocities: tuple[float, ...] = ()
    accelerations: tuple[float, ...] = ()


@dataclass(frozen=True)
class TrajectoryMsg:
    """A ``JointTrajectory`` in numbers: ``start`` = header stamp [s since the epoch,
    0 = now], ``joint_names`` and ``points`` (:class:`TrajectoryPoint`)."""

    joint_names: tuple[str, ...]
    start: float
    points: tuple[TrajectoryPoint, ...]

    @classmethod
    def for_joint(cls, joint: str, times, positions, velocities=None) -> 'TrajectoryMsg':
        """A one-joint message with absolute point ``times`` [s since the epoch]
        (``start`` = the first time, so times of 0 stay absolute as well)."""
        times = [float(t) for t in times]
        vel = list(velocities) if velocities is not None and len(velocities) else []
        start = times[0] if times else 0.0
        pts = []
        for k, t in enumerate(times):
            # a length mismatch is kept for validate_trajectory to refuse
            p = (float(positions[k]),) if len(positions) == len(times) else ()
            v = (float(vel[k]),) if k < len(vel) else ()
            pts.append(TrajectoryPoint(t - start, p, v))
        return cls((joint,), start, tuple(pts))


@dataclass(frozen=True)
class Trajectory:
    """One joint's trajectory: absolute times [s, Unix epoch] and positions [rad].

    ``velocities`` [rad/s] is optional; when given, :meth:`sample` uses cubic
    Hermite interpolation between points, otherwise linear.
    """

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None = None

    @property
    def start(self) -> float:
        """Time of the first point [s since the Unix epoch]."""
        return float(self.times[0])

    @property
    def end(self) -> float:
        """Time of the last point [s since the Unix epoch]."""
        return float(self.times[-1])

    def sample(self, t: float) -> tuple[float, float]:
        """Setpoint ``(position [rad], velocity [rad/s])`` at time ``t`` [s].

        Before the first point the first position is held, after the last point the
        last position is held (velocity 0): trajectory starvation holds position.
        """
        ts, ps = self.times, self.positions
        if t <= ts[0]:
            return float(ps[0]), 0.0
        if t >= ts[-1]:
            return float(ps[-1]), 0.0
        i = int(np.searchsorted(ts, t, side='right')) - 1
        t0, t1 = ts[i], ts[i + 1]
        h = t1 - t0
        s = (t - t0) / h
        p0, p1 = ps[i], ps[i + 1]
        if self.velocities is None:
            return float(p0 + s * (p1 - p0)), float((p1 - p0) / h)
        m0, m1 = self.velocities[i] * h, self.velocities[i + 1] * h
        s2, s3 = s * s, s * s * s
        pos = ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0
               + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1)
        dpos = ((6 * s2 - 6 * s) * p0 + (3 * s2 - 4 * s + 1) * m0
                + (-6 * s2 + 6 * s) * p1 + (3 * s2 - 2 * s) * m1) / h
        return float(pos), float(dpos)


def _joint_column(msg: TrajectoryMsg, j: int) -> tuple[list, list, list | None]:
    """Times, positions and velocities (or None) of joint index ``j``; structural
    refusals (lengths, velocities on some points only)."""
    n = len(msg.joint_names)
    times, pos, vel = [], [], []
    with_vel = 0
    for k, pt in enumerate(msg.points):
        if len(pt.positions) != n:
            raise TrajectoryRejected(f'point {k} has {len(pt.positions)} positions for {n} joints')
        for field, values in (('velocities', pt.velocities), ('accelerations', pt.accelerations)):
            if values and len(values) != n:
                raise TrajectoryRejected(f'point {k} has {len(values)} {field} for {n} joints')
        times.append(msg.start + pt.time_from_start)
        pos.append(pt.positions[j])
        if pt.velocities:
            with_vel += 1
            vel.append(pt.velocities[j])
    if 0 < with_vel < len(msg.points):
        raise TrajectoryRejected(f'velocities on {with_vel} of {len(msg.points)} points (all or none)')
    return times, pos, (vel if with_vel else None)


def validate_trajectory(msg: TrajectoryMsg, joint: str, now: float,
                        limits: SoftLimits) -> Trajectory | None:
    """The one validation: ``msg`` -> this joint's :class:`Trajectory`.

    Parameters
    ----------
    msg : TrajectoryMsg
        The received trajectory in numbers (see the module docstring for the rules).
    joint : str
        This driver's joint name.
    now : float
        Current ROS time [s since the Unix epoch]; also the start of a message whose
        stamp is 0.
    limits : SoftLimits
        The axis soft limits [rad].

    Returns
    -------
    Trajectory or None
        None when ``joint`` is not in ``msg.joint_names`` (not for this driver).

    Raises
    ------
    TrajectoryRejected
        With the reason, for every refusal listed in the module docstring.
    """
    names = list(msg.joint_names)
    if joint not in names:
        return None
    dup = sorted({x for x in names if names.count(x) > 1})
    if dup:
        raise TrajectoryRejected(f'duplicate joint names: {", ".join(dup)}')
    if msg.start == 0.0:
        msg = TrajectoryMsg(msg.joint_names, now, msg.points)
    times, positions, velocities = _joint_column(msg, names.index(joint))
    t = np.asarray(times, dtype=np.float64)
    p = np.asarray(positions, dtype=np.float64)
    if t.size == 0:
        raise TrajectoryRejected('no points')
    if not np.all(np.isfinite(t)):
        raise TrajectoryRejected('non-finite point time')
    bad = np.flatnonzero(~np.isfinite(p))
    if bad.size:
        raise TrajectoryRejected(f'non-finite position at point {int(bad[0])}')
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise TrajectoryRejected('point times not strictly increasing')
    out = np.flatnonzero((p < limits.lower - 1e-9) | (p > limits.upper + 1e-9))
    if out.size:
        k = int(out[0])
        raise TrajectoryRejected(
            f'point {k} position {p[k]:.6f} rad outside soft limits '
            f'[{limits.lower:.6f}, {limits.upper:.6f}] rad')
    if t[-1] < now:
        raise TrajectoryRejected(f'past-only trajectory: last point {now - t[-1]:.3f} s before now')
    v = None
    if velocities is not None:
        v = np.asarray(velocities, dtype=np.float64)
        if not np.all(np.isfinite(v)):
            raise TrajectoryRejected('non-finite velocity')
    return Trajectory(t, p, v)


class TrajectoryStore:
    """Holds the last good trajectory; refused ones leave it untouched.

    ``accepted`` / ``rejected`` count the messages for this joint [-];
    ``last_reason`` is the last refusal.
    """

    def __init__(self) -> None:
        self.current: Trajectory | None = None
        self.accepted = 0
        self.rejected = 0
        self.last_reason = ''

    def offer(self, msg: TrajectoryMsg, joint: str, now: float, limits: SoftLimits) -> str | None:
        """Validate and keep a trajectory; None when accepted or not for ``joint``,
        else the refusal reason (counted)."""
        try:
            traj = validate_trajectory(msg, joint, now, limits)
        except TrajectoryRejected as exc:
            self.rejected += 1
            self.last_reason = str(exc)
            return self.last_reason
        if traj is not None:
            self.current = traj
            self.accepted += 1
        return None

    def clear(self) -> None:
        """Forget the current trajectory (no setpoint until the next one)."""
        self.current = None

    def setpoint(self, t: float) -> tuple[float, float, str] | None:
        """``(position [rad], velocity [rad/s], status)`` at ``t`` [s], or None.

        status: ``'waiting'`` (before the first point: first position held),
        ``'following'``, ``'starved'`` (past the last point: last position held).
        """
        if self.current is None:
            return None
        pos, vel = self.current.sample(t)
        if t < self.current.start:
            return pos, 0.0, 'waiting'
        if t > self.current.end:
            return pos, 0.0, 'starved'
        return pos, vel, 'following'
