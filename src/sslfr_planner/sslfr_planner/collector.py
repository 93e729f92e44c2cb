"""Collector (tracker) description: geometry, tracking law, actuators, day cycle.

SI units and radians. Defaults are seed 000 Table 3 (the Almeria SSLFR) and seed 000
section 4 (mechanical ranges, sleeping position, 0.006 deg per motor step).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from sslfr_common.contract import JOINT_RANGE, JOINTS, STEP_ANGLE, STOW_POSITION

#: the longitudinal laws of :mod:`sslfr_planner.laws`
LAWS = ('continuous', 'optimum_fixed', 'horizontal', 'daily')
#: axis names, in the order of every per-axis tuple (the contract's joints)
AXES = JOINTS


@dataclass(frozen=True)
class Collector:
    """A linear Fresnel collector and its tracker.

    Attributes
    ----------
    n_per_side : int
        Mirrors on each side of the central one, n [-] (seed 000 Table 3: 12).
    mirror_width : float
        W_M [m] (0.06).
    gap : float
        d, gap between consecutive mirrors [m] (0.024).
    receiver_height : float
        f, receiver height above the mirror pivots [m] (1.5).
    tube_diameter : float
        D, absorber tube diameter [m] (0.0486).
    azimuth : float
        Azimuth of the collector axis, clockwise from north [rad]; 0 = north-south
        (seed 004 eqs. 1-2; seed 004's gamma_col is -azimuth).
    law : str
        Longitudinal law of the mobile structure and secondary reflector:
        'continuous' | 'optimum_fixed' | 'horizontal' | 'daily' (:mod:`laws`).
    mirror_min, mirror_max : float
        Mechanical range of the central mirror tilt beta_0 [rad] (-pi/4 .. +pi/2).
    sleeping : float
        Mirror sleeping position [rad] (+pi/2: mirrors vertical, no dust).
    tilt_max : float
        Largest |beta_M|, |beta_a| of the mobile structure and reflector [rad] (pi/2).
    structure_rest, reflector_rest : float
        Position of the mobile structure / secondary reflector at NIGHT and while
        STOWING under the 'continuous' law [rad] (0: horizontal). Fixed laws hold
        their value day and night.
    step_angle : float
        Axis rotation per motor step with a gear ratio of 1 [rad] (seed 000: 0.006 deg).
    gear_ratio : tuple of 3 floats
        Motor-to-axis reduction per axis (mirrors, mobile_structure,
        secondary_reflector) [-]; the axis step is step_angle / gear_ratio.
    pre_dawn_lead : float
        Length of the PRE_DAWN phase before sunrise [s] (move from sleeping to the
        initial position, seed 000 section 4.2).
    stow_duration : float
        Length of the STOWING phase after sunset [s] (seed 000 section 4.4).
    tracking_step : float
        0: continuous tracking; > 0: the axes hold the position computed for the
        middle of each interval [k step, (k+1) step) of UTC (seed 003: 900 s) [s].
    lepten_radius : float
        r, distance of the mirror surface from its rotation axis [m] (seed 004: 0.065).
        Used by :mod:`sslfr_planner.lepten`; 0 for the seed 000 field.
    lepten_positions : tuple of floats
        Rotation-axis positions x_i of the LEPTEN lines (west positive) [m]; empty
        for the seed 000 field (positions from n_per_side, mirror_width, gap).
    """

    n_per_side: int = 12
    mirror_width: float = 0.06
    gap: float = 0.024
    receiver_height: float = 1.5
    tube_diameter: float = 0.0486
    azimuth: float = 0.0
    law: str = 'continuous'
    mirror_min: float = JOINT_RANGE['mirrors'][0]
    mirror_max: float = JOINT_RANGE['mirrors'][1]
    sleeping: float = STOW_POSITION['mirrors']
    tilt_max: float = JOINT_RANGE['mobile_structure'][1]
    structure_rest: float = STOW_POSITION['mobile_structure']
    reflector_rest: float = STOW_POSITION['secondary_reflector']
    step_angle: float = STEP_ANGLE
    gear_ratio: tuple = (1.0, 1.0, 1.0)
    pre_dawn_lead: float = 600.0
    stow_duration: float = 600.0
    tracking_step: float = 0.0
    lepten_radius: float = 0.0
    lepten_positions: tuple = field(default_factory=tuple)

    def __post_init__(self):
        def finite(name):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f'collector {name} must be a finite number, got {v!r}')
            return v
        for name in ('mirror_width', 'gap', 'receiver_height', 'tube_diameter', 'azimuth', 'mirror_min',
                     'mirror_max', 'sleeping', 'tilt_max', 'structure_rest', 'reflector_rest', 'step_angle',
                     'pre_dawn_lead', 'stow_duration', 'tracking_step', 'lepten_radius'):
            finite(name)
        if not isinstance(self.n_per_side, int) or self.n_per_side < 0:
            raise ValueError(f'n_per_side must be an integer >= 0, got {self.n_per_side!r}')
        if self.law not in LAWS:
            raise ValueError(f'law must be one of {", ".join(LAWS)}; got {self.law!r}')
        checks = [
            (self.mirror_width > 0, 'mirror_width must be > 0 m'),
            (self.gap >= 0, 'gap must be >= 0 m'),
            (self.receiver_height > 0, 'receiver_height must be > 0 m'),
            (self.tube_diameter >= 0, 'tube_diameter must be >= 0 m'),
            (-math.pi <= self.mirror_min < self.mirror_max <= math.pi,
             'mirror range must satisfy -pi <= mirror_min < mirror_max <= pi'),
            (self.mirror_min <= self.sleeping <= self.mirror_max, 'sleeping must lie in the mirror range'),
            (0 < self.tilt_max <= math.pi / 2, 'tilt_max must be in (0, pi/2] rad'),
            (abs(self.structure_rest) <= self.tilt_max, '|structure_rest| must be <= tilt_max'),
            (abs(self.reflector_rest) <= self.tilt_max, '|reflector_rest| must be <= tilt_max'),
            (self.step_angle > 0, 'step_angle must be > 0 rad'),
            (0 <= self.pre_dawn_lead <= 6 * 3600, 'pre_dawn_lead must be within 0..21600 s'),
            (0 <= self.stow_duration <= 6 * 3600, 'stow_duration must be within 0..21600 s'),
            (0 <= self.tracking_step <= 6 * 3600, 'tracking_step must be within 0..21600 s'),
            (0 <= self.lepten_radius < self.receiver_height, 'lepten_radius must be in [0, receiver_height)'),
        ]
        for ok, text in checks:
            if not ok:
                raise ValueError(text)
        if len(self.gear_ratio) != 3 or not all(isinstance(g, (int, float)) and math.isfinite(g) and g > 0
                                                for g in self.gear_ratio):
            raise ValueError(f'gear_ratio must be three positive numbers, got {self.gear_ratio!r}')
        if not all(isinstance(x, (int, float)) and math.isfinite(x) for x in self.lepten_positions):
            raise ValueError('lepten_positions must be finite numbers [m]')

    @property
    def axis_steps(self) -> tuple:
        """Axis rotation per motor step for (mirrors, mobile_structure, secondary_reflector) [rad]."""
        return tuple(self.step_angle / g for g in self.gear_ratio)
