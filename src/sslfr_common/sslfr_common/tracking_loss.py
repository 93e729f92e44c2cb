"""Optical loss caused by a tracking error: a collector's loss table (pure Python).

Seed 000 section 5.2 (eqs. 17-24, Figs. 21-24) measures the power a linear Fresnel
collector loses when its mirrors are held epsilon away from their ideal tilt: about
0.3 % at 0.06 deg and 2.6-3.5 % at 0.36 deg for its prototype. The same study run on
the project's 3-D ray trace for the collector at hand
(:func:`sslfr_planner.analysis.ideal.loss_table`: its description's optics at its site,
the equinoxes and solstices at 9:00, 12:00 and 15:00 solar time) gives a table of rows
(error [rad], smallest loss [%], largest loss [%]); the node set hands it to the mirror
movement's driver as ``accuracy.loss_table`` and the day report builds the same one.
The table covers the mirrors' tilt error; the longitudinal axes' errors move the image
along the tube, which the study does not cover (their loss is not estimated).
"""
from __future__ import annotations

import math

#: a loss table: rows (tracking error [rad], smallest loss [%], largest loss [%]), the
#: errors increasing from 0; fewer than two rows: no estimate
LossTable = tuple[tuple[float, float, float], ...]


def table_problems(table) -> list[str]:
    """Why ``table`` (rows of three numbers) is not a loss table (empty: it is one, or it
    has fewer than two rows, which means no estimate)."""
    rows = [tuple(r) for r in table]
    if len(rows) < 2:
        return []
    if any(len(r) != 3 or not all(isinstance(x, (int, float)) and math.isfinite(x) for x in r) for r in rows):
        return ['each row is three finite numbers (error [rad], smallest loss [%], largest loss [%])']
    out = []
    if rows[0][0] != 0.0 or any(b[0] <= a[0] for a, b in zip(rows, rows[1:])):
        out.append('errors must start at 0 and increase')
    if any(not 0.0 <= lo <= hi <= 100.0 for _, lo, hi in rows):
        out.append('losses must satisfy 0 <= smallest <= largest <= 100 %')
    return out


def from_flat(values) -> LossTable:
    """The table of a flat parameter array [e0, low0, high0, e1, ...] (a length that is
    not a multiple of three: no table)."""
    v = [float(x) for x in values]
    if len(v) % 3:
        return ()
    rows = tuple((v[i], v[i + 1], v[i + 2]) for i in range(0, len(v), 3))
    return rows if len(rows) >= 2 and not table_problems(rows) else ()


def to_flat(table: LossTable) -> list[float]:
    """The flat parameter array of ``table`` (:func:`from_flat`'s inverse)."""
    return [float(x) for row in table for x in row]


def estimated_loss(error: float, table: LossTable) -> tuple[float, float, bool]:
    """Estimated optical loss of a tracking error.

    Parameters
    ----------
    error : float
        Tracking error of the mirrors [rad], either sign (the table is read at |error|).
    table : LossTable
        The collector's loss table (at least two rows).

    Returns
    -------
    (low, high, beyond) : (float, float, bool)
        The loss range [%] linearly interpolated in the table; beyond its last error the
        last row and ``beyond`` True (the loss is at least that). NaN error or no table:
        (nan, nan, False).
    """
    e = abs(error)
    if math.isnan(e) or len(table) < 2:
        return math.nan, math.nan, False
    last = table[-1]
    if e >= last[0]:
        return last[1], last[2], e > last[0]
    for (e0, lo0, hi0), (e1, lo1, hi1) in zip(table, table[1:]):
        if e <= e1:
            f = (e - e0) / (e1 - e0)
            return lo0 + f * (lo1 - lo0), hi0 + f * (hi1 - hi0), False
    return last[1], last[2], True   # not reached


def loss_text(error: float, table: LossTable) -> str:
    """One phrase for people: ``estimated optical loss 0.2-0.7 %`` (seed 000 section 5.2
    on the collector's optics), or why there is no estimate."""
    if len(table) < 2:
        return 'optical loss not estimated for this axis (no loss table: the table covers the mirrors\' tilt)'
    low, high, beyond = estimated_loss(error, table)
    if math.isnan(low):
        return 'optical loss unknown (no measured position)'
    return f'estimated optical loss {">= " if beyond else ""}{low:.1f}-{high:.1f} %'
