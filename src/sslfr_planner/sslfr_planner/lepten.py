"""LEPTEN mirror lines (seed 004 section 2.2): rotation axis off the mirror surface.

In the LEPTEN collector each mirror line turns about an axis at x_i (west positive,
as in :mod:`sslfr_planner.geometry`) while the centre of its reflecting surface sits
a radius r above that axis, at (x_i + r sin theta_m, r cos theta_m). The receiver is
at height Z_abs above the axes, at x = 0. Seed 004:

* eq. 3: theta_r = arctan((-x_i - r sin theta_m) / (Z_abs - r cos theta_m)), the
  direction (from the vertical, +x positive) from the mirror centre to the receiver;
* eq. 4: theta_T = 2 theta_m - theta_r (the normal bisects sun and receiver);
* eq. 5: the common-drive linear law theta_m = a theta_T + b, one a for all lines.

:func:`exact_mirror_angle` solves eqs. 3-4 (transcendental in theta_m) for each line
and instant; :func:`fit_linear` fits eq. 5 by least squares over a uniform theta_T
grid and gives the worst-case linearisation error; :func:`position_from_offset`
inverts the fit (line position from its offset b), used to rebuild seed 004 Table 1.
With r = 0 every line has a = 1/2 exactly (the seed 000 law, eq. 13 and 11-12).
All angles radians, lengths metres.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: seed 004: distance of the mirror surface from its rotation axis [m]
SEED004_RADIUS = 0.065
#: seed 004: receiver height above the rotation axes [m]
SEED004_HEIGHT = 3.75
#: seed 004: transversal range of the fit [rad]
SEED004_RANGE = (math.radians(-80.0), math.radians(80.0))


def reflected_angle(theta_m, x, height: float, radius: float):
    """theta_r of seed 004 eq. 3 [rad] for mirror angle theta_m [rad] and axis at x [m]."""
    tm = np.asarray(theta_m, dtype=float)
    return np.arctan2(-np.asarray(x, dtype=float) - radius * np.sin(tm), height - radius * np.cos(tm))


def exact_mirror_angle(theta_t, x, height: float, radius: float, tol: float = 1e-13):
    """Exact mirror angle theta_m [rad] solving seed 004 eqs. 3-4 for theta_T = ``theta_t``.

    theta_m = (theta_T + theta_r(theta_m)) / 2 is a contraction (|d theta_r/d theta_m|
    <= r / (Z_abs - r) < 1 for r < Z_abs / 2), iterated with Newton steps from the
    r = 0 solution until the change is below ``tol`` [rad]. Broadcasts ``theta_t``
    against ``x``.
    """
    if not (0 <= radius < height / 2):
        raise ValueError('need 0 <= radius < height/2')
    tt = np.asarray(theta_t, dtype=float)
    x = np.asarray(x, dtype=float)
    tm = (tt + np.arctan2(-x, height)) / 2.0
    for _ in range(50):
        # g(tm) = 2 tm - theta_r(tm) - theta_T; g' = 2 - d theta_r / d tm
        sn, cs = np.sin(tm), np.cos(tm)
        u = -x - radius * sn
        v = height - radius * cs
        tr = np.arctan2(u, v)
        dtr = (-radius * cs * v - u * radius * sn) / (u * u + v * v)
        step = (2.0 * tm - tr - tt) / (2.0 - dtr)
        tm = tm - step
        if np.all(np.abs(step) < tol):
            break
    return tm


@dataclass(frozen=True)
class LineFit:
    """Linear common-drive law of one mirror line (seed 004 eq. 5).

    Attributes
    ----------
    x : float
        Rotation-axis position [m], west positive.
    a : float
        Angular pace [-].
    b : float
        Offset [rad].
    max_error : float
        max |exact theta_m - (a theta_T + b)| over the fitted range [rad].
    """
    x: float
    a: float
    b: float
    max_error: float


def fit_linear(x, height: float, radius: float, theta_range=SEED004_RANGE, n: int = 1601) -> LineFit:
    """Least-squares fit of theta_m = a theta_T + b to the exact solution (seed 004 eq. 5).

    Parameters
    ----------
    x : float
        Axis position of the line [m].
    height, radius : float
        Z_abs and r [m].
    theta_range : (float, float)
        Transversal range [rad] (seed 004: -80..80 deg).
    n : int
        Number of uniformly spaced theta_T samples.
    """
    lo, hi = theta_range
    if not hi > lo:
        raise ValueError('the fit range must have FROM < TO')
    tt = np.linspace(lo, hi, n)
    tm = exact_mirror_angle(tt, float(x), height, radius)
    a, b = np.polyfit(tt, tm, 1)
    err = float(np.max(np.abs(tm - (a * tt + b))))
    return LineFit(float(x), float(a), float(b), err)


def position_from_offset(b, height: float, radius: float, theta_range=SEED004_RANGE) -> float:
    """The axis position x [m] whose fitted offset (:func:`fit_linear`) is ``b`` [rad].

    b(x) is close to arctan(-x / Z_abs)/2 (the r = 0 law) and decreases monotonically
    with x, so Newton's method with a numerical derivative, started from
    x = -Z_abs tan(2 b), converges in a few steps (to 1e-12 m).
    """
    f = lambda xx: fit_linear(xx, height, radius, theta_range).b - b
    x = -height * math.tan(2.0 * b)
    for _ in range(30):
        fx = f(x)
        h = 1e-6
        d = (f(x + h) - fx) / h
        if d == 0:
            break
        step = fx / d
        x -= step
        if abs(step) < 1e-12:
            return float(x)
    if abs(f(x)) > 1e-12:
        raise ValueError(f'offset {b} rad is out of reach for this geometry')
    return float(x)


def common_drive_errors(lines, a_common: float, theta_range=SEED004_RANGE, height=SEED004_HEIGHT,
                        radius=SEED004_RADIUS, n: int = 1601):
    """Worst error of each line when all share one pace ``a_common`` [rad per line].

    Each line keeps its own offset, re-fitted for the common pace
    (b = mean(theta_m - a theta_T)); returns max |error| per line [rad].
    """
    tt = np.linspace(*theta_range, n)
    out = []
    for x in lines:
        tm = exact_mirror_angle(tt, float(x), height, radius)
        b = float(np.mean(tm - a_common * tt))
        out.append(float(np.max(np.abs(tm - a_common * tt - b))))
    return np.array(out)
