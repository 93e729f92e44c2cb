"""Time conversions between ROS time types and float seconds, written once (pure).

No rclpy import: pure cores (bag readers, reports, the web page's state) use these on
the messages they decode, nodes on the messages they build. ``builtin_interfaces`` is
imported only when a message is built. :mod:`sslfr_common.node` re-exports them.

Seconds are float seconds since the Unix epoch (UTC) for instants, float seconds for
durations; nanoseconds are Python integers (exact).
"""
from __future__ import annotations

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


def stamp_from_ns(ns: int):
    """``builtin_interfaces/Time`` for an integer of nanoseconds since the epoch (exact)."""
    from builtin_interfaces.msg import Time
    sec, nanosec = divmod(int(ns), NS_PER_S)
    return Time(sec=sec, nanosec=nanosec)


def stamp(seconds: float):
    """``builtin_interfaces/Time`` for ``seconds`` [s since the epoch], rounded to the
    nanosecond. ValueError for NaN or infinity."""
    return stamp_from_ns(round(seconds * 1e9))


def duration(seconds: float):
    """``builtin_interfaces/Duration`` for ``seconds`` [s], rounded to the nanosecond
    (nanosec is always in [0, 1e9), as the message requires). ValueError for NaN or
    infinity."""
    from builtin_interfaces.msg import Duration
    sec, nanosec = divmod(round(seconds * 1e9), NS_PER_S)
    return Duration(sec=sec, nanosec=nanosec)


def steady_now(clock) -> float:
    """``clock.now()`` in seconds [s] (a steady or ROS clock)."""
    return clock.now().nanoseconds * 1e-9
