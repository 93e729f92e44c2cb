"""A collector description turned into the planner's geometry and line angles (pure numpy).

:func:`field_geometry` is the :class:`~sslfr_planner.collector.FieldGeometry` of a
:class:`~sslfr_planner.description.Description` (2n lines without a central line);
:func:`commanded_lines` the angles its law gives the drive and every line;
:func:`exact_lines` the angles every line would need with its own drive (the ideal);
:func:`held_lines` every line's angle with the drive at a measured angle (the lines ride
on the drive at the law's offsets) and :func:`line_errors` their error against
:func:`exact_lines`.
Angles radians, lengths metres, theta_t the transversal angle (afternoon positive).
"""
from __future__ import annotations

import numpy as np

from sslfr_common.contract import MIRRORS

from . import mirror_laws
from .collector import FieldGeometry
from .description import Description


def field_geometry(desc: Description) -> FieldGeometry:
    """The mirror field and receiver of ``desc`` (receiver_height there is the aim point,
    FieldGeometry's f = aim - D/2)."""
    o = desc.optics
    ends = o.tube_ends if o.tube_ends is not None else (-o.receiver_length / 2.0, o.receiver_length / 2.0)
    return FieldGeometry(n_per_side=o.n_per_side, mirror_width=o.line_width, mirror_length=o.line_length,
                         gap=o.gap, receiver_height=o.receiver_height - o.tube_diameter / 2.0,
                         tube_diameter=o.tube_diameter, tube_left=ends[1], tube_right=ends[0],
                         central_mirror=o.central_line)


def line_positions(desc: Description) -> np.ndarray:
    """Rotation-axis positions x_i of the lines, east to west, west positive [m]."""
    return field_geometry(desc).mirror_positions()


def commanded_lines(desc: Description, theta_t):
    """(drive, lines) [rad] of the description's mirror law at transversal angles ``theta_t``.

    seed003_linkage: the caller passes the sun of the step's middle instant
    (:func:`sslfr_planner.mirror_laws.step_instants`, ``law_params['step_s']``).
    """
    m = desc.movements[MIRRORS]
    x, h = line_positions(desc), desc.optics.receiver_height
    if m.law == 'lepten_linear':
        p = m.law_params
        return mirror_laws.lepten_linear(theta_t, p['pace'], p['offsets'], p['transversal_limit'])
    if m.law == 'seed003_linkage':
        return mirror_laws.seed003_linkage(theta_t, x, h, m.law_params['max_inclination'])
    drive, lines = mirror_laws.half_transversal(theta_t, x, h)
    lo, hi = m.range
    clipped = np.clip(drive, lo, hi)
    return clipped, lines + (clipped - drive)[..., None]


def exact_lines(desc: Description, theta_t):
    """Every line's exact angle [rad], (..., n_lines): seed 004 eqs. 3-4 with the rotation
    radius r (exactly seed 000 eqs. 11-14 / seed 003 eqs. 5-6 when r = 0)."""
    o = desc.optics
    return mirror_laws.lepten_exact(theta_t, line_positions(desc), o.receiver_height, o.rotation_radius)


def law_offsets(desc: Description, theta_t):
    """Each line's offset from the drive under the description's law [rad], (..., n_lines):
    the angle the mechanism keeps between line i and the drive (seed 004 Table 1's b_i,
    seed 003's -phi_i / 2, seed 000's psi_i / 2), fixed at assembly."""
    drive, lines = commanded_lines(desc, theta_t)
    return lines - np.asarray(drive)[..., None]


def held_lines(desc: Description, theta_t, drive):
    """Every line's angle [rad], (..., n_lines), with the common drive held at ``drive``
    [rad] (e.g. the measured ``mirrors`` joint) at transversal angles ``theta_t`` [rad]."""
    return np.asarray(drive, dtype=float)[..., None] + law_offsets(desc, theta_t)


def line_errors(desc: Description, theta_t, drive):
    """Tracking error of every line [rad], (..., n_lines): :func:`held_lines` minus the
    exact angle of seed 004 eqs. 3-4 (:func:`exact_lines`), positive = the line turned
    too far west. With ``drive`` the law's own command this is the law's systematic
    error (seed 004 section 3, the linearisation); with a measured drive it adds the
    drive's tracking error."""
    return held_lines(desc, theta_t, drive) - exact_lines(desc, theta_t)
