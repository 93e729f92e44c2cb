"""The day report as people read it: the one-minute text summary, ``report.md`` and
the PNG plots (matplotlib, Agg) of a :class:`~.report.DayReport`."""
from __future__ import annotations

import datetime as dt
import math
from pathlib import Path

import numpy as np
from sslfr_common.contract import JOINT_STATES, JOINTS
from sslfr_common.tracking_loss import loss_text

from . import report_thermal
from .report import MOVE_CAP, DayReport

#: the timeline's longest listing in the text (the counts cover the rest)
TIMELINE_MAX = 300


def utc(t: float, fmt: str = '%H:%M:%S') -> str:
    """UTC clock text of a time [s since the Unix epoch]."""
    return dt.datetime.fromtimestamp(t, tz=dt.timezone.utc).strftime(fmt)



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
    lines.append(f'collector       {rep.collector or "no collector description"}: '
                 + (', '.join(rep.joints) if rep.joints else 'no movement recorded'))
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
    lines += render_lines(rep)
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
        def share(x):
            return f'{100.0 * x / en["ideal_kwh"]:.1f} %' if en['ideal_kwh'] > 0 else 'no ideal energy'
        law = ''
        if 'law_kwh' in en:
            law = (f'; the collector\'s law gives {en["law_kwh"]:.3f} kWh ({share(en["law_kwh"])} of ideal), '
                   'achieved ' + (f'{100.0 * en["achieved_kwh"] / en["law_kwh"]:.1f} %' if en['law_kwh'] > 0
                                  else '-') + ' of it')
        lines.append(f'absorbed energy {en["achieved_kwh"]:.3f} kWh achieved vs {en["ideal_kwh"]:.3f} kWh with ideal '
                     f'angles ({share(en["achieved_kwh"])}){law} ({en["note"]})')
    elif en:
        lines.append(f'absorbed energy {en["note"]}')
    lines += report_thermal.render(rep.thermal, utc)
    for axis, lk in rep.links.items():
        lines.append(f'link            {axis}: {lk["drops"]} drop(s), not up {lk["time_not_up"]:.0f} s, '
                     f'{lk["frames_lost"]} frames lost, {lk["frames_bad"]} bad, '
                     f'{lk["fault_samples"]} samples with fault bits')
    if rep.accuracy:
        a0 = next(iter(rep.accuracy.values()))
        lines.append(f'accuracy alarm  time above {math.degrees(a0["warn"]):.2f} deg (WARN) / '
                     f'{math.degrees(a0["error"]):.2f} deg (ERROR), RMS over {a0["window"]:g} s while tracking')
    for axis, a in rep.accuracy.items():
        lines.append(f'  {axis:<20} {a["warn_s"]:8.0f} s / {a["error_s"]:6.0f} s of {a["judged_s"]:.0f} s judged; '
                     f'largest {math.degrees(a["peak"]):.3f} deg'
                     + (f' ({loss_text(a["peak"], a["loss_table"])})' if a['peak'] > a['warn'] else ''))
    lines += render_timeline(rep)
    return '\n'.join(lines)


def render_lines(rep: DayReport) -> list[str]:
    """Every mirror line's error against its exact angle and seed 004's budget
    (:func:`.report.line_tracking`), or why it is not computed."""
    ln = rep.lines
    if not ln:
        return []
    if 'lines' not in ln:
        return [f'line errors     not computed: {ln["note"]}']
    lo, hi = (math.degrees(b) for b in ln['budget'])
    out = ['line errors     each mirror line on the measured drive vs its exact angle (seed 004 eqs. 3-4), '
           f'while tracking ({ln["samples"]} samples); budget {lo:.3f} deg for |theta_T| <= 45 deg, '
           f'{hi:.2f} deg up to 80 deg (seed 004 section 3; {ln["judged"]} samples there)',
           '  line   x [m]  RMS [deg]  max [deg]  law max [deg]  within budget']
    for r in ln['lines']:
        h = r['held']
        within = f'{100.0 * r["within"]:11.1f} %' if math.isfinite(r['within']) else f'{"-":>13}'
        out.append(f'  {r["line"]:>4} {r["x"]:7.3f} {math.degrees(h.rms):10.4f} {math.degrees(h.max):10.4f} '
                   f'{math.degrees(r["law_max"]):14.4f}   {within}')
    return out


def render_timeline(rep: DayReport) -> list[str]:
    """The timeline section: counts of log lines per level and node, then the events
    (at most :data:`TIMELINE_MAX`)."""
    lines = ['timeline (UTC): phase and safety changes, the nodes\' warnings and errors (/rosout)']
    if rep.log_counts:
        by_level: dict = {}
        for (level, node), n in sorted(rep.log_counts.items()):
            by_level.setdefault(level, []).append((node, n))
        lines.append('  log lines: ' + '; '.join(f'{lvl} {sum(n for _, n in v)} ('
                                                  + ', '.join(f'{node} {n}' for node, n in v) + ')'
                                                  for lvl, v in by_level.items()))
    else:
        lines.append('  log lines: no warning or error in /rosout' if rep.has_rosout else '  log lines: none recorded')
    for t, kind, text, repeats, last_t in rep.timeline[:TIMELINE_MAX]:
        more = f' (x{repeats} until {utc(last_t)})' if repeats > 1 else ''
        lines.append(f'  {utc(t)}  {kind:<6} {text}{more}')
    if len(rep.timeline) > TIMELINE_MAX:
        lines.append(f'  ... {len(rep.timeline) - TIMELINE_MAX} more entries (see the counts above)')
    return lines


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

    axes_present = [a for a in (rep.joints or JOINTS) if f'status_{a}' in rep.series or f'joint_{a}' in rep.series]
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
                ax.plot(*_decimate(hours(t), np.degrees(v['measured'])), label=JOINT_STATES.name, lw=1)
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
    if rep.lines.get('samples'):
        fig, ax = plt.subplots(figsize=(10, 3.5))
        ln = rep.lines
        for k, r in enumerate(ln['lines']):
            ax.plot(*_decimate(hours(ln['t']), np.degrees(ln['errors'][:, k])), label=f'line {r["line"]}', lw=0.8)
        for b in ln['budget']:
            ax.axhline(math.degrees(b), color='#dc2626', ls='--', lw=0.8)
            ax.axhline(-math.degrees(b), color='#dc2626', ls='--', lw=0.8)
        ax.set_ylabel('line - exact (eqs. 3-4) [deg]')
        ax.set_xlabel('hour of the day [UTC]')
        ax.set_title("each line's error while tracking; dashed: seed 004's 0.085 / 0.12 deg budget")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, ncol=5)
        save(fig, 'line_errors.png')
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


