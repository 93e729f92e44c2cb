"""The planner node's parameters: one :class:`~sslfr_common.params.ParamTable` (pure).

Every parameter has a default, a description that states its unit, and a range (or a
set of choices). :data:`PLANNER_PARAMS` checks a complete set of values (ranges,
NaN, the cross-parameter rules of :func:`cross_check`); the node declares it with
``sslfr_common.node.declare_parameters`` and guards run-time changes with
``ParameterGuard``, so a refused change leaves the last good configuration in force.
Floating-point parameters also take integers (a site config's ``22`` for 22.0).

Units are SI and angles radians, except the site's latitude/longitude in degrees
(``_deg`` suffix, as NavSatFix) -- the team convention. Shared site keys
(``site.latitude_deg``, ``site.longitude_deg``, ``site.elevation``) normally come from
the ``/**`` section of the site config; the rest from its ``planner`` section.
"""
from __future__ import annotations

import math
from typing import Any

from sslfr_common.params import ParamSpec, ParamTable, writable_directory

from .collector import LAWS
from .site_source import ALTITUDE_RANGE

ALMERIA_LAT = 36 + 50 / 60 + 7 / 3600      # 36 deg 50' 07" N (seed 000 section 5.1)
ALMERIA_LON = -(2 + 24 / 60 + 8 / 3600)    # 2 deg 24' 08" W


_SPECS = (
    # --- site (fallback when there is neither a GPS fix nor a persisted one)
    ParamSpec('site.latitude_deg', ALMERIA_LAT,
              'Site latitude [deg], north positive (WGS-84); used without GPS fix or persisted fix',
              'deg', -90.0, 90.0),
    ParamSpec('site.longitude_deg', ALMERIA_LON,
              'Site longitude [deg], east positive (WGS-84); used without GPS fix or persisted fix',
              'deg', -180.0, 180.0),
    ParamSpec('site.elevation', 22.0, 'Site altitude [m] above the WGS-84 ellipsoid', 'm',
              *ALTITUDE_RANGE),
    ParamSpec('site.pressure', 101325.0,
              'Annual mean local air pressure [Pa], for refraction (NREL SPA)', 'Pa',
              30000.0, 110000.0),
    ParamSpec('site.temperature', 12.0,
              'Annual mean local air temperature [degC], for refraction (NREL SPA)', 'degC',
              -60.0, 60.0),
    ParamSpec('site.delta_t_model', True,
              'true: delta-T = TT - UT from the built-in model; false: use site.delta_t'),
    ParamSpec('site.delta_t', 69.0, 'delta-T = TT - UT [s] when site.delta_t_model is false',
              's', -100.0, 400.0),
    ParamSpec('site.replan_distance', 100.0,
              'A new GPS fix farther than this [m] from the planned site triggers a replan',
              'm', 1.0, 1.0e6),
    ParamSpec('gps.max_horizontal_std', 500.0,
              'Largest horizontal standard deviation [m] of an accepted gps/fix (known covariance)',
              'm', 1.0, 1.0e6),
    ParamSpec('gps.persist_min_distance', 50.0,
              'A valid fix is written to the state file when it moved more than this [m]',
              'm', 0.0, 1.0e6),
    ParamSpec('state_dir', '~/.local/state/sslfr',
              'Directory of the persisted site file planner_site.json ("" disables persistence); '
              'must be a directory the planner can write in, or create', validator=writable_directory),
    # --- collector (see sslfr_planner.collector.Collector)
    ParamSpec('collector.description', '',
              'The collector description file (docs/collectors.md), relative to the site config '
              "that names it or absolute; '' = none (the collector.* parameters alone, seed 000 by "
              'default). sslfr up / sim / doctor and the launch file validate it and refuse '
              'collector.* values that contradict it (read-only)', read_only=True),
    ParamSpec('collector.law', 'continuous',
              'Longitudinal law of mobile structure and secondary reflector: continuous '
              '(rays centred on the tube at every instant, 3-D trace; the most annual energy '
              'without jumps, docs/optics.md), eq16 (seed 000 eq. 16 as published), '
              'optimum_fixed (seed 001), daily (seed 000 section 1), horizontal (0/0: '
              'single-axis trackers, seeds 003 and 004)',
              '-', choices=LAWS),
    ParamSpec('collector.azimuth', 0.0,
              'Collector axis azimuth [rad], clockwise from true north (0: north-south axis); '
              "seed 004's gamma_col = -4.6 deg (west positive) is +0.0803 rad here",
              'rad', -math.pi / 2, math.pi / 2),
    ParamSpec('collector.n_per_side', 12,
              'Mirrors on each side of the central one, n [-] (2n+1 in all; seed 000: 12)',
              '-', 0, 100),
    ParamSpec('collector.central_mirror', True,
              'true: 2n+1 mirror lines with a central one (seed 000); false: 2n lines, none on '
              'the axis (seeds 003, 004). The published mirrors joint is always the common '
              "drive angle beta_0 = theta_t' / 2 (seed 000 eq. 13 in the tilted rows' frame)"),
    ParamSpec('collector.mirror_width', 0.06, 'Mirror width W_M [m]', 'm', 0.001, 5.0),
    ParamSpec('collector.gap', 0.024, 'Gap between consecutive mirrors d [m]', 'm', 0.0, 5.0),
    ParamSpec('collector.receiver_height', 1.5,
              'Receiver (focal) height above the mirror pivots f [m]', 'm', 0.05, 50.0),
    ParamSpec('collector.tube_diameter', 0.0486, 'Absorber tube diameter D [m]', 'm', 0.0, 1.0),
    ParamSpec('collector.pre_dawn_lead', 600.0,
              'PRE_DAWN starts this long [s] before tracking starts (seed 000 Step 2)',
              's', 0.0, 21600.0),
    ParamSpec('collector.stow_duration', 600.0,
              'STOWING lasts this long [s] after tracking ends (seed 000 Step 4)',
              's', 0.0, 21600.0),
    ParamSpec('collector.tracking_step', 0.0,
              '0: continuous tracking; > 0: the axes hold the position of the middle of each '
              'step interval [s] (seed 003: 900 s)', 's', 0.0, 21600.0),
    ParamSpec('collector.tracking_start', -1.0,
              '-1: track from sunrise; else tracking starts no earlier than this local clock '
              'time [s after local midnight] (seed 003: 7:00 = 25200 s)', 's', -1.0, 86400.0),
    ParamSpec('collector.tracking_end', -1.0,
              '-1: track until sunset; else tracking ends no later than this local clock '
              'time [s after local midnight] (seed 003: 17:00 = 61200 s)', 's', -1.0, 86400.0),
    ParamSpec('collector.utc_offset', 0.0,
              'Local clock = UTC + this [s], for tracking_start/tracking_end (Colombia: -18000)',
              's', -50400.0, 50400.0),
    # --- planner timing
    ParamSpec('horizon', 120.0, 'Length of the published setpoint horizon [s]', 's', 1.0, 3600.0),
    ParamSpec('step', 1.0, 'Spacing of the trajectory points [s]', 's', 0.1, 60.0),
    ParamSpec('republish_period', 5.0,
              'The trajectory is republished every this many seconds of ROS time [s]',
              's', 0.1, 600.0),
    ParamSpec('sun_period', 1.0, 'tracker/sun publication period [s] (ROS time)', 's', 0.1, 60.0),
    ParamSpec('phase_period', 1.0,
              'tracker/phase is republished at least every this many seconds [s] (ROS time)',
              's', 0.1, 60.0),
    ParamSpec('time_jump_threshold', 300.0,
              'A ROS-time jump larger than this [s] (either direction) triggers a replan',
              's', 0.5, 86400.0),
    ParamSpec('stow.speeds', [0.0175, 0.0175, 0.0175],
              'Axis rates of the stow ramp [rad/s]: mirrors, mobile_structure, secondary_reflector',
              'rad/s', 1e-4, 1.0, length=3),
    ParamSpec('initial_mode', 'auto', 'Operator mode at start-up', '-',
              choices=('auto', 'stow', 'manual', 'maintenance')),
)


def cross_check(values: dict[str, Any]) -> list[str]:
    """Rules between parameters: ``step <= horizon``; ``collector.tracking_start`` and
    ``collector.tracking_end`` are both set or both unset (-1) and start < end."""
    errors = []
    if values['step'] > values['horizon']:
        errors.append(f'step {values["step"]} s > horizon {values["horizon"]} s')
    ts, te = values['collector.tracking_start'], values['collector.tracking_end']
    if (ts < 0) != (te < 0):
        errors.append('collector.tracking_start and collector.tracking_end must both be set '
                      '(>= 0) or both be -1')
    elif ts >= 0 and not ts < te:
        errors.append(f'collector.tracking_start {ts} s must be before collector.tracking_end {te} s')
    return errors


#: Every parameter of the planner node, in declaration order.
PLANNER_PARAMS = ParamTable(_SPECS, cross_check, integers_for_floats=True)
