"""The link's heartbeat and silence check (no I/O): PING when nothing was sent for
``period`` (keeps the board's 1 s watchdog quiet), the board counted silent when
nothing was heard for ``silence``. Times are steady seconds."""
from __future__ import annotations


class Heartbeat:
    """Last send / receive times of one link and the deadlines derived from them.

    period : float or None
        PING after this long without sending [s]; None: the owner sends traffic itself.
    silence : float
        No frame heard for this long -> the board is silent [s].
    """

    def __init__(self, period: float | None, silence: float):
        self.period = period
        self.silence = silence
        self.last_tx = -1e9
        self.last_rx = -1e9

    def ping_due(self, now: float) -> bool:
        return bool(self.period) and now - self.last_tx >= self.period

    def unheard(self, now: float) -> bool:
        """Heartbeats go out but no frame came back for ``max(silence, 2 period)``."""
        return bool(self.period) and now - self.last_rx > max(self.silence, 2 * self.period)

    def quiet(self, now: float) -> bool:
        """No frame heard for ``silence`` (checked when a request expired)."""
        return now - self.last_rx > self.silence

    def next_ping(self) -> float:
        return self.last_tx + self.period

    def next_unheard(self) -> float:
        return self.last_rx + max(self.silence, 2 * self.period) + 1e-3
