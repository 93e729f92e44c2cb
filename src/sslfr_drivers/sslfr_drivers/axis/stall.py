"""Stall and lost-step detection of one axis from board STATUS samples (no rclpy):
joint angles [rad], steady-clock times [s]."""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class StallDetector:
    """Stall and lost-step detection from board STATUS samples.

    Two checks:

    1. *stall*: the step counter moved by more than ``min_motion`` [rad] of joint
       angle within the last ``window`` [s] while the position sensor moved by less
       than a quarter of that (commanded motion with no sensor motion); and, for
       boards without a sensor, a MOVE_TO pending (target != position) with no step
       change for ``window`` while the board is not moving.
    2. *lost steps*: ``|angle(steps) - sensor| > tolerance`` [rad].

    Parameters
    ----------
    tolerance : float
        Allowed step-count vs sensor disagreement [rad] (> sensor noise).
    window : float
        Stall observation window [s] (steady clock).
    min_motion : float
        Commanded motion that must show on the sensor [rad] (> sensor noise).
    """

    tolerance: float
    window: float = 1.0
    min_motion: float = 0.01
    _hist: list = field(default_factory=list)
    _pending_since: float | None = None

    def reset(self) -> None:
        """Forget the history (after a fault is cleared or the axis re-referenced)."""
        self._hist.clear()
        self._pending_since = None

    def update(self, now: float, step_angle: float, sensor: float | None, moving: bool,
               target_pending: bool) -> str | None:
        """Feed one sample; return a fault reason or None.

        Parameters
        ----------
        now : float
            Steady time [s].
        step_angle : float
            Joint angle from the step counter [rad].
        sensor : float or None
            Joint angle from the position sensor [rad], None when the board has none.
        moving : bool
            Board reports the motor moving.
        target_pending : bool
            A MOVE_TO target differs from the current step count by more than one step.
        """
        if sensor is not None:
            if abs(step_angle - sensor) > self.tolerance:
                return (f'lost steps: step count says {step_angle:.5f} rad, sensor '
                        f'{sensor:.5f} rad (|diff| > {self.tolerance:.5f} rad)')
            self._hist.append((now, step_angle, sensor))
            while self._hist and now - self._hist[0][0] > self.window:
                self._hist.pop(0)
            if len(self._hist) >= 2 and now - self._hist[0][0] >= 0.8 * self.window:
                d_steps = abs(self._hist[-1][1] - self._hist[0][1])
                d_sensor = abs(self._hist[-1][2] - self._hist[0][2])
                if d_steps > self.min_motion and d_sensor < 0.25 * d_steps:
                    return (f'stall: motor stepped {d_steps:.5f} rad in {self.window:.1f} s '
                            f'but the sensor moved {d_sensor:.5f} rad')
        if target_pending and not moving:
            if self._pending_since is None:
                self._pending_since = now
            elif now - self._pending_since > self.window:
                return f'stall: move pending for {now - self._pending_since:.1f} s but the motor is not moving'
        else:
            self._pending_since = None
        return None
