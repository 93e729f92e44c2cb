"""``sslfr report BAG [--out DIR]``: the day report of a recorded bag.

A summary a person reads in a minute, as text on stdout and as ``report.md`` with
PNG plots (matplotlib, Agg) in ``--out`` (default: ``<bag>/report``):

- site and date; sunrise / solar noon / sunset (from ``tracker/phase``);
- time spent in each phase (a phase holds until the next tracker/phase message);
- per-axis tracking error, RMS / max / 95th percentile [mrad], only while the axis is
  tracking: phase TRACKING and not inside one of the axis' deliberate moves (see
  :func:`axis_moves`): measured vs the commanded setpoint (``axes/<axis>/status``)
  and measured vs the ideal command of :func:`sslfr_planner.tracking_table.evaluate` at the
  same instants (when that module is installed; otherwise "ideal unavailable");
- per-axis moves, reported separately: count, total duration and the largest
  (PRE_DAWN's slew from the sleeping position, stows, a law's repositioning);
- stow events (``safety/state`` level >= STOW) with reasons and durations, and
  commanded stows (phase STOW);
- max absorber temperatures; max beam irradiance and the day's beam irradiation
  H = integral of G_b dt [kWh/m^2] (trapezoids, gaps > 120 s not bridged);
- link faults per axis (time not LINK_UP, frames lost / bad, fault bits);
- the day's absorbed energy estimate: the optical model of seed 000 (eqs. 18, 20, 25;
  :func:`sslfr_planner.analysis.performance.day_energy`) fed with the recorded beam irradiance and
  once with the ideal axis angles, once with the measured ones (ideal vs achieved).

Pure analysis (no rclpy): messages are decoded through the bag's own schemas.
"""
from __future__ import annotations

import argparse
import datetime as dt
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from sslfr_common.contract import JOINTS, LEVEL_NAMES, PHASE_NAMES, LinkState
from sslfr_common.timeconv import to_sec
from sslfr_planner.cli_input import CliError, OneLineParser, output_dir

from sslfr_bringup.nodeset import NodeSetError, checked_params, node_params
from sslfr_bringup.nodeset import load as load_nodeset

from .bag.metadata import BagError
from .bag.reader import BagReader, message_time

MAX_GAP_S = 120.0
#: a setpoint moving faster than this is a deliberate move, not sun tracking [rad/s]: the
#: longitudinal laws' jump bound (0.05 deg in 1 s, docs/optics.md), ten times the fastest
#: sun-following axis rate (~0.004 deg/s)
MOVE_RATE = math.radians(0.05)
#: a move ends when the axis is back within this of its setpoint [rad] (~10 motor steps)
SETTLE = 1e-3
#: a move not settled after this long ends anyway: what follows counts as tracking error [s]
MOVE_CAP = 300.0


def utc(t: float, fmt: str = '%H:%M:%S') -> str:
    """UTC clock text of a time [s since the Unix epoch]."""
    return dt.datetime.fromtimestamp(t, tz=dt.timezone.utc).strftime(fmt)


@dataclass
class ErrorStats:
    """Statistics of an error series [rad]."""

    rms: float
    max: float
    p95: float
    samples: int

    @classmethod
    def of(cls, err: np.ndarray) -> 'ErrorStats':
        e = np.abs(np.asarray(err, dtype=float))
        e = e[np.isfinite(e)]
        if e.size == 0:
            return cls(float('nan'), float('nan'), float('nan'), 0)
        return cls(float(np.sqrt(np.mean(e ** 2))), float(e.max()), float(np.percentile(e, 95)),
                   int(e.size))

    def text(self) -> str:
        if not self.samples:
            return 'no samples'
        return (f'RMS {1e3 * self.rms:7.2f}  max {1e3 * self.max:7.2f}  p95 {1e3 * self.p95:7.2f} '
                f'mrad ({self.samples} samples)')


@dataclass
class Series:
    """Time series: t [s since epoch] and named value arrays."""

    t: list = field(default_factory=list)
    v: dict = field(default_factory=dict)

    def add(self, t: float, **values) -> None:
        self.t.append(t)
        for k, x in values.items():
            self.v.setdefault(k, []).append(x)

    def arrays(self):
        order = np.argsort(np.asarray(self.t, dtype=float), kind='stable')
        t = np.asarray(self.t, dtype=float)[order]
        return t, {k: np.asarray(x)[order] for k, x in self.v.items()}


@dataclass
class DayReport:
    """Everything the report shows (plain data, for text/Markdown/plots and tests)."""

    bag: str
    start: float
    end: float
    site: dict = field(default_factory=dict)
    events: dict = field(default_factory=dict)
    phase_time: dict = field(default_factory=dict)
    tracking: dict = field(default_factory=dict)          # axis -> {'setpoint': ErrorStats, 'ideal': ErrorStats|None}
    moves: dict = field(default_factory=dict)             # axis -> list of axis_moves() dicts
    ideal_note: str = ''
    stows: list = field(default_factory=list)             # dicts: start, end, duration, level, reasons
    commanded_stows: list = field(default_factory=list)
    temperatures: dict = field(default_factory=dict)      # name -> {'max', 't_max', 'nan_samples'}
    irradiance: dict = field(default_factory=dict)
    links: dict = field(default_factory=dict)             # axis -> dict
    energy: dict = field(default_factory=dict)            # 'ideal_kwh', 'achieved_kwh', 'note'
    series: dict = field(default_factory=dict, repr=False)


def _find(topics, name: str) -> str | None:
    suffix = '/' + name
    if suffix in topics:
        return suffix
    for t in topics:
        if t.endswith(suffix):
            return t
    return None


def gap_limit(t: np.ndarray, floor: float = MAX_GAP_S) -> float:
    """Longest interval [s] bridged between samples: max(``floor``, 5 x the median spacing)
    (a recording at reduced rate, e.g. a fast simulation, is still integrated)."""
    if len(t) < 3:
        return floor
    return max(floor, 5.0 * float(np.median(np.diff(t))))


def step_durations(t: np.ndarray, v: np.ndarray, end: float, max_gap: float | None = None) -> dict:
    """Seconds spent at each value of a step function sampled at ``t`` (held up to
    ``max_gap`` [s], default :func:`gap_limit`)."""
    out: dict[int, float] = {}
    if len(t) == 0:
        return out
    max_gap = gap_limit(t) if max_gap is None else max_gap
    nxt = np.append(t[1:], end)
    d = np.clip(nxt - t, 0.0, max_gap)
    for val in np.unique(v):
        out[int(val)] = float(d[v == val].sum())
    return out


def intervals(t: np.ndarray, active: np.ndarray, end: float) -> list[tuple[int, int]]:
    """Index ranges [i, j) where ``active`` is true (j = len(t) when still active at the end)."""
    out = []
    i = 0
    n = len(t)
    while i < n:
        if active[i]:
            j = i
            while j < n and active[j]:
                j += 1
            out.append((i, j))
            i = j
        else:
            i += 1
    return out


def axis_moves(t: np.ndarray, setpoint: np.ndarray, measured: np.ndarray) -> list[dict]:
    """Deliberate moves of one axis, from its status samples (times [s], angles [rad]).

    A move starts where the setpoint changes faster than :data:`MOVE_RATE` (a jump of
    the setpoint: PRE_DAWN's slew from the sleeping position, a stow, a law's
    repositioning; sun tracking moves the setpoints at most ~0.004 deg/s) and ends at
    the first sample, after the setpoint has stopped jumping, where the axis is within
    :data:`SETTLE` of it, or :data:`MOVE_CAP` seconds after it started (an axis that
    never arrives is then judged as tracking, so a fault is never hidden). Returns
    dicts: i0, i1 (sample range [i0, i1)), start, end [s], duration [s], size (the
    angle travelled |measured(end) - measured(start)| [rad], NaN if unknown), settled (bool).
    """
    t = np.asarray(t, dtype=float)
    sp = np.asarray(setpoint, dtype=float)
    me = np.asarray(measured, dtype=float)
    n = t.size
    if n < 2:
        return []
    dt_ = np.diff(t)
    jump = np.abs(np.diff(sp)) > MOVE_RATE * np.maximum(dt_, 1e-3) + 1e-9
    off = ~(np.abs(me - sp) <= SETTLE)   # NaN counts as off
    moves = []
    k = 0
    starts = np.flatnonzero(jump) + 1    # sample i is the first at the new setpoint
    while k < starts.size:
        i0 = int(starts[k]) - 1
        i = i0 + 1
        last_jump = i
        while i < n and t[i] - t[i0] <= MOVE_CAP:
            if i < n - 1 and jump[i]:
                last_jump = i + 1
            elif i >= last_jump and not off[i]:
                break
            i += 1
        settled = i < n and not off[i] and t[i] - t[i0] <= MOVE_CAP
        i1 = i                               # samples [i0, i1) are the move
        end = float(t[i] if settled else t[i - 1])
        last = i if settled else i - 1
        moves.append({'i0': i0, 'i1': i1, 'start': float(t[i0]), 'end': end, 'duration': end - float(t[i0]),
                      'size': float(abs(me[last] - me[i0])), 'settled': bool(settled)})
        k = int(np.searchsorted(starts, i1 + 1, side='left'))
    return moves


def beam_irradiation(t: np.ndarray, g: np.ndarray, max_gap: float | None = None) -> float:
    """H = integral of G_b dt [kWh/m^2] by trapezoids over gaps <= ``max_gap`` [s]
    (default :func:`gap_limit`); NaN samples skipped."""
    ok = np.isfinite(g)
    t, g = t[ok], g[ok]
    if len(t) < 2:
        return 0.0
    max_gap = gap_limit(t) if max_gap is None else max_gap
    dtt = np.diff(t)
    area = 0.5 * (g[1:] + g[:-1]) * dtt
    return float(area[(dtt > 0) & (dtt <= max_gap)].sum() / 3.6e6)


def planner_config(path: str | None) -> dict:
    """The planner's parameter values: its defaults, overlaid with the ``/**`` and
    ``planner`` sections of a ROS params file (the site config) when given. The file
    is judged as ``sslfr up`` judges it (:func:`checked_params`, the nodes' own
    parameter tables): NodeSetError naming the file and each bad key."""
    from sslfr_planner.planner_params import PLANNER_PARAMS
    cfg = PLANNER_PARAMS.defaults()
    if path:
        flat = node_params(checked_params(load_nodeset(), path), 'planner')
        cfg.update(PLANNER_PARAMS.coerce({k: v for k, v in flat.items() if k in cfg}))
    return cfg


def _ideal(site: dict, t: np.ndarray, config: str | None = None):
    """Ideal axis commands at ``t`` from sslfr_planner.tracking_table, or (None, reason)."""
    try:
        from sslfr_planner.day_cycle import make_collector
        from sslfr_planner.tracking_table import evaluate
        from sslfr_planner.site import Site
    except ImportError:
        return None, 'ideal unavailable (sslfr_planner.tracking_table not installed)'
    if not site or not np.isfinite(site.get('latitude', np.nan)):
        return None, 'ideal unavailable (no site in the bag)'
    try:
        collector = make_collector(planner_config(config))
        s = Site.from_degrees(site['latitude'], site['longitude'], site.get('altitude', 0.0))
        table = evaluate(t, s, collector)
        return {a: np.asarray(getattr(table, a), dtype=float) for a in JOINTS}, \
            ('ideal = sslfr_planner.tracking_table.evaluate at the same instants, collector from '
             + (config or 'the planner defaults') + ', site from the bag')
    except Exception as exc:  # noqa: BLE001 - any failure of the optional reference is reported
        return None, f'ideal unavailable ({type(exc).__name__}: {exc})'


def analyse(reader: BagReader, config: str | None = None) -> DayReport:
    """Decode the report's topics from a bag and compute the figures (``config``: site
    params file for the ideal commands' collector)."""
    topics = reader.topics
    names = {k: _find(topics, k) for k in (
        'tracker/phase', 'safety/state', 'gps/fix', 'absorber/inlet_temperature',
        'absorber/outlet_temperature', 'irradiance/beam', 'joint_states',
        *(f'axes/{a}/status' for a in JOINTS))}
    have_status = any(names[f'axes/{a}/status'] for a in JOINTS)
    wanted = [t for k, t in names.items() if t and not (k == 'joint_states' and have_status)]
    rep = DayReport(bag=str(reader.path), start=to_sec(reader.start_ns), end=to_sec(reader.end_ns))
    by_topic = {t: k for k, t in names.items() if t}
    phase, safety, temps, beam, fix = Series(), Series(), {}, Series(), Series()
    status = {a: Series() for a in JOINTS}
    joints = {a: Series() for a in JOINTS}
    last_phase = None
    for raw in reader.messages(wanted):
        key = by_topic[raw.topic]
        if key == 'gps/fix' and len(fix.t) >= 10:
            continue  # the site needs only the first valid fixes: skip decoding the rest
        try:
            m = reader.decoder(raw.type)(raw.data)
        except BagError:
            raise
        except Exception as exc:  # noqa: BLE001 - decoder errors vary
            raise BagError(f'cannot decode a {raw.type} message on {raw.topic}: {exc}') from exc
        if key == 'tracker/phase':
            phase.add(message_time(m.header, raw.log_time), phase=int(m.phase), reason=str(m.reason))
            last_phase = m
        elif key == 'safety/state':
            safety.add(message_time(m.header, raw.log_time), level=int(m.level), reasons='; '.join(m.reasons))
        elif key.startswith('absorber/'):
            temps.setdefault(key.split('/')[1], Series()).add(message_time(m.header, raw.log_time),
                                                              v=float(m.temperature))
        elif key == 'irradiance/beam':
            beam.add(message_time(m.header, raw.log_time), g=float(m.beam), sat=bool(m.saturated))
        elif key == 'gps/fix':
            if len(fix.t) < 10 and int(m.status.status) >= 0:
                fix.add(message_time(m.header, raw.log_time), lat=m.latitude, lon=m.longitude, alt=m.altitude)
        elif key == 'joint_states':
            t = message_time(m.header, raw.log_time)
            for name, pos in zip(m.name, m.position):
                if name in joints:
                    joints[name].add(t, measured=float(pos))
        else:
            axis = key.split('/')[1]
            status[axis].add(message_time(m.header, raw.log_time), measured=float(m.measured),
                             setpoint=float(m.setpoint), commanded=float(m.commanded),
                             link=int(m.link_state), lost=int(m.frames_lost), bad=int(m.frames_bad),
                             faults=int(m.fault_bits))
    end = rep.end
    # -- site and sun events
    if last_phase is not None:
        rep.site = {'latitude': float(last_phase.latitude), 'longitude': float(last_phase.longitude),
                    'altitude': float(last_phase.altitude), 'source': str(last_phase.site_source)}
        if int(last_phase.day_type) == 0:
            rep.events = {k: to_sec(getattr(last_phase, k)) for k in ('sunrise', 'solar_noon', 'sunset')}
        else:
            rep.events = {'day_type': {1: 'polar day', 2: 'polar night'}.get(int(last_phase.day_type), '?'),
                          'solar_noon': to_sec(last_phase.solar_noon)}
    elif fix.t:
        rep.site = {'latitude': float(fix.v['lat'][0]), 'longitude': float(fix.v['lon'][0]),
                    'altitude': float(fix.v['alt'][0]), 'source': 'gps/fix'}
    # -- phases
    pt, pv = phase.arrays()
    if len(pt):
        rep.phase_time = {PHASE_NAMES.get(k, str(k)): v for k, v in
                          step_durations(pt, pv['phase'], end, max_gap=np.inf).items()}
        # (the planner publishes on change: a phase holds until the next message)
        for i, j in intervals(pt, pv['phase'] == 5, end):
            t1 = pt[j] if j < len(pt) else end
            rep.commanded_stows.append({'start': pt[i], 'end': t1, 'duration': t1 - pt[i],
                                        'reason': str(pv['reason'][i])})
    # -- safety stows
    st, sv = safety.arrays()
    if len(st):
        for i, j in intervals(st, sv['level'] >= 2, end):
            t1 = st[j] if j < len(st) else end
            reasons = []
            for r in sv['reasons'][i:j]:
                for part in str(r).split('; '):
                    if part and part not in reasons:
                        reasons.append(part)
            rep.stows.append({'start': st[i], 'end': t1, 'duration': t1 - st[i],
                              'level': LEVEL_NAMES.get(int(sv['level'][i:j].max()), '?'),
                              'reasons': reasons, 'ongoing': j >= len(st)})
    # -- tracking error
    ideal_cache = {}
    for axis in JOINTS:
        src = status[axis] if status[axis].t else None
        if src is None:
            continue
        t, v = src.arrays()
        mask = np.ones(len(t), dtype=bool)
        if len(pt):
            ph = np.asarray(pv['phase'])[np.clip(np.searchsorted(pt, t, side='right') - 1, 0, None)]
            mask = (ph == 2) & (t >= pt[0])
        moves = axis_moves(t, v['setpoint'], v['measured'])
        for mv in moves:   # tracking only: the deliberate moves are reported on their own
            mask[mv['i0']:mv['i1']] = False
        rep.moves[axis] = moves
        err = v['measured'] - v['setpoint']
        entry = {'setpoint': ErrorStats.of(err[mask]), 'ideal': None}
        ideal, note = ideal_cache.get(axis, (None, None))
        if axis not in ideal_cache:
            ideal, note = _ideal(rep.site, t, config)
            ideal_cache[axis] = (ideal, note)
        rep.ideal_note = note
        if ideal is not None:
            entry['ideal'] = ErrorStats.of((v['measured'] - ideal[axis])[mask])
            rep.series[f'ideal_{axis}'] = (t, ideal[axis])
        rep.tracking[axis] = entry
        rep.series[f'status_{axis}'] = (t, v)
        lk = v['link']
        down = step_durations(t, (lk != LinkState.LINK_UP).astype(int), end).get(1, 0.0)
        drops = int(np.sum((lk[1:] != LinkState.LINK_UP) & (lk[:-1] == LinkState.LINK_UP))) if len(lk) > 1 else 0
        rep.links[axis] = {'time_not_up': down, 'drops': drops,
                           'frames_lost': int(v['lost'].max() - v['lost'][0]) if len(t) else 0,
                           'frames_bad': int(v['bad'].max() - v['bad'][0]) if len(t) else 0,
                           'fault_samples': int(np.sum(v['faults'] != 0))}
    if not rep.tracking:
        for axis in JOINTS:
            if joints[axis].t:
                t, v = joints[axis].arrays()
                rep.series[f'joint_{axis}'] = (t, v)
        rep.ideal_note = rep.ideal_note or 'no axes/<axis>/status: tracking error not computed'
    # -- temperatures, irradiance
    for name, s in temps.items():
        t, v = s.arrays()
        x = v['v'].astype(float)
        ok = np.isfinite(x)
        rep.temperatures[name] = {'max': float(x[ok].max()) if ok.any() else float('nan'),
                                  't_max': float(t[ok][np.argmax(x[ok])]) if ok.any() else float('nan'),
                                  'nan_samples': int((~ok).sum())}
        rep.series[f'temp_{name}'] = (t, x)
    bt, bv = beam.arrays()
    if len(bt):
        g = bv['g'].astype(float)
        ok = np.isfinite(g)
        rep.irradiance = {'max': float(g[ok].max()) if ok.any() else float('nan'),
                          't_max': float(bt[ok][np.argmax(g[ok])]) if ok.any() else float('nan'),
                          'H_kWh_m2': beam_irradiation(bt, g), 'saturated': int(bv['sat'].sum())}
        rep.series['beam'] = (bt, g)
    rep.series['phase'] = (pt, pv.get('phase', np.zeros(0)))
    if len(bt) > 1:
        rep.energy = energy_estimate(rep.site, bt, bv['g'].astype(float),
                                     {a: status[a].arrays() for a in JOINTS if status[a].t}, config)
    return rep


def energy_estimate(site: dict, t: np.ndarray, beam: np.ndarray, measured: dict, config: str | None) -> dict:
    """Absorbed energy of the day [kWh], ideal vs achieved (seed 000 eqs. 18, 20, 25).

    ``beam`` [W/m^2] at ``t`` [s]; ``measured``: axis -> (t, {'measured': rad, ...}) from
    ``axes/<axis>/status``. The ideal angles and the sun come from
    :func:`sslfr_planner.tracking_table.evaluate`; an axis without status counts as ideal.
    """
    try:
        from sslfr_planner.analysis.optics import OpticalParameters
        from sslfr_planner.analysis.performance import day_energy
        from sslfr_planner.day_cycle import make_collector
        from sslfr_planner.tracking_table import evaluate
        from sslfr_planner.site import Site
    except ImportError:
        return {'note': 'energy estimate unavailable (sslfr_planner not installed)'}
    if not site or not np.isfinite(site.get('latitude', np.nan)):
        return {'note': 'energy estimate unavailable (no site in the bag)'}
    ok = np.isfinite(beam)
    t, beam = t[ok], np.clip(beam[ok], 0.0, None)
    if t.size < 2:
        return {'note': 'energy estimate unavailable (no valid beam samples)'}
    c = make_collector(planner_config(config))
    table = evaluate(t, Site.from_degrees(site['latitude'], site['longitude'], site.get('altitude', 0.0)), c)
    try:
        params = OpticalParameters(geometry=c.geometry)
    except ValueError as exc:
        return {'note': f'energy estimate unavailable ({exc})'}
    ideal = {a: np.asarray(getattr(table, a), dtype=float) for a in JOINTS}
    held = dict(ideal)
    for axis, (ta, va) in measured.items():
        good = np.isfinite(va['measured'])
        if good.sum() >= 2:
            held[axis] = np.interp(t, ta[good], va['measured'][good])
    args = (t, beam, table.zenith, table.azimuth)
    e_ideal = day_energy(*args, ideal['mirrors'], ideal['mobile_structure'], ideal['secondary_reflector'],
                         params, c.azimuth) / 1000.0
    e_held = day_energy(*args, held['mirrors'], held['mobile_structure'], held['secondary_reflector'],
                        params, c.azimuth) / 1000.0
    missing = [a for a in JOINTS if a not in measured]
    note = 'seed 000 optical model on the 3-D ray trace (docs/optics.md), recorded beam irradiance'
    if missing:
        note += '; no status for ' + ', '.join(missing) + ' (taken as ideal)'
    return {'ideal_kwh': e_ideal, 'achieved_kwh': e_held, 'note': note}


def render_text(rep: DayReport) -> str:
    """The one-minute summary."""
    day = utc(rep.start, '%Y-%m-%d') if rep.end else '-'
    lines = [f'SSLFR day report: {rep.bag}',
             f'date (UTC)      {day}, recorded {utc(rep.start)}..{utc(rep.end)} '
             f'({(rep.end - rep.start) / 3600:.2f} h)']
    if rep.site:
        s = rep.site
        lines.append(f'site            {s["latitude"]:.5f} deg, {s["longitude"]:.5f} deg, '
                     f'{s["altitude"]:.0f} m ({s["source"]})')
    else:
        lines.append('site            unknown (no tracker/phase, no gps/fix)')
    if 'sunrise' in rep.events:
        e = rep.events
        lines.append(f'sun             sunrise {utc(e["sunrise"])}, noon {utc(e["solar_noon"])}, '
                     f'sunset {utc(e["sunset"])} UTC (day length {(e["sunset"] - e["sunrise"]) / 3600:.2f} h)')
    elif rep.events:
        lines.append(f'sun             {rep.events["day_type"]}, noon {utc(rep.events["solar_noon"])} UTC')
    else:
        lines.append('sun             no tracker/phase in the bag')
    if rep.phase_time:
        lines.append('time in phase   ' + ', '.join(f'{k} {v / 3600:.2f} h'
                                                 for k, v in sorted(rep.phase_time.items(),
                                                                    key=lambda kv: -kv[1])))
    lines.append('tracking error (while tracking: phase TRACKING, outside moves; |error|)')
    if not rep.tracking:
        lines.append('  no axes/<axis>/status in the bag')
    for axis, e in rep.tracking.items():
        lines.append(f'  {axis:<20} vs setpoint  {e["setpoint"].text()}')
        if e['ideal'] is not None:
            lines.append(f'  {"":<20} vs ideal     {e["ideal"].text()}')
    if rep.moves:
        lines.append('moves (setpoint jumps: pre-dawn slew, stows, repositioning)')
    for axis, moves in rep.moves.items():
        if not moves:
            lines.append(f'  {axis:<20} none')
            continue
        big = max(moves, key=lambda m: m['size'] if np.isfinite(m['size']) else -1.0)
        unsettled = sum(not m['settled'] for m in moves)
        lines.append(f'  {axis:<20} {len(moves)} move(s), {sum(m["duration"] for m in moves):.0f} s in all; largest '
                     f'{math.degrees(big["size"]):.2f} deg in {big["duration"]:.0f} s at {utc(big["start"])}'
                     + (f'; {unsettled} not settled within {MOVE_CAP:.0f} s' if unsettled else ''))
    if rep.ideal_note:
        lines.append(f'  ({rep.ideal_note})')
    lines.append(f'stow events     {len(rep.stows)} safety stow(s), {len(rep.commanded_stows)} commanded')
    for s in rep.stows:
        lines.append(f'  {utc(s["start"])}..{utc(s["end"])} {s["level"]:<5} {s["duration"]:8.0f} s'
                     f'{" (ongoing at end)" if s["ongoing"] else ""}: {"; ".join(s["reasons"]) or "-"}')
    for s in rep.commanded_stows:
        lines.append(f'  {utc(s["start"])}..{utc(s["end"])} STOW phase {s["duration"]:8.0f} s: {s["reason"] or "-"}')
    for name, tmp in rep.temperatures.items():
        lines.append(f'temperature     {name}: max {tmp["max"]:.1f} degC at {utc(tmp["t_max"]) if np.isfinite(tmp["t_max"]) else "-"}'
                     + (f', {tmp["nan_samples"]} invalid samples' if tmp['nan_samples'] else ''))
    if rep.irradiance:
        ir = rep.irradiance
        lines.append(f'irradiance      beam max {ir["max"]:.0f} W/m2 at {utc(ir["t_max"]) if np.isfinite(ir["t_max"]) else "-"}, '
                     f'day beam irradiation {ir["H_kWh_m2"]:.2f} kWh/m2'
                     + (f', {ir["saturated"]} saturated samples' if ir['saturated'] else ''))
    else:
        lines.append('irradiance      no irradiance/beam in the bag')
    en = rep.energy
    if 'ideal_kwh' in en:
        share = 100.0 * en['achieved_kwh'] / en['ideal_kwh'] if en['ideal_kwh'] > 0 else float('nan')
        lines.append(f'absorbed energy {en["achieved_kwh"]:.3f} kWh achieved vs {en["ideal_kwh"]:.3f} kWh with ideal '
                     f'angles ({share:.1f} %) ({en["note"]})')
    elif en:
        lines.append(f'absorbed energy {en["note"]}')
    for axis, lk in rep.links.items():
        lines.append(f'link            {axis}: {lk["drops"]} drop(s), not up {lk["time_not_up"]:.0f} s, '
                     f'{lk["frames_lost"]} frames lost, {lk["frames_bad"]} bad, '
                     f'{lk["fault_samples"]} samples with fault bits')
    return '\n'.join(lines)


def _decimate(t, y, n=20000):
    if len(t) <= n:
        return t, y
    step = int(np.ceil(len(t) / n))
    return t[::step], y[::step]


def make_plots(rep: DayReport, out: Path) -> list[Path]:
    """PNG plots: axis angles, tracking error, temperatures, irradiance."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    t0 = dt.datetime.fromtimestamp(rep.start, tz=dt.timezone.utc).replace(
        hour=0, minute=0, second=0, microsecond=0).timestamp()

    def hours(t):
        return (np.asarray(t) - t0) / 3600.0

    files = []

    def save(fig, name):
        path = out / name
        fig.tight_layout()
        fig.savefig(path, dpi=90)
        plt.close(fig)
        files.append(path)

    axes_present = [a for a in JOINTS if f'status_{a}' in rep.series or f'joint_{a}' in rep.series]
    if axes_present:
        fig, axs = plt.subplots(len(axes_present), 1, figsize=(10, 2.6 * len(axes_present)),
                                sharex=True, squeeze=False)
        for ax, a in zip(axs[:, 0], axes_present):
            if f'status_{a}' in rep.series:
                t, v = rep.series[f'status_{a}']
                ax.plot(*_decimate(hours(t), np.degrees(v['setpoint'])), label='setpoint', lw=1)
                ax.plot(*_decimate(hours(t), np.degrees(v['measured'])), label='measured', lw=1, ls='--')
            else:
                t, v = rep.series[f'joint_{a}']
                ax.plot(*_decimate(hours(t), np.degrees(v['measured'])), label='joint_states', lw=1)
            if f'ideal_{a}' in rep.series:
                t, y = rep.series[f'ideal_{a}']
                ax.plot(*_decimate(hours(t), np.degrees(y)), label='ideal', lw=0.8, alpha=0.7)
            ax.set_ylabel(f'{a} [deg]')
            ax.grid(alpha=0.3)
            ax.legend(loc='best', fontsize=8)
        axs[-1, 0].set_xlabel('hour of the day [UTC]')
        save(fig, 'angles.png')
    if rep.tracking:
        fig, ax = plt.subplots(figsize=(10, 3.5))
        for a in rep.tracking:
            t, v = rep.series[f'status_{a}']
            err = 1e3 * (v['measured'] - v['setpoint'])
            for mv in rep.moves.get(a, []):
                err[mv['i0']:mv['i1']] = np.nan   # moves are not tracking error
            ax.plot(*_decimate(hours(t), err), label=a, lw=0.8)
        ax.set_ylabel('measured - setpoint, outside moves [mrad]')
        ax.set_xlabel('hour of the day [UTC]')
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        save(fig, 'tracking_error.png')
    temps = [k for k in rep.series if k.startswith('temp_')]
    if temps:
        fig, ax = plt.subplots(figsize=(10, 3.5))
        for k in temps:
            t, y = rep.series[k]
            ax.plot(*_decimate(hours(t), y), label=k[5:], lw=1)
        ax.set_ylabel('temperature [degC]')
        ax.set_xlabel('hour of the day [UTC]')
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        save(fig, 'temperatures.png')
    if 'beam' in rep.series:
        fig, ax = plt.subplots(figsize=(10, 3.5))
        t, y = rep.series['beam']
        ax.plot(*_decimate(hours(t), y), lw=1)
        ax.set_ylabel('beam irradiance [W/m$^2$]')
        ax.set_xlabel('hour of the day [UTC]')
        ax.set_title(f'day beam irradiation {rep.irradiance["H_kWh_m2"]:.2f} kWh/m$^2$')
        ax.grid(alpha=0.3)
        save(fig, 'irradiance.png')
    return files


def render_markdown(rep: DayReport, plots: list[Path]) -> str:
    """report.md: the text summary plus the plots."""
    md = [f'# SSLFR day report {utc(rep.start, "%Y-%m-%d")}', '', '```', render_text(rep), '```', '']
    for p in plots:
        md += [f'## {p.stem.replace("_", " ")}', '', f'![{p.stem}]({p.name})', '']
    return '\n'.join(md)


def main(argv: list[str]) -> int:
    ap = OneLineParser(prog='sslfr report', description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('bag', help='bag directory or .mcap file')
    ap.add_argument('--out', default=None, type=output_dir,
                    help='directory for report.md and PNGs (default <bag>/report)')
    ap.add_argument('--no-plots', action='store_true', help='text only')
    ap.add_argument('--config', default=None,
                    help='site params file (collector geometry for the ideal commands)')
    try:
        ns = ap.parse_args(argv)
        planner_config(ns.config)           # a bad site config: refused before any work
    except CliError as exc:
        print(f'sslfr report: error: {exc}', file=sys.stderr)
        return 2
    except NodeSetError as exc:
        print(f'sslfr report: error: --config {ns.config}: '
              + '; '.join(line.strip() for line in str(exc).splitlines()[1:] or [str(exc)]), file=sys.stderr)
        return 2
    try:
        reader = BagReader(ns.bag)
    except BagError as exc:  # missing, damaged or wrong-kind bag: bad input
        print(f'sslfr report: error: bag {ns.bag}: {exc}', file=sys.stderr)
        return 2
    try:
        rep = analyse(reader, ns.config)
    except (BagError, OSError) as exc:
        print(f'sslfr report: {exc}', file=sys.stderr)
        return 1
    print(render_text(rep))
    if not ns.no_plots:
        out = Path(ns.out) if ns.out else (reader.directory / 'report')
        out.mkdir(parents=True, exist_ok=True)
        plots = make_plots(rep, out)
        (out / 'report.md').write_text(render_markdown(rep, plots), encoding='utf-8')
        print(f'report: {out / "report.md"} ({len(plots)} plots)')
    return 0
