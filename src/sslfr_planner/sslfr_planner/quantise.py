"""Actuator quantisation: axis angles to motor steps, and seed 000's step "database".

Seed 000 section 4.1: the tracker tabulates, for every second of the day, the steps
and direction of each axis (0.006 deg per step at the axis). Here the axis step is
``Collector.step_angle / gear_ratio`` [rad per motor step] (:attr:`Collector.axis_steps`);
positions are rounded to the nearest whole step (half away from zero), so the
quantisation error is at most half a step. Angles radians.
"""
from __future__ import annotations

import numpy as np

from .collector import AXES, Collector


def angle_to_steps(angle, axis_step: float):
    """Nearest whole number of motor steps for an axis angle [rad] -> int64 [-]."""
    if not axis_step > 0:
        raise ValueError('axis_step must be > 0 rad')
    a = np.asarray(angle, dtype=float) / axis_step
    return (np.sign(a) * np.floor(np.abs(a) + 0.5)).astype(np.int64)


def steps_to_angle(steps, axis_step: float):
    """Axis angle [rad] of a whole number of motor steps."""
    return np.asarray(steps, dtype=float) * axis_step


def step_database(table, collector: Collector, day_start: float | None = None) -> np.ndarray:
    """Seed 000's per-row database from a :class:`~sslfr_planner.tracking_table.TrackingTable`.

    Parameters
    ----------
    table : TrackingTable
        Rows in time order (e.g. :func:`tabulate_day` at 1 s).
    collector : Collector
        Gives the axis steps.
    day_start : float, optional
        Origin of ``second`` [s since the epoch]; default: 00:00 UTC of the first row.

    Returns
    -------
    numpy.ndarray (structured)
        ``second`` (seconds of the day, int64) and, for each axis in
        (mirrors, mobile_structure, secondary_reflector): ``<axis>_position``
        (absolute position in steps), ``<axis>_steps`` (steps to move since the
        previous row, >= 0) and ``<axis>_direction`` (+1 toward positive angles, -1
        toward negative, 0 still; int8). The first row moves from its own position.
    """
    t = np.asarray(table.t, dtype=float)
    if t.size and np.any(np.diff(t) < 0):
        raise ValueError('table rows must be in time order')
    if day_start is None:
        day_start = np.floor(t[0] / 86400.0) * 86400.0 if t.size else 0.0
    fields = [('second', np.int64)]
    for axis in AXES:
        fields += [(f'{axis}_position', np.int64), (f'{axis}_steps', np.int64), (f'{axis}_direction', np.int8)]
    out = np.zeros(t.size, dtype=fields)
    out['second'] = np.round(t - day_start).astype(np.int64)
    for axis, step in zip(AXES, collector.axis_steps):
        pos = angle_to_steps(getattr(table, axis), step)
        move = np.diff(pos, prepend=pos[:1])
        out[f'{axis}_position'] = pos
        out[f'{axis}_steps'] = np.abs(move)
        out[f'{axis}_direction'] = np.sign(move).astype(np.int8)
    return out
