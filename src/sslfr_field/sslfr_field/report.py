"""``sslfr field-report``: the field's day, summed from the collectors' own bags.

Each collector records its own bag, named after it (``<collector id>_YYYY-MM-DD``, the
recorder's prefix under a namespace). This command runs the day report of every
collector's bag (sslfr_recording.report.analyse: the one analysis) and prints one line
per collector and the field's totals: time tracking, safety and commanded stows, the
hottest absorber temperature, the beam irradiation and the absorbed energy estimate
(seed 000 eqs. 18, 20, 25; achieved and ideal) where the bag allows it.
"""
from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path

#: a collector's bag directory: <collector id>_YYYY-MM-DD
BAG_NAME = re.compile(r'^(?P<id>[A-Za-z][A-Za-z0-9_]*)_(?P<day>\d{4}-\d{2}-\d{2})$')


def collector_of(bag: Path) -> str:
    """The collector a bag names (``c2_2026-06-21`` -> ``c2``); the directory name when
    it does not follow the pattern."""
    m = BAG_NAME.match(Path(bag).name)
    return m.group('id') if m else Path(bag).name


def summary_row(rep) -> dict:
    """The field-report figures of one collector's DayReport (SI except kWh, h, degC)."""
    temps = [t['max'] for t in rep.temperatures.values() if math.isfinite(t.get('max', float('nan')))]
    en = rep.energy or {}
    return {'tracking_h': rep.phase_time.get('TRACKING', 0.0) / 3600.0,
            'safety_stows': len(rep.stows), 'commanded_stows': len(rep.commanded_stows),
            'max_temperature_degC': max(temps) if temps else float('nan'),
            'beam_kwh_m2': rep.irradiance.get('H_kWh_m2', float('nan')) if rep.irradiance else float('nan'),
            'achieved_kwh': en.get('achieved_kwh', float('nan')), 'ideal_kwh': en.get('ideal_kwh', float('nan')),
            'note': '' if 'achieved_kwh' in en else en.get('note', 'no energy estimate')}


def totals(rows: dict[str, dict]) -> dict:
    """The field's sums (energies, stows, tracking hours; NaN rows left out of a sum
    and counted in ``without_energy``) and its hottest temperature."""
    def fsum(key):
        vals = [r[key] for r in rows.values() if math.isfinite(r[key])]
        return sum(vals) if vals else float('nan')
    temps = [r['max_temperature_degC'] for r in rows.values() if math.isfinite(r['max_temperature_degC'])]
    return {'collectors': len(rows), 'tracking_h': fsum('tracking_h'),
            'safety_stows': sum(r['safety_stows'] for r in rows.values()),
            'commanded_stows': sum(r['commanded_stows'] for r in rows.values()),
            'max_temperature_degC': max(temps) if temps else float('nan'),
            'achieved_kwh': fsum('achieved_kwh'), 'ideal_kwh': fsum('ideal_kwh'),
            'without_energy': sorted(k for k, r in rows.items() if not math.isfinite(r['achieved_kwh']))}


def render(rows: dict[str, dict], tot: dict) -> str:
    """The field report as text: one line per collector, then the field."""
    def f(x, fmt):
        return format(x, fmt) if math.isfinite(x) else '-'
    head = f'{"collector":<14}{"tracking h":>11}{"stows s/c":>11}{"max degC":>10}{"beam kWh/m2":>13}' \
           f'{"energy kWh":>12}{"ideal kWh":>11}'
    lines = ['SSLFR field report', head]
    for cid, r in rows.items():
        lines.append(f'{cid:<14}{f(r["tracking_h"], ".2f"):>11}{r["safety_stows"]:>6}/{r["commanded_stows"]:<4}'
                     f'{f(r["max_temperature_degC"], ".1f"):>10}{f(r["beam_kwh_m2"], ".2f"):>13}'
                     f'{f(r["achieved_kwh"], ".3f"):>12}{f(r["ideal_kwh"], ".3f"):>11}'
                     + (f'  ({r["note"]})' if r['note'] else ''))
    lines.append(f'{"field":<14}{f(tot["tracking_h"], ".2f"):>11}{tot["safety_stows"]:>6}/{tot["commanded_stows"]:<4}'
                 f'{f(tot["max_temperature_degC"], ".1f"):>10}{"":>13}{f(tot["achieved_kwh"], ".3f"):>12}'
                 f'{f(tot["ideal_kwh"], ".3f"):>11}')
    if tot['without_energy']:
        lines.append(f'(no energy estimate for: {", ".join(tot["without_energy"])}; not in the field\'s sum)')
    return '\n'.join(lines)


def find_bags(paths: list[str], day: str | None) -> list[Path]:
    """Bag directories among ``paths`` (a bag itself, or a folder searched recursively
    for ``<id>_YYYY-MM-DD`` bags), of ``day`` when given."""
    out = []
    for p in map(Path, paths):
        cands = [p] if (p / 'metadata.yaml').exists() else sorted(q.parent for q in p.rglob('metadata.yaml'))
        for b in cands:
            m = BAG_NAME.match(b.name)
            if day is None or (m and m.group('day') == day):
                out.append(b)
    return out


def main(argv: list[str]) -> int:
    from sslfr_common.cliargs import CliError, OneLineParser, one_line
    ap = OneLineParser(prog='sslfr field-report', description=__doc__.split('\n\n')[0],
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('paths', nargs='+', help='collector bags, or folders holding them (searched recursively)')
    ap.add_argument('--day', default=None, help='only bags of this UTC day YYYY-MM-DD')
    ap.add_argument('--config', default=None, help='site params file (collector geometry for the ideal commands)')
    try:
        ns = ap.parse_args(argv)
    except CliError as exc:
        print(f'sslfr field-report: error: {one_line(exc)}', file=sys.stderr)
        return 2
    try:
        bags = find_bags(ns.paths, ns.day)
    except OSError as exc:
        print(f'sslfr field-report: {one_line(exc.strerror or exc)}', file=sys.stderr)
        return 2
    if not bags:
        print(one_line('sslfr field-report: no bag found in ' + ', '.join(ns.paths)), file=sys.stderr)
        return 2
    from sslfr_recording.bag import BagError, BagReader
    from sslfr_common.contract import TRACKER_PHASE
    from sslfr_recording.report import analyse
    rows = {}
    for b in bags:
        cid = collector_of(b)
        if cid in rows:
            print(f'sslfr field-report: two bags for collector {cid}: give one day (--day)', file=sys.stderr)
            return 2
        try:
            reader = BagReader(b)
            phase = '/' + TRACKER_PHASE.name
            spaces = {t.rsplit(phase, 1)[0] for t in reader.topics if t.endswith(phase)}
            if len(spaces) > 1:
                print(f'sslfr field-report: skipped {b}: it holds several collectors ({", ".join(sorted(spaces))}), '
                      f'a station\'s field recording', file=sys.stderr)
                continue
            rows[cid] = summary_row(analyse(reader, ns.config))
        except (BagError, OSError) as exc:
            print(f'sslfr field-report: bag {b}: {exc}', file=sys.stderr)
            return 1
    if not rows:
        print('sslfr field-report: no collector bag among ' + ', '.join(map(str, bags)), file=sys.stderr)
        return 2
    print(render(rows, totals(rows)))
    return 0
