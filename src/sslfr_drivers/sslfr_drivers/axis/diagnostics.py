"""The axis driver's diagnostics verdict (no rclpy): level and message from the
lifecycle state, the supervisor's state and the board session."""
from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from sslfr_drivers.axis.supervisor import AxisSupervisor


#: diagnostic_msgs/DiagnosticStatus levels (tested equal to the message's).
DIAG_OK, DIAG_WARN, DIAG_ERROR = 0, 1, 2


def diagnostic_verdict(lifecycle: str, sup: AxisSupervisor, connected: bool,
                       last_error: str) -> tuple[int, str]:
    """Level and message of the driver's diagnostics status.

    ERROR: a latched fault, or no board session after a failed attempt
    (``last_error``); WARN: lifecycle not active, or active but stopped by safety,
    link down or holding; OK otherwise (following, waiting, stowing, jogging, homing).
    """
    if sup.fault or (not connected and last_error):
        return DIAG_ERROR, sup.fault or last_error
    if lifecycle != 'active':
        return DIAG_WARN, f'{lifecycle}: {last_error or "not active"}'
    if sup.state in ('stopped', 'link_down', 'holding'):
        return DIAG_WARN, f'{sup.state}: {sup.reason}'
    return DIAG_OK, f'{sup.state} {sup.reason}'.strip()
