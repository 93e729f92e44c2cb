"""The axis board's own stow on host loss, set by the driver at configure (pure
Python, no rclpy; issue 35: a dead host must not leave the mirrors focused).

The board keeps the record in its EEPROM (docs/protocol.md SET_HOST_LOSS_STOW): after
its host-silence watchdog has stopped the motor (1 s of silence), and
``host_loss_stow_delay`` [s] more of silence, it drives by itself to

* ``position``: ``host_loss_stow_position`` [rad] (default the axis' stow position:
  mirrors +pi/2 sleeping = defocused), only when the board is referenced (HOMED);
* ``switch``: toward its ``home_switch`` until it closes (works without a reference),
  in the direction of increasing joint angle when the switch's angle
  (``home_position``) lies in the upper half of the soft limits, else decreasing;
* ``off``: it stays where the watchdog stopped it;

at ``max_speed``, its switches and step range respected, and reports fault HOST_LOSS
until the driver commands again.
"""
from __future__ import annotations

from sslfr_drivers.axis.commands import HOME_SWITCHES
from sslfr_drivers.axis.joint import Calibration
from sslfr_drivers.link import messages as m

#: ``host_loss_stow`` values -> board modes.
MODES = {'off': m.HostLossMode.OFF, 'position': m.HostLossMode.POSITION, 'switch': m.HostLossMode.SWITCH}


def host_loss_request(p: dict) -> m.SetHostLossStow:
    """The SET_HOST_LOSS_STOW record of the driver's (validated) parameters ``p``."""
    mode = MODES[p['host_loss_stow']]
    cal = Calibration(p['step_angle'], p['gear_ratio'], p['offset'], p['invert'])
    speed = float(cal.step_rate(p['max_speed']))
    delay_ms = int(round(p['host_loss_stow_delay'] * 1000.0))
    if mode == m.HostLossMode.SWITCH:
        upward = p['home_position'] >= (p['lower_limit'] + p['upper_limit']) / 2.0
        toward = 1.0 if upward else -1.0
        step_sign = 1.0 if cal.steps(1.0) > cal.steps(0.0) else -1.0     # steps grow with the angle?
        return m.SetHostLossStow(int(mode), HOME_SWITCHES[p['home_switch']], 0, toward * step_sign * speed,
                                 delay_ms)
    if mode == m.HostLossMode.POSITION:
        return m.SetHostLossStow(int(mode), 0, cal.steps(p['host_loss_stow_position']), speed, delay_ms)
    return m.SetHostLossStow(int(mode), 0, 0, speed, delay_ms)


def describe(p: dict) -> str:
    """One line for the log: what the board will do on host loss."""
    if p['host_loss_stow'] == 'off':
        return 'host-loss stow off'
    what = (f"to {p['host_loss_stow_position']:.4f} rad" if p['host_loss_stow'] == 'position'
            else f"to the {p['home_switch']} switch")
    return f"host-loss stow {what} after {p['host_loss_stow_delay']:.0f} s of host silence"


def configure_host_loss(link, p: dict) -> str:
    """Send the record to the board (blocking: the configure thread); the log line, or
    why the board did not take it (an older firmware: NACK UNKNOWN_TYPE). The line also
    says when the board's status (read at link up) shows it stowed by itself."""
    st = getattr(link, 'last_status', None)
    stowed = ('; the board stowed by itself while its host was away (fault HOST_LOSS)'
              if st is not None and st.fault_bits & m.FaultBits.HOST_LOSS else '')
    try:
        link.request(host_loss_request(p))
    except Exception as exc:  # noqa: BLE001 - NackError, LinkTimeout...: reported, configure goes on
        return f'host-loss stow NOT set on the board ({type(exc).__name__}: {exc}){stowed}'
    return describe(p) + stowed
