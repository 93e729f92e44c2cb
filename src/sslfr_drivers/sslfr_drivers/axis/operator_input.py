"""The operator's say over one axis (no rclpy): the mode from ``tracker/phase`` and
the rules of a maintenance jog."""
from __future__ import annotations

import math

from sslfr_common.contract import Phase

from sslfr_drivers.axis.commands import BoardState


def operator_mode(phase: int, mode: str) -> str:
    """Operator mode of the driver from ``tracker/phase``: ``'maintenance'`` (phase
    MAINTENANCE or mode maintenance: automatic motion off, jog allowed), ``'manual'``
    (phase MANUAL or mode manual: hold), else ``'auto'`` (follow the trajectory; the
    planner plans the stows)."""
    if phase == Phase.MAINTENANCE or mode == 'maintenance':
        return 'maintenance'
    if phase == Phase.MANUAL or mode == 'manual':
        return 'manual'
    return 'auto'


def check_jog(mode: str, active: bool, board: BoardState | None, fault: str | None, delta: float,
              speed: float, max_jog: float) -> str:
    """Why a jog of ``delta`` [rad] at ``speed`` [rad/s] is refused ('' when it is not),
    in this order: not in maintenance mode; not active; no board answer; a latched
    fault; axis not homed; ``delta`` not finite or ``|delta| > max_jog`` [rad];
    ``speed`` not finite or negative. The soft limits are checked on the target."""
    if mode != 'maintenance':
        return 'jog refused: not in maintenance mode (tracker/phase)'
    if not active:
        return 'jog refused: driver not active'
    if board is None:
        return 'jog refused: board not answering'
    if fault:
        return f'jog refused: fault: {fault}'
    if not board.homed:
        return 'jog refused: axis not homed'
    if not math.isfinite(delta) or abs(delta) > max_jog:
        return f'jog refused: |delta| must be finite and <= max_jog {max_jog:.4f} rad'
    if not math.isfinite(speed) or speed < 0:
        return 'jog refused: speed must be finite and >= 0'
    return ''
