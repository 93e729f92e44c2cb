"""Time conversions between ROS time types and float seconds, written once (pure).

No rclpy import: pure cores (bag readers, reports, the web page's state) use these on
the messages they decode, nodes on the messages they build. ``builtin_interfaces`` is
imported only when a message is built. :mod:`sslfr_common.node` re-exports them.

Seconds are float seconds since the Unix epoch (UTC) for instants, float seconds for
durations; nanoseconds are Python integers (exact).
"""
from __future__ import annotations

import math

NS_PER_S = 1_000_000_000


def to_sec(t) -> float:
    """Seconds [s] of a ``builtin_interfaces`` Time/Duration message (``sec`` +
    ``nanosec``), an ``rclpy.time.Time``/``Duration`` (``nanoseconds``) or an
    integer of nanoseconds."""
    if isinstance(t, int):
        return t * 1e-9
    ns = getattr(t, 'nanoseconds', None)
    if ns is not None:
        return ns * 1e-9
    return t.sec + t.nanosec * 1e-9


def to_ns(seconds: float) -> int:
    """Nanoseconds (integer, rounded) of ``seconds`` [s]; ValueError for NaN/infinity."""
    if not math.isfinite(seconds):
        raise ValueError(f'{seconds} s is not a finite time')
    return int(round(seconds * NS_PER_S))


def stamp_from_ns(ns: int):
    """``builtin_interfaces/Time`` for an integer of nanoseconds since the epoch (exact)."""
    from builtin_interfaces.msg import Time
    sec, nanosec = divmod(int(ns), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def split_seconds(seconds: float) -> tuple[int, int]:
    """``(sec, nanosec)`` of ``seconds`` [s], nanosec in [0, 1e9), rounded to the
    nanosecond of the float's own value (exact: the fraction is taken before scaling,
    so an epoch instant keeps its sub-microsecond digits). ValueError for NaN or
    infinity."""
    if not math.isfinite(seconds):
        raise ValueError(f'{seconds} s is not a finite time')
    sec = math.floor(seconds)
    nanosec = round((seconds - sec) * 1e9)
    if nanosec >= NS_PER_S:
        sec, nanosec = sec + 1, nanosec - NS_PER_S
    return int(sec), int(nanosec)


def stamp(seconds: float):
    """``builtin_interfaces/Time`` for ``seconds`` [s since the epoch] (:func:`split_seconds`)."""
    from builtin_interfaces.msg import Time
    sec, nanosec = split_seconds(seconds)
    return Time(sec=sec, nanosec=nanosec)


def duration(seconds: float):
    """``builtin_interfaces/Duration`` for ``seconds`` [s] (:func:`split_seconds`; a
    negative duration has sec < 0 and nanosec >= 0, as the message requires)."""
    from builtin_interfaces.msg import Duration
    sec, nanosec = split_seconds(seconds)
    return Duration(sec=sec, nanosec=nanosec)


def steady_now(clock) -> float:
    """``clock.now()`` in seconds [s] (a steady or ROS clock)."""
    return clock.now().nanoseconds * 1e-9
