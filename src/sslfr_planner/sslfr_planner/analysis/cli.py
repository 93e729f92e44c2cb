"""``sslfr analyse``: optical power with tracking error, annual energy, EAR, LCOE and the
optimum longitudinal tilts (seed 000 section 5, seed 001). Degrees in, degrees out.

Subcommands::

    sslfr analyse error --config FILE --errors 0.03,0.06 --days 2024-03-21 --hours 9,12,15
    sslfr analyse year  --config FILE [--mode LAW,...] [--model trace|eq18|seed001] [--year 2023]
    sslfr analyse tilts --config FILE [--grid 11] [--out tilts.png]

The config is a tracker config (ROS params-file YAML, src/sslfr_bringup/config/):
the site from ``/**: ros__parameters: site.*``, the collector from the collector
description its planner's ``collector.description`` names (docs/collectors.md: lines,
widths, gap, central line or not, receiver height, width and tube, row length, axis
azimuth, its longitudinal law), else from ``collector.*``, and, optionally, an
``analysis`` section (``analysis: ros__parameters: {optics.*, tube.<law>.left/right,
costs.<law>.*}``); missing values default to seed 000 Table 3 and section 5. Bad input
exits 2 with one line naming the argument or key.
"""
from __future__ import annotations

import math
import sys
from dataclasses import fields, replace
from datetime import date
from pathlib import Path

import numpy as np
from sslfr_common.params import flatten as flatten_params

from ..cli_input import (CliError, OneLineParser, ranged_float, bounded_int, load_yaml_file, output_file, run,
                         time_step, write_atomically)
from ..collector import LAWS, MOVING_LAWS, FieldGeometry
from . import performance
from .optics import AIMS, OpticalParameters
from .performance import MODELS, AnalysisSite, Costs, YearSky

#: Seed 000 section 5.1: absorber tube placement (L_a^r, L_a^l) of the classic LFR and of the
#: three-movement tracker [m]; every tilting law uses the latter unless the config says otherwise.
SEED_TUBES = {'horizontal': (-2.037, -0.037), 'tilting': (-1.005, 1.005)}
#: Seed 000 section 5.5: total cost C_T [EUR] of the classic LFR (one movement) and of the
#: three-movement tracker. Laws with moving longitudinal axes need the latter's drives;
#: ``optimum_fixed`` (tilts set once) is costed as the classic one (an assumption, docs/optics.md).
SEED_COSTS = {'one_movement': 5299.53, 'three_movements': 5865.98}
#: years the analysis accepts: the pandas clock of the clear-sky model and the delta-T model
YEARS = (1800, 2200)
#: the most time steps of one year the analysis computes (a leap year at 60 s)
MAX_YEAR_SAMPLES = 527_040
#: the most time steps of one year the tilt search computes (a leap year at 300 s)
MAX_TILT_SAMPLES = 105_408

_YEAR_SPAN = 366 * 86400.0


def default_config() -> Path | None:
    """The Almeria seed 000 config (installed share/ or the source tree)."""
    here = Path(__file__).resolve()
    candidates = [here.parents[3] / 'sslfr_bringup' / 'config' / 'almeria_sslfr.yaml']
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.insert(0, Path(get_package_share_directory('sslfr_bringup')) / 'config' / 'almeria_sslfr.yaml')
    except Exception:  # noqa: BLE001 - not installed / no ament index: fall back to the source tree
        pass
    for path in candidates:
        if path.is_file():
            return path
    return None


def _number(params: dict, key: str, default, lo: float, hi: float, where: str, integer: bool = False):
    value = params.get(key, default)
    ok = not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value) \
        and lo <= value <= hi and (not integer or float(value).is_integer())
    if not ok:
        kind = 'an integer' if integer else 'a number'
        raise CliError(f'config {where}: {key} must be {kind} within {lo:g}..{hi:g}, got {value!r}')
    return int(value) if integer else float(value)


def load_config(path: str | None) -> tuple[AnalysisSite, OpticalParameters, dict]:
    """Read site, collector geometry, optics and the analysis section from a tracker config."""
    cfg_path = Path(path) if path else default_config()
    raw = load_yaml_file(str(cfg_path)) if cfg_path is not None else {}
    where = str(cfg_path)
    params: dict = {'__config__': where}
    for node, section in raw.items():
        if not isinstance(section, dict) or not isinstance(section.get('ros__parameters', {}), dict):
            raise CliError(f'config {where}: section {node!r} must be a mapping with a ros__parameters mapping')
        flat = flatten_params(section.get('ros__parameters') or {})
        if node in ('/**', 'planner'):
            params.update({k: v for k, v in flat.items() if k.startswith(('site.', 'collector.'))})
        if node == 'analysis':
            params.update({f'analysis.{k}': v for k, v in flat.items()})
    lat = _number(params, 'site.latitude_deg', 36 + 50 / 60 + 7 / 3600, -90.0, 90.0, where)
    lon = _number(params, 'site.longitude_deg', -(2 + 24 / 60 + 8 / 3600), -180.0, 180.0, where)
    elev = _number(params, 'site.elevation', 22.0, -500.0, 9000.0, where)
    desc = _description(params, where)
    params['__description__'] = desc
    optic = {}
    if desc is not None:        # the described collector: its geometry, receiver and azimuth
        from ..prototype import field_geometry
        azi = desc.optics.azimuth
        geo = {f.name: getattr(field_geometry(desc), f.name) for f in fields(FieldGeometry)}
        optic['cavity_aperture'] = desc.optics.receiver_width
    else:
        azi = _number(params, 'collector.azimuth', 0.0, -math.pi / 2, math.pi / 2, where)
        geo = {'n_per_side': _number(params, 'collector.n_per_side', 12, 0, 100, where, integer=True)}
        for name, lo, hi in (('mirror_width', 1e-3, 5.0), ('gap', 0.0, 5.0), ('receiver_height', 0.05, 50.0),
                             ('tube_diameter', 1e-3, 1.0), ('mirror_length', 0.01, 1000.0)):
            key = f'collector.{name}'
            if key in params:
                geo[name] = _number(params, key, None, lo, hi, where)
        if 'collector.central_mirror' in params:                 # seeds 003, 004: no central line
            if not isinstance(params['collector.central_mirror'], bool):
                raise CliError(f'config {where}: collector.central_mirror must be true or false, '
                               f'got {params["collector.central_mirror"]!r}')
            geo['central_mirror'] = params['collector.central_mirror']
    site = AnalysisSite(lat, lon, elev, azi)
    known = {f.name for f in fields(OpticalParameters)} - {'geometry'}
    for key, value in params.items():
        if key.startswith('analysis.optics.'):
            name = key.split('.', 2)[2]
            if name in ('mirror_length',):
                geo[name] = _number(params, key, None, 0.01, 1000.0, where)
            elif name not in known:
                raise CliError(f'config {where}: unknown optics parameter {name!r} '
                               f'(known: {", ".join(sorted(known | {"mirror_length"}))})')
            elif name == 'mirror_aim':
                if value not in AIMS:
                    raise CliError(f'config {where}: {key} must be one of {", ".join(AIMS)}, got {value!r}')
                optic[name] = value
            else:
                optic[name] = _number(params, key, None, 0.0, 1.0 if name != 'cavity_aperture' else 10.0, where)
    try:
        return site, OpticalParameters(geometry=FieldGeometry(**geo), **optic), params
    except (TypeError, ValueError) as exc:
        raise CliError(f'config {where}: {exc}') from None


def _description(params: dict, where: str):
    """The collector description the config's ``collector.description`` names (relative
    to the config, as the planner finds it), or None; CliError naming the file and keys."""
    name = params.get('collector.description')
    if name is None or name == '':
        return None
    if not isinstance(name, str):
        raise CliError(f'config {where}: collector.description must be a file name, got {name!r}')
    from ..description import DescriptionError, find, load
    try:
        return load(find(name, [where]))
    except DescriptionError as exc:
        raise CliError(f'config {where}: collector.description: ' + '; '.join(exc.problems)) from None


def _floats(text: str, what: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(',') if x.strip()]
    except ValueError:
        raise CliError(f'--{what}: expected comma-separated numbers, got {text!r}') from None
    if not values:
        raise CliError(f'--{what}: empty list')
    if not all(math.isfinite(v) for v in values):
        raise CliError(f'--{what}: expected finite numbers, got {text!r}')
    return values


def _days(text: str) -> list[date]:
    out = []
    for item in text.split(','):
        try:
            day = date.fromisoformat(item.strip())
        except ValueError:
            raise CliError(f'--days: {item!r} is not a date (YYYY-MM-DD)') from None
        if not YEARS[0] <= day.year <= YEARS[1]:
            raise CliError(f'--days: {item!r} outside the supported years {YEARS[0]}..{YEARS[1]}')
        out.append(day)
    return out


def cmd_error(args) -> int:
    site, optic, params = load_config(args.config)
    errors = _floats(args.errors, 'errors')
    if any(e < 0 or e > 10 for e in errors):
        raise CliError('--errors: tracking errors must be within 0..10 deg')
    hours = _floats(args.hours, 'hours')
    if any(h < 0 or h > 24 for h in hours):
        raise CliError('--hours: solar hours must be within 0..24')
    desc = params.get('__description__')
    law = args.mode or (desc.longitudinal_law if desc is not None else 'eq16')
    rows = performance.error_table(site, optic, np.radians(errors), _days(args.days), hours, law=law,
                                   receiver_fixed=desc is not None and desc.receiver_fixed)
    labels = optic.geometry.mirror_labels()
    out = sys.stdout
    out.write('day,solar_hour,error_deg,transversal_deg,total_loss_pct,' + ','.join(labels) + '\n')
    for r in rows:
        out.write(f'{r.day.isoformat()},{r.hour:g},{np.degrees(r.error):g},{np.degrees(r.transversal):.3f},'
                  f'{r.loss_total:.4f},' + ','.join(f'{x:.4f}' for x in r.loss_per_mirror) + '\n')
    return 0


def law_tube(law: str, params: dict) -> tuple[float, float]:
    """(L_a^r, L_a^l) [m] of ``law``: the config's ``analysis.tube.<law>.*``; else, for a
    described collector, its receiver (the description's tube ends, or its receiver
    length centred) under every law but 'horizontal' on a collector that tilts (seed
    000 section 5.1's classic LFR, the horizontal variant of its design study); without
    a description seed 000 section 5.1's placements."""
    desc = params.get('__description__')
    if desc is not None and not (law == 'horizontal' and desc.longitudinal_law != 'horizontal'):
        from ..prototype import field_geometry
        right, left = field_geometry(desc).tube
    else:
        right, left = SEED_TUBES['horizontal' if law == 'horizontal' else 'tilting']
    key, where = f'analysis.tube.{law}.', params.get('__config__', '')
    return (_number(params, key + 'right', right, -100.0, 100.0, where),
            _number(params, key + 'left', left, -100.0, 100.0, where))


def law_costs(law: str, params: dict) -> Costs:
    """Costs of ``law`` (config ``analysis.costs.<law>.*`` or seed 000 section 5.5)."""
    key, where = f'analysis.costs.{law}.', params.get('__config__', '')
    default = SEED_COSTS['three_movements' if law in MOVING_LAWS or law == 'daily' else 'one_movement']
    return Costs(direct_capital=_number(params, key + 'direct_capital', default, 0.0, 1e12, where),
                 indirect_capital=_number(params, key + 'indirect_capital', 0.0, 0.0, 1e12, where),
                 om_fraction=_number(params, 'analysis.costs.om_fraction', 0.005, 0.0, 1.0, where),
                 lifetime=_number(params, 'analysis.costs.lifetime', 25, 1, 200, where, integer=True),
                 discount_rate=_number(params, 'analysis.costs.discount_rate', 0.03, -0.5, 1.0, where))


def _laws(text: str) -> list[str]:
    laws = [m.strip() for m in text.split(',') if m.strip()]
    for law in laws:
        if law not in LAWS:
            raise CliError(f'--mode: unknown law {law!r}; expected a comma list of {", ".join(LAWS)}')
    if not laws:
        raise CliError(f'--mode: empty list; expected a comma list of {", ".join(LAWS)}')
    return laws


def cmd_year(args) -> int:
    laws = _laws(args.mode)
    site, optic, params = load_config(args.config)
    if args.aim:
        optic = replace(optic, mirror_aim=args.aim)
    dni = None
    if args.dni_csv:
        from .beam import dni_from_samples, read_dni_csv
        try:
            st, sd = read_dni_csv(args.dni_csv)
        except (OSError, ValueError, UnicodeDecodeError) as exc:
            raise CliError(f'--dni-csv: {exc}') from None
        dni = lambda t: dni_from_samples(t, st, sd)  # noqa: E731
    tubes = {law: law_tube(law, params) for law in laws}
    costs = {law: law_costs(law, params) for law in laws}
    sky = YearSky.compute(site, args.year, args.step, dni=dni)
    results = []
    for law in laws:
        try:
            p = performance.with_tube(optic, tubes[law])
        except ValueError as exc:
            raise CliError(f'tube placement for {law}: {exc}') from None
        results.append(performance.annual_energy(sky, site, p, law, model=args.model, costs=costs[law]))
    model_text = {'trace': '3-D trace, 3-D incidence', 'eq18': '3-D trace, eq. 18 incidence in the rows\' plane',
                  'seed001': 'seed 001 eq. 20 on the 3-D trace'}[args.model]
    print(f'site {site.latitude_deg:.4f} deg, {site.longitude_deg:.4f} deg, {site.elevation:g} m; year {args.year}, '
          f'{args.step:g} s steps, DNI {"from " + args.dni_csv if args.dni_csv else "clear sky (Ineichen-Perez)"}; '
          f'beam irradiation {sky.dni.sum() * args.step / 3.6e6:.0f} kWh/m2; model {args.model} ({model_text}), '
          f'mirrors {optic.mirror_aim}')
    print('law,energy_mwh,area_m2,ear_mwh_m2,lcoe_per_kwh,end_loss_efficiency,tube_right_m,tube_left_m')
    for r in results:
        lc = f'{r.lcoe:.4f}' if r.lcoe is not None else ''
        el = f'{r.end_loss_efficiency:.3f}' if math.isfinite(r.end_loss_efficiency) else ''
        print(f'{r.law},{r.energy_wh / 1e6:.4f},{r.area_m2:.4f},{r.ear / 1e6:.4f},{lc},{el},'
              f'{r.tube[0]:g},{r.tube[1]:g}')
    base = next((r for r in results if r.law == 'horizontal'), None)
    if base is not None and base.energy_wh > 0:
        for r in results:
            if r is base:
                continue
            line = (f'{r.law} vs horizontal: energy {100 * (r.energy_wh / base.energy_wh - 1):+.2f} %, '
                    f'EAR {100 * (r.ear / base.ear - 1):+.2f} %')
            if r.lcoe is not None and base.lcoe is not None:
                line += f', LCOE {100 * (r.lcoe / base.lcoe - 1):+.2f} %'
            print(line)
    return 0


def cmd_tilts(args) -> int:
    site, optic, _ = load_config(args.config)
    if site.latitude_deg == 0.0:
        raise CliError('config: the tilt search spans 0..latitude; at latitude 0 there is nothing to search')
    sky = YearSky.compute(site, args.year, args.step)
    res = performance.tilt_search(sky, site, optic, grid=args.grid, max_area=args.max_area)
    if not np.any(np.isfinite(res.ear)):
        raise CliError(f'--max-area: no tilt pair fits in {args.max_area:g} m2 '
                       f'(smallest area {np.min(res.area):.2f} m2)')
    bm, ba = res.optimum
    lat = abs(site.latitude_deg)
    print(f'site latitude {site.latitude_deg:.4f} deg; grid {args.grid}x{args.grid} '
          f'(step {lat / (args.grid - 1):.3f} deg); area <= {args.max_area:g} m2')
    print(f'optimum beta_M = {np.degrees(bm):.3f} deg ({100 * np.degrees(bm) / lat:.0f} % of latitude), '
          f'beta_a = {np.degrees(ba):.3f} deg ({100 * np.degrees(ba) / lat:.0f} % of latitude); '
          f'seed 001: beta_M = latitude/2 = {lat / 2:.3f} deg, beta_a = latitude = {lat:.3f} deg')
    print(f'EAR at the optimum {np.nanmax(res.ear) / 1e6:.4f} MWh/m2')
    if args.out:
        write_atomically(args.out, lambda tmp: write_heatmap(res, site, tmp))
        print(f'heat map: {args.out}')
    return 0


def write_heatmap(res, site: AnalysisSite, path: str) -> None:
    """PNG heat map of the EAR over (beta_a, beta_M) in % of latitude (seed 001 Figs. 7-11)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    lat = np.radians(abs(site.latitude_deg))
    fig, ax = plt.subplots(figsize=(6, 5))
    mesh = ax.pcolormesh(100 * res.beta_a / lat, 100 * res.beta_m / lat, res.ear / 1e6, shading='nearest',
                         cmap='viridis')
    bm, ba = res.optimum
    ax.plot([100 * ba / lat], [100 * bm / lat], 'r*', ms=14, label='optimum')
    ax.set_xlabel('beta_a (% of latitude)')
    ax.set_ylabel('beta_M (% of latitude)')
    ax.set_title(f'EAR at latitude {site.latitude_deg:.2f} deg')
    fig.colorbar(mesh, ax=ax, label='EAR (MWh/m2)')
    ax.legend(loc='lower left')
    fig.tight_layout()
    fig.savefig(path, dpi=100, format='png')
    plt.close(fig)


def parser() -> OneLineParser:
    """The argument parser of ``sslfr analyse``."""
    p = OneLineParser(prog='sslfr analyse', description=__doc__.split('\n\n')[0])
    sub = p.add_subparsers(dest='what', required=True, parser_class=OneLineParser)
    year_type = bounded_int(*YEARS)
    e = sub.add_parser('error', help='power loss per mirror caused by tracking errors (seed 000 Figs. 22-24)')
    e.add_argument('--config')
    e.add_argument('--errors', default='0.03,0.06,0.12,0.24,0.36', help='tracking errors [deg]')
    e.add_argument('--days', default='2024-03-21,2024-06-21,2024-09-21,2024-12-21')
    e.add_argument('--hours', default='9,12,15', help='local solar hours')
    e.add_argument('--mode', choices=LAWS, default=None,
                   help="longitudinal law of the structure during the study (default: the collector "
                        "description's, else eq16 as seed 000)")
    e.set_defaults(func=cmd_error)
    y = sub.add_parser('year', help='annual energy, area, EAR, LCOE per longitudinal law (seed 000 5.3-5.5)')
    y.add_argument('--config')
    y.add_argument('--mode', default=','.join(LAWS), help=f'comma list of {", ".join(LAWS)} (default: all)')
    y.add_argument('--year', type=year_type, default=2023, help=f'{YEARS[0]}..{YEARS[1]}')
    y.add_argument('--step', type=time_step(_YEAR_SPAN, MAX_YEAR_SAMPLES, 'a year'), default=600.0,
                   help='time step [s] (default 600, at least 60)')
    y.add_argument('--dni-csv', help='measured DNI (columns utc,dni_w_m2) instead of clear sky')
    y.add_argument('--model', choices=MODELS, default='trace',
                   help="power model: trace (3-D incidence), eq18 (seed 000 eq. 18's incidence in the rows' "
                        'plane: the paper comparison), seed001 (annex eq. 20)')
    y.add_argument('--aim', choices=AIMS, default=None,
                   help="mirrors' offsets: focused (default, seed 000 eqs. 11-14) or fixed at assembly")
    y.set_defaults(func=cmd_year)
    t = sub.add_parser('tilts', help='brute-force EAR over the two longitudinal tilts (seed 001)')
    t.add_argument('--config')
    t.add_argument('--grid', type=bounded_int(2, 101), default=11, help='grid points per tilt, 2..101')
    t.add_argument('--year', type=year_type, default=2023, help=f'{YEARS[0]}..{YEARS[1]}')
    t.add_argument('--step', type=time_step(_YEAR_SPAN, MAX_TILT_SAMPLES, 'a year'), default=600.0,
                   help='time step [s] (default 600, at least 300)')
    t.add_argument('--max-area', type=ranged_float(0.0, 1e6, lo_open=True, unit='m2'), default=10.0,
                   help='largest installation area [m2] (seed 001: 10)')
    t.add_argument('--out', type=output_file, help='PNG heat map path (written only when complete)')
    t.set_defaults(func=cmd_tilts)
    return p


def _main(argv) -> int:
    args = parser().parse_args(argv)
    return args.func(args)


def main(argv=None) -> int:
    """Entry point of ``sslfr analyse`` (returns the exit status)."""
    return run('analyse', _main, sys.argv[1:] if argv is None else argv)


if __name__ == '__main__':
    sys.exit(main())
