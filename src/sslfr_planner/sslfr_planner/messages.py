"""The planner's outgoing messages, built from its cores' results (no rclpy).

The planner node publishes what these functions return; they import only message
classes, so they are unit-tested without a node. Stamps are ROS time; angles
radians (REP-103); site latitude/longitude degrees as in NavSatFix.
"""
from __future__ import annotations

from sslfr_common.contract import JOINTS, PHASE_NAMES, DayType
from sslfr_common.timeconv import duration, stamp
from sslfr_interfaces.msg import SunPosition, TrackerPhase
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from .phase_control import DAY_TYPE_CODES, PhaseControl
from .site_source import SiteFix
from .trajectory import Horizon


def trajectory_msg(h: Horizon, joints: tuple[str, ...] = JOINTS) -> JointTrajectory:
    """``tracker/trajectory``: the horizon's points for ``joints`` (the collector's
    movements, :data:`JOINTS` order; the horizon holds every contract joint), stamped
    at the first point, ``time_from_start`` relative to it (exact to the ns)."""
    t0 = float(h.t[0])
    msg = JointTrajectory(joint_names=list(joints))
    msg.header.stamp = stamp(t0)
    cols = [JOINTS.index(j) for j in joints]
    pos, vel = h.positions[:, cols].tolist(), h.velocities[:, cols].tolist()
    msg.points = [JointTrajectoryPoint(positions=pos[k], velocities=vel[k],
                                       time_from_start=duration(float(h.t[k]) - t0))
                  for k in range(len(h))]
    return msg


def phase_msg(control: PhaseControl, schedule, site: SiteFix, now: float) -> TrackerPhase:
    """``tracker/phase`` at ``now`` [s]: phase, mode and reason of ``control``; day
    type and events of ``schedule`` (a :class:`~sslfr_planner.day_cycle.DaySchedule`,
    None before the first plan); the planned ``site``."""
    msg = TrackerPhase(phase=control.phase, phase_name=PHASE_NAMES[control.phase], mode=control.mode,
                       reason=control.reason, latitude=site.latitude_deg, longitude=site.longitude_deg,
                       altitude=site.elevation, site_source=site.source)
    msg.header.stamp = stamp(now)
    if schedule is not None:
        ev = schedule.events
        msg.day_type = int(DAY_TYPE_CODES.get(ev.day_type, DayType.DAY_NORMAL))
        if ev.sunrise is not None:
            msg.sunrise = stamp(ev.sunrise)
        if ev.sunset is not None:
            msg.sunset = stamp(ev.sunset)
        msg.solar_noon = stamp(ev.solar_noon)
    return msg


def sun_msg(sun: tuple, now: float) -> SunPosition:
    """``tracker/sun`` at ``now`` [s] from ``DayCycle.sun(now)``: (zenith, azimuth,
    transversal, longitudinal [rad], above horizon, algorithm)."""
    zen, azi, tra, lon, above, algo = sun
    msg = SunPosition(zenith=float(zen), azimuth=float(azi), transversal=float(tra),
                      longitudinal=float(lon), above_horizon=bool(above), algorithm=algo)
    msg.header.stamp = stamp(now)
    return msg
