"""Detect jumps of the ROS clock against the steady clock (pure Python).

A Raspberry Pi without an RTC boots with a wrong wall clock; when the GPS (or NTP)
corrects it, system time jumps by hours. The planner must then replan and must never
schedule motion into the past. With ``use_sim_time`` the node uses rcl's jump
callbacks on /clock instead (simulated time has no fixed rate against the steady
clock); this detector covers system time, where ROS time should advance at the same
rate as the steady (monotonic) clock.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Jump:
    """A detected clock jump.

    Attributes
    ----------
    delta : float
        ROS-time advance minus steady-clock advance since the previous sample [s];
        positive: ROS time jumped forward.
    ros_time : float
        ROS time after the jump [s since the Unix epoch].
    """

    delta: float
    ros_time: float


class ClockJumpDetector:
    """Compare successive (ROS time, steady time) samples.

    Parameters
    ----------
    threshold : float
        Smallest |delta| reported as a jump [s]; must be > 0. Scheduling jitter of a
        busy machine is milliseconds, NTP slews are ppm, so one second or more only
        happens when the clock is stepped.
    """

    def __init__(self, threshold: float):
        if not threshold > 0:
            raise ValueError(f'threshold must be > 0 s, got {threshold}')
        self.threshold = float(threshold)
        self._last: tuple[float, float] | None = None
        self.count = 0

    def reset(self) -> None:
        """Forget the previous sample (e.g. after switching clock type)."""
        self._last = None

    def update(self, ros_time: float, steady_time: float) -> Jump | None:
        """Feed one sample; return a :class:`Jump` when the clocks disagree.

        Parameters
        ----------
        ros_time : float
            ROS (system) time [s since the Unix epoch].
        steady_time : float
            Monotonic clock [s], arbitrary origin.
        """
        last, self._last = self._last, (ros_time, steady_time)
        if last is None:
            return None
        delta = (ros_time - last[0]) - (steady_time - last[1])
        if abs(delta) >= self.threshold:
            self.count += 1
            return Jump(delta, ros_time)
        return None
