"""The axis driver's timing (no rclpy): the ROS/steady time rate and when the
setpoint next crosses a motor step, so that an idle driver polls the board no more
often than the physics needs."""
from __future__ import annotations

import math


class TimeRate:
    """ROS seconds per steady second, smoothed: 1 in real time, e.g. 400 in a
    simulated day; the supervisor takes its setpoint ``lead * rate`` ROS seconds ahead.

    Each :meth:`update` with a pair of clock readings moves the estimate by ``gain``
    toward the rate since the previous pair; a clock jump (ROS time going back, or
    faster than ``max_rate``: a replay restarting, the time being set) is ignored.
    """

    def __init__(self, gain: float = 0.3, max_rate: float = 1e5, min_interval: float = 0.04) -> None:
        self.rate = 1.0
        self.gain = gain
        self.max_rate = max_rate
        self.min_interval = min_interval
        self._last: tuple[float, float] | None = None

    def update(self, now_ros: float, now_steady: float) -> float:
        """Feed ROS time [s] and steady time [s]; return the rate [-]. A pair less than
        ``min_interval`` [s] after the reference is not used (a control step woken by
        an event just after a /clock jump would read a rate of thousands)."""
        if self._last is not None and now_steady - self._last[1] < self.min_interval:
            return self.rate
        last, self._last = self._last, (now_ros, now_steady)
        if last is None or now_steady - last[1] <= 0.0:
            return self.rate
        inst = (now_ros - last[0]) / (now_steady - last[1])
        if 0.0 <= inst <= self.max_rate:
            self.rate += self.gain * (inst - self.rate)
        return self.rate


def setpoint_wait(store, cfg, now_ros: float, time_rate: float, slow: float) -> float | None:
    """Steady seconds [s] until the commanded setpoint (``cfg.lead * time_rate`` ROS
    seconds ahead in ``store``) starts or crosses to the next motor step, +1 ms; inf
    when it does neither; None when it moves a step or more per ``slow`` [s] (a
    simulation many times faster than real time: no prediction, tick fast)."""
    if time_rate <= 0.0:
        return math.inf
    t = now_ros + cfg.lead * time_rate
    sp = store.setpoint(t)
    cal = cfg.calibration
    if sp is not None and sp[2] == 'waiting' and store.current is not None:
        return (store.current.start - t) / time_rate
    if sp is not None and sp[2] == 'following' and sp[1] != 0.0:
        x = (cfg.limits.clamp(sp[0]) - cal.offset) / cal.joint_per_step   # [steps]
        v = sp[1] / cal.joint_per_step                                       # [steps/s ROS]
        if abs(v) * time_rate * slow >= 1.0:
            return None
        boundary = round(x) + (0.5 if v > 0 else -0.5)
        return max(0.0, (boundary - x) / v) / time_rate + 1e-3
    return math.inf
