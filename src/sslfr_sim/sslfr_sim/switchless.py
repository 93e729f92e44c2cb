"""Simulated stepper axis board without limit switches (seed 003: Arduino UNO, TB6600
microstep driver, NEMA23 moving all mirrors through a linkage; no switches, no
position sensor).

The stepper board of :mod:`sslfr_sim.axis` with no switch inputs wired: the limit
bits are always 0, HOME is not implemented (NACK UNKNOWN_TYPE: there is no switch to
look for), and the only way to reference the counter is SET_ZERO, which the host
sends when the operator says where the axis is (docs/collectors.md "Drives"). The
hard stops stay ``overtravel`` beyond the movement's range: driven past them the
counter keeps counting and the mirrors do not move (lost steps). A reset loses the
reference (counter 0, not HOMED, fault RESET) and counts a boot (HELLO_REPLY).
"""
from __future__ import annotations

import math
import random

from sslfr_common.contract import MIRRORS, DriveKind
from sslfr_drivers.link import messages as m
from sslfr_sim.axis import AxisConfig, AxisSim


def config_from_description(desc, axis: str = MIRRORS, **kw) -> AxisConfig:
    """The axis of a collector description's ``axis`` movement (a stepper_no_switches
    drive): range ends, stow angle, step [rad/step] = step_deg / gear_ratio; ``kw`` sets
    other :class:`AxisConfig` fields."""
    mv = desc.movement(axis)
    if mv is None or mv.drive != DriveKind.STEPPER_NO_SWITCHES:
        raise ValueError(f'{desc.path}: {axis} is not a stepper_no_switches movement')
    return AxisConfig(axis=axis, lo=mv.range[0], hi=mv.range[1], sleep=mv.stow,
                      step_rad=mv.step / mv.gear_ratio, has_sensor=False, **kw)


def config_from_options(options: dict) -> AxisConfig:
    """The axis of runner options (``sim_board`` / ``fw_board --opt``): ``description``
    (default the shipped seed-003 file), ``axis``, ``initial_angle_deg``, ``max_speed``
    [steps/s], ``accel`` [steps/s^2]."""
    from sslfr_planner.description import load
    from sslfr_sim.actuator import shipped_description
    opts = dict(options)
    desc = load(opts['description']) if opts.get('description') else shipped_description('bucaramanga_single_axis')
    kw = {k: float(opts[k]) for k in ('max_speed', 'accel') if k in opts}
    if 'initial_angle_deg' in opts:
        kw['initial_angle'] = math.radians(float(opts['initial_angle_deg']))
    return config_from_description(desc, opts.get('axis', MIRRORS), **kw)


class SwitchlessAxisSim(AxisSim):
    """Stepper axis board without switches (see module docstring)."""

    name = 'sim-axis-noswitch'
    REQUESTS = AxisSim.REQUESTS - {m.Home.TYPE}

    @classmethod
    def from_description(cls, desc, axis: str = MIRRORS, board_id: int = 1,
                         rng: random.Random | None = None, **kw) -> 'SwitchlessAxisSim':
        """From a collector description's ``axis`` movement (:func:`config_from_description`)."""
        return cls(config_from_description(desc, axis, **kw), board_id=board_id, rng=rng)

    @classmethod
    def from_options(cls, options: dict, rng: random.Random, board_id: int = 1) -> 'SwitchlessAxisSim':
        """Build from runner options (:func:`config_from_options`)."""
        return cls(config_from_options(options), board_id=board_id, rng=rng)

    def limit_bits(self) -> int:
        """No switches wired: always 0."""
        return 0

    def _host_loss_valid(self, h: m.SetHostLossStow) -> bool:
        """As the switchless firmware (hl_valid with AXIS_NO_SWITCHES): no switch to stow
        toward, so only OFF and a step position are accepted."""
        return h.mode != m.HostLossMode.SWITCH and super()._host_loss_valid(h)
