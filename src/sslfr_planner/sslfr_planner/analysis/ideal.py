"""Absorbed power of a described collector: ideal, under its law, or with held angles (pure).

For the day report's ideal and ``./sslfr analyse`` on any prototype: the collector's
geometry comes from its description (:mod:`sslfr_planner.description`), the power from
seed 000's optical model on the 3-D trace (:func:`sslfr_planner.analysis.optics.power`,
docs/optics.md) with the receiver's width as the cavity opening. Lines are flat mirrors
turning about their own surface in the trace (seed 004's r = 0.065 m displaces a line's
centre by at most r sin(theta_m), ~4 cm; it enters the line ANGLES through eqs. 3-4, not
the trace); seed 004's curved mirrors are modelled flat; the optical constants are seed
000 Table 3's for every prototype (the other seeds give none but seed 003's eta_0).
W, W/m^2, radians.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from sslfr_common.contract import MIRRORS, MOBILE_STRUCTURE

from .. import laws, raytrace
from ..description import Description
from ..prototype import commanded_lines, exact_lines, field_geometry, held_lines, law_offsets
from .optics import OpticalParameters, incidence_factor, optical_yield, power


def optical_parameters(desc: Description) -> OpticalParameters:
    """Seed 000 Table 3's optical constants on ``desc``'s geometry; the cavity opening is
    the receiver's width."""
    return OpticalParameters(geometry=field_geometry(desc), cavity_aperture=desc.optics.receiver_width)


def aperture_area(desc: Description) -> float:
    """Mirror area: lines x width x length [m^2] (seed 003: 1 m^2; seed 004: 54 m^2)."""
    o = desc.optics
    return o.lines * o.line_width * o.line_length


def longitudinal(desc: Description, sun):
    """(beta_M, beta_a) [rad] of the description's longitudinal law ('continuous' traced;
    0 when the collector has no longitudinal movement). Laws needing the date or the
    latitude ('eq16', 'optimum_fixed', 'daily') are the planner's: ValueError here."""
    law = desc.longitudinal_law
    shape = np.shape(sun)[:-1]
    if law == 'horizontal':
        return np.zeros(shape), np.zeros(shape)
    if law == 'continuous':
        bm, ba = laws.continuous(sun, field_geometry(desc))
        lo, hi = desc.movements[MOBILE_STRUCTURE].range
        return np.clip(bm, lo, hi), np.clip(ba, lo, hi)
    raise ValueError(f'longitudinal law {law!r} needs the site and date: use the planner table')


def absorbed_power(desc: Description, zenith, azimuth, dni, lines, beta_m=None, beta_a=None):
    """Power absorbed by the receiver [W] with the mirror lines at ``lines`` [rad] (..., n_lines).

    ``zenith``, ``azimuth`` [rad] of the sun (azimuth clockwise from north), ``dni``
    [W/m^2]; ``beta_m``, ``beta_a`` [rad] the longitudinal tilts (default: the law's).
    """
    o = desc.optics
    sun = raytrace.sun_vector(zenith, azimuth, o.azimuth)
    beta_m, beta_a = _tilts(desc, sun, beta_m, beta_a)
    lines = np.asarray(lines, dtype=float)
    drive = lines.mean(axis=-1)
    p = replace(optical_parameters(desc), mirror_aim='fixed')
    # the trace places line i at beta_0 + psi_i / 2 (raytrace.mirror_normals): psi_i = 2 (line - drive)
    tr_offsets = 2.0 * (lines - drive[..., None])
    tr = raytrace.trace(sun, drive, beta_m, beta_a, p.geometry, offsets=tr_offsets)
    cap = raytrace.receiver_capture(tr, p.cavity_aperture, p.cavity_reflectivity)
    q = np.asarray(dni, dtype=float)[..., None] * optical_yield(p) * incidence_factor(tr, sun, beta_m) * cap
    return q.sum(axis=-1)


def _tilts(desc: Description, sun, beta_m, beta_a):
    """The longitudinal tilts given, else the description's law's (:func:`longitudinal`)."""
    if beta_m is None or beta_a is None:
        bm, ba = longitudinal(desc, sun)
        beta_m = bm if beta_m is None else beta_m
        beta_a = ba if beta_a is None else beta_a
    return np.asarray(beta_m, dtype=float), np.asarray(beta_a, dtype=float)


def ideal_absorbed_power(desc: Description, zenith, azimuth, dni, beta_m=None, beta_a=None):
    """Power [W] with every line at its exact angle within the collector's mechanical
    range (one drive per line, no law error): the collector's own ideal.

    With longitudinal movements (seed 000) this is :func:`optics.power` at the central
    mirror's theta_t'/2 with the mirrors focused on the tilted receiver, the tilts
    ``beta_m``, ``beta_a`` [rad] (default: the law's, :func:`longitudinal`); else every
    line at seed 004 eqs. 3-4 (r = 0: seed 000 eqs. 11-14, seed 003 eqs. 5-6). Where the
    exact angles need the common drive beyond ``movements.mirrors.range`` (seed 004's
    actuator ends at +-40 deg, theta_T ~ +-80 deg), the drive stops at its range end and
    every line rides with it (:func:`ideal_lines`).
    """
    o = desc.optics
    sun = raytrace.sun_vector(zenith, azimuth, o.azimuth)
    lo, hi = desc.movements[MIRRORS].range
    if desc.longitudinal_law != 'horizontal':
        bm, ba = _tilts(desc, sun, beta_m, beta_a)
        tilt = np.clip(raytrace.central_mirror_tilt(sun, bm), lo, hi)
        return power(dni, sun, tilt, bm, ba, optical_parameters(desc))
    return absorbed_power(desc, zenith, azimuth, dni, ideal_lines(desc, raytrace.transversal_angle(sun)))


def ideal_lines(desc: Description, theta_t):
    """Every line's ideal angle [rad], (..., n_lines), at transversal angles ``theta_t``:
    its exact angle (:func:`sslfr_planner.prototype.exact_lines`), all lines shifted
    together where the common drive that carries them at the law's offsets would leave
    its mechanical range (the drive held at the range end)."""
    exact = exact_lines(desc, theta_t)
    drive = np.mean(exact - law_offsets(desc, theta_t), axis=-1)
    lo, hi = desc.movements[MIRRORS].range
    return exact + (np.clip(drive, lo, hi) - drive)[..., None]


def held_absorbed_power(desc: Description, zenith, azimuth, dni, drive, beta_m=None, beta_a=None):
    """Power [W] with the common mirror drive held at ``drive`` [rad] (the ``mirrors``
    joint, e.g. as measured) and the longitudinal tilts at ``beta_m``, ``beta_a`` [rad]
    (default: the law's): every line rides on the drive at the law's offset
    (:func:`sslfr_planner.prototype.held_lines`). With longitudinal movements the
    mirrors are focused on the tilted receiver as in :func:`ideal_absorbed_power`, the
    drive being the central mirror's tilt.
    """
    o = desc.optics
    sun = raytrace.sun_vector(zenith, azimuth, o.azimuth)
    drive = np.asarray(drive, dtype=float)
    if desc.longitudinal_law != 'horizontal':
        bm, ba = _tilts(desc, sun, beta_m, beta_a)
        return power(dni, sun, drive, bm, ba, optical_parameters(desc))
    theta_t = raytrace.transversal_angle(sun)
    return absorbed_power(desc, zenith, azimuth, dni, held_lines(desc, theta_t, drive))


def law_absorbed_power(desc: Description, zenith, azimuth, dni, law_zenith=None, law_azimuth=None):
    """Power [W] with the lines where the description's law puts them.

    ``law_zenith``, ``law_azimuth``: the sun the law was evaluated for (seed 003 holds
    the middle of each 15-minute step: :func:`sslfr_planner.mirror_laws.step_instants`);
    default the same sun.
    """
    if desc.longitudinal_law != 'horizontal':
        return ideal_absorbed_power(desc, zenith, azimuth, dni)
    o = desc.optics
    lz = zenith if law_zenith is None else law_zenith
    la = azimuth if law_azimuth is None else law_azimuth
    theta_t = raytrace.transversal_angle(raytrace.sun_vector(lz, la, o.azimuth))
    _, lines = commanded_lines(desc, theta_t)
    return absorbed_power(desc, zenith, azimuth, dni, lines)


__all__ = ['MIRRORS', 'aperture_area', 'optical_parameters', 'longitudinal', 'absorbed_power',
           'ideal_absorbed_power', 'ideal_lines', 'held_absorbed_power', 'law_absorbed_power']


#: the loss table's tracking errors [deg]: seed 000 Figs. 22-24's span and its 0.06 / 0.36 deg
LOSS_ERRORS_DEG = (0.0, 0.03, 0.06, 0.09, 0.12, 0.18, 0.24, 0.30, 0.36, 0.48, 0.60, 0.72, 1.0)
#: the instants of the loss table: the equinoxes and solstices (of 2024) at these solar hours [h]
LOSS_DAYS = ('2024-03-21', '2024-06-21', '2024-09-21', '2024-12-21')
LOSS_HOURS = (9.0, 12.0, 15.0)


def loss_table(desc: Description, latitude_deg: float, longitude_deg: float, elevation: float = 0.0):
    """The collector's loss table (:mod:`sslfr_common.tracking_loss`): seed 000 section
    5.2's study (eqs. 17-24: every line held epsilon below its ideal tilt, one drive) on
    the 3-D trace of ``desc``'s optics at the site [deg, deg, m], under its longitudinal
    law; for each error of :data:`LOSS_ERRORS_DEG`, the smallest and the largest loss [%]
    over :data:`LOSS_DAYS` x :data:`LOSS_HOURS` (sun above the horizon). Rows (error
    [rad], low [%], high [%]); ~0.1 s."""
    from datetime import date

    from .performance import AnalysisSite, error_table
    site = AnalysisSite(latitude_deg, longitude_deg, elevation, desc.optics.azimuth)
    errors = np.radians(LOSS_ERRORS_DEG)
    rows = error_table(site, optical_parameters(desc), errors, [date.fromisoformat(d) for d in LOSS_DAYS],
                       list(LOSS_HOURS), law=desc.longitudinal_law, receiver_fixed=desc.receiver_fixed)
    out = []
    for e in errors:
        losses = [r.loss_total for r in rows if abs(r.error - e) < 1e-12]
        if not losses:                 # the sun never up at those hours (polar night)
            return ()
        out.append((float(e), round(max(0.0, min(losses)), 2), round(min(100.0, max(losses)), 2)))
    return tuple(out)
