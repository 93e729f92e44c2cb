"""``sslfr plan``: the per-step day table as CSV (degrees in, degrees out).

One row per step of the whole UTC day: sun zenith and azimuth (NREL SPA), transversal
and longitudinal incidence angles, the day-cycle phase and the commanded axis
angles (:func:`sslfr_planner.tracking_table.tabulate_day`). Header (exact)::

    utc,phase,zenith_deg,azimuth_deg,transversal_deg,longitudinal_deg,mirrors_deg,mobile_structure_deg,secondary_reflector_deg

Bad input (latitude 91, 2023-02-30, step 0, ...) exits 2 with one line on stderr.
"""
from __future__ import annotations

import datetime
import math
import sys

import numpy as np

from sslfr_common.contract import JOINTS, PHASE_NAMES

from .cli_input import OneLineParser, finite_float, output_file, ranged_float, run, time_step, write_atomically
from .collector import LAWS, Collector
from .tracking_table import tabulate_day
from .site import Site

#: the most rows one day table may have (a step of 0.1 s; ~100 MB of CSV)
MAX_ROWS = 864_000
HEADER = ','.join(['utc', 'phase', 'zenith_deg', 'azimuth_deg', 'transversal_deg', 'longitudinal_deg',
                   *(f'{joint}_deg' for joint in JOINTS)])


def _date(text: str) -> datetime.date:
    import argparse
    try:
        day = datetime.date.fromisoformat(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a valid date YYYY-MM-DD: {text!r}') from None
    if day.year > 6000:
        raise argparse.ArgumentTypeError(f'{text}: the solar position algorithm (NREL SPA) holds for '
                                         'years -2000..6000')
    return day


def parser() -> OneLineParser:
    """The argument parser of ``sslfr plan``."""
    p = OneLineParser(prog='sslfr plan', description='Per-step day table of the tracker as CSV '
                      '(whole UTC day; angles in degrees).')
    p.add_argument('--lat', type=finite_float, required=True, help='latitude [deg], north positive')
    p.add_argument('--lon', type=finite_float, required=True, help='longitude [deg], east positive')
    p.add_argument('--elevation', type=ranged_float(-1000.0, 10000.0, unit='m'), default=0.0,
                   help='elevation [m], -1000..10000 (default 0)')
    p.add_argument('--date', type=_date, default=None, help='UTC date YYYY-MM-DD (default: today, UTC)')
    p.add_argument('--step', type=time_step(86400.0, MAX_ROWS, 'a day'), default=1.0,
                   help=f'time step [s] (default 1; at least {86400.0 / MAX_ROWS:g}: {MAX_ROWS:,} rows a day)')
    p.add_argument('--mode', choices=LAWS, default='continuous',
                   help='longitudinal law of the mobile structure and secondary reflector')
    p.add_argument('--collector-azimuth', type=ranged_float(-360.0, 360.0, unit='deg'), default=0.0,
                   help='azimuth of the collector axis, clockwise from north [deg], -360..360 (default 0: N-S)')
    p.add_argument('--pressure', type=finite_float, default=1013.25, help='mean air pressure [hPa], 10..1200')
    p.add_argument('--temperature', type=ranged_float(-90.0, 70.0, unit='degC'), default=12.0,
                   help='mean air temperature [degC], -90..70')
    p.add_argument('--delta-t', type=ranged_float(-8000.0, 8000.0, unit='s'), default=None,
                   help='TT - UT [s], -8000..8000 (the SPA\'s range; default: Espenak-Meeus model)')
    p.add_argument('--out', type=output_file, default=None,
                   help='output CSV file (default: stdout; written only when complete)')
    return p


def format_rows(table) -> list[str]:
    """CSV lines (without header) of a TrackingTable, degrees with 6 decimals."""
    t = table.t
    whole = np.all(np.abs(t - np.round(t)) < 5e-4)
    stamps = np.datetime_as_string(np.round(t * 1000.0).astype('datetime64[ms]'),
                                   unit='s' if whole else 'ms', timezone='UTC')
    names = np.array([PHASE_NAMES[i] for i in range(7)], dtype=object)[table.phase]
    cols = [np.degrees(getattr(table, k)) for k in ('zenith', 'azimuth', 'transversal', 'longitudinal', *JOINTS)]
    cols = np.round(np.stack(cols, axis=1), 6) + 0.0  # + 0.0: no "-0.000000"
    fmt = '%s,%s,' + ','.join(['%.6f'] * 7)
    return [fmt % (s, n, *row) for s, n, row in zip(stamps, names, cols.tolist())]


def _main(argv) -> int:
    a = parser().parse_args(argv)
    if not -90.0 <= a.lat <= 90.0:
        raise ValueError(f'latitude must be within -90..90 deg, got {a.lat:g}')
    if not -180.0 <= a.lon <= 180.0:
        raise ValueError(f'longitude must be within -180..180 deg, got {a.lon:g}')
    if not 10.0 <= a.pressure <= 1200.0:
        raise ValueError(f'pressure must be within 10..1200 hPa, got {a.pressure:g}')
    day = a.date or datetime.datetime.now(datetime.timezone.utc).date()
    site = Site.from_degrees(a.lat, a.lon, a.elevation, pressure=a.pressure * 100.0,
                             temperature=a.temperature, delta_t=a.delta_t)
    collector = Collector(law=a.mode, azimuth=math.radians(a.collector_azimuth))
    table = tabulate_day(day, site, collector, a.step)
    text = HEADER + '\n' + '\n'.join(format_rows(table)) + '\n'
    if a.out:
        def write(path):
            with open(path, 'w', encoding='ascii') as fh:
                fh.write(text)
        write_atomically(a.out, write)
    else:
        sys.stdout.write(text)
        sys.stdout.flush()
    return 0


def main(argv=None) -> int:
    """Entry point of ``sslfr plan`` (returns the exit status)."""
    return run('plan', _main, sys.argv[1:] if argv is None else argv)


if __name__ == '__main__':
    sys.exit(main())
