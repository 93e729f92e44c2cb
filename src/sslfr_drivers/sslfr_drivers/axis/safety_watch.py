"""What ``safety/state`` means for one axis (no rclpy): the heartbeat watchdog and
the one rule by which a safety state, an e-stop or a lost heartbeat stops or stows
the axis (:meth:`SafetyWatch.verdict`). Times are steady-clock seconds."""
from __future__ import annotations

import enum
from dataclasses import dataclass

from sslfr_common.contract import Level


class SafetyVerdict(enum.Enum):
    FOLLOW = 'follow'
    STOW = 'stow'
    STOP = 'stop'


@dataclass
class SafetyWatch:
    """Watchdog on ``safety/state`` on the steady clock.

    A message refreshes the watchdog only when its ``sequence`` differs from the
    previous one (a stuck publisher repeating itself is not a heartbeat).

    Parameters
    ----------
    axis : str
        This driver's axis name (matched against ``stopped_axes``).
    timeout : float
        Maximum steady-clock age of the last fresh message [s] (1.0 by the spec).
    silent_stow_after : float
        Further silence after the stop before the fail-safe stow [s]: with the
        supervisor gone nobody watches the absorber, so the axis stops first and then
        defocuses. Only after messages were once received: at boot without a
        supervisor the axis does not move at all.
    """

    axis: str
    timeout: float = 1.0
    silent_stow_after: float = 1.0
    last_rx: float | None = None
    last_sequence: int | None = None
    level: int = Level.OK
    stow_required: bool = False
    stopped_axes: tuple = ()
    reasons: tuple = ()
    _stop_ordered: bool = False

    def receive(self, now_steady: float, level: int, stow_required: bool, stopped_axes,
                sequence: int, reasons=()) -> bool:
        """Record a SafetyState; return True when it was fresh (new sequence)."""
        fresh = sequence != self.last_sequence
        self.level, self.stow_required = int(level), bool(stow_required)
        self.stopped_axes, self.reasons = tuple(stopped_axes), tuple(reasons)
        if fresh:
            self.last_rx = now_steady
            self.last_sequence = sequence
        return fresh

    def verdict(self, now_steady: float, msg=None) -> tuple[SafetyVerdict, str]:
        """``(verdict, reason)``: the one decision of what safety orders this axis.

        STOP when no fresh message for > ``timeout`` (or never), then STOW once the
        silence passes ``timeout + silent_stow_after``; STOP when this axis is in
        ``stopped_axes`` or the level is ESTOP with no axis listed (every axis);
        STOW when ``stow_required`` or level STOW; FOLLOW otherwise.

        ``msg`` (anything with ``level``, ``stow_required``, ``stopped_axes``,
        ``reasons``): judge that message as it arrives (fresh, so no silence counts),
        storing nothing; else the last received one at steady ``now_steady`` [s].
        """
        if msg is None:
            if self.last_rx is None:
                return SafetyVerdict.STOP, 'no safety/state received yet'
            age = now_steady - self.last_rx
            if age > self.timeout + self.silent_stow_after:
                return SafetyVerdict.STOW, f'safety/state silent for {age:.2f} s: fail-safe stow (defocus)'
            if age > self.timeout:
                return SafetyVerdict.STOP, f'safety/state silent for {age:.2f} s > {self.timeout:.2f} s'
            msg = self
        if msg.level == Level.ESTOP and not msg.stopped_axes:
            return SafetyVerdict.STOP, 'safety ESTOP: ' + '; '.join(msg.reasons)
        if self.axis in msg.stopped_axes:
            return SafetyVerdict.STOP, f'safety stops axis {self.axis}: ' + '; '.join(msg.reasons)
        if msg.stow_required or msg.level == Level.STOW:
            return SafetyVerdict.STOW, 'safety requires stow: ' + '; '.join(msg.reasons)
        return SafetyVerdict.FOLLOW, ''

    def stop_at_receipt(self, now_steady: float, msg) -> bool:
        """True when ``msg`` (as for :meth:`verdict`) newly orders this axis to STOP:
        the driver then sends STOP at once, before its next control tick. Reads no
        state the control tick writes (called without the driver's lock)."""
        stop = self.verdict(now_steady, msg)[0] is SafetyVerdict.STOP
        new, self._stop_ordered = stop and not self._stop_ordered, stop
        return new

    def next_deadline(self, now_steady: float) -> float:
        """Seconds [s] until silence can change the verdict (STOP, then STOW), +1 ms;
        inf when no message was ever received or both deadlines passed."""
        wait = float('inf')
        if self.last_rx is not None:
            age = now_steady - self.last_rx
            for deadline in (self.timeout, self.timeout + self.silent_stow_after):
                if deadline >= age:
                    wait = min(wait, deadline - age + 1e-3)
        return wait
