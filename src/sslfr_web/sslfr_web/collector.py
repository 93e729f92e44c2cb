"""The collector the operator page draws, from its collector description (pure).

The planner names the run's description in its ``collector.description`` parameter
(docs/collectors.md); the web node reads that parameter (:mod:`.remote`), loads the
file once (:func:`load`) and puts :func:`page_collector` in the page's ``info``: the
movements the collector has (the axes table, the jog list and the plots show only
those), every mirror line's position and its offset from the common drive under the
collector's law (the drawing seen from the south puts line i at drive + offset_i), the
receiver's aim height and width, and whether the rows tilt (the side view). The day
plots' ideal drive angle is the law's (:func:`ideal_drive`). SI units and radians.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from sslfr_common.contract import MIRRORS
from sslfr_planner import description as description_mod
from sslfr_planner.prototype import commanded_lines, law_offsets, line_positions


def load(name: str, ros_args=()) -> description_mod.Description | None:
    """The description ``name`` (the planner's ``collector.description``; '' = none),
    relative to the node's params files as the planner finds it; DescriptionError (a
    ValueError) naming the file and key when it cannot be used."""
    return description_mod.for_node(name, ros_args)


def page_collector(desc: description_mod.Description) -> dict:
    """The page's view of ``desc`` (JSON-ready): name, joints (the movements, contract
    order), law, lines (east to west: 'x' [m] west positive, 'offset' [rad] from the
    drive), line_width, aim_height (receiver axis above the pivots), receiver_width
    [m], central_line, tilting (the collector has longitudinal movements)."""
    o = desc.optics
    offsets = law_offsets(desc, np.zeros(1))[0]
    return {'name': desc.name, 'joints': list(desc.joints), 'law': desc.movements[MIRRORS].law,
            'lines': [{'x': round(float(x), 6), 'offset': round(float(b), 9)}
                      for x, b in zip(line_positions(desc), offsets)],
            'line_width': o.line_width, 'aim_height': o.receiver_height, 'receiver_width': o.receiver_width,
            'central_line': o.central_line, 'tilting': desc.longitudinal_law != 'horizontal'}


def ideal_drive(desc: description_mod.Description) -> Callable[[float], float]:
    """theta_t [rad] -> the drive angle the collector's law commands for it [rad]
    (seed 000 eq. 13, seed 004 eq. 5 with Table 1, seed 003 eqs. 5-6 within its 72 deg;
    seed 003's 15-minute holds are the planner's, not drawn here)."""
    def drive(theta_t: float) -> float:
        return float(np.asarray(commanded_lines(desc, np.array([float(theta_t)]))[0])[0])
    return drive
