"""``sslfr analyse``: optical power with tracking error, annual energy, EAR, LCOE and the
optimum longitudinal tilts (seed 000 section 5, seed 001). Degrees in, degrees out.

Subcommands::

    sslfr analyse error --config FILE --errors 0.03,0.06 --days 2024-03-21 --hours 9,12,15
    sslfr analyse year  --config FILE --mode continuous,horizontal [--year 2023]
    sslfr analyse tilts --config FILE [--grid 11] [--out tilts.png]

The config is a tracker config (ROS params-file YAML, src/sslfr_bringup/config/):
the site from ``/**: ros__parameters: site.*`` and, optionally, an ``analysis`` section
(``analysis: ros__parameters: {optics.*, tube.<law>.left/right, costs.<law>.*}``);
missing values default to seed 000 Table 3 and section 5.
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import fields, replace
from datetime import date
from pathlib import Path

import numpy as np

from . import analysis, optics
from .analysis import AnalysisSite, Costs, YearSky
from .optics import OpticalParameters

#: Seed 000 section 5.1: absorber tube placement of each configuration [m].
SEED_TUBES = {'horizontal': (-2.037, -0.037), 'continuous': (-1.005, 1.005)}
#: Seed 000 section 5.5: total cost C_T of each configuration [EUR].
SEED_COSTS = {'horizontal': 5299.53, 'continuous': 5865.98}


class CliError(Exception):
    """A user error: printed as one line, exit status 2."""


def _flatten(d: dict, prefix: str = '') -> dict:
    out = {}
    for key, value in d.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            out.update(_flatten(value, name + '.'))
        else:
            out[name] = value
    return out


def default_config() -> Path | None:
    """The Almeria seed 000 config (installed share/ or the source tree)."""
    here = Path(__file__).resolve()
    candidates = [here.parents[2] / 'sslfr_bringup' / 'config' / 'almeria_sslfr.yaml']
    try:
        from ament_index_python.packages import get_package_share_directory
        candidates.insert(0, Path(get_package_share_directory('sslfr_bringup')) / 'config' / 'almeria_sslfr.yaml')
    except Exception:  # noqa: BLE001 - not installed / no ament index: fall back to the source tree
        pass
    for path in candidates:
        if path.is_file():
            return path
    return None


def load_config(path: str | None) -> tuple[AnalysisSite, OpticalParameters, dict]:
    """Read site, optics and the analysis section from a tracker config file."""
    import yaml

    cfg_path = Path(path) if path else default_config()
    raw: dict = {}
    if cfg_path is not None:
        try:
            raw = yaml.safe_load(Path(cfg_path).read_text()) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise CliError(f'cannot read config {cfg_path}: {exc}') from None
    params: dict = {}
    for node, section in raw.items():
        if isinstance(section, dict) and isinstance(section.get('ros__parameters'), dict):
            flat = _flatten(section['ros__parameters'])
            if node in ('/**', 'planner'):
                params.update({k: v for k, v in flat.items() if k.startswith('site.') or k.startswith('collector.')})
            if node == 'analysis':
                params.update({f'analysis.{k}': v for k, v in flat.items()})
    lat = params.get('site.latitude_deg', 36 + 50 / 60 + 7 / 3600)
    lon = params.get('site.longitude_deg', -(2 + 24 / 60 + 8 / 3600))
    elev = params.get('site.elevation', 22.0)
    azi = params.get('collector.azimuth', 0.0)
    try:
        site = AnalysisSite(float(lat), float(lon), float(elev), float(azi))
    except ValueError as exc:
        raise CliError(f'config {cfg_path}: {exc}') from None
    known = {f.name for f in fields(OpticalParameters)}
    overrides = {}
    for key, value in params.items():
        if key.startswith('analysis.optics.'):
            name = key.split('.', 2)[2]
            if name not in known:
                raise CliError(f'config {cfg_path}: unknown optics parameter {name!r}')
            overrides[name] = value
    for key, name in (('collector.n_per_side', 'n_per_side'), ('collector.mirror_width', 'mirror_width'),
                      ('collector.gap', 'gap'), ('collector.receiver_height', 'receiver_height'),
                      ('collector.tube_diameter', 'tube_diameter')):
        if key in params and name not in overrides:
            overrides[name] = params[key]
    try:
        optic = OpticalParameters(**overrides)
    except (TypeError, ValueError) as exc:
        raise CliError(f'config {cfg_path}: {exc}') from None
    return site, optic, params


def _floats(text: str, what: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(',') if x.strip()]
    except ValueError:
        raise CliError(f'--{what}: expected comma-separated numbers, got {text!r}') from None
    if not values:
        raise CliError(f'--{what}: empty list')
    return values


def _days(text: str) -> list[date]:
    out = []
    for item in text.split(','):
        try:
            out.append(date.fromisoformat(item.strip()))
        except ValueError:
            raise CliError(f'--days: {item!r} is not a date (YYYY-MM-DD)') from None
    return out


def cmd_error(args) -> int:
    site, optic, _ = load_config(args.config)
    errors = _floats(args.errors, 'errors')
    if any(e < 0 or e > 10 for e in errors):
        raise CliError('--errors: tracking errors must be within 0..10 deg')
    hours = _floats(args.hours, 'hours')
    if any(h < 0 or h > 24 for h in hours):
        raise CliError('--hours: solar hours must be within 0..24')
    rows = analysis.error_table(site, optic, np.radians(errors), _days(args.days), hours)
    labels = optics.mirror_labels(optic)
    out = sys.stdout
    out.write('day,solar_hour,error_deg,transversal_deg,total_loss_pct,' + ','.join(labels) + '\n')
    for r in rows:
        out.write(f'{r.day.isoformat()},{r.hour:g},{np.degrees(r.error):g},{np.degrees(r.transversal):.3f},'
                  f'{r.loss_total:.4f},' + ','.join(f'{x:.4f}' for x in r.loss_per_mirror) + '\n')
    return 0


def _costs_for(law: str, params: dict) -> Costs | None:
    key = f'analysis.costs.{law}.'
    dc = params.get(key + 'direct_capital', SEED_COSTS.get(law))
    if dc is None:
        return None
    return Costs(direct_capital=float(dc),
                 indirect_capital=float(params.get(key + 'indirect_capital', 0.0)),
                 om_fraction=float(params.get('analysis.costs.om_fraction', 0.005)),
                 lifetime=int(params.get('analysis.costs.lifetime', 25)),
                 discount_rate=float(params.get('analysis.costs.discount_rate', 0.03)))


def cmd_year(args) -> int:
    site, optic, params = load_config(args.config)
    laws = [m.strip() for m in args.mode.split(',') if m.strip()]
    for law in laws:
        if law not in analysis.LAWS:
            raise CliError(f'--mode: unknown law {law!r}; expected {", ".join(analysis.LAWS)}')
    dni = None
    if args.dni_csv:
        from .beam import read_dni_csv, dni_from_samples
        try:
            st, sd = read_dni_csv(args.dni_csv)
        except (OSError, ValueError) as exc:
            raise CliError(str(exc)) from None
        dni = lambda t: dni_from_samples(t, st, sd)  # noqa: E731
    sky = YearSky.compute(site, args.year, args.step, dni=dni)
    results = []
    for law in laws:
        key = f'analysis.tube.{law}.'
        right, left = SEED_TUBES.get(law, SEED_TUBES['continuous'])
        right = float(params.get(key + 'right', right))
        left = float(params.get(key + 'left', left))
        try:
            p = replace(optic, tube_right=right, tube_left=left)
        except ValueError as exc:
            raise CliError(f'tube placement for {law}: {exc}') from None
        results.append(analysis.annual_energy(sky, site, p, law, model=args.model, costs=_costs_for(law, params)))
    print(f'site {site.latitude_deg:.4f} deg, {site.longitude_deg:.4f} deg, {site.elevation:g} m; year {args.year}, '
          f'{args.step:g} s steps, DNI {"from " + args.dni_csv if args.dni_csv else "clear sky (Ineichen-Perez)"}, '
          f'power model {args.model}; beam irradiation {sky.dni.sum() * args.step / 3.6e6:.0f} kWh/m2')
    print('law,energy_mwh,area_m2,ear_mwh_m2,lcoe_per_kwh,tube_right_m,tube_left_m')
    for r in results:
        lc = f'{r.lcoe:.4f}' if r.lcoe is not None else ''
        print(f'{r.law},{r.energy_wh / 1e6:.4f},{r.area_m2:.4f},{r.ear / 1e6:.4f},{lc},{r.tube[0]:g},{r.tube[1]:g}')
    base = next((r for r in results if r.law == 'horizontal'), None)
    if base is not None:
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
    if not 2 <= args.grid <= 101:
        raise CliError('--grid must be within 2..101')
    sky = YearSky.compute(site, args.year, args.step)
    res = analysis.tilt_search(sky, site, optic, grid=args.grid, max_area=args.max_area)
    bm, ba = res.optimum
    lat = abs(site.latitude_deg)
    print(f'site latitude {site.latitude_deg:.4f} deg; grid {args.grid}x{args.grid} '
          f'(step {lat / (args.grid - 1):.3f} deg); area <= {args.max_area:g} m2')
    print(f'optimum beta_M = {np.degrees(bm):.3f} deg ({100 * np.degrees(bm) / lat:.0f} % of latitude), '
          f'beta_a = {np.degrees(ba):.3f} deg ({100 * np.degrees(ba) / lat:.0f} % of latitude); '
          f'seed 001: beta_M = latitude/2 = {lat / 2:.3f} deg, beta_a = latitude = {lat:.3f} deg')
    print(f'EAR at the optimum {np.nanmax(res.ear) / 1e6:.4f} MWh/m2')
    if args.out:
        write_heatmap(res, site, args.out)
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
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='sslfr analyse', description=__doc__.split('\n\n')[0])
    sub = parser.add_subparsers(dest='what', required=True)
    e = sub.add_parser('error', help='power loss per mirror caused by tracking errors (seed 000 Figs. 22-24)')
    e.add_argument('--config')
    e.add_argument('--errors', default='0.03,0.06,0.12,0.24,0.36', help='tracking errors [deg]')
    e.add_argument('--days', default='2024-03-21,2024-06-21,2024-09-21,2024-12-21')
    e.add_argument('--hours', default='9,12,15', help='local solar hours')
    e.set_defaults(func=cmd_error)
    y = sub.add_parser('year', help='annual energy, area, EAR, LCOE per longitudinal law (seed 000 5.3-5.5)')
    y.add_argument('--config')
    y.add_argument('--mode', default='continuous,horizontal', help=f'comma list of {", ".join(analysis.LAWS)}')
    y.add_argument('--year', type=int, default=2023)
    y.add_argument('--step', type=float, default=600.0, help='time step [s]')
    y.add_argument('--dni-csv', help='measured DNI (columns utc,dni_w_m2) instead of clear sky')
    y.add_argument('--model', choices=('seed000', 'seed001'), default='seed000')
    y.set_defaults(func=cmd_year)
    t = sub.add_parser('tilts', help='brute-force EAR over the two longitudinal tilts (seed 001)')
    t.add_argument('--config')
    t.add_argument('--grid', type=int, default=11)
    t.add_argument('--year', type=int, default=2023)
    t.add_argument('--step', type=float, default=600.0, help='time step [s]')
    t.add_argument('--max-area', type=float, default=10.0, help='largest installation area [m2]')
    t.add_argument('--out', help='PNG heat map path')
    t.set_defaults(func=cmd_tilts)
    return parser


def main(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, 'step', 600.0) <= 0 or getattr(args, 'step', 600.0) > 86400:
        print('sslfr analyse: --step must be within (0, 86400] s', file=sys.stderr)
        return 2
    try:
        return args.func(args)
    except CliError as exc:
        print(f'sslfr analyse: {exc}', file=sys.stderr)
        return 2
