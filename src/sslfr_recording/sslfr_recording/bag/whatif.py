"""What-if comparison core (pure, no rclpy): recorded decisions vs a fresh run's.

A what-if replay feeds a recorded day's sensor inputs to a freshly started planner
and safety supervisor and records what they decide. This module extracts the
decisions from two bags and compares them:

- ``tracker/phase`` (TrackerPhase.phase) and ``safety/state`` (SafetyState.level) as
  step functions of time, sampled on a common grid over the overlapping interval:
  agreement fraction [-], the intervals where they differ, and each recorded
  transition matched with the same transition in the new run (time offset [s]);
- ``tracker/trajectory`` (JointTrajectory): the setpoint of each joint at time t
  is the latest trajectory received before t, linearly interpolated between its
  points (``header.stamp + time_from_start``), held at the ends; RMS / max difference
  [rad] between the two runs on the grid.

Times are float seconds since the Unix epoch (UTC) from ``header.stamp`` (ROS time,
so sim-time runs line up with the recorded day); the bag log time is used when a
stamp is zero.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sslfr_common.contract import JOINTS, LEVEL_NAMES, PHASE_NAMES, SAFETY_STATE, TRACKER_PHASE, TRACKER_TRAJECTORY

from ..day import Trajectory, read_day

#: the topics that hold a run's decisions
DECISION_TOPICS = (TRACKER_PHASE.name, SAFETY_STATE.name, TRACKER_TRAJECTORY.name)


@dataclass
class Decisions:
    """Decision series of one run."""

    phase_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    phase: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    phase_reason: list[str] = field(default_factory=list)
    safety_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    safety: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    safety_reasons: list[list[str]] = field(default_factory=list)
    trajectories: list[Trajectory] = field(default_factory=list)


def extract_decisions(reader, start_ns: int | None = None, end_ns: int | None = None) -> Decisions:
    """The decisions of a run: tracker/phase, safety/state and tracker/trajectory of a
    bag (any namespace), read through :func:`~sslfr_recording.day.read_day`."""
    day = read_day(reader, start_ns, end_ns, topics=DECISION_TOPICS)
    return Decisions(phase_t=day.phase.t, phase=np.asarray(day.phase['phase'], dtype=int),
                     phase_reason=list(day.phase['reason']), safety_t=day.safety.t,
                     safety=np.asarray(day.safety['level'], dtype=int),
                     safety_reasons=list(day.safety['reasons']), trajectories=day.trajectories)


def step_values(t: np.ndarray, v: np.ndarray, tq: np.ndarray, missing: int = -1) -> np.ndarray:
    """Value of the step function (t, v) at times ``tq`` (last sample at or before; ``missing`` before the first)."""
    idx = np.searchsorted(t, tq, side='right') - 1
    out = np.where(idx >= 0, v[np.clip(idx, 0, max(len(v) - 1, 0))] if len(v) else missing, missing)
    return out.astype(int)


def transitions(t: np.ndarray, v: np.ndarray) -> list[tuple[float, int, int]]:
    """(time [s], from, to) for every change of value."""
    if len(v) < 2:
        return []
    ch = np.nonzero(np.diff(v) != 0)[0] + 1
    return [(float(t[i]), int(v[i - 1]), int(v[i])) for i in ch]


@dataclass
class StepComparison:
    """Comparison of two step functions (phase or safety level)."""

    name: str
    agreement: float                 # fraction of grid samples equal [-]
    samples: int
    differences: list[tuple[float, float, int, int]]  # (t0, t1, recorded, new)
    matched: list[tuple[float, int, int, float]]      # (t recorded, from, to, dt new - rec [s])
    unmatched_recorded: list[tuple[float, int, int]]
    unmatched_new: list[tuple[float, int, int]]
    reasons: dict = field(default_factory=dict)   # ('rec'|'new', t) -> reason text


def _reason_map(tag, t, reasons, trans) -> dict:
    out = {}
    if not reasons:
        return out
    t = np.asarray(t)
    for tt, _, _ in trans:
        i = int(np.searchsorted(t, tt, side='left'))
        if i < len(reasons):
            r = reasons[i]
            out[(tag, tt)] = '; '.join(r) if isinstance(r, list) else str(r)
    return out


def compare_steps(name: str, rec_t, rec_v, new_t, new_v, grid: np.ndarray,
                  tolerance_s: float = 300.0, rec_reasons=None, new_reasons=None) -> StepComparison:
    """Compare two step functions on ``grid`` [s] and match their transitions.

    A recorded transition a->b is matched with the nearest new transition a->b no
    farther than ``tolerance_s``; each new transition is used once.
    """
    a = step_values(np.asarray(rec_t), np.asarray(rec_v), grid)
    b = step_values(np.asarray(new_t), np.asarray(new_v), grid)
    valid = (a >= 0) & (b >= 0)
    agree = float(np.mean(a[valid] == b[valid])) if valid.any() else float('nan')
    diffs = []
    bad = valid & (a != b)
    i = 0
    n = len(grid)
    while i < n:
        if bad[i]:
            j = i
            while j + 1 < n and bad[j + 1] and a[j + 1] == a[i] and b[j + 1] == b[i]:
                j += 1
            diffs.append((float(grid[i]), float(grid[j]), int(a[i]), int(b[i])))
            i = j + 1
        else:
            i += 1
    lo, hi = (grid[0], grid[-1]) if len(grid) else (0.0, 0.0)
    rec_tr = [x for x in transitions(np.asarray(rec_t), np.asarray(rec_v)) if lo <= x[0] <= hi]
    new_tr = [x for x in transitions(np.asarray(new_t), np.asarray(new_v)) if lo <= x[0] <= hi]
    used = [False] * len(new_tr)
    matched, unmatched = [], []
    for t, f, to in rec_tr:
        best, best_dt = None, None
        for k, (tn, fn, ton) in enumerate(new_tr):
            if used[k] or (fn, ton) != (f, to):
                continue
            dt = tn - t
            if abs(dt) <= tolerance_s and (best_dt is None or abs(dt) < abs(best_dt)):
                best, best_dt = k, dt
        if best is None:
            unmatched.append((t, f, to))
        else:
            used[best] = True
            matched.append((t, f, to, float(best_dt)))
    reasons = _reason_map('rec', rec_t, rec_reasons, rec_tr)
    reasons.update(_reason_map('new', new_t, new_reasons, new_tr))
    return StepComparison(name, agree, int(valid.sum()), diffs, matched, unmatched,
                          [x for k, x in enumerate(new_tr) if not used[k]], reasons)


def trajectory_setpoints(trajs: list[Trajectory], joint: str, tq: np.ndarray) -> np.ndarray:
    """Setpoint [rad] of ``joint`` at times ``tq`` from the latest trajectory received
    (``stamp <= t``), linearly interpolated, held at its ends; NaN before the first."""
    out = np.full(len(tq), np.nan)
    usable = [tr for tr in trajs if joint in tr.joints]
    if not usable:
        return out
    stamps = np.array([tr.stamp for tr in usable])
    idx = np.searchsorted(stamps, tq, side='right') - 1
    for k in np.unique(idx[idx >= 0]):
        tr = usable[k]
        sel = idx == k
        col = tr.positions[:, tr.joints.index(joint)]
        ok = np.isfinite(col)
        if ok.any():
            out[sel] = np.interp(tq[sel], tr.times[ok], col[ok])
    return out


@dataclass
class WhatIfResult:
    """Everything the comparison found."""

    start: float
    end: float
    phase: StepComparison | None
    safety: StepComparison | None
    trajectory: dict[str, dict[str, float]]   # joint -> {rms, max, samples}

    def text(self) -> str:
        """Human-readable summary."""
        import datetime as dt

        def hhmm(t: float) -> str:
            return dt.datetime.fromtimestamp(t, tz=dt.timezone.utc).strftime('%H:%M:%S')

        lines = [f'what-if comparison {hhmm(self.start)}..{hhmm(self.end)} UTC '
                 f'({(self.end - self.start) / 3600:.2f} h)']
        for comp, names in ((self.phase, PHASE_NAMES), (self.safety, LEVEL_NAMES)):
            if comp is None:
                continue
            lines.append(f'{comp.name}: agreement {100 * comp.agreement:.1f} % of {comp.samples} samples, '
                         f'{len(comp.matched)} transitions matched, {len(comp.unmatched_recorded)} '
                         f'recorded-only, {len(comp.unmatched_new)} new-only')
            for t, f, to, d in comp.matched:
                lines.append(f'  {hhmm(t)} {names.get(f, f)} -> {names.get(to, to)}: new run {d:+.1f} s')
            for t, f, to in comp.unmatched_recorded:
                why = comp.reasons.get(('rec', t))
                lines.append(f'  {hhmm(t)} {names.get(f, f)} -> {names.get(to, to)}: recorded only'
                             + (f' ({why})' if why else ''))
            for t, f, to in comp.unmatched_new:
                why = comp.reasons.get(('new', t))
                lines.append(f'  {hhmm(t)} {names.get(f, f)} -> {names.get(to, to)}: new run only'
                             + (f' ({why})' if why else ''))
            for t0, t1, a, b in comp.differences[:10]:
                lines.append(f'  differ {hhmm(t0)}..{hhmm(t1)}: recorded {names.get(a, a)}, '
                             f'new {names.get(b, b)}')
            if len(comp.differences) > 10:
                lines.append(f'  ... {len(comp.differences) - 10} more intervals')
        for joint, st in self.trajectory.items():
            if st['samples']:
                lines.append(f'trajectory {joint}: RMS {st["rms"]:.2e} rad, max {st["max"]:.2e} rad '
                             f'over {st["samples"]} samples')
            else:
                lines.append(f'trajectory {joint}: no common samples')
        return '\n'.join(lines)


def compare(recorded: Decisions, new: Decisions, grid_s: float = 1.0,
            joints: tuple[str, ...] = JOINTS,
            tolerance_s: float = 300.0) -> WhatIfResult:
    """Compare a recorded run with a what-if run over the interval both cover.

    Parameters
    ----------
    grid_s : float
        Sampling step of the comparison grid [s].
    tolerance_s : float
        Max time offset [s] to match a transition.
    """
    starts, ends = [], []
    for d in (recorded, new):
        ts = [x for x in (d.phase_t, d.safety_t) if len(x)]
        ts += [np.array([tr.stamp for tr in d.trajectories])] if d.trajectories else []
        if ts:
            starts.append(min(float(x[0]) for x in ts))
            ends.append(max(float(x[-1]) for x in ts))
    if len(starts) < 2:
        start = end = starts[0] if starts else 0.0
    else:
        start, end = max(starts), min(ends)
    grid = np.arange(start, end + 1e-9, grid_s) if end > start else np.array([start])
    phase = compare_steps(TRACKER_PHASE.name, recorded.phase_t, recorded.phase, new.phase_t,
                          new.phase, grid, tolerance_s, recorded.phase_reason, new.phase_reason) \
        if len(recorded.phase) and len(new.phase) else None
    safety = compare_steps(SAFETY_STATE.name, recorded.safety_t, recorded.safety, new.safety_t,
                           new.safety, grid, tolerance_s, recorded.safety_reasons,
                           new.safety_reasons) \
        if len(recorded.safety) and len(new.safety) else None
    traj = {}
    for j in joints:
        a = trajectory_setpoints(recorded.trajectories, j, grid)
        b = trajectory_setpoints(new.trajectories, j, grid)
        ok = np.isfinite(a) & np.isfinite(b)
        if not ok.any():
            if any(j in tr.joints for tr in recorded.trajectories + new.trajectories):
                traj[j] = {'rms': float('nan'), 'max': float('nan'), 'samples': 0}
            continue
        diff = b[ok] - a[ok]
        traj[j] = {'rms': float(np.sqrt(np.mean(diff ** 2))), 'max': float(np.max(np.abs(diff))),
                   'samples': int(ok.sum())}
    return WhatIfResult(start, end, phase, safety, traj)


def compare_bags(recorded_reader, new_reader, grid_s: float = 1.0, **kw) -> WhatIfResult:
    """:func:`compare` on the decisions extracted from two bags."""
    return compare(extract_decisions(recorded_reader), extract_decisions(new_reader), grid_s, **kw)
