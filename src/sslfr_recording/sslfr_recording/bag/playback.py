"""Pure helpers of ``sslfr replay``: time specs, remaps, timing, progress text.

Times: integer nanoseconds since the Unix epoch (bag log times) and float seconds
on the player's monotonic clock (wall).
"""
from __future__ import annotations

import datetime as _dt
import re

from sslfr_common.timeconv import NS_PER_S, to_ns, to_sec


MAX_OFFSET_S = 1e9      # [s] largest offset from the bag's start or end (~31 years)


def parse_time_spec(spec: str, bag_start_ns: int, bag_end_ns: int | None = None) -> int:
    """Resolve a ``--start``/``--end`` value to a log time [ns].

    Accepted forms:

    - ``120`` or ``+120.5``: seconds after the bag start;
    - ``-60``: seconds before the bag end;
    - ``HH:MM`` or ``HH:MM:SS`` (UTC) on the UTC day of the bag start;
    - an ISO 8601 date-time (``2026-06-21T10:00:00Z``; naive means UTC).

    Raises
    ------
    ValueError
        On an unparseable value.
    """
    s = spec.strip()
    if re.fullmatch(r'[+-]?\d+(\.\d*)?', s) and not abs(float(s)) <= MAX_OFFSET_S:
        raise ValueError(f'{spec!r}: an offset is at most {MAX_OFFSET_S:.0e} s')
    if re.fullmatch(r'[+]?\d+(\.\d*)?', s):
        return bag_start_ns + to_ns(float(s))
    if re.fullmatch(r'-\d+(\.\d*)?', s):
        if bag_end_ns is None:
            raise ValueError('a negative offset needs the bag end time')
        return bag_end_ns + to_ns(float(s))
    m = re.fullmatch(r'(\d{1,2}):(\d{2})(?::(\d{2}(?:\.\d*)?))?', s)
    if m:
        day = _dt.datetime.fromtimestamp(to_sec(bag_start_ns), tz=_dt.timezone.utc).replace(
            hour=0, minute=0, second=0, microsecond=0)
        secs = int(m.group(1)) * 3600 + int(m.group(2)) * 60 + float(m.group(3) or 0)
        return to_ns(day.timestamp() + secs)
    try:
        t = _dt.datetime.fromisoformat(s.replace('Z', '+00:00'))
    except ValueError as exc:
        raise ValueError(f'cannot read time {spec!r}: use seconds from the start, -seconds '
                         'from the end, HH:MM[:SS] UTC or an ISO date-time') from exc
    if t.tzinfo is None:
        t = t.replace(tzinfo=_dt.timezone.utc)
    try:
        return to_ns(t.timestamp())
    except (OverflowError, OSError) as exc:
        raise ValueError(f'cannot use time {spec!r}: {exc}') from None


def absolute(name: str) -> str:
    """Topic name with a leading ``/``."""
    return name if name.startswith('/') else '/' + name


class Timeline:
    """Map bag log time to wall time for a replay at ``rate``.

    ``due(t_ns) = wall0 + (t_ns - t0_ns) / 1e9 / rate`` [s, monotonic clock];
    ``rate <= 0`` means as fast as possible (everything is due now).
    """

    def __init__(self, t0_ns: int, wall0: float, rate: float):
        self.t0_ns = int(t0_ns)
        self.wall0 = float(wall0)
        self.rate = float(rate)

    def due(self, t_ns: int) -> float:
        """Wall time [s] at which a message logged at ``t_ns`` must be published."""
        if self.rate <= 0:
            return self.wall0
        return self.wall0 + to_sec(t_ns - self.t0_ns) / self.rate

    def bag_time(self, wall: float) -> int:
        """Bag time [ns] that corresponds to wall time ``wall`` [s]."""
        if self.rate <= 0:
            return self.t0_ns
        return self.t0_ns + int((wall - self.wall0) * self.rate * NS_PER_S)


def progress_line(t_ns: int, start_ns: int, end_ns: int, count: int, wall_elapsed: float,
                  width: int = 30) -> str:
    """One-line progress bar: bar, percent, bag UTC time, achieved speed, messages."""
    span = max(1, end_ns - start_ns)
    frac = min(1.0, max(0.0, (t_ns - start_ns) / span))
    filled = int(round(frac * width))
    stamp = _dt.datetime.fromtimestamp(to_sec(t_ns), tz=_dt.timezone.utc).strftime('%H:%M:%S')
    speed = (to_sec(t_ns - start_ns) / wall_elapsed) if wall_elapsed > 0 else 0.0
    return (f'[{"#" * filled}{"." * (width - filled)}] {100 * frac:5.1f}% {stamp} UTC '
            f'x{speed:8.1f} {count} msgs')
