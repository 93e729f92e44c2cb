"""Collector (tracker) description: field geometry, tracking law, actuators, day cycle.

SI units and radians. Defaults are seed 000 Table 3 (the Almeria SSLFR) and seed 000
section 4 (mechanical ranges, sleeping position, 0.006 deg per motor step).

:class:`FieldGeometry` is the one definition of the mirror field and receiver
geometry: the tracker (:class:`Collector`), the 3-D ray model
(:mod:`sslfr_planner.raytrace`) and the offline analysis
(:class:`sslfr_planner.analysis.optics.OpticalParameters`) all hold one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sslfr_common.contract import (JOINT_RANGE, JOINTS, MIRRORS, MOBILE_STRUCTURE, SECONDARY_REFLECTOR, STEP_ANGLE,
                                   STOW_POSITION)

from . import geometry as _geometry

#: the longitudinal laws of :mod:`sslfr_planner.laws` (docs/optics.md compares them)
LAWS = ('continuous', 'eq16', 'optimum_fixed', 'daily', 'horizontal')
#: laws whose setpoints move during the day (the others hold one value per day or forever)
MOVING_LAWS = ('continuous', 'eq16')
#: axis names, in the order of every per-axis tuple (the contract's joints)
AXES = JOINTS


def _finite(owner: str, obj, names) -> None:
    for name in names:
        v = getattr(obj, name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ValueError(f'{owner} {name} must be a finite number, got {v!r}')


@dataclass(frozen=True)
class FieldGeometry:
    """Mirror field and receiver of a linear Fresnel collector (seed 000 Table 3, Fig. 4).

    Frame (docs/conventions.md): x west (across the rows), p along the rows toward the
    collector's +p ("south") end, z up; the origin is the centre of the central row,
    which is also the pivot of the mobile structure's longitudinal tilt beta_M. The
    absorber tube's axis passes through its own pivot at height ``aim_height`` =
    f + D/2 straight above the origin and tilts by beta_a about it (seed 001 Fig. 4,
    eqs. 31-32).

    Attributes
    ----------
    n_per_side : int
        Mirrors on each side of the central one, n [-] (12).
    mirror_width : float
        W_M [m] (0.06).
    mirror_length : float
        L_M, length of the mirror rows [m] (2.0).
    gap : float
        d, gap between consecutive mirrors [m] (0.024).
    receiver_height : float
        f, receiver height above the mirror pivots [m] (1.5).
    tube_diameter : float
        D, absorber tube diameter [m] (0.0486).
    tube_left, tube_right : float
        L_a^l and L_a^r, positions of the tube's ends along the tube from its pivot,
        +p positive [m] (seed 000 section 5.1, the three-movement tracker: +/-1.005;
        the classic horizontal LFR's tube is at -2.037..-0.037).
    central_mirror : bool
        True: 2n+1 mirrors with one on the axis (seed 000); False: 2n mirrors, none on
        the axis (seeds 003 and 004), at +/-(i - 1/2)(W_M + d).
    """

    n_per_side: int = 12
    mirror_width: float = 0.06
    mirror_length: float = 2.0
    gap: float = 0.024
    receiver_height: float = 1.5
    tube_diameter: float = 0.0486
    tube_left: float = 1.005
    tube_right: float = -1.005
    central_mirror: bool = True

    def __post_init__(self):
        _finite('collector', self, ('mirror_width', 'mirror_length', 'gap', 'receiver_height', 'tube_diameter',
                                    'tube_left', 'tube_right'))
        if isinstance(self.n_per_side, bool) or not isinstance(self.n_per_side, int) or self.n_per_side < 0:
            raise ValueError(f'n_per_side must be an integer >= 0, got {self.n_per_side!r}')
        if not isinstance(self.central_mirror, bool):
            raise ValueError(f'central_mirror must be true or false, got {self.central_mirror!r}')
        if not self.central_mirror and self.n_per_side < 1:
            raise ValueError('a field without a central mirror needs n_per_side >= 1')
        checks = [
            (self.mirror_width > 0, 'mirror_width must be > 0 m'),
            (self.mirror_length > 0, 'mirror_length must be > 0 m'),
            (self.gap >= 0, 'gap must be >= 0 m'),
            (self.receiver_height > 0, 'receiver_height must be > 0 m'),
            (self.tube_diameter >= 0, 'tube_diameter must be >= 0 m'),
            (self.tube_left > self.tube_right, 'tube_left must be > tube_right'),
        ]
        for ok, text in checks:
            if not ok:
                raise ValueError(text)

    @property
    def n_mirrors(self) -> int:
        """2n + 1 with a central mirror, else 2n [-]."""
        return 2 * self.n_per_side + (1 if self.central_mirror else 0)

    @property
    def aim_height(self) -> float:
        """Height of the tube's axis (the aim point) above the mirror pivots, f + D/2 [m]
        (seed 000 eq. 14)."""
        return self.receiver_height + self.tube_diameter / 2.0

    @property
    def tube(self) -> tuple[float, float]:
        """(L_a^r, L_a^l) [m]."""
        return (self.tube_right, self.tube_left)

    def mirror_positions(self) -> np.ndarray:
        """Pivot positions x_i of the mirrors, west positive [m] (seed 000 eq. 15; 2n without
        a central mirror)."""
        return _geometry.mirror_positions(self.n_per_side, self.mirror_width, self.gap, self.central_mirror)

    def receiver_angles(self) -> np.ndarray:
        """Signed angle psi_i from each mirror to the aim point [rad] (seed 000 eq. 14)."""
        return _geometry.receiver_angles(self.mirror_positions(), self.receiver_height, self.tube_diameter)

    def mirror_labels(self) -> list[str]:
        """Labels as in seed 000 Figs. 21-24: '12L', ..., '1L', 'C', '1R', ..., '12R'."""
        n = self.n_per_side
        return [f'{n - k}L' for k in range(n)] + (['C'] if self.central_mirror else []) \
            + [f'{k}R' for k in range(1, n + 1)]

    def field_width(self) -> float:
        """Mirror field width [m]: W = 2 n (W_M + d) + W_M (seed 000 eq. 28, seed 001 eq. 22);
        without a central mirror 2 n W_M + (2 n - 1) d."""
        k = self.n_mirrors
        return k * self.mirror_width + (k - 1) * self.gap


@dataclass(frozen=True)
class Collector:
    """A linear Fresnel collector and its tracker.

    Attributes
    ----------
    geometry : FieldGeometry
        The mirror field and receiver (seed 000 Table 3 by default).
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
    description : sslfr_planner.description.Description or None
        The collector description whose mirror law the tracker follows
        (:func:`sslfr_planner.prototype.commanded_lines`: seed 004 eq. 5, seed 003 eqs.
        5-6); None or a 'half_transversal' law: beta_0 = theta_t' / 2 (seed 000 eq. 13).
    """

    geometry: FieldGeometry = field(default_factory=FieldGeometry)
    azimuth: float = 0.0
    law: str = 'continuous'
    mirror_min: float = JOINT_RANGE[MIRRORS][0]
    mirror_max: float = JOINT_RANGE[MIRRORS][1]
    sleeping: float = STOW_POSITION[MIRRORS]
    tilt_max: float = JOINT_RANGE[MOBILE_STRUCTURE][1]
    structure_rest: float = STOW_POSITION[MOBILE_STRUCTURE]
    reflector_rest: float = STOW_POSITION[SECONDARY_REFLECTOR]
    step_angle: float = STEP_ANGLE
    gear_ratio: tuple = (1.0, 1.0, 1.0)
    pre_dawn_lead: float = 600.0
    stow_duration: float = 600.0
    tracking_step: float = 0.0
    lepten_radius: float = 0.0
    lepten_positions: tuple = field(default_factory=tuple)
    description: object = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        if not isinstance(self.geometry, FieldGeometry):
            raise ValueError(f'collector geometry must be a FieldGeometry, got {self.geometry!r}')
        _finite('collector', self, ('azimuth', 'mirror_min', 'mirror_max', 'sleeping', 'tilt_max', 'structure_rest',
                                    'reflector_rest', 'step_angle', 'pre_dawn_lead', 'stow_duration',
                                    'tracking_step', 'lepten_radius'))
        if self.law not in LAWS:
            raise ValueError(f'law must be one of {", ".join(LAWS)}; got {self.law!r}')
        checks = [
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
            (0 <= self.lepten_radius < self.geometry.receiver_height, 'lepten_radius must be in [0, receiver_height)'),
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
    def mirror_law(self) -> str:
        """The mirror law: the description's, else 'half_transversal' (seed 000 eq. 13)."""
        if self.description is None:
            return 'half_transversal'
        return self.description.movements[AXES[0]].law

    @property
    def axis_steps(self) -> tuple:
        """Axis rotation per motor step for (mirrors, mobile_structure, secondary_reflector) [rad]."""
        return tuple(self.step_angle / g for g in self.gear_ratio)
