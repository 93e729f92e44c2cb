"""Fault specifications of ``./sslfr sim --fault SPEC`` (pure Python, no rclpy).

Grammar (times are UTC on the simulated day, ``HH:MM`` or ``HH:MM:SS``; ``SECONDS``
is a simulated duration, > 0)::

    overtemp@HH:MM[+SECONDS]                   absorber outlet over the safety limit
    thermocouple-open[:inlet|outlet]@HH:MM[+SECONDS]   a MAX6675 input open (default outlet)
    link-drop:BOARD@HH:MM+SECONDS              the board's link silent (frames dropped)
    board-reset:BOARD@HH:MM                    the board reboots (step counter lost)
    gps-loss@HH:MM+SECONDS                     the GPS receiver loses its fix
    kill:NODE@HH:MM[+SECONDS]                  SIGKILL a node; held down SECONDS, else
                                               for the rest of the run
    hang:NODE@HH:MM                            SIGSTOP the process of a node (its
                                               executor stops as in a deadlock)
    slip:AXIS@HH:MM+SECONDS:DEG                the axis' coupling slips: the joint (and its
                                               encoder) turns DEG away from the motor over
                                               SECONDS, and stays there

BOARD is a board of the node set (``mirrors``, ``mobile_structure``,
``secondary_reflector``, ``gps``, ``absorber``, ``irradiance``); NODE a node name.

Documented reactions (docs/deploy.md, checked by tests/test_system_faults.py):

==================  ==========================================================
overtemp            safety level STOW, planner phase STOWING/STOW, mirrors to
                    +pi/2 (sleeping position); latched until ``safety/reset``
thermocouple-open   the temperature reads NaN, safety WARN then STOW (no
                    temperature supervision = no focusing)
link-drop           axis status link_state degraded/lost, frames_lost grows;
                    after the drop the link recovers and tracking resumes
board-reset         the driver sees the reset (board info / step counter) and
                    re-homes the axis before following the trajectory again
gps-loss            gps/fix status NO_FIX; the planner keeps the persisted site
                    and keeps tracking
kill:planner        the drivers finish the trajectory horizon they hold, then
                    hold position
kill:safety         no safety heartbeat: every axis stops/stows within 1.2 s
hang                no executor beat: the supervisor SIGKILLs the process within
                    its watchdog_timeout (5 s) and restarts it; meanwhile safety
                    stows if the node is a watched one (or, safety hung, the axes
                    stop on their own heartbeat watchdog); then tracking resumes
slip                the axis' accuracy alarm: WARN past 0.06 deg, ERROR past
                    0.36 deg (``<axis>_driver: accuracy`` diagnostics, log);
                    past ``lost_step_tolerance`` (0.29 deg by default) the
                    driver's lost-step check faults the axis
==================  ==========================================================
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from sslfr_common.contract import JOINTS, MIRRORS

KINDS = ('overtemp', 'thermocouple-open', 'link-drop', 'board-reset', 'gps-loss', 'kill', 'hang', 'slip')
#: kind -> (target required?, duration: 'required' | 'optional' | 'forbidden')
_RULES = {
    'overtemp': (False, 'optional'),
    'thermocouple-open': (False, 'optional'),
    'link-drop': (True, 'required'),
    'board-reset': (True, 'forbidden'),
    'gps-loss': (False, 'required'),
    'kill': (True, 'optional'),
    'hang': (True, 'forbidden'),
    'slip': (True, 'required'),
}
DEFAULT_BOARDS = (*JOINTS, 'gps', 'absorber', 'irradiance')
#: board each sensor fault is fired at
FAULT_BOARD = {'overtemp': 'absorber', 'thermocouple-open': 'absorber', 'gps-loss': 'gps'}

_SPEC = re.compile(r'^(?P<kind>[a-z-]+)(?::(?P<target>[A-Za-z0-9_/]+))?'
                   r'@(?P<hh>\d{1,2}):(?P<mm>\d{2})(?::(?P<ss>\d{2}(?:\.\d+)?))?'
                   r'(?:\+(?P<dur>\d+(?:\.\d*)?|\.\d+))?'
                   r'(?::(?P<amount>[-+]?(?:\d+(?:\.\d*)?|\.\d+)))?$')


class FaultSpecError(ValueError):
    """A ``--fault`` argument does not follow the grammar (message says why)."""


@dataclass(frozen=True)
class Fault:
    """One parsed fault.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    at : float
        Seconds after 00:00 UTC of the simulated day [s].
    target : str or None
        Board (link-drop, board-reset), node (kill, hang) or thermocouple (inlet/outlet).
    duration : float or None
        Simulated seconds the fault lasts [s]; None = until the end (or instantaneous).
    spec : str
        The text it was parsed from.
    """

    kind: str
    at: float
    target: str | None
    duration: float | None
    spec: str
    amount: float | None = None     # slip: the joint's angle away from the motor [deg]

    @property
    def end(self) -> float | None:
        """End of the fault [s after 00:00 UTC], None when it does not end."""
        return None if self.duration is None else self.at + self.duration

    @property
    def board(self) -> str | None:
        """The simulated board that receives this fault (None for ``kill``, ``hang``)."""
        if self.kind in ('link-drop', 'board-reset', 'slip'):
            return self.target
        return FAULT_BOARD.get(self.kind)


def parse(spec: str, boards=DEFAULT_BOARDS, nodes=None) -> Fault:
    """Parse one fault spec (see module docstring); raise :class:`FaultSpecError`."""
    text = spec.strip()
    m = _SPEC.match(text)
    if not m:
        raise FaultSpecError(f'fault {spec!r}: expected KIND[:TARGET]@HH:MM[:SS][+SECONDS][:DEG], '
                             f'KIND one of {", ".join(KINDS)}')
    kind, target, dur = m['kind'], m['target'], m['dur']
    if kind not in _RULES:
        raise FaultSpecError(f'fault {spec!r}: unknown kind {kind!r} (known: {", ".join(KINDS)})')
    hh, mm, ss = int(m['hh']), int(m['mm']), float(m['ss'] or 0.0)
    if hh > 23 or mm > 59 or ss >= 60:
        raise FaultSpecError(f'fault {spec!r}: time {m["hh"]}:{m["mm"]} is not a time of day (UTC)')
    needs_target, dur_rule = _RULES[kind]
    if kind == 'thermocouple-open':
        if target not in (None, 'inlet', 'outlet'):
            raise FaultSpecError(f'fault {spec!r}: thermocouple is inlet or outlet, not {target!r}')
        target = target or 'outlet'
    elif needs_target and not target:
        on_node = kind in ('kill', 'hang')
        what = 'NODE' if on_node else 'BOARD'
        raise FaultSpecError(f'fault {spec!r}: {kind} needs :{what} (e.g. {kind}:'
                             f'{"planner" if on_node else MIRRORS}@10:00'
                             f'{"+60" if dur_rule == "required" else ""})')
    elif not needs_target and target:
        raise FaultSpecError(f'fault {spec!r}: {kind} takes no target')
    if kind == 'slip' and target not in JOINTS:
        raise FaultSpecError(f'fault {spec!r}: slip needs an axis ({", ".join(JOINTS)}), not {target!r}')
    if kind in ('link-drop', 'board-reset', 'slip') and target not in boards:
        raise FaultSpecError(f'fault {spec!r}: unknown board {target!r} (known: {", ".join(boards)})')
    if kind in ('kill', 'hang') and nodes is not None and target not in nodes:
        raise FaultSpecError(f'fault {spec!r}: unknown node {target!r} (known: {", ".join(nodes)})')
    duration = float(dur) if dur is not None else None
    if dur_rule == 'required' and duration is None:
        raise FaultSpecError(f'fault {spec!r}: {kind} needs a duration: @HH:MM+SECONDS')
    if dur_rule == 'forbidden' and duration is not None:
        raise FaultSpecError(f'fault {spec!r}: {kind} is instantaneous, no +SECONDS')
    if duration is not None and not duration > 0:
        raise FaultSpecError(f'fault {spec!r}: duration must be > 0 s')
    amount = float(m['amount']) if m['amount'] is not None else None
    if kind == 'slip' and (amount is None or amount == 0 or abs(amount) > 90):
        raise FaultSpecError(f'fault {spec!r}: slip needs the slipped angle in degrees, 0 < |DEG| <= 90: '
                             'slip:AXIS@HH:MM+SECONDS:DEG')
    if kind != 'slip' and amount is not None:
        raise FaultSpecError(f'fault {spec!r}: {kind} takes no :DEG after its duration')
    return Fault(kind=kind, at=hh * 3600.0 + mm * 60.0 + ss, target=target, duration=duration, spec=text,
                 amount=amount)


def format_fault(f: Fault) -> str:
    """Inverse of :func:`parse` (canonical text)."""
    hh, mm = int(f.at // 3600), int((f.at % 3600) // 60)
    ss = f.at - hh * 3600 - mm * 60
    when = f'{hh:02d}:{mm:02d}'
    if ss:
        when += f':{int(ss):02d}' if ss == int(ss) else f':{ss:05.2f}'
    target = f':{f.target}' if f.target and not (f.kind == 'thermocouple-open' and f.target == 'outlet') else ''
    dur = '' if f.duration is None else f'+{f.duration:g}'
    amount = '' if f.amount is None else f':{f.amount:g}'
    return f'{f.kind}{target}@{when}{dur}{amount}'


class Schedule:
    """Faults in time order; :meth:`due` returns each start and end once.

    Times are seconds after 00:00 UTC of the simulated day (the caller converts its
    sim clock). Events: ``(fault, 'start')`` at ``fault.at``, ``(fault, 'end')`` at
    ``fault.end`` when the fault has a duration.
    """

    def __init__(self, faults):
        events = []
        for f in faults:
            events.append((f.at, 0, f, 'start'))
            if f.end is not None:
                events.append((f.end, 1, f, 'end'))
        self._events = sorted(events, key=lambda e: (e[0], e[1]))
        self._next = 0

    def due(self, now: float) -> list[tuple[Fault, str]]:
        out = []
        while self._next < len(self._events) and self._events[self._next][0] <= now:
            _, _, f, what = self._events[self._next]
            out.append((f, what))
            self._next += 1
        return out

    def pending(self) -> int:
        return len(self._events) - self._next
