"""What the sensor nodes report in ``diagnostics`` (pure Python, no rclpy).

:class:`RateMeter` counts samples (rate over the last diagnostics period, last-sample
age, steady clock); :func:`board_report` decides the level, message and key/values of
a node's ``<node>: board`` status; :func:`fix_report` those of ``gps: fix``. The node
copies a :class:`Report` into a ``diagnostic_msgs/DiagnosticStatus`` (level names are
the names of its ``OK``/``WARN``/``ERROR`` constants).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

#: Source states in which the board gives nothing at all (diagnostics ERROR).
DEAD_STATES = ('unconfigured', 'down', 'refused')


class RateMeter:
    """Samples per second over the last diagnostics period, and last-sample age.

    Parameters
    ----------
    clock : callable
        Steady clock [s].
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic):
        self.clock = clock
        self.count = 0
        self.total = 0
        self.last: float | None = None
        self._t0 = clock()

    def tick(self) -> None:
        """Count one sample at the current clock time."""
        self.count += 1
        self.total += 1
        self.last = self.clock()

    def rate(self) -> float:
        """[Hz] since the previous call."""
        now = self.clock()
        r = self.count / max(1e-6, now - self._t0)
        self.count, self._t0 = 0, now
        return r

    def age(self) -> float:
        """Seconds since the last sample (inf before the first) [s]."""
        return math.inf if self.last is None else self.clock() - self.last


@dataclass
class Report:
    """One diagnostics status: ``level`` 'OK', 'WARN' or 'ERROR', ``message``,
    ``values`` (key -> text, in order)."""

    level: str
    message: str
    values: dict[str, str] = field(default_factory=dict)


def board_report(source, meter: RateMeter, max_age: float, faults: list[str],
                 extra: dict) -> Report:
    """The ``<node>: board`` status of one sensor board.

    Parameters
    ----------
    source : sslfr_drivers.sensors.source.BoardSource
        Its ``state``, ``framing``, ``port``, ``error()`` and ``counters()`` are read.
    meter : RateMeter
        Samples; :meth:`RateMeter.rate` is reset by this call.
    max_age : float
        Older last sample -> WARN [s].
    faults : list of str
        Sensor faults (each makes the level ERROR).
    extra : dict
        Node-specific key/values appended after the link counters.

    Level: ERROR when the board is unconfigured/down/refused or a sensor reports a
    fault; WARN when the board-protocol link is not up or the last sample is older
    than ``max_age``; OK otherwise.
    """
    rate = meter.rate()
    age = meter.age()
    state = source.state
    if state in DEAD_STATES:
        level, msg = 'ERROR', f'board {state}: {source.error() or "no data"}'
    elif faults:
        level, msg = 'ERROR', 'sensor fault: ' + '; '.join(faults)
    elif state != 'up' and source.framing == 'protocol':
        level, msg = 'WARN', f'link {state}'
    elif age > max_age:
        level, msg = 'WARN', f'no sample for {age:.1f} s'
    else:
        level, msg = 'OK', 'ok'
    values = {'port': source.port or '(none)', 'framing': source.framing, 'link_state': state,
              'rate_hz': f'{rate:.2f}', 'samples': str(meter.total),
              'last_sample_age_s': 'never' if math.isinf(age) else f'{age:.2f}',
              'sensor_faults': '; '.join(faults) or 'none'}
    values.update({k: str(v) for k, v in source.counters().items()})
    values.update({k: str(v) for k, v in extra.items()})
    return Report(level, msg, values)


def fix_report(last_status: int | None, fixes: int, no_fix: int, fix) -> Report:
    """The ``gps: fix`` status: WARN 'no fix' until a fix (NavSatStatus status >= 0)
    was last seen, else OK 'fix'; ``fix`` is the last
    :class:`~sslfr_drivers.sensors.nmea.FixRecord` (or None)."""
    if last_status is None or last_status < 0:
        level, msg = 'WARN', 'no fix'
    else:
        level, msg = 'OK', 'fix'
    return Report(level, msg, {
        'fixes': str(fixes), 'no_fix': str(no_fix),
        'satellites': str(fix.satellites) if fix else 'none',
        'hdop': f'{fix.hdop:.2f}' if fix else 'none',
        'quality': str(fix.quality) if fix else 'none',
        'nav_mode': str(fix.nav_mode) if fix else 'none'})
