"""Optical loss caused by a tracking error: the project's loss table (pure Python).

Seed 000 section 5.2 (eqs. 17-24, Figs. 21-24) measures the power a linear Fresnel
collector loses when its mirrors are held epsilon away from their ideal tilt: about
0.3 % at 0.06 deg and 2.6-3.5 % at 0.36 deg. :data:`LOSS_TABLE` is that study run on
the project's 3-D ray trace (:func:`sslfr_planner.analysis.performance.error_table`,
``./sslfr analyse error``, docs/optics.md) for the seed 000 prototype at Almeria
(default :class:`~sslfr_planner.analysis.optics.OpticalParameters`, law eq. 16), on
the equinoxes and solstices of 2024 at 9:00, 12:00 and 15:00 solar time: for each
error, the smallest and the largest total loss of those twelve instants [%]
(noon loses least, the mornings and afternoons most).
``test_tracking_loss.py`` recomputes it from the trace, so the two cannot drift.

It is kept as numbers (not computed at run time) so that a driver can quote it
without importing the ray trace. The table is the seed's transversal study: it
applies to the mirrors' tilt error; the longitudinal axes' errors move the image
along the tube, which the study does not cover (their loss is not estimated).
"""
from __future__ import annotations

import math

from .contract import MIRRORS

#: (tracking error [deg], smallest loss [%], largest loss [%]) over the twelve instants
#: above, at the errors ``./sslfr analyse error --errors`` was run with.
LOSS_TABLE: tuple[tuple[float, float, float], ...] = (
    (0.00, 0.00, 0.00),
    (0.03, 0.00, 0.07),
    (0.06, 0.00, 0.20),
    (0.09, 0.03, 0.37),
    (0.12, 0.18, 0.65),
    (0.18, 0.70, 1.29),
    (0.24, 1.22, 1.92),
    (0.30, 1.75, 2.56),
    (0.36, 2.47, 3.38),
    (0.48, 5.41, 7.39),
    (0.60, 10.23, 16.68),
    (0.72, 17.37, 28.44),
    (1.00, 41.41, 55.32),
)
#: Axes whose error the table covers (seed 000's study tilts the mirrors).
AXES_COVERED = (MIRRORS,)


def estimated_loss(error: float) -> tuple[float, float, bool]:
    """Estimated optical loss of a tracking error.

    Parameters
    ----------
    error : float
        Tracking error of the mirrors [rad], either sign (the table is read at |error|).

    Returns
    -------
    (low, high, beyond) : (float, float, bool)
        The loss range [%] linearly interpolated in the table; beyond its last error
        (1 deg) the last row and ``beyond`` True (the loss is at least that).
        NaN error: (nan, nan, False).
    """
    e = abs(math.degrees(error))
    if math.isnan(e):
        return math.nan, math.nan, False
    last = LOSS_TABLE[-1]
    if e >= last[0]:
        return last[1], last[2], e > last[0]
    for (e0, lo0, hi0), (e1, lo1, hi1) in zip(LOSS_TABLE, LOSS_TABLE[1:]):
        if e <= e1:
            f = (e - e0) / (e1 - e0)
            return lo0 + f * (lo1 - lo0), hi0 + f * (hi1 - hi0), False
    return last[1], last[2], True   # not reached


def loss_text(error: float, axis: str = MIRRORS) -> str:
    """One phrase for people: ``estimated optical loss 0.2-0.7 %`` (seed 000 Figs.
    22-24 on the project's ray trace), or why there is no estimate for ``axis``."""
    if axis not in AXES_COVERED:
        return 'optical loss not estimated for this axis (the loss table is the mirrors\' tilt error)'
    low, high, beyond = estimated_loss(error)
    if math.isnan(low):
        return 'optical loss unknown (no measured position)'
    return f'estimated optical loss {">= " if beyond else ""}{low:.1f}-{high:.1f} %'
