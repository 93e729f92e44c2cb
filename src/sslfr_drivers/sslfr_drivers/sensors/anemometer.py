"""Cup anemometer: pulse counts -> wind speed, 3 s gust and 10 min mean (pure Python).

The absorber board counts the anemometer's pulses on one input (falling edges, a
reed contact to GND or an open-collector output) and reports the running count with
its millisecond tick at 4 Hz (``PulseSample``, docs/protocol.md). Here:

* :func:`speed` - the calibration of a cup anemometer, linear in the pulse
  frequency: ``v = slope * f + offset`` for f > 0 and 0 at rest (the offset is the
  starting threshold of the cups, so it only applies while they turn). Typical
  values of a 3-cup anemometer with one pulse per turn: slope 0.765 m/s per Hz,
  offset 0.35 m/s (the calibration sheet of the instrument gives the real ones).
* :class:`PulseCounter` - samples -> (interval [s], pulses), across the u32 wrap of
  both fields; a board reset (tick or count going back) or a gap restarts it.
* :class:`WindStats` - WMO No. 8 (Guide to Instruments and Methods of Observation,
  Vol. I ch. 5): the wind is sampled at 4 Hz (0.25 s), a *gust* is the highest 3 s
  running mean within the reporting period, the *mean* wind is averaged over 10 min.

Units: m/s, Hz. The pulse frequency is measured on the board's clock (the count and
its tick come together); the gust and mean windows run on ROS time, the samples'
stamps (control logic: a simulation or a replay at any speed averages the wind over
its own seconds), each sample weighted by its board interval.
"""
from __future__ import annotations

import collections
import math
from dataclasses import dataclass

#: Typical calibration of a 3-cup anemometer with one pulse per turn [m/s per Hz], [m/s].
SLOPE = 0.765
OFFSET = 0.35
#: WMO No. 8: gust averaging time and mean-wind period [s].
GUST_WINDOW = 3.0
MEAN_WINDOW = 600.0
#: A sample interval longer than this is a gap: the windows start again [s].
MAX_GAP = 2.0
#: Arduino pins the absorber board can count on (the others are its switches and SPI
#: lines: docs/firmware.md "Wiring"): D7, D8, D11, A0..A3 (14..17).
FREE_PINS = (7, 8, 11, 14, 15, 16, 17)
_U32 = 1 << 32


def speed(frequency: float, slope: float = SLOPE, offset: float = OFFSET) -> float:
    """Wind speed [m/s] of a pulse ``frequency`` [Hz]: ``slope * f + offset`` while the
    cups turn (f > 0), 0 at rest."""
    return slope * frequency + offset if frequency > 0.0 else 0.0


def frequency(wind: float, slope: float = SLOPE, offset: float = OFFSET) -> float:
    """Inverse of :func:`speed`: the pulse frequency [Hz] at wind speed ``wind`` [m/s]
    (0 below the starting threshold ``offset``)."""
    return (wind - offset) / slope if wind > offset else 0.0


def check_calibration(slope: float, offset: float) -> None:
    """Raise ValueError unless 0 < slope and 0 <= offset (finite)."""
    if not (math.isfinite(slope) and slope > 0.0):
        raise ValueError(f'anemometer slope must be > 0 m/s per Hz, got {slope!r}')
    if not (math.isfinite(offset) and offset >= 0.0):
        raise ValueError(f'anemometer offset must be >= 0 m/s, got {offset!r}')


class PulseCounter:
    """Turns the board's (tick, running count) samples into intervals.

    :meth:`add` returns ``(dt [s], pulses)`` since the previous sample, or None for
    the first sample, after a board reset (tick or count going back by more than half
    the u32 range is a wrap, anything else a reset) and after a gap > ``max_gap``.
    """

    def __init__(self, max_gap: float = MAX_GAP):
        self.max_gap = max_gap
        self._last: tuple[int, int] | None = None
        self.restarts = 0

    def add(self, board_ms: int, count: int) -> tuple[float, int] | None:
        last, self._last = self._last, (board_ms, count)
        if last is None:
            return None
        dms = (board_ms - last[0]) % _U32
        dn = (count - last[1]) % _U32
        if dms == 0 or dms >= _U32 // 2 or dn >= _U32 // 2 or dms / 1000.0 > self.max_gap:
            self.restarts += 1
            return None
        return dms / 1000.0, dn


@dataclass(frozen=True)
class WindReading:
    """What :class:`WindStats` says after a sample (the fields of sslfr_interfaces/Wind)."""

    speed: float        # 3 s running mean [m/s]
    gust: float         # highest 3 s running mean over the window [m/s]
    mean: float         # mean over the window [m/s]
    window: float       # time covered by mean and gust [s]
    pulse_rate: float   # last interval's pulse frequency [Hz]


class WindStats:
    """Running 3 s mean, gust and 10 min mean of the wind from pulse intervals.

    Every interval (``dt`` [s] of the board's clock, ``pulses``) becomes a speed by the
    calibration; means are weighted by ``dt`` over the intervals whose end ``t`` [s of
    ROS time] lies within the window. A gap (the caller passes ``restart``) or ROS time
    going back empties every window.
    """

    def __init__(self, slope: float = SLOPE, offset: float = OFFSET,
                 gust_window: float = GUST_WINDOW, mean_window: float = MEAN_WINDOW):
        check_calibration(slope, offset)
        self.slope, self.offset = slope, offset
        self.gust_window, self.mean_window = gust_window, mean_window
        self.restart()

    def restart(self) -> None:
        """Forget every sample (a gap, a board reset)."""
        self._t: float | None = None      # end of the last interval [s, ROS time]
        self._origin = 0.0                 # start of the first interval since the restart [s]
        self._short: collections.deque = collections.deque()   # (t_end, dt, v)
        self._long: collections.deque = collections.deque()
        self._short_sum = [0.0, 0.0]      # sum v*dt, sum dt
        self._long_sum = [0.0, 0.0]
        self._runs: collections.deque = collections.deque()    # (t, 3 s mean), decreasing means

    def add(self, dt: float, pulses: int, t: float | None = None) -> WindReading:
        """One interval of ``dt`` [s, board clock] with ``pulses`` counted, ending at
        ``t`` [s, ROS time: the sample's stamp; None: the previous end + ``dt``, the
        board's own clock]; the reading after it."""
        rate = pulses / dt
        v = speed(rate, self.slope, self.offset)
        if t is None:
            t = dt if self._t is None else self._t + dt
        elif self._t is not None and t < self._t:
            self.restart()                 # ROS time went back (a replay looped): start again
        if self._t is None:
            self._origin = t - dt
        self._t = t
        for q, s, w in ((self._short, self._short_sum, self.gust_window),
                        (self._long, self._long_sum, self.mean_window)):
            q.append((t, dt, v))
            s[0] += v * dt
            s[1] += dt
            while q and q[0][0] <= t - w:
                _, odt, ov = q.popleft()
                s[0] -= ov * odt
                s[1] -= odt
        run = self._short_sum[0] / self._short_sum[1]
        while self._runs and self._runs[-1][1] <= run:
            self._runs.pop()
        self._runs.append((t, run))
        while self._runs[0][0] <= t - self.mean_window:
            self._runs.popleft()
        covered = t - self._origin
        return WindReading(max(0.0, run), max(0.0, self._runs[0][1]), max(0.0, self._long_sum[0] / self._long_sum[1]),
                           min(covered, self.mean_window), rate)


class PublishGate:
    """Which readings go on ``wind``: one every ``1 / rate`` [s of ROS time] and at once
    any whose gust is a new maximum (a gust reaches safety on the sample that shows it;
    every sample still enters the means). Within 0.06 s (a quarter of the board's
    0.25 s sample period) of the period counts as due: the sample clock jitters."""

    def __init__(self, rate: float):
        self.rate = rate
        self.restart()

    def restart(self) -> None:
        """Forget the last published reading (the windows started again)."""
        self._last: tuple[float, float] | None = None     # (t [s], gust [m/s])

    def due(self, t: float, gust: float) -> bool:
        """Whether the reading at ROS time ``t`` [s] with ``gust`` [m/s] is published
        (recorded as the last one when it is)."""
        last = self._last
        if last is not None and gust <= last[1] and t - last[0] < 1.0 / self.rate - 0.06:
            return False
        self._last = (t, gust)
        return True
