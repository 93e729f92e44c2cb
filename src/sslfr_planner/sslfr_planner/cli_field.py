"""``sslfr field``: LEPTEN mirror lines, exact model fitted with the common-drive law.

For each mirror line (axis position x, west positive, metres) the exact mirror angle
of seed 004 eqs. 3-4 is fitted by least squares with theta_m = a theta_T + b (eq. 5)
over the transversal range ``--fit FROM:TO`` (degrees, default -80:80, the seed's);
prints CSV ``x_m,a,b,max_error_deg`` (b and the worst linearisation error in degrees).
"""
from __future__ import annotations

import math
import sys

from .cli_input import OneLineParser, finite_float, ranged_float, run
from .lepten import fit_linear

HEADER = 'x_m,a,b,max_error_deg'
MAX_POSITION = 1000.0   # [m] |axis position| allowed
MAX_HEIGHT = 1000.0     # [m] receiver height allowed
MAX_LINES = 1000        # mirror lines in one call


def _positions(text: str) -> list[float]:
    import argparse
    try:
        values = [float(v) for v in text.split(',') if v.strip() != '']
    except ValueError:
        raise argparse.ArgumentTypeError(f'positions must be comma-separated numbers [m]: {text!r}') from None
    if not values or not all(math.isfinite(v) and abs(v) <= MAX_POSITION for v in values):
        raise argparse.ArgumentTypeError(f'positions must be comma-separated finite numbers within '
                                         f'-{MAX_POSITION:g}..{MAX_POSITION:g} m: {text[:80]!r}')
    if len(values) > MAX_LINES:
        raise argparse.ArgumentTypeError(f'at most {MAX_LINES} positions, got {len(values)}')
    return values


def _range(text: str) -> tuple[float, float]:
    import argparse
    try:
        lo, hi = (float(v) for v in text.split(':'))
    except ValueError:
        raise argparse.ArgumentTypeError(f'fit range must be FROM:TO in degrees: {text!r}') from None
    if not (math.isfinite(lo) and math.isfinite(hi) and -90.0 < lo < hi < 90.0):
        raise argparse.ArgumentTypeError(f'fit range must satisfy -90 < FROM < TO < 90 deg: {text!r}')
    return lo, hi


def parser() -> OneLineParser:
    """The argument parser of ``sslfr field``."""
    p = OneLineParser(prog='sslfr field', description='LEPTEN mirror lines: exact model (seed 004 '
                      'eqs. 3-4) fitted with the common-drive law theta_m = a theta_T + b (eq. 5).')
    p.add_argument('--positions', type=_positions, required=True,
                   help=f'rotation-axis positions X1,X2,... [m], west positive, within +-{MAX_POSITION:g}')
    p.add_argument('--height', type=ranged_float(0.0, MAX_HEIGHT, lo_open=True, unit='m'), required=True,
                   help=f'receiver height above the axes [m], (0, {MAX_HEIGHT:g}]')
    p.add_argument('--radius', type=finite_float, required=True,
                   help='distance of the mirror surface from its axis, r [m], 0 <= r < height/2')
    p.add_argument('--fit', type=_range, default=(-80.0, 80.0),
                   help='transversal range of the fit FROM:TO [deg] (default -80:80)')
    return p


def _glue_negative(argv):
    """Let ``--positions -2.3,0,2.3`` and ``--fit -80:80`` through argparse (values may start with '-')."""
    out, argv = [], list(argv)
    i = 0
    while i < len(argv):
        if argv[i] in ('--positions', '--fit') and i + 1 < len(argv) and argv[i + 1][:1] == '-' \
                and argv[i + 1][1:2].isdigit() or argv[i] in ('--positions', '--fit') and i + 1 < len(argv) \
                and argv[i + 1][:2] == '-.':
            out.append(f'{argv[i]}={argv[i + 1]}')
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def _main(argv) -> int:
    a = parser().parse_args(_glue_negative(argv))
    if not a.height > 0:
        raise ValueError(f'height must be > 0 m, got {a.height:g}')
    if not 0 <= a.radius < a.height / 2:
        raise ValueError(f'radius must be >= 0 and < height/2 m, got {a.radius:g}')
    rng = (math.radians(a.fit[0]), math.radians(a.fit[1]))
    lines = [HEADER]
    for x in a.positions:
        f = fit_linear(x, a.height, a.radius, rng)
        b = round(math.degrees(f.b), 6) + 0.0  # no '-0.000000'
        lines.append(f'{x:.6f},{f.a:.6f},{b:.6f},{math.degrees(f.max_error):.6f}')
    sys.stdout.write('\n'.join(lines) + '\n')
    return 0


def main(argv=None) -> int:
    """Entry point of ``sslfr field`` (returns the exit status)."""
    return run('field', _main, sys.argv[1:] if argv is None else argv)


if __name__ == '__main__':
    sys.exit(main())
