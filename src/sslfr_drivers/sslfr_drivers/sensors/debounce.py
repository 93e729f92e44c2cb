"""Time-based debouncing of the five limit switches (pure Python, no rclpy).

Seed 000 section 3.5.1: five limit switches mark the initial, last and sleeping
positions of the mirrors and the two longitudinal positions. The board samples them
as a 5-bit mask; :class:`SwitchDebouncer` accepts a new state for a switch only once
the raw input has held it for ``hold_time`` seconds, and remembers when each switch
last changed.

Bit order of the mask (also the board message's bit order)::

    bit 0 initial, 1 last, 2 sleeping, 3 longitudinal_1, 4 longitudinal_2

Times are float seconds in the caller's clock (the node uses ROS time).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from sslfr_common.contract import SWITCHES


@dataclass
class SwitchState:
    """Debounced state of one switch.

    Attributes
    ----------
    closed : bool
        Debounced state (True = switch closed / actuated).
    changed : float
        Time the raw input first showed the current debounced state [s]; the time of
        the first sample for a switch that never changed.
    """

    closed: bool
    changed: float


class SwitchDebouncer:
    """Debounce a stream of 5-bit switch masks.

    Parameters
    ----------
    hold_time : float
        A raw change must persist this long before it is accepted [s], >= 0.
    names : tuple of str
        Switch names in bit order.
    """

    def __init__(self, hold_time: float = 0.03, names: tuple = SWITCHES):
        if not (hold_time >= 0.0) or not math.isfinite(hold_time):
            raise ValueError(f'hold_time must be a finite value >= 0 s, got {hold_time!r}')
        self.hold_time = float(hold_time)
        self.names = tuple(names)
        self.states: dict[str, SwitchState] | None = None
        self._pending: dict[str, float | None] = {n: None for n in self.names}
        self.bounces = 0  #: raw changes that reverted before hold_time

    def update(self, mask: int, t: float) -> list[str]:
        """Feed one raw sample; return the names whose debounced state changed.

        Parameters
        ----------
        mask : int
            Raw switch bits (bit i = ``names[i]`` closed).
        t : float
            Sample time [s]; samples must come in non-decreasing time order.
        """
        raw = {n: bool(mask >> i & 1) for i, n in enumerate(self.names)}
        if self.states is None:
            self.states = {n: SwitchState(raw[n], t) for n in self.names}
            return []
        changed = []
        for n in self.names:
            st = self.states[n]
            if raw[n] == st.closed:
                if self._pending[n] is not None:
                    self.bounces += 1
                self._pending[n] = None
                continue
            if self._pending[n] is None:
                self._pending[n] = t
            if t - self._pending[n] >= self.hold_time:
                st.closed = raw[n]
                st.changed = self._pending[n]
                self._pending[n] = None
                changed.append(n)
        return changed

    def mask(self) -> int:
        """Debounced states as a bit mask (0 before the first sample)."""
        if self.states is None:
            return 0
        return sum(1 << i for i, n in enumerate(self.names) if self.states[n].closed)


class BoardClock:
    """The board's millisecond tick (u32) -> continuous seconds [s]: a wrap-around
    adds 2**32 ms, a board reset (the tick going back by less than half the range)
    keeps the time continuous instead of jumping back."""

    def __init__(self):
        self._last: int | None = None
        self._offset = 0.0

    def seconds(self, ms: int) -> float:
        """Continuous board time [s] of the tick ``ms`` [ms]."""
        if self._last is not None and ms < self._last:
            if self._last - ms > 1 << 31:
                self._offset += (1 << 32) / 1000.0      # u32 wrap-around
            else:
                self._offset += (self._last - ms) / 1000.0  # board reset: stay continuous
        self._last = ms
        return ms / 1000.0 + self._offset


class SwitchTracker:
    """Raw switch samples (board tick, bits) received at host times -> debounced
    states and the host time each switch changed.

    The debouncing runs on the board's clock (:class:`BoardClock`, so transport
    jitter does not count as holding time); a change is dated at the host time of
    the first raw sample showing the new state: ``received - (board time now - board
    time of that sample)``, never below 0 (at sim time ~0, before /clock, the receive
    time itself).

    Parameters
    ----------
    hold_time : float
        Debounce hold time [s] (:class:`SwitchDebouncer`).
    """

    def __init__(self, hold_time: float = 0.03, names: tuple = SWITCHES):
        self.debouncer = SwitchDebouncer(hold_time, names)
        self.board_clock = BoardClock()
        #: switch name -> host time [s] of its last change (the first sample's time at first)
        self.changed_at: dict[str, float] = {}

    @property
    def states(self) -> dict[str, SwitchState] | None:
        """Debounced states (None before the first sample)."""
        return self.debouncer.states

    def update(self, board_ms: int, bits: int, received: float) -> list[str]:
        """Feed one sample of tick ``board_ms`` [ms] received at ``received`` [s, host
        clock]; return the switches whose debounced state changed (every switch for
        the first sample: its initial state)."""
        t = self.board_clock.seconds(board_ms)
        if self.debouncer.states is None:
            self.debouncer.update(bits, t)
            self.changed_at = {n: received for n in self.debouncer.names}
            return list(self.debouncer.names)
        changed = self.debouncer.update(bits, t)
        for name in changed:
            lag = max(0.0, t - self.debouncer.states[name].changed)
            self.changed_at[name] = received - lag if received >= lag else received
        return changed
