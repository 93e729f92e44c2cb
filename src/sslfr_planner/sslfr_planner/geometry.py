"""Tracker geometry: projection (incidence) angles and mirror tilts (numpy, no rclpy).

Frames and signs (docs/conventions.md has the figure and worked numbers; the same
frame as :mod:`sslfr_planner.raytrace`):

* azimuths are clockwise from north (east positive), like the SPA's eq. 46;
* the collector axis has azimuth gamma_c (0: the classic north-south axis; seed 004's
  gamma_col, which is measured positive toward the WEST, is ``-gamma_c``:
  :func:`collector_azimuth_from_seed004`);
* transversal plane: x axis perpendicular to the collector axis, pointing to azimuth
  gamma_c - 90 deg (WEST for a north-south collector). The transversal incidence
  angle theta_t is measured from the vertical, positive toward +x: negative in the
  morning, zero at solar noon, positive in the afternoon (seed 000 eq. 9, seed 004
  eq. 1);
* longitudinal plane: p axis along the collector axis, pointing to azimuth
  gamma_c + 180 deg (SOUTH for a north-south collector). theta_l is measured from
  the vertical, positive toward +p (seed 000 eq. 10; seed 004 eq. 2 measures it
  positive toward the north end: theta_L(seed 004) = -theta_l);
* mirror i pivots at x_i (west positive); tilts beta are positive when the mirror
  normal leans toward +x (west, i.e. counter-clockwise seen from the south end, as
  seed 000 section 2.4.1 measures them).

All angles radians, lengths metres.
"""
from __future__ import annotations

import numpy as np


def collector_azimuth_from_seed004(gamma_col):
    """Convert seed 004's collector azimuth (from north, WEST positive) to ours [rad].

    Seed 004 section 2.2 measures azimuths from north positive toward the west; this
    module measures them clockwise (east positive), so gamma_c = -gamma_col. The
    seed's bench, gamma_col = -4.6 deg, is gamma_c = +4.6 deg.
    """
    return -np.asarray(gamma_col, dtype=float)


def projection_angles(zenith, azimuth, collector_azimuth=0.0):
    """Transversal and longitudinal incidence angles (theta_t, theta_l) [rad].

    Seed 004 eqs. 1-2 with our azimuth convention:
    theta_t = arctan(-tan(theta_z) sin(gamma_s - gamma_c)),
    theta_l = arctan(-tan(theta_z) cos(gamma_s - gamma_c)); for gamma_c = 0 these are
    seed 000 eqs. 9-10 (theta_t = arctan(sin gamma_S / tan alpha_S) with gamma_S from
    south, west positive). Evaluated as atan2 of the sun vector's components, so they
    are defined for any sun position (below the horizon |theta| may exceed pi/2, the
    continuation of the same projection).

    Parameters
    ----------
    zenith : array_like
        Sun zenith angle [rad].
    azimuth : array_like
        Sun azimuth, clockwise from north [rad].
    collector_azimuth : float or array_like
        Azimuth of the collector axis, clockwise from north [rad].

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        theta_t (afternoon / +x positive) and theta_l (+p positive) [rad].
    """
    z = np.asarray(zenith, dtype=float)
    rel = np.asarray(azimuth, dtype=float) - collector_azimuth
    sz, cz = np.sin(z), np.cos(z)
    return np.arctan2(-sz * np.sin(rel), cz), np.arctan2(-sz * np.cos(rel), cz)


def mirror_positions(n_per_side: int, mirror_width: float, gap: float, central: bool = True) -> np.ndarray:
    """Pivot positions x_i of the mirrors, west (+x) positive [m], east to west.

    Seed 000 eq. 15: L_i = i (W_M + d); left (east) mirrors at -L_i, right (west) at
    +L_i, ordered from the n-th left mirror through the central one to the n-th right
    (2n+1 mirrors). ``central=False``: no mirror on the axis, 2n mirrors at
    +/-(i - 1/2)(W_M + d), i = 1..n (seed 003: 10 mirrors 0.15 m apart; seed 004: 10 lines).
    """
    if central:
        i = np.arange(-n_per_side, n_per_side + 1, dtype=float)
    else:
        k = np.arange(1, n_per_side + 1) - 0.5
        i = np.concatenate([-k[::-1], k])
    return i * (mirror_width + gap)


def receiver_angles(x, receiver_height: float, tube_diameter: float):
    """Signed angle psi_i from the vertical of the ray from mirror i to the tube [rad].

    Seed 000 eq. 14: alpha_i = arctan(L_i / (f + D/2)); signed toward +x:
    psi_i = -arctan(x_i / (f + D/2)) (a west mirror sends its ray east).
    """
    return -np.arctan(np.asarray(x, dtype=float) / (receiver_height + tube_diameter / 2.0))


def central_mirror_tilt(transversal):
    """Central mirror tilt beta_0 = theta_t / 2 [rad] (seed 000 eq. 13)."""
    return np.asarray(transversal, dtype=float) / 2.0


def mirror_tilts(transversal, x, receiver_height: float, tube_diameter: float):
    """Tilt of every mirror [rad], shape (..., len(x)) (seed 000 eqs. 11-15).

    The mirror normal bisects the sun's transversal direction theta_t and the
    direction psi_i to the tube: beta_i = (theta_t + psi_i)/2. For the right (west)
    mirrors psi_i = -alpha_i and for the left ones +alpha_i: these are eqs. 11-12 up to
    the seed's own left/right sign convention (it measures beta_i^l, beta_i^r
    separately); eq. 13 is the central case psi_0 = 0. Every mirror moves at the same
    rate, half the transversal rate: one drive (the central one) is enough.
    """
    tt = np.asarray(transversal, dtype=float)[..., None]
    return (tt + receiver_angles(x, receiver_height, tube_diameter)) / 2.0


def mirror_tilts_seed003(theta, distances, focal_length: float):
    """Mirror tilts of seed 003 eqs. 5-6: beta = (theta - phi)/2, phi = arctan(L_i/F) [rad].

    ``theta`` is the transversal sun angle [rad], ``distances`` L_i the signed
    distance of each mirror centre from the centre of the reflection area [m]
    (west positive, so phi_i = arctan(L_i/F) = -psi_i), ``focal_length`` F [m].
    Identical to :func:`mirror_tilts` with f + D/2 = F.
    """
    phi = np.arctan(np.asarray(distances, dtype=float) / focal_length)
    return (np.asarray(theta, dtype=float)[..., None] - phi) / 2.0
