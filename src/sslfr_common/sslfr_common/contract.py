"""The facts of the graph contract, defined once (docs/architecture.md).

Pure Python (no rclpy, no generated messages), so every core can import it. Where
ROS carries a fact as message constants (phase codes in ``TrackerPhase``, safety
levels in ``SafetyState``, link states in ``AxisStatus``) the values here are the
same numbers, and ``test_contract.py`` fails if they ever differ, or if another
module of the project defines one of these facts again.

Units: radians, SI.
"""
from __future__ import annotations

import enum
import math

# --------------------------------------------------------------------------- joints
#: The tracker's three movements (seed 000 section 4), in the order of every
#: per-axis tuple and of ``tracker/trajectory``'s joint_names.
JOINTS: tuple[str, ...] = ('mirrors', 'mobile_structure', 'secondary_reflector')

#: The longitudinal movements (the structure and reflector tilts beta_M, beta_a).
LONGITUDINAL_JOINTS: tuple[str, ...] = JOINTS[1:]

#: Seed 000 section 3.4: stepper motors and drivers "with a step of 0.006 deg" [rad].
STEP_ANGLE = math.radians(0.006)

#: Mechanical joint ranges [rad]: seed 000 section 4 gives the mirrors -45..+90 deg;
#: the mobile structure and the secondary reflector tilt 0..90 deg in magnitude
#: toward either end, so -pi/2..+pi/2 signed, rest at 0. The limit switches of the
#: boards (and of the simulated boards) sit at these ends.
JOINT_RANGE: dict[str, tuple[float, float]] = {
    'mirrors': (-math.pi / 4, math.pi / 2),
    'mobile_structure': (-math.pi / 2, math.pi / 2),
    'secondary_reflector': (-math.pi / 2, math.pi / 2),
}

#: Stow (defocus) position per joint [rad], also where the SLEEP switch (the home
#: reference) closes: mirrors go to the sleeping position +pi/2 (seed 000 section
#: 3.5.2, "no dust is deposited on the mirrors"); the longitudinal axes go back to
#: their 0 rad rest position.
STOW_POSITION: dict[str, float] = {'mirrors': math.pi / 2, 'mobile_structure': 0.0,
                                   'secondary_reflector': 0.0}


def driver_node(joint: str) -> str:
    """Default node name of the axis driver of ``joint`` (``mirrors_driver``)."""
    return f'{joint}_driver'


# --------------------------------------------------------------------------- switches
#: The five limit switches of seed 000 section 3.5.1 (the fields of
#: ``sslfr_interfaces/LimitSwitches``), the joint each belongs to, and the nominal
#: joint angle [rad] at which it is closed in normal operation.
SWITCH_AXIS: dict[str, str] = {
    'initial': 'mirrors',                      # beta_0 = -pi/4, sunrise end (seed 000 section 4)
    'last': 'mirrors',                         # beta_0 = +pi/4, sunset end
    'sleeping': 'mirrors',                     # beta_0 = +pi/2, sleeping position
    'longitudinal_1': 'mobile_structure',      # beta_M = 0, starting position
    'longitudinal_2': 'secondary_reflector',   # beta_a = 0, starting position
}
SWITCHES: tuple[str, ...] = tuple(SWITCH_AXIS)
SWITCH_POSITION: dict[str, float] = {
    'initial': -math.pi / 4, 'last': math.pi / 4, 'sleeping': STOW_POSITION['mirrors'],
    'longitudinal_1': STOW_POSITION['mobile_structure'],
    'longitudinal_2': STOW_POSITION['secondary_reflector'],
}

#: The absorber tube's thermocouples (seed 000 section 3.5.3): ``absorber/<name>_temperature``.
THERMOCOUPLES: tuple[str, ...] = ('inlet', 'outlet')

#: Seed 000 section 3.5.3: above this absorber temperature [degC] the tracker defocuses.
TEMPERATURE_LIMIT_C = 150.0


# --------------------------------------------------------------------------- codes
class Phase(enum.IntEnum):
    """Day-cycle phase: the constants of ``sslfr_interfaces/TrackerPhase``."""

    NIGHT = 0
    PRE_DAWN = 1
    TRACKING = 2
    STOWING = 3
    MANUAL = 4
    STOW = 5
    MAINTENANCE = 6


#: Phase code -> constant name (``TrackerPhase.phase_name``).
PHASE_NAMES: dict[int, str] = {int(p): p.name for p in Phase}


class DayType(enum.IntEnum):
    """``TrackerPhase.day_type`` constants."""

    DAY_NORMAL = 0
    DAY_POLAR_DAY = 1
    DAY_POLAR_NIGHT = 2


#: Operator modes (``planner/set_mode``, ``TrackerPhase.mode``).
MODES: tuple[str, ...] = ('auto', 'stow', 'manual', 'maintenance')


class Level(enum.IntEnum):
    """Safety verdict: the constants of ``sslfr_interfaces/SafetyState``."""

    OK = 0
    WARN = 1
    STOW = 2
    ESTOP = 3


#: Level code -> constant name.
LEVEL_NAMES: dict[int, str] = {int(lv): lv.name for lv in Level}


class LinkState(enum.IntEnum):
    """Board link state: the ``LINK_*`` constants of ``sslfr_interfaces/AxisStatus``."""

    LINK_DOWN = 0
    LINK_CONNECTING = 1
    LINK_UP = 2
    LINK_FAULT = 3


#: Lifecycle states in which an axis driver does not drive its axis
#: (``AxisStatus.state`` carries the lifecycle label then).
IDLE_DRIVER_STATES: frozenset[str] = frozenset({'unconfigured', 'inactive', 'finalized'})


# --------------------------------------------------------------------------- diagnostics
#: Every node's diagnostics go to the ABSOLUTE ``/diagnostics`` (the ROS convention that
#: ``diagnostic_aggregator`` and rqt_robot_monitor read), also under a collector's
#: namespace; the collector is named by each status' ``hardware_id``
#: (:func:`collector_id`) and the status' ``name`` is ``"<node>: <task>"``.
DIAGNOSTICS_TOPIC = '/diagnostics'

#: ``hardware_id`` of a collector run in the root namespace (a single collector)
ROOT_COLLECTOR_ID = 'sslfr'


def collector_id(namespace: str) -> str:
    """The collector's id for a node in ``namespace``: the namespace's last name
    (``/field/c2`` -> ``c2``), :data:`ROOT_COLLECTOR_ID` in the root namespace. A field
    description makes each collector's namespace end in its id (sslfr_field.field)."""
    last = (namespace or '').rstrip('/').rsplit('/', 1)[-1]
    return last or ROOT_COLLECTOR_ID
