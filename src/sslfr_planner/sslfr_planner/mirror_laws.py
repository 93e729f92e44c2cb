"""Mirror laws of the prototypes: the common drive's angle and every line's angle (pure numpy).

Every prototype moves all its mirror lines with ONE drive; line i sits at the drive
angle plus a fixed offset (set at assembly). The ``mirrors`` joint is the drive angle,
zero when every line is at its solar-noon offset (for seed 000 it is the central
mirror's beta_0). Signs and frames: docs/conventions.md (theta_T < 0 in the morning;
line positions x_i west positive, east to west). All angles radians, lengths metres.

* :func:`half_transversal`: seed 000 eq. 13, drive = theta_t / 2 and offsets psi_i / 2
  (eqs. 11-14), exact for flat mirrors turning about their own surface.
* :func:`lepten_linear`: seed 004 eq. 5 with Table 1: drive = a theta_T, offsets b_i,
  one pace a for every line; :func:`lepten_exact` is eqs. 3-4 per line and
  :func:`line_errors` the law's error of every line against it.
* :func:`seed003_linkage`: seed 003 eqs. 5-6, beta_i = (theta - phi_i)/2 with
  phi_i = atan(L_i / F), held in steps (15 min) and never beyond the maximum inclination.
"""
from __future__ import annotations

import math

import numpy as np

from . import lepten

#: seed 004 section 3 (eq. 10): the largest mirror positioning error of the LEPTEN tracker,
#: 0.085 deg while |theta_T| <= 45 deg (its main operating period) and 0.12 deg up to 80 deg [rad]
POSITIONING_BUDGET = (math.radians(0.085), math.radians(0.12))
#: |theta_T| up to which the smaller budget applies [rad]
POSITIONING_BUDGET_SPLIT = math.radians(45.0)
#: |theta_T| up to which seed 004 states a budget (its analysis spans -80..80 deg) [rad]
POSITIONING_BUDGET_RANGE = math.radians(80.0)


def positioning_budget(theta_t):
    """Seed 004's mirror positioning budget at transversal angles ``theta_t`` [rad]:
    0.085 deg for |theta_T| <= 45 deg, 0.12 deg up to 80 deg (section 3, eq. 10), NaN
    beyond (no budget: the seed's analysis stops at 80 deg) [rad]."""
    tt = np.abs(np.asarray(theta_t, dtype=float))
    return np.where(tt <= POSITIONING_BUDGET_SPLIT, POSITIONING_BUDGET[0],
                    np.where(tt <= POSITIONING_BUDGET_RANGE, POSITIONING_BUDGET[1], np.nan))


def half_transversal(theta_t, positions, height: float):
    """Seed 000 eqs. 11-14: (drive, lines) [rad] for transversal angles ``theta_t`` [rad].

    drive = theta_t / 2 (eq. 13); line i at drive + psi_i / 2 with psi_i = -atan(x_i / h),
    ``height`` h the aim height above the pivots [m]. ``lines`` has shape (..., n_lines).
    """
    tt = np.asarray(theta_t, dtype=float)
    drive = tt / 2.0
    offsets = -np.arctan(np.asarray(positions, dtype=float) / height) / 2.0
    return drive, drive[..., None] + offsets


def lepten_linear(theta_t, pace: float, offsets, limit: float | None = None):
    """Seed 004 eq. 5 on the common drive: (drive, lines) [rad].

    drive = a theta_T (a = ``pace``, seed 004: 0.4962, the mean of Table 1's a); line i at
    drive + b_i (``offsets``, Table 1's b in radians). ``limit`` [rad]: theta_T is
    clipped to [-limit, limit] (seed 004: the mechanism tracks -80..80 deg).
    """
    tt = np.asarray(theta_t, dtype=float)
    if limit is not None:
        tt = np.clip(tt, -limit, limit)
    drive = pace * tt
    return drive, drive[..., None] + np.asarray(offsets, dtype=float)


def lepten_exact(theta_t, positions, height: float, radius: float):
    """Seed 004 eqs. 3-4 solved for every line: theta_m,i [rad], shape (..., n_lines).

    The angle each line would need with its own drive (:func:`sslfr_planner.lepten.exact_mirror_angle`;
    ``radius`` r = 0.065 m, ``height`` Z_abs = 3.75 m for seed 004).
    """
    tt = np.asarray(theta_t, dtype=float)[..., None]
    return lepten.exact_mirror_angle(tt, np.asarray(positions, dtype=float), height, radius)


def line_errors(theta_t, lines, positions, height: float, radius: float):
    """Tracking error of every line: commanded - exact (seed 004 eqs. 3-4) [rad], (..., n_lines).

    ``lines`` are the lines' commanded angles (e.g. from :func:`lepten_linear` or a
    pace-0.5 law), at the transversal angles ``theta_t`` [rad].
    """
    return np.asarray(lines, dtype=float) - lepten_exact(theta_t, positions, height, radius)


def step_instants(t, step: float):
    """The instant whose sun a stepped tracker holds at ``t`` [s]: the middle of the step
    interval [k step, (k+1) step) containing t (seed 003: 900 s). ``step`` 0: t itself."""
    t = np.asarray(t, dtype=float)
    if step <= 0:
        return t
    return np.floor(t / step) * step + step / 2.0


def seed003_linkage(theta_t, positions, focal_length: float, max_inclination: float):
    """Seed 003 eqs. 5-6 on its linkage: (drive, lines) [rad], every |line| <= max_inclination.

    phi_i = atan(L_i / F) (eq. 5, L_i the signed distance of mirror i from the centre
    of the field, west positive here), beta_i = (theta - phi_i) / 2 (eq. 6) with theta
    the transversal angle (seed 003 eq. 3's angle carries the sign of the hour angle;
    :func:`sslfr_planner.geometry.mirror_tilts_seed003`). One stepper moves every mirror
    through the linkage (section 2.2.1): drive = theta / 2, line i at drive - phi_i / 2.
    The drive is clipped so that no mirror passes ``max_inclination`` (section 2.2.1:
    72 deg). Feed it the sun of :func:`step_instants` for the 15-minute steps.
    """
    tt = np.asarray(theta_t, dtype=float)
    offsets = -np.arctan(np.asarray(positions, dtype=float) / focal_length) / 2.0
    lo = -max_inclination - float(np.min(offsets))
    hi = max_inclination - float(np.max(offsets))
    if lo > hi:
        raise ValueError('the offsets alone exceed the maximum inclination')
    drive = np.clip(tt / 2.0, lo, hi)
    return drive, drive[..., None] + offsets


def drive_limits_seed003(positions, focal_length: float, max_inclination: float) -> tuple[float, float]:
    """The drive range [rad] that keeps every mirror of seed 003's linkage within
    ``max_inclination`` (what :func:`seed003_linkage` clips to)."""
    offsets = -np.arctan(np.asarray(positions, dtype=float) / focal_length) / 2.0
    return -max_inclination - float(np.min(offsets)), max_inclination - float(np.max(offsets))
