"""``sslfr report BAG [--out DIR]``: the day report of a recorded bag.

A summary a person reads in a minute, as text on stdout and as ``report.md`` with
PNG plots (matplotlib, Agg) in ``--out`` (default: ``<bag>/report``):

- site and date; the collector (the collector description ``--config`` names) and its
  movements, the only ones reported; sunrise / solar noon / sunset (from ``tracker/phase``);
- time spent in each phase (a phase holds until the next tracker/phase message);
- per-movement tracking error, RMS / max / 95th percentile [mrad], only while the axis is
  tracking: phase TRACKING and not inside one of the axis' deliberate moves (see
  :func:`.report.axis_moves`): measured vs the commanded setpoint (``axes/<axis>/status``)
  and measured vs the ideal command of :func:`sslfr_planner.tracking_table.evaluate` at the
  same instants (when that module is installed; otherwise "ideal unavailable");
- per-axis moves, reported separately: count, total duration and the largest
  (PRE_DAWN's slew from the sleeping position, stows, a law's repositioning);
- stow events (``safety/state`` level >= STOW) with reasons and durations, and
  commanded stows (phase STOW);
- max absorber temperatures; max beam irradiance and the day's beam irradiation
  H = integral of G_b dt [kWh/m^2] (trapezoids, gaps > 120 s not bridged);
- link faults per axis (time not LINK_UP, frames lost / bad, fault bits);
- rows that do not tilt: every mirror line's error against its exact angle (seed 004
  eqs. 3-4) and seed 004's 0.085 / 0.12 deg budget (:func:`.report.line_tracking`);
- the day's absorbed energy estimate: the optical model of seed 000 (eqs. 18, 20, 25) on
  the collector's optics (:mod:`.report_energy`) fed with the recorded beam irradiance:
  every line exact (ideal), the collector's law, and the measured angles (achieved).

The bag is decoded once (:func:`.day.read_day`); the ideal is the run's reference
(:func:`.day.reference`) built from ``--config``, the run's site config (default: the
node set's, the one ``sslfr up`` starts with). Figures: :mod:`.report`; text and
plots: :mod:`.report_render`.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sslfr_bringup.nodeset import NodeSetError
from sslfr_planner.cli_input import CliError, OneLineParser, one_line, output_dir

from .bag.metadata import BagError
from .bag.reader import BagReader
from .day import default_config, planner_config, read_day
from .report import REPORT_TOPICS, analyse
from .report_render import make_plots, render_markdown, render_text


def main(argv: list[str]) -> int:
    ap = OneLineParser(prog='sslfr report', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('bag', help='bag directory or .mcap file')
    ap.add_argument('--out', default=None, type=output_dir,
                    help='directory for report.md and PNGs (default <bag>/report)')
    ap.add_argument('--no-plots', action='store_true', help='text only')
    ap.add_argument('--config', default=None,
                    help="the run's site params file, a path or a name in sslfr_bringup/config (collector "
                         "and site parameters of the ideal commands; default: the node set's, as sslfr up)")
    try:
        ns = ap.parse_args(argv)
        ns.config = ns.config or str(default_config())
        planner_config(ns.config)           # a bad site config: refused before any work
    except CliError as exc:
        print(f'sslfr report: error: {one_line(exc)}', file=sys.stderr)
        return 2
    except NodeSetError as exc:
        print(f'sslfr report: error: --config {one_line(ns.config)}: '
              + one_line('; '.join(line.strip() for line in str(exc).split('\n')[1:] or [str(exc)])),
              file=sys.stderr)
        return 2
    try:
        reader = BagReader(ns.bag)
    except BagError as exc:  # missing, damaged or wrong-kind bag: bad input
        print(f'sslfr report: error: bag {one_line(ns.bag)}: {one_line(exc)}', file=sys.stderr)
        return 2
    try:
        rep = analyse(read_day(reader, topics=REPORT_TOPICS), ns.config)
    except (BagError, OSError) as exc:
        print(f'sslfr report: {one_line(exc)}', file=sys.stderr)
        return 1
    print(render_text(rep))
    if not ns.no_plots:
        out = Path(ns.out) if ns.out else (reader.directory / 'report')
        out.mkdir(parents=True, exist_ok=True)
        plots = make_plots(rep, out)
        (out / 'report.md').write_text(render_markdown(rep, plots), encoding='utf-8')
        print(f'report: {out / "report.md"} ({len(plots)} plots)')
    return 0
