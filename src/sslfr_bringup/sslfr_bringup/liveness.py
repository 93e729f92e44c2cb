"""Which node processes have stopped turning their executor (pure Python, no rclpy).

Every node process sends ``READY=1`` when its executor starts and ``WATCHDOG=1`` from
its spin loop (:mod:`sslfr_common.sdnotify`, :func:`sslfr_common.node.run_nodes`).
:class:`LivenessWatch` keeps, per watched process, when it was started and when it
last beat, on the steady clock, and says which ones are overdue:

- running (it has beaten): no beat for longer than ``timeout`` [s];
- starting (not one beat yet): nothing for ``startup_timeout`` [s] after it was
  started (a process that hangs while it imports or builds its nodes).

A process that sent ``STOPPING=1`` is stopping on purpose and no longer watched.
Used by the supervisor of ``sslfr up`` / ``sslfr sim`` (keys: program names) and by
the launch file's watchdog (:mod:`sslfr_bringup.watchdog`; keys: pids).
"""
from __future__ import annotations

from dataclasses import dataclass

#: [s] default bound between two executor beats (nodeset.yaml ``defaults.watchdog_timeout``)
DEFAULT_TIMEOUT = 5.0
#: [s] default bound from a process's start to its first beat (``defaults.watchdog_startup``)
DEFAULT_STARTUP_TIMEOUT = 60.0
#: accepted ranges [s] of the two bounds: at least 2 s (a beat comes at least every
#: 0.5 s of an idle executor, sslfr_common.node.SPIN_TIMEOUT_S, plus its 0.5-1 s period)
TIMEOUT_RANGE = (2.0, 300.0)
STARTUP_RANGE = (5.0, 600.0)


def check_bounds(timeout: float, startup_timeout: float) -> list[str]:
    """Problems with the two bounds [s] (empty when both are in their ranges)."""
    out = []
    for name, value, (lo, hi) in (('watchdog_timeout', timeout, TIMEOUT_RANGE),
                                  ('watchdog_startup', startup_timeout, STARTUP_RANGE)):
        if not (isinstance(value, (int, float)) and lo <= value <= hi):
            out.append(f'{name} {value!r} s outside {lo:g}..{hi:g} s')
    return out


@dataclass
class _Watched:
    started: float            # [s, monotonic] watching began (the process was started)
    last: float | None = None  # [s, monotonic] last beat (READY=1 counts as one)
    beats: int = 0
    status: str = ''           # last STATUS=


@dataclass(frozen=True)
class Overdue:
    """A watched process found silent: its ``key``, ``silence`` [s] (since its last
    beat, or since its start when ``starting``) and the bound it passed [s]."""

    key: object
    silence: float
    bound: float
    starting: bool
    status: str = ''

    @property
    def cause(self) -> str:
        """One line for the log: why it is killed."""
        if self.starting:
            return (f'no executor beat {self.silence:.1f} s after its start '
                    f'(start-up bound {self.bound:g} s)')
        return f'no executor beat for {self.silence:.1f} s (bound {self.bound:g} s)'


class LivenessWatch:
    """Beats per key, on a caller-given steady clock ``now`` [s] (see module doc)."""

    def __init__(self, timeout: float = DEFAULT_TIMEOUT, startup_timeout: float = DEFAULT_STARTUP_TIMEOUT):
        problems = check_bounds(timeout, startup_timeout)
        if problems:
            raise ValueError('; '.join(problems))
        self.timeout = float(timeout)
        self.startup_timeout = float(startup_timeout)
        self._w: dict = {}

    def watch(self, key, now: float) -> None:
        """Start watching ``key`` (its process was just started); forgets an earlier one."""
        self._w[key] = _Watched(started=now)

    def forget(self, key) -> None:
        self._w.pop(key, None)

    def watching(self, key) -> bool:
        return key in self._w

    def beats(self, key) -> int:
        w = self._w.get(key)
        return 0 if w is None else w.beats

    def status(self, key) -> str:
        w = self._w.get(key)
        return '' if w is None else w.status

    def note(self, key, fields: dict, now: float) -> bool:
        """Take one message of ``key`` (sd_notify fields). ``READY=1`` and
        ``WATCHDOG=1`` are beats; ``STOPPING=1`` ends the watch. False when ``key``
        is not watched (the message is ignored)."""
        w = self._w.get(key)
        if w is None:
            return False
        if 'STATUS' in fields:
            w.status = fields['STATUS']
        if fields.get('STOPPING') == '1':
            del self._w[key]
            return True
        if fields.get('WATCHDOG') == '1' or fields.get('READY') == '1':
            w.last = now
            w.beats += 1
        return True

    def overdue(self, now: float) -> list[Overdue]:
        """The watched processes past their bound (still watched: the caller kills
        them and calls :meth:`forget` or :meth:`watch` again)."""
        out = []
        for key, w in self._w.items():
            if w.last is None:
                if now - w.started > self.startup_timeout:
                    out.append(Overdue(key, now - w.started, self.startup_timeout, True, w.status))
            elif now - w.last > self.timeout:
                out.append(Overdue(key, now - w.last, self.timeout, False, w.status))
        return out
