"""Re-referencing an axis whose position is lost (no rclpy): SET_ZERO from the
position sensor at rest, else HOME toward the configured limit switch."""
from __future__ import annotations

from sslfr_drivers.axis.commands import HOME_SWITCHES, NOTHING, STOP, Action, ActionKind, BoardState


def home_action(cfg, board: BoardState, samples: list, last_known: float | None) -> tuple[Action, str]:
    """``(action, reason)`` of one re-referencing tick for tuning ``cfg`` (AxisTuning).

    SET_ZERO at the mean of ``cfg.ref_samples`` sensor readings [rad] taken at rest
    (collected in ``samples``; no action while collecting, STOP while moving), else
    HOME toward the switch at ``cfg.home_speed``.
    """
    cal = cfg.calibration
    if cfg.use_sensor and board.sensor is not None:
        reason = 'position lost: re-establishing it from the position sensor'
        if board.moving:
            samples.clear()
            return STOP, reason
        samples.append(board.sensor)
        if len(samples) < cfg.ref_samples:
            return NOTHING, reason
        mean = sum(samples) / len(samples)
        samples.clear()
        return Action(ActionKind.SET_ZERO, cal.steps(mean)), reason
    direction = home_direction(cfg, board, last_known)      # joint direction toward the switch
    rate = cal.step_rate(cfg.home_speed) * direction * (1.0 if cal.joint_per_step > 0 else -1.0)
    return (Action(ActionKind.HOME, cal.steps(cfg.home_position), rate, HOME_SWITCHES[cfg.home_switch]),
            f'homing toward the {cfg.home_switch} switch')


def home_direction(cfg, board: BoardState, last_known: float | None) -> float:
    """Joint direction (+1 / -1) toward the home switch.

    'low' -> -1, 'high' -> +1. 'sleep' may lie inside the range (0 rad on the
    structure and reflector axes): go toward it from the last known angle [rad]
    (``home_position - last_known``), +1 when unknown; after a homing attempt
    that ended on an end switch (LOW/HIGH closed) go the other way.
    """
    sw = cfg.home_switch
    if sw == 'low':
        return -1.0
    if sw == 'high':
        return 1.0
    if board.limit_bits & 0x2:          # HIGH closed: the switch is below
        return -1.0
    if board.limit_bits & 0x1:          # LOW closed: it is above
        return 1.0
    if last_known is not None and last_known > cfg.home_position:
        return -1.0
    return 1.0
