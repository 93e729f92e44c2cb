"""The figures of the day report (``sslfr report``, :mod:`.report_cli`), computed from a
recorded day decoded once (:class:`~.day.Day`) for the run's own collector (the
movements its description names, :func:`.day.run_description`; without one, the axes
recorded): time in each phase, per-axis tracking
error while tracking (vs the setpoint and vs the run's ideal reference, outside the
axis' deliberate moves: :func:`axis_moves`), every mirror line's error against its
exact angle (:func:`line_tracking`), moves, safety and commanded stows,
temperatures, irradiance and irradiation, link faults, the absorbed-energy estimate
(:mod:`.report_energy`), each axis' time above the accuracy alarm's thresholds (the
driver's own filter, :class:`sslfr_common.accuracy.AccuracyAlarm`, replayed on the
recorded status and phase, thresholds from the ``<axis>_driver`` sections of the site
config) and the day's timeline: phase and safety-level changes beside the nodes'
warnings and errors (``/rosout`` lines of level WARN and above, repeats collapsed).
Pure (no rclpy); plain data for the text, plots and tests.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sslfr_common import accuracy as accuracy_mod
from sslfr_common.accuracy import MOVE_CAP, MOVE_RATE, SETTLE  # noqa: F401 - one definition (the alarm's)
from sslfr_common.contract import JOINTS, LEVEL_NAMES, MIRRORS, PHASE_NAMES, TRACKER_TRAJECTORY, LinkState

from .day import TOPICS, Day, planner_config, read_day, reference, run_description
from .report_energy import energy_estimate
from .report_thermal import thermal_of

MAX_GAP_S = 120.0
#: rcl_interfaces/msg/Log levels: the timeline lists WARN and above
LOG_LEVELS = {10: 'DEBUG', 20: 'INFO', 30: 'WARN', 40: 'ERROR', 50: 'FATAL'}
LOG_WARN = 30


#: the topics the report reads (not the trajectories, not the diagnostics)
REPORT_TOPICS = tuple(k for k in TOPICS if k != TRACKER_TRAJECTORY.name)

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
    energy: dict = field(default_factory=dict)            # 'ideal_kwh', 'law_kwh', 'achieved_kwh', 'note'
    collector: str = ''                                   # the collector description's name ('' without one)
    joints: tuple = ()                                    # the movements reported
    lines: dict = field(default_factory=dict)             # line_tracking() or {'note': why not}
    thermal: dict = field(default_factory=dict)           # report_thermal.thermal_of (a flow meter only)
    accuracy: dict = field(default_factory=dict)          # axis -> accuracy_of() dict
    timeline: list = field(default_factory=list)          # (t, kind, text, repeats, last_t), time order
    log_counts: dict = field(default_factory=dict)        # (level name, node) -> lines
    has_rosout: bool = False                              # the bag holds /rosout
    series: dict = field(default_factory=dict, repr=False)



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
    repositioning; sun tracking moves the setpoints at most ~0.004 deg/s), or at the
    first sample when the axis is not within :data:`SETTLE` of its setpoint there (a
    recording that starts with the axis elsewhere: a run started in daytime from the
    sleeping position), and ends at
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
    if off[0] and (starts.size == 0 or starts[0] != 1):
        starts = np.concatenate([[1], starts])   # the recording starts mid-move
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


def _ideal(day: Day, config: str | None):
    """The ideal reference of the day's run, or (None, reason)."""
    site = day.site
    if not site or not np.isfinite(site.get('latitude', np.nan)):
        return None, 'ideal unavailable (no site in the bag)'
    try:
        ref = reference(config, site['latitude'], site['longitude'], site.get('altitude', 0.0))
    except ImportError:
        return None, 'ideal unavailable (sslfr_planner.tracking_table not installed)'
    except Exception as exc:  # noqa: BLE001 - any failure of the optional reference is reported
        return None, f'ideal unavailable ({type(exc).__name__}: {exc})'
    desc = ref.description
    return ref, ('ideal = sslfr_planner.tracking_table.evaluate at the same instants, collector and site '
                 'parameters from ' + (str(config) if config else 'the planner defaults')
                 + (f', collector description {desc.name} (its laws)' if desc is not None else '')
                 + ', site from the bag')


def collector_joints(day: Day, config: str | None) -> tuple[tuple[str, ...], str, str]:
    """The movements to report: the run's collector description's (its name), else the
    axes the bag recorded; and a note when the description cannot be read."""
    try:
        desc = run_description(config)
    except ImportError:
        desc = None
    except Exception as exc:  # noqa: BLE001 - a broken description is reported, the recorded axes used
        recorded = tuple(a for a in JOINTS if len(day.axes.get(a, ())) or a in day.joints)
        return recorded, '', f'collector description unavailable ({type(exc).__name__}: {exc})'
    if desc is not None:
        return desc.joints, desc.name, ''
    return tuple(a for a in JOINTS if len(day.axes.get(a, ())) or a in day.joints), '', ''


def line_tracking(desc, t: np.ndarray, zenith, azimuth, measured, commanded) -> dict:
    """Every mirror line's error against its exact angle (seed 004 eqs. 3-4), rows horizontal.

    ``t`` [s] the samples judged (tracking, outside moves), the sun's ``zenith`` and
    ``azimuth`` [rad] there, the drive's ``measured`` angle and the law's ``commanded``
    drive [rad]. Each line rides on the drive at the law's offset
    (:func:`sslfr_planner.prototype.held_lines`). Returns 'lines': per line (1-based,
    east to west) 'x' [m], 'held' (:class:`ErrorStats` of held - exact), 'law_max' (the
    law's own largest error [rad]) and 'within' (share of the samples with |theta_T| <=
    80 deg within seed 004's positioning budget at that instant's theta_T,
    :func:`sslfr_planner.mirror_laws.positioning_budget`; NaN when none); 'budget' (the
    two budgets [rad]); 'samples'; 'judged' (the samples with a budget); 't' and 'errors'
    (samples x lines [rad]).
    """
    from sslfr_planner import mirror_laws, raytrace
    from sslfr_planner.prototype import line_errors, line_positions

    theta_t = raytrace.transversal_angle(raytrace.sun_vector(zenith, azimuth, desc.optics.azimuth))
    held = line_errors(desc, theta_t, measured)
    law = line_errors(desc, theta_t, commanded)
    budget = mirror_laws.positioning_budget(theta_t)
    judged = np.isfinite(budget)                 # |theta_T| <= 80 deg: where the seed states one
    within = (np.mean(np.abs(held[judged]) <= budget[judged][:, None], axis=0) if judged.any()
              else np.full(held.shape[-1], np.nan))
    lines = [{'line': i + 1, 'x': float(x), 'held': ErrorStats.of(held[:, i]),
              'law_max': float(np.max(np.abs(law[:, i]))) if len(t) else float('nan'), 'within': float(within[i])}
             for i, x in enumerate(line_positions(desc))]
    return {'lines': lines, 'budget': mirror_laws.POSITIONING_BUDGET, 'samples': int(len(t)),
            'judged': int(judged.sum()), 't': np.asarray(t, dtype=float), 'errors': held}


def accuracy_config(axis: str, config: str | None) -> accuracy_mod.AccuracyConfig:
    """The accuracy alarm's configuration of ``axis`` as the node set gives its driver:
    the driver's defaults, the mirrors' loss table of the run's collector at its site
    (:func:`sslfr_bringup.collector_set.loss_table_param`), overlaid with the
    ``<axis>_driver`` section of a site params file (judged as ``sslfr up`` does)."""
    from sslfr_bringup import collector_set, nodeset
    from sslfr_planner import description as description_mod
    p = {spec.name: spec.default for spec in accuracy_mod.PARAM_SPECS}
    if axis == MIRRORS:
        desc = run_description(config) or description_mod.load(
            description_mod.resolve(nodeset.load().collector, nodeset.config_dir()))
        p['accuracy.loss_table'] = collector_set.loss_table_param(desc, planner_config(config))
    if config:
        flat = nodeset.node_params(nodeset.checked_params(nodeset.load(), nodeset.resolve_config(config)),
                                   f'{axis}_driver')
        p.update({k: (list(v) if isinstance(v, (list, tuple)) else float(v)) for k, v in flat.items() if k in p})
    return accuracy_mod.AccuracyConfig.from_params(p)


def accuracy_of(axis: str, t: np.ndarray, v: dict, phases, config: str | None = None) -> dict:
    """The driver's accuracy alarm replayed on the recorded status samples of ``axis``
    (times [s], the status' state / setpoint / measured [rad], the planner's phase in
    force at each sample (-1: none before it)): time [s] at or above each level, time
    judged (tracking), the largest filtered error [rad] and the level changes
    [(t, level, line)]."""
    alarm = accuracy_mod.AccuracyAlarm(axis, accuracy_config(axis, config))
    changes = []
    for ti, state, phase, sp, me in zip(t, v['state'], phases, v['setpoint'], v['measured']):
        change = alarm.sample(float(ti), accuracy_mod.tracking(state, int(phase)), float(sp), float(me))
        if change:
            changes.append((float(ti), *change))
    c = alarm.cfg
    return {'warn_s': alarm.time_above[accuracy_mod.WARN], 'error_s': alarm.time_above[accuracy_mod.ERROR],
            'judged_s': alarm.judged_time, 'peak': alarm.peak, 'warn': c.warn, 'error': c.error,
            'window': c.window, 'loss_table': c.loss_table, 'changes': changes}


def timeline(pt, pv, st, sv, logs) -> tuple[list, dict]:
    """The day's events in time order: phase changes, safety-level changes (with their
    reasons) and the nodes' log lines of level WARN and above (``logs``: (t [s], level,
    node, text)). A line repeating the previous line of the same node and level is
    counted on it (repeats, last time). Returns (entries (t, kind, text, repeats,
    last_t), counts {(level name, node): lines})."""
    out, counts = [], {}
    for i in range(len(pt)):
        if i == 0 or pv['phase'][i] != pv['phase'][i - 1]:
            reason = str(pv['reason'][i])
            out.append([float(pt[i]), 'phase', PHASE_NAMES.get(int(pv['phase'][i]), '?')
                        + (f' ({reason})' if reason else ''), 1, float(pt[i])])
    for i in range(len(st)):
        if i == 0 or sv['level'][i] != sv['level'][i - 1]:
            reasons = '; '.join(sv['reasons'][i])
            out.append([float(st[i]), 'safety', LEVEL_NAMES.get(int(sv['level'][i]), '?')
                        + (f': {reasons}' if reasons else ''), 1, float(st[i])])
    last: dict = {}
    for t, level, node, text in sorted(logs, key=lambda x: x[0]):
        name = LOG_LEVELS.get(level, str(level))
        counts[(name, node)] = counts.get((name, node), 0) + 1
        prev = last.get((level, node))
        if prev is not None and prev[2] == f'{node}: {text}':
            prev[3] += 1
            prev[4] = t
            continue
        entry = [t, name, f'{node}: {text}', 1, t]
        last[(level, node)] = entry
        out.append(entry)
    out.sort(key=lambda e: e[0])
    return [tuple(e) for e in out], counts


def analyse(source, config: str | None = None) -> DayReport:
    """The report's figures of a recorded day: ``source`` a :class:`~.day.Day`, a
    :class:`BagReader` or a bag path (decoded once, :func:`~.day.read_day`); ``config``
    the run's site config (collector and site parameters of the ideal reference; None:
    the planner's defaults)."""
    day = source if isinstance(source, Day) else read_day(source, topics=REPORT_TOPICS)
    rep = DayReport(bag=day.bag, start=day.start, end=day.end)
    end = rep.end
    # -- site and sun events
    rep.site = day.site
    if len(day.phase):
        if int(day.phase['day_type'][-1]) == 0:
            rep.events = {k: float(day.phase[k][-1]) for k in ('sunrise', 'solar_noon', 'sunset')}
        else:
            rep.events = {'day_type': {1: 'polar day', 2: 'polar night'}.get(int(day.phase['day_type'][-1]), '?'),
                          'solar_noon': float(day.phase['solar_noon'][-1])}
    # -- phases
    pt, pv = day.phase.t, day.phase.cols
    if len(pt):
        rep.phase_time = {PHASE_NAMES.get(k, str(k)): v for k, v in
                          step_durations(pt, pv['phase'], end, max_gap=np.inf).items()}
        # (the planner publishes on change: a phase holds until the next message)
        for i, j in intervals(pt, pv['phase'] == 5, end):
            t1 = pt[j] if j < len(pt) else end
            rep.commanded_stows.append({'start': pt[i], 'end': t1, 'duration': t1 - pt[i],
                                        'reason': str(pv['reason'][i])})
    # -- safety stows
    st, sv = day.safety.t, day.safety.cols
    if len(st):
        for i, j in intervals(st, sv['level'] >= 2, end):
            t1 = st[j] if j < len(st) else end
            reasons = []
            for r in sv['reasons'][i:j]:
                for part in '; '.join(r).split('; '):
                    if part and part not in reasons:
                        reasons.append(part)
            rep.stows.append({'start': st[i], 'end': t1, 'duration': t1 - st[i],
                              'level': LEVEL_NAMES.get(int(sv['level'][i:j].max()), '?'),
                              'reasons': reasons, 'ongoing': j >= len(st)})
    # -- tracking error, for the collector's own movements
    joints, rep.collector, desc_note = collector_joints(day, config)
    rep.joints = joints
    ref = note = None
    for axis in joints:
        s = day.axes[axis]
        if not len(s):
            continue
        t, v = s.t, s.cols
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
        if note is None:
            ref, note = _ideal(day, config)
        rep.ideal_note = note
        if ref is not None:
            try:
                ideal = ref.angles(t)[axis]
            except Exception as exc:  # noqa: BLE001 - any failure of the optional reference is reported
                ref, note = None, f'ideal unavailable ({type(exc).__name__}: {exc})'
                rep.ideal_note = note
            else:
                entry['ideal'] = ErrorStats.of((v['measured'] - ideal)[mask])
                rep.series[f'ideal_{axis}'] = (t, ideal)
                if axis == MIRRORS:
                    rep.lines = _lines(ref, t[mask], v['measured'][mask], ideal[mask])
        rep.tracking[axis] = entry
        rep.series[f'status_{axis}'] = (t, v)
        lk = v['link_state']
        down = step_durations(t, (lk != LinkState.LINK_UP).astype(int), end).get(1, 0.0)
        drops = int(np.sum((lk[1:] != LinkState.LINK_UP) & (lk[:-1] == LinkState.LINK_UP))) if len(lk) > 1 else 0
        rep.links[axis] = {'time_not_up': down, 'drops': drops,
                           'frames_lost': int(v['frames_lost'].max() - v['frames_lost'][0]) if len(t) else 0,
                           'frames_bad': int(v['frames_bad'].max() - v['frames_bad'][0]) if len(t) else 0,
                           'fault_samples': int(np.sum(v['fault_bits'] != 0))}
        phases = np.asarray(pv['phase'])[np.clip(np.searchsorted(pt, t, side='right') - 1, 0, None)] \
            if len(pt) else np.full(len(t), -1)
        rep.accuracy[axis] = accuracy_of(axis, t, v, phases, config)
    if not rep.tracking:
        for axis, s in day.joints.items():
            if axis in joints:
                rep.series[f'joint_{axis}'] = (s.t, s.cols)
        rep.ideal_note = rep.ideal_note or 'no axes/<axis>/status: tracking error not computed'
    if desc_note:
        rep.ideal_note = f'{rep.ideal_note}; {desc_note}' if rep.ideal_note else desc_note
    # -- temperatures, irradiance
    for name, s in (('inlet_temperature', day.inlet), ('outlet_temperature', day.outlet)):
        if not len(s):
            continue
        t, x = s.t, s['value'].astype(float)
        ok = np.isfinite(x)
        rep.temperatures[name] = {'max': float(x[ok].max()) if ok.any() else float('nan'),
                                  't_max': float(t[ok][np.argmax(x[ok])]) if ok.any() else float('nan'),
                                  'nan_samples': int((~ok).sum())}
        rep.series[f'temp_{name}'] = (t, x)
    bt = day.beam.t
    if len(bt):
        g = day.beam['g'].astype(float)
        ok = np.isfinite(g)
        rep.irradiance = {'max': float(g[ok].max()) if ok.any() else float('nan'),
                          't_max': float(bt[ok][np.argmax(g[ok])]) if ok.any() else float('nan'),
                          'H_kWh_m2': beam_irradiation(bt, g), 'saturated': int(np.sum(day.beam['saturated']))}
        rep.series['beam'] = (bt, g)
    rep.series['phase'] = (pt, pv['phase'])
    lg = day.logs
    logs = [(float(t), int(lvl), str(n), str(m)) for t, lvl, n, m in zip(lg.t, lg['level'], lg['name'], lg['msg'])
            if int(lvl) >= LOG_WARN] if len(lg) else []
    rep.timeline, rep.log_counts = timeline(pt, pv, st, sv, logs)
    rep.has_rosout = day.has_rosout
    rep.thermal = thermal_of(day, gap_limit(day.thermal.t)) if len(day.thermal) else {}
    if len(bt) > 1:
        try:
            rep.energy = energy_estimate(rep.site, bt, day.beam['g'].astype(float),
                                         {a: (s.t, s.cols) for a, s in day.axes.items() if len(s) and a in joints},
                                         config, ref=ref)
        except Exception as exc:  # noqa: BLE001 - any failure of the optional estimate is reported
            rep.energy = {'note': f'energy estimate unavailable ({type(exc).__name__}: {exc})'}
    return rep


def _lines(ref, t: np.ndarray, measured: np.ndarray, commanded: np.ndarray) -> dict:
    """:func:`line_tracking` of the run's collector, or {'note': why not}."""
    desc = ref.description
    if desc is None:
        return {'note': 'no collector description: the lines\' offsets are unknown'}
    if desc.longitudinal_law != 'horizontal':
        return {'note': 'the rows tilt (longitudinal movements): seed 004 eqs. 3-4 hold for horizontal rows; '
                        'the mirrors\' error is the drive\'s (vs ideal above)'}
    if not len(t):
        return {'note': 'no tracking samples'}
    try:
        table = ref(t)
        return line_tracking(desc, t, table.zenith, table.azimuth, measured, commanded)
    except Exception as exc:  # noqa: BLE001 - an optional figure: its failure is reported, not fatal
        return {'note': f'unavailable ({type(exc).__name__}: {exc})'}
