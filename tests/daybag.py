"""Test support: write a synthetic recorded day with the bag writer (known figures).

The day (UTC, 2026-06-21 at Almeria-like coordinates) has: tracker/phase at 1 Hz
(NIGHT, PRE_DAWN, TRACKING 06:00-20:00, STOWING, NIGHT) with known sunrise/sunset,
safety/state at ``safety_hz`` (one STOW 13:00-13:10 "outlet over-temperature"),
axes/mirrors/status at ``status_hz`` with a known sinusoidal error (amplitude
``err_amp`` rad), absorber temperatures (peak 152 degC at 13:00), irradiance/beam
(half-sine 800 W/m2 between 06:00 and 20:00 -> H = 800 * 14 h * 2/pi / 1000 kWh/m2),
gps/fix, and tracker/trajectory every ``traj_period`` s; optionally /rosout lines
(rcl_interfaces/msg/Log) at given times.
"""
from __future__ import annotations

import datetime as dt
import math

from rcl_interfaces.msg import Log
from rclpy.serialization import serialize_message
from sensor_msgs.msg import NavSatFix, Temperature
from sslfr_interfaces.msg import AxisStatus, Irradiance, SafetyState, TrackerPhase
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from sslfr_recording.bag import BagWriter, WriterOptions, profile

DAY0 = int(dt.datetime(2026, 6, 21, tzinfo=dt.timezone.utc).timestamp())
SUNRISE = DAY0 + 6 * 3600
SUNSET = DAY0 + 20 * 3600
STOW = (DAY0 + 13 * 3600, DAY0 + 13 * 3600 + 600)
BEAM_PEAK = 800.0


def expected_H(start: float, end: float) -> float:
    """Beam irradiation [kWh/m2] of the half-sine between SUNRISE and SUNSET within [start, end]."""
    a, b = max(start, SUNRISE), min(end, SUNSET)
    if b <= a:
        return 0.0
    w = math.pi / (SUNSET - SUNRISE)
    return BEAM_PEAK / w * (math.cos(w * (a - SUNRISE)) - math.cos(w * (b - SUNRISE))) / 3.6e6


def phase_at(t: float) -> int:
    if t < SUNRISE - 600:
        return 0
    if t < SUNRISE:
        return 1
    if t < SUNSET:
        return 2
    if t < SUNSET + 900:
        return 3
    return 0


def _stamp(msg, t: float):
    msg.header.stamp.sec = int(t)
    msg.header.stamp.nanosec = int(round((t - int(t)) * 1e9)) % 1_000_000_000
    return msg


def _time(field, t: float):
    field.sec = int(t)
    field.nanosec = int(round((t - int(t)) * 1e9)) % 1_000_000_000


def write_day(directory, start: float = DAY0, end: float = DAY0 + 86400, status_hz: float = 1.0,
              safety_hz: float = 1.0, err_amp: float = 0.002, traj_period: float = 60.0,
              phase_offset: float = 0.0, options: WriterOptions | None = None,
              error_of=None, state: str = 'active', logs=()) -> dict:
    """Write the day [start, end) to ``directory``; return the message counts per topic.

    ``phase_offset`` [s] shifts every phase transition (to make a what-if differ);
    ``error_of(t)`` [rad] replaces the sinusoidal error; ``state`` is the status' state;
    ``logs``: (t [s], level, node, text) written on /rosout at t.
    """
    w = BagWriter(directory, options or WriterOptions(fsync=False))
    tl = [profile(durability='transient_local', depth=1)]
    w.add_topic('/tracker/phase', 'sslfr_interfaces/msg/TrackerPhase', tl)
    w.add_topic('/tracker/trajectory', 'trajectory_msgs/msg/JointTrajectory', tl)
    w.add_topic('/safety/state', 'sslfr_interfaces/msg/SafetyState', [profile()])
    w.add_topic('/axes/mirrors/status', 'sslfr_interfaces/msg/AxisStatus', [profile()])
    w.add_topic('/absorber/outlet_temperature', 'sensor_msgs/msg/Temperature', [profile()])
    w.add_topic('/absorber/inlet_temperature', 'sensor_msgs/msg/Temperature', [profile()])
    w.add_topic('/irradiance/beam', 'sslfr_interfaces/msg/Irradiance', [profile()])
    w.add_topic('/gps/fix', 'sensor_msgs/msg/NavSatFix', [profile()])
    if logs:
        w.add_topic('/rosout', 'rcl_interfaces/msg/Log', [profile(durability='transient_local', depth=1000)])
    events = [(t, ('log', lg)) for lg in logs for t in [lg[0]]]
    t = start
    while t < end:
        events.append((t, 'sec'))
        t += 1.0
    if status_hz != 1.0:
        k = 0
        while start + k / status_hz < end:
            events.append((start + k / status_hz, 'status'))
            k += 1
    if safety_hz != 1.0:
        k = 0
        while start + k / safety_hz < end:
            events.append((start + k / safety_hz, 'safety'))
            k += 1
    events.sort(key=lambda e: e[0])
    seq = 0
    for t, kind in events:
        ns = int(round(t * 1e9))
        if isinstance(kind, tuple):
            _, level, node, text = kind[1]
            line = Log(level=level, name=node, msg=text, file='x.py', function='f', line=1)
            _time(line.stamp, t)
            w.write('/rosout', serialize_message(line), ns)
            continue
        if kind == 'sec':
            ph = phase_at(t - phase_offset)
            m = TrackerPhase(phase=ph, phase_name=['NIGHT', 'PRE_DAWN', 'TRACKING', 'STOWING'][ph],
                             mode='auto', reason='sun', day_type=0, latitude=36.8381,
                             longitude=-2.4597, altitude=60.0, site_source='gps')
            _time(m.sunrise, SUNRISE)
            _time(m.solar_noon, (SUNRISE + SUNSET) / 2)
            _time(m.sunset, SUNSET)
            w.write('/tracker/phase', serialize_message(_stamp(m, t)), ns)
            fix = NavSatFix(latitude=36.8381, longitude=-2.4597, altitude=60.0)
            w.write('/gps/fix', serialize_message(_stamp(fix, t)), ns)
            temp = 20.0 + 132.0 * math.exp(-((t - STOW[0]) / 3600.0) ** 2)
            w.write('/absorber/outlet_temperature', serialize_message(_stamp(Temperature(temperature=temp), t)), ns)
            w.write('/absorber/inlet_temperature',
                    serialize_message(_stamp(Temperature(temperature=temp - 10.0), t)), ns)
            g = BEAM_PEAK * math.sin(math.pi * (t - SUNRISE) / (SUNSET - SUNRISE)) if SUNRISE <= t <= SUNSET else 0.0
            w.write('/irradiance/beam', serialize_message(_stamp(Irradiance(beam=g, illuminance=g * 104,
                                                                             luminous_efficacy=104.0), t)), ns)
            if (t - start) % traj_period == 0:
                traj = JointTrajectory(joint_names=['mirrors'])
                for k in range(int(traj_period) + 1):
                    p = JointTrajectoryPoint(positions=[mirror_setpoint(t + k)])
                    p.time_from_start.sec = k
                    traj.points.append(p)
                w.write('/tracker/trajectory', serialize_message(_stamp(traj, t)), ns)
        if kind == 'sec' and status_hz == 1.0 or kind == 'status':
            sp = mirror_setpoint(t)
            err = err_amp * math.sin(2 * math.pi * t / 600.0) if error_of is None else error_of(t)
            st = AxisStatus(axis='mirrors', state=state, commanded=sp, setpoint=sp,
                            measured=sp + err, error=err, link_state=2, homed=True)
            w.write('/axes/mirrors/status', serialize_message(_stamp(st, t)), ns)
        if kind == 'sec' and safety_hz == 1.0 or kind == 'safety':
            stow = STOW[0] <= t < STOW[1]
            seq += 1
            s = SafetyState(level=2 if stow else 0, stow_required=stow,
                            reasons=['absorber: outlet 152.0 degC > 150 degC'] if stow else [],
                            sequence=seq)
            w.write('/safety/state', serialize_message(_stamp(s, t)), ns)
    w.close()
    return {k: v.message_count for k, v in w.topics.items()}


def mirror_setpoint(t: float) -> float:
    """A smooth mirror setpoint [rad]: +pi/2 at night, a ramp during the day."""
    if t < SUNRISE or t > SUNSET:
        return math.pi / 2
    return -math.pi / 4 + (math.pi / 2) * (t - SUNRISE) / (SUNSET - SUNRISE)
