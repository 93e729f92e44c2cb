"""The facts of the graph contract, defined once (docs/architecture.md).

Pure Python (no rclpy, no generated messages), so every core can import it. The topic
and service table at the end is the one place a topic or service name is written
(``test_topic_table.py`` scans the product code and docs/architecture.md). Where
ROS carries a fact as message constants (phase codes in ``TrackerPhase``, safety
levels in ``SafetyState``, link states in ``AxisStatus``) the values here are the
same numbers, and ``test_contract.py`` fails if they ever differ, or if another
module of the project defines one of these facts again.

Units: radians, SI.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass

# --------------------------------------------------------------------------- joints
#: The tracker's three movements (seed 000 section 4), in the order of every
#: per-axis tuple and of ``tracker/trajectory``'s joint_names.
MIRRORS, MOBILE_STRUCTURE, SECONDARY_REFLECTOR = 'mirrors', 'mobile_structure', 'secondary_reflector'
JOINTS: tuple[str, ...] = (MIRRORS, MOBILE_STRUCTURE, SECONDARY_REFLECTOR)

#: The longitudinal movements (the structure and reflector tilts beta_M, beta_a).
LONGITUDINAL_JOINTS: tuple[str, ...] = JOINTS[1:]

#: Seed 000 section 3.4: stepper motors and drivers "with a step of 0.006 deg" [rad].
STEP_ANGLE = math.radians(0.006)

#: Mechanical joint ranges [rad]: seed 000 section 4 gives the mirrors -45..+90 deg;
#: the mobile structure and the secondary reflector tilt 0..90 deg in magnitude
#: toward either end, so -pi/2..+pi/2 signed, rest at 0. The limit switches of the
#: boards (and of the simulated boards) sit at these ends.
JOINT_RANGE: dict[str, tuple[float, float]] = {
    MIRRORS: (-math.pi / 4, math.pi / 2),
    MOBILE_STRUCTURE: (-math.pi / 2, math.pi / 2),
    SECONDARY_REFLECTOR: (-math.pi / 2, math.pi / 2),
}

#: Kinematic limits of each joint [rad], whatever the collector: a mirror line turns at
#: most half a turn either way, the structure and the reflector tilt at most to the
#: vertical. A collector description's mechanical range lies within them; the rules on
#: a range (a driver's soft limits, a planner pose) are judged against the collector's.
JOINT_LIMITS: dict[str, tuple[float, float]] = {
    MIRRORS: (-math.pi, math.pi),
    MOBILE_STRUCTURE: (-math.pi / 2, math.pi / 2),
    SECONDARY_REFLECTOR: (-math.pi / 2, math.pi / 2),
}

#: Stow (defocus) position per joint [rad], also where the SLEEP switch (the home
#: reference) closes: mirrors go to the sleeping position +pi/2 (seed 000 section
#: 3.5.2, "no dust is deposited on the mirrors"); the longitudinal axes go back to
#: their 0 rad rest position.
STOW_POSITION: dict[str, float] = {MIRRORS: math.pi / 2, MOBILE_STRUCTURE: 0.0,
                                   SECONDARY_REFLECTOR: 0.0}

#: Wind stow position per joint [rad] (the default of the planner's ``stow.wind_pose``
#: and of each driver's ``wind_stow_position``): every surface face-up. A flat mirror
#: row edge-on to a horizontal wind (beta_0 = 0) shows it the least area and the least
#: overturning moment about its axis; the sleeping position (+pi/2, vertical mirrors)
#: is seed 000's protection against dust at night and turns the rows broadside to the
#: wind. The longitudinal axes are horizontal at their rest position (0).
WIND_STOW_POSITION: dict[str, float] = {'mirrors': 0.0, 'mobile_structure': 0.0,
                                        'secondary_reflector': 0.0}


def driver_node(joint: str) -> str:
    """Default node name of the axis driver of ``joint`` (``mirrors_driver``)."""
    return f'{joint}_driver'


# --------------------------------------------------------------------------- switches
#: The five limit switches of seed 000 section 3.5.1 (the fields of
#: ``sslfr_interfaces/LimitSwitches``), the joint each belongs to, and the nominal
#: joint angle [rad] at which it is closed in normal operation.
SWITCH_AXIS: dict[str, str] = {
    'initial': MIRRORS,                        # beta_0 = -pi/4, sunrise end (seed 000 section 4)
    'last': MIRRORS,                           # beta_0 = +pi/4, sunset end
    'sleeping': MIRRORS,                       # beta_0 = +pi/2, sleeping position
    'longitudinal_1': MOBILE_STRUCTURE,        # beta_M = 0, starting position
    'longitudinal_2': SECONDARY_REFLECTOR,     # beta_a = 0, starting position
}
SWITCHES: tuple[str, ...] = tuple(SWITCH_AXIS)
SWITCH_POSITION: dict[str, float] = {
    'initial': -math.pi / 4, 'last': math.pi / 4, 'sleeping': STOW_POSITION[MIRRORS],
    'longitudinal_1': STOW_POSITION[MOBILE_STRUCTURE],
    'longitudinal_2': STOW_POSITION[SECONDARY_REFLECTOR],
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


class DriveKind(str, enum.Enum):
    """How a movement is driven and where its position comes from (docs/collectors.md)."""

    STEPPER_SWITCHES = 'stepper_switches'                          # seed 000: stepper, limit switches, encoder
    LINEAR_ACTUATOR_INCLINOMETER = 'linear_actuator_inclinometer'  # seed 004: PWM actuator, inclinometer
    STEPPER_NO_SWITCHES = 'stepper_no_switches'                    # seed 003: stepper, referenced by the operator


#: The drive kinds' names, the first the default.
DRIVE_KINDS: tuple[str, ...] = tuple(k.value for k in DriveKind)


#: Lifecycle states in which an axis driver does not drive its axis
#: (``AxisStatus.state`` carries the lifecycle label then).
IDLE_DRIVER_STATES: frozenset[str] = frozenset({'unconfigured', 'inactive', 'finalized'})


# --------------------------------------------------------------------------- topics
class Qos(enum.Enum):
    """The QoS profiles of docs/architecture.md (built as rclpy profiles once, in
    ``sslfr_common.node.qos``)."""

    R10 = 'R10'     # reliable, volatile, keep last 10
    BE = 'BE'       # best effort, volatile, keep last 10
    TL1 = 'TL1'     # reliable, transient local, keep last 1: latched (late joiners get the latest)
    LOG = 'LOG'     # rcl's /rosout profile: reliable, transient local, keep last 1000, lifespan 10 s


@dataclass(frozen=True)
class Endpoint:
    """A topic or service of the graph: relative name and ROS type (``pkg/msg/Type``,
    ``pkg/srv/Type``). A name with a ``{field}`` (``axes/{axis}/status``) is a family,
    one per axis or sensor: :meth:`of` gives a member's name."""

    name: str
    type: str

    def of(self, part: str) -> str:
        """The member of a family for ``part`` (an axis, a thermocouple)."""
        head, brace, tail = self.name.partition('{')
        if not brace:
            raise ValueError(f'{self.name} is not a family of names')
        return head + part + tail.partition('}')[2]


@dataclass(frozen=True)
class Topic(Endpoint):
    """A topic: the publisher's QoS profile is :attr:`qos`; subscribers ask the same
    unless docs/architecture.md says otherwise (the safety node subscribes best effort)."""

    qos: Qos = Qos.R10

    @property
    def latched(self) -> bool:
        """Transient local: a late subscriber gets the latest message."""
        return self.qos is Qos.TL1


#: The topics of the graph (docs/architecture.md, section Topics; a test compares the two).
GPS_FIX = Topic('gps/fix', 'sensor_msgs/msg/NavSatFix')
GPS_TIME_REFERENCE = Topic('gps/time_reference', 'sensor_msgs/msg/TimeReference')
TRACKER_SUN = Topic('tracker/sun', 'sslfr_interfaces/msg/SunPosition')
TRACKER_PHASE = Topic('tracker/phase', 'sslfr_interfaces/msg/TrackerPhase', Qos.TL1)
TRACKER_TRAJECTORY = Topic('tracker/trajectory', 'trajectory_msgs/msg/JointTrajectory', Qos.TL1)
JOINT_STATES = Topic('joint_states', 'sensor_msgs/msg/JointState')
AXIS_STATUS = Topic('axes/{axis}/status', 'sslfr_interfaces/msg/AxisStatus')
ABSORBER_TEMPERATURE = Topic('absorber/{thermocouple}_temperature', 'sensor_msgs/msg/Temperature')
LIMIT_SWITCHES = Topic('limit_switches', 'sslfr_interfaces/msg/LimitSwitches')
WIND = Topic('wind', 'sslfr_interfaces/msg/Wind')
ABSORBER_FLOW = Topic('absorber/flow', 'sslfr_interfaces/msg/Flow')
THERMAL_POWER = Topic('absorber/thermal_power', 'sslfr_interfaces/msg/ThermalPower')
IRRADIANCE_ILLUMINANCE = Topic('irradiance/illuminance', 'sensor_msgs/msg/Illuminance')
IRRADIANCE_BEAM = Topic('irradiance/beam', 'sslfr_interfaces/msg/Irradiance')
SAFETY_STATE = Topic('safety/state', 'sslfr_interfaces/msg/SafetyState')
DIAGNOSTICS = Topic('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray')   # absolute: see collector_id
CLOCK = Topic('/clock', 'rosgraph_msgs/msg/Clock', Qos.BE)

#: rcl's log topic: every node's logger publishes it (rcl's QoS), the recorder keeps it.
ROSOUT = Topic('/rosout', 'rcl_interfaces/msg/Log', Qos.LOG)


def namespace_remaps(namespace: str) -> dict[str, str]:
    """Remappings (``from -> to``) every node of a collector in ``namespace`` gets.

    rcl's ``/rosout`` is absolute: in a field every collector's recorder would subscribe
    to every other collector's log lines (their bags then mixed the field's lines, and
    the links carried them). Under a namespace the nodes log to ``<namespace>/rosout``
    instead, which their own recorder keeps. ``/diagnostics`` stays absolute (ROS's
    aggregators read it there; collectors publish it and do not subscribe)."""
    nsp = (namespace or '').strip('/')
    return {ROSOUT.name: f'/{nsp}{ROSOUT.name}'} if nsp else {}

TOPICS: tuple[Topic, ...] = (
    GPS_FIX, GPS_TIME_REFERENCE, TRACKER_SUN, TRACKER_PHASE, TRACKER_TRAJECTORY, JOINT_STATES,
    AXIS_STATUS, ABSORBER_TEMPERATURE, LIMIT_SWITCHES, WIND, ABSORBER_FLOW, THERMAL_POWER,
    IRRADIANCE_ILLUMINANCE, IRRADIANCE_BEAM,
    SAFETY_STATE, DIAGNOSTICS, CLOCK, ROSOUT)

#: Each family's members: the axes and the thermocouples.
FAMILY_MEMBERS: dict[str, tuple[str, ...]] = {AXIS_STATUS.name: JOINTS,
                                              ABSORBER_TEMPERATURE.name: THERMOCOUPLES}

#: The services of the graph (docs/architecture.md, section Services).
PLANNER_REPLAN = Endpoint('planner/replan', 'std_srvs/srv/Trigger')
PLANNER_SET_MODE = Endpoint('planner/set_mode', 'sslfr_interfaces/srv/SetMode')
AXIS_HOME = Endpoint('axes/{axis}/home', 'std_srvs/srv/Trigger')
AXIS_JOG = Endpoint('axes/{axis}/jog', 'sslfr_interfaces/srv/Jog')
SAFETY_ESTOP = Endpoint('safety/estop', 'std_srvs/srv/SetBool')
SAFETY_RESET = Endpoint('safety/reset', 'std_srvs/srv/Trigger')

SERVICES: tuple[Endpoint, ...] = (PLANNER_REPLAN, PLANNER_SET_MODE, AXIS_HOME, AXIS_JOG,
                                  SAFETY_ESTOP, SAFETY_RESET)


def topic_names() -> dict[str, Topic]:
    """Every concrete topic name of the graph -> its topic (families expanded)."""
    out: dict[str, Topic] = {}
    for t in TOPICS:
        for name in ([t.of(m) for m in FAMILY_MEMBERS[t.name]] if '{' in t.name else [t.name]):
            out[name] = t
    return out


# --------------------------------------------------------------------------- diagnostics
#: Every node's diagnostics go to the ABSOLUTE ``/diagnostics`` (the ROS convention that
#: ``diagnostic_aggregator`` and rqt_robot_monitor read), also under a collector's
#: namespace; the collector is named by each status' ``hardware_id``
#: (:func:`collector_id`) and the status' ``name`` is ``"<node>: <task>"`` (the topic:
#: :data:`DIAGNOSTICS`).

#: ``hardware_id`` of a collector run in the root namespace (a single collector)
ROOT_COLLECTOR_ID = 'sslfr'


def collector_id(namespace: str) -> str:
    """The collector's id for a node in ``namespace``: the namespace's last name
    (``/field/c2`` -> ``c2``), :data:`ROOT_COLLECTOR_ID` in the root namespace. A field
    description makes each collector's namespace end in its id (sslfr_field.field)."""
    last = (namespace or '').rstrip('/').rsplit('/', 1)[-1]
    return last or ROOT_COLLECTOR_ID
