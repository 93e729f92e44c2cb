"""The axis driver's parameters: one table (pure, no rclpy), per-axis defaults, the
rules between parameters, and the check of a board port.

:data:`PARAMS` is declared by the node (``sslfr_common.node.declare_parameters``),
checked on every run-time change (``ParameterGuard``) and usable by the CLI to check
a site config's driver sections without ROS. :func:`params_for` gives the table of
one axis (its soft limits, stow and home positions as defaults).
"""
from __future__ import annotations

import math
import os
import re
import stat as stat_mod

from sslfr_common.contract import JOINT_LIMITS, JOINT_RANGE, JOINTS, STEP_ANGLE, STOW_POSITION, WIND_STOW_POSITION
from sslfr_common.params import ParamSpec, ParamTable

from sslfr_common import accuracy
from sslfr_drivers.axis.commands import HOME_SWITCHES
from sslfr_common.contract import DRIVE_KINDS, DriveKind
from sslfr_drivers.axis.stall import StallDetector
from sslfr_drivers.axis.supervisor import AxisTuning
from sslfr_drivers.axis.joint import Calibration, SoftLimits
from sslfr_drivers.link.keys import KEY_FILE_PARAM

_P = ParamSpec
_ANGLE = (-math.pi, math.pi)
_SPEED = (1e-5, 2.0)


_M = JOINTS[0]          # the base table carries the mirrors' defaults
_SPECS = [
    _P('axis', _M, 'axis driven: mirrors | mobile_structure | secondary_reflector (read-only)',
       choices=JOINTS, read_only=True),
    _P('drive', DRIVE_KINDS[0], 'drive kind of the axis (the collector description\'s movement drive): '
       'stepper_switches | linear_actuator_inclinometer | stepper_no_switches (read-only)',
       choices=DRIVE_KINDS, read_only=True),
    _P('deadband', 0.0, 'position deadband of a linear_actuator_inclinometer drive [rad] (its board '
       'rests anywhere within it; 0 for steppers)', 'rad', 0.0, 0.1),
    _P('state_dir', '~/.local/state/sslfr', 'directory of the kept reference of a stepper_no_switches drive '
       "(reference_<axis>.json); '' = not kept"),
    _P('port', '', "board port: pyserial URL/device (/dev/ttyUSB0, a pty, loop://) or "
       "'xbee:<uart>?addr=<64-bit hex>'; '' = /dev/sslfr/<axis>"),
    _P('baudrate', 115200, 'serial line speed [bit/s]', 'bit/s', 1200, 4_000_000),
    KEY_FILE_PARAM,
    _P('autostart', True, 'reach and keep the active state by itself: configure (retried with '
       'back-off from retry_period to retry_period_max while no board answers), then activate; '
       'an external deactivate / cleanup / shutdown is respected', read_only=True),
    _P('retry_period', 2.0, 'autostart: first wait between configure attempts [s]', 's', 0.1, 3600.0),
    _P('retry_period_max', 10.0, 'autostart: longest wait between configure attempts [s] (the '
       'wait doubles from retry_period up to the larger of the two)', 's', 0.1, 3600.0),
    _P('control_rate', 20.0, 'control loop and STATUS poll rate [Hz] (steady clock)', 'Hz', 1.0, 200.0,
       read_only=True),
    _P('idle_poll_period', 0.2, 'longest wait between STATUS polls while nothing moves [s]: the '
       'control tick runs at control_rate only while the board moves, homes or has a command under '
       'way, else at the next setpoint step, safety deadline or this period (events: at once); '
       'default one status period, so that every status carries a new reading', 's', 0.02, 5.0),
    _P('status_rate', 5.0, 'axes/<axis>/status rate [Hz]', 'Hz', 0.1, 50.0),
    _P('joint_state_rate', 10.0, 'joint_states rate [Hz]', 'Hz', 0.1, 100.0),
    _P('request_timeout', 0.25, 'board answer time-out per try [s] (STATUS polls use '
       'min(this, 2 / control_rate))', 's', 0.01, 5.0),
    _P('link_timeout', 1.0, 'no answer for this long -> link down, reconnect [s]', 's', 0.1, 30.0),
    _P('heartbeat_period', 0.25, 'PING when nothing was sent for this long [s] (board watchdog is 1 s)',
       's', 0.02, 0.9),
    _P('step_angle', STEP_ANGLE, 'motor rotation per step [rad/step] (seed 000: 0.006 deg)',
       'rad/step', 1e-7, 0.5),
    _P('gear_ratio', 1.0, 'motor angle per joint angle [-]', '-', 1e-3, 1e4),
    _P('offset', 0.0, 'joint angle at step count 0 [rad]', 'rad', -2 * math.pi, 2 * math.pi),
    _P('invert', False, 'positive steps turn the joint negative'),
    _P('lower_limit', JOINT_RANGE[_M][0], 'soft lower limit [rad] (mirrors -pi/4, others -pi/2)', 'rad', *_ANGLE),
    _P('upper_limit', JOINT_RANGE[_M][1], 'soft upper limit [rad] (pi/2)', 'rad', *_ANGLE),
    _P('max_speed', 0.05, 'maximum joint speed of a move [rad/s]', 'rad/s', *_SPEED),
    _P('min_speed', 1e-4, 'minimum joint speed of a move [rad/s]', 'rad/s', 1e-6, 2.0),
    _P('stow_position', STOW_POSITION[_M], 'stow (defocus) position [rad] (mirrors pi/2 sleeping, others 0)',
       'rad', *_ANGLE),
    _P('wind_stow_position', WIND_STOW_POSITION[_M], 'position of a wind stow (safety/state wind_stow) '
       '[rad] (default face-up: mirrors 0, others 0; least wind load)', 'rad', *_ANGLE),
    _P('host_loss_stow', 'position', "the board's own stow after losing the host (stored in its EEPROM "
       'at configure): off | position (host_loss_stow_position, only when referenced) | switch (toward '
       'home_switch)', choices=('off', 'position', 'switch')),
    _P('host_loss_stow_position', STOW_POSITION[_M], 'joint angle of the host-loss stow [rad] (default the '
       'stow position: mirrors pi/2 sleeping, defocused)', 'rad', *_ANGLE),
    _P('host_loss_stow_delay', 60.0, 'host silence after the board watchdog stop (1 s) before the board '
       'stows by itself [s]', 's', 1.0, 86400.0),
    _P('home_switch', 'sleep', 'limit switch HOME drives to: low | high | sleep (default sleep: '
       'mirrors +pi/2, others 0)', choices=tuple(HOME_SWITCHES)),
    _P('home_position', STOW_POSITION[_M], 'joint angle where the home switch closes [rad]', 'rad', *_ANGLE),
    _P('home_speed', 0.05, 'homing speed [rad/s]', 'rad/s', *_SPEED),
    _P('use_sensor', True, "use the board's position sensor (measured angle, re-referencing after a reset)"),
    _P('auto_home', True, 'home by itself when the board lost its position'),
    _P('reference_samples', 5, 'sensor readings at rest averaged to re-reference (SET_ZERO) [-]',
       '-', 1, 100),
    _P('safety_timeout', 1.0, 'safety/state silence that stops the axis [s] (steady clock)', 's', 0.05, 10.0),
    _P('safety_silent_stow_after', 1.0, 'further safety/state silence after the stop before the '
       'fail-safe stow (defocus) [s] (steady clock)', 's', 0.0, 60.0),
    _P('lost_step_tolerance', 0.005, 'step count vs sensor disagreement that faults [rad]', 'rad', 1e-5, 1.0),
    _P('stall_window', 1.0, 'stall observation window [s]', 's', 0.1, 60.0),
    _P('stall_min_motion', 0.01, 'commanded motion that must show on the sensor within '
       'stall_window [rad]', 'rad', 1e-5, 1.0),
    _P('max_jog', 0.2, 'largest |delta| of a jog [rad]', 'rad', 0.0, math.pi),
    _P('jog_speed', 0.02, 'default jog speed [rad/s]', 'rad/s', *_SPEED),
    *accuracy.PARAM_SPECS,
]


def cross_check(p: dict) -> list[str]:
    """Rules between parameters (each value alone is valid): soft limits ordered and
    inside the joint's kinematic limits (contract JOINT_LIMITS; the collector's range
    comes as the soft limits from its description), the stow positions inside them,
    min_speed <= max_speed."""
    axis = p['axis']
    if not p['lower_limit'] < p['upper_limit']:
        return [f"soft limits need lower_limit < upper_limit, got {p['lower_limit']!r}..{p['upper_limit']!r} rad"]
    mech = JOINT_LIMITS[axis]
    errors = []
    if p['lower_limit'] < mech[0] - 1e-9 or p['upper_limit'] > mech[1] + 1e-9:
        errors.append(f"soft limits [{p['lower_limit']:.4f}, {p['upper_limit']:.4f}] rad exceed the "
                      f'kinematic limits [{mech[0]:.4f}, {mech[1]:.4f}] rad of {axis}')
    else:
        for key in ('stow_position', 'wind_stow_position', 'host_loss_stow_position'):
            if not SoftLimits(p['lower_limit'], p['upper_limit']).contains(p[key]):
                errors.append(f"{key} {p[key]:.4f} rad outside the soft limits")
    if p['min_speed'] > p['max_speed']:
        errors.append('min_speed > max_speed')
    drive = p.get('drive', DRIVE_KINDS[0])
    if drive == DriveKind.LINEAR_ACTUATOR_INCLINOMETER and not (p['deadband'] > 0 and p['use_sensor']):
        errors.append('a linear_actuator_inclinometer drive needs deadband > 0 and use_sensor (its inclinometer)')
    if drive == DriveKind.STEPPER_NO_SWITCHES and (p['auto_home'] or p['use_sensor']):
        errors.append('a stepper_no_switches drive has no switch or sensor: auto_home and use_sensor must be '
                      'false (the operator references it with the home service at home_position)')
    if drive != DriveKind.LINEAR_ACTUATOR_INCLINOMETER and p['deadband'] != 0.0:
        errors.append(f'deadband is a property of a linear_actuator_inclinometer drive, not of {drive}')
    return errors + accuracy.cross_check(p)


#: The driver's parameters with the mirrors' defaults (:func:`params_for` per axis).
PARAMS = ParamTable(_SPECS, cross_check)


def params_for(axis: str, **_role) -> ParamTable:
    """The table of ``axis`` (defaults: its mechanical range as soft limits, its stow
    position as stow and home position); KeyError for an unknown axis. The node set's
    other role parameters (``_role``: the collector description's) are values, checked
    against this table like the site config's."""
    lo, hi = JOINT_RANGE[axis]
    return PARAMS.with_defaults(axis=axis, lower_limit=lo, upper_limit=hi,
                                stow_position=STOW_POSITION[axis], home_position=STOW_POSITION[axis],
                                wind_stow_position=WIND_STOW_POSITION[axis],
                                host_loss_stow_position=STOW_POSITION[axis])


def tuning_from(p: dict) -> tuple[AxisTuning, StallDetector]:
    """The core's tuning from a complete, valid set of values (``PARAMS.validate``)."""
    cal = Calibration(p['step_angle'], p['gear_ratio'], p['offset'], p['invert'])
    tuning = AxisTuning(p['axis'], cal, SoftLimits(p['lower_limit'], p['upper_limit']), p['max_speed'],
                        p['min_speed'], 1.0 / p['control_rate'], p['stow_position'], p['home_switch'],
                        p['home_position'], p['home_speed'], p['use_sensor'], p['auto_home'],
                        p['reference_samples'], p['drive'], p['deadband'],
                        wind_stow_position=p['wind_stow_position'])
    return tuning, StallDetector(p['lost_step_tolerance'], p['stall_window'], p['stall_min_motion'])


def board_port(p: dict) -> str:
    """The board's port: parameter ``port``, default ``/dev/sslfr/<axis>`` (udev name)."""
    return p['port'] or f'/dev/sslfr/{p["axis"]}'


#: pyserial URL schemes (serial_for_url) a board can be reached through.
URL_SCHEMES = ('loop', 'socket', 'rfc2217', 'spy', 'alt', 'hwgrep', 'cp2110')
#: Character-device majors that are never a board (Linux devices.txt): 1 = memory
#: devices (/dev/null, zero, full, random, urandom, mem, kmsg), 5 = /dev/tty,
#: console, ptmx; 4 with minor < 64 = virtual consoles /dev/tty0..63.
_NOT_A_BOARD = {1: 'a memory device', 5: 'the terminal / console / pty multiplexer'}


def port_problem(port: str, stat=os.stat) -> str | None:
    """None when ``port`` can be a board's port, else the reason (one line).

    Accepted: '' (the udev name), a pyserial URL of :data:`URL_SCHEMES`,
    ``xbee:<device>?addr=<16 hex digits>[&baud=N]``, and a device path that does not
    exist yet (a board plugged in later) or is a character device other than the
    memory devices, /dev/tty, the console, /dev/ptmx and the virtual consoles.
    ``stat`` is ``os.stat`` (injectable for tests).
    """
    if port == '':
        return None
    if any(ord(c) < 32 or c == '\x7f' for c in port):
        return f'port {port!r}: control characters'
    if port.startswith('xbee:'):
        m = re.fullmatch(r'xbee:([^?]+)\?addr=([0-9A-Fa-f]{16})(&baud=\d+)?', port)
        if m is None:
            return f"port {port!r}: expected 'xbee:<uart>?addr=<16 hex digits>[&baud=<bit/s>]'"
        return port_problem(m.group(1), stat)
    if '://' in port:
        scheme = port.split('://', 1)[0]
        if scheme not in URL_SCHEMES:
            return f'port {port!r}: unknown URL scheme {scheme!r} (pyserial: {", ".join(URL_SCHEMES)})'
        return None
    try:
        st = stat(port)
    except FileNotFoundError:
        return None                  # not plugged in yet: configure retries
    except OSError as exc:
        return f'port {port!r}: {exc.strerror or exc}'
    if not stat_mod.S_ISCHR(st.st_mode):
        return f'port {port!r} is not a character device (a serial port, pty or USB adapter)'
    major, minor = os.major(st.st_rdev), os.minor(st.st_rdev)
    what = _NOT_A_BOARD.get(major) or ('a virtual console' if major == 4 and minor < 64 else None)
    if what:
        return f'port {port!r} is {what} ({major}:{minor}), not a board'
    return None
