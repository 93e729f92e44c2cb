"""The axis driver's messages in and out: a trajectory in numbers, and the status,
joint state and diagnostics built from one control step's
:class:`~sslfr_drivers.axis.supervisor.Snapshot` (no node, no lock, no board I/O)."""
from __future__ import annotations

from sensor_msgs.msg import JointState
from sslfr_common.contract import LinkState
from sslfr_common.node import stamp, to_sec
from sslfr_interfaces.msg import AxisStatus
from trajectory_msgs.msg import JointTrajectory

from sslfr_drivers.axis.trajectory import TrajectoryMsg, TrajectoryPoint


def trajectory_msg(msg: JointTrajectory) -> TrajectoryMsg:
    """A ``JointTrajectory`` in numbers (seconds) for :mod:`.trajectory`."""
    return TrajectoryMsg(tuple(msg.joint_names), to_sec(msg.header.stamp), tuple(
        TrajectoryPoint(to_sec(p.time_from_start), tuple(p.positions), tuple(p.velocities),
                        tuple(p.accelerations)) for p in msg.points))


def status_msg(axis: str, snap, lifecycle: str, session, refused: bool, now, last_error: str = '') -> AxisStatus:
    """``axes/<axis>/status``: the supervisor state when active, else the lifecycle
    state; stamped with the time the board was read (``now``, a builtin Time, before
    the first read). A refused board (wrong key, old protocol, exposed key file) shows
    ``refused: <last_error>`` in ``board_info`` with LINK_FAULT."""
    m = AxisStatus(axis=axis, state=snap.state if lifecycle == 'active' else lifecycle,
                   commanded=snap.commanded, setpoint=snap.setpoint, measured=snap.measured,
                   error=snap.measured - snap.setpoint)
    m.header.stamp = stamp(snap.stamp) if snap.stamp > 0 else now
    if snap.board is not None:
        b = snap.board
        m.steps, m.moving, m.homed = int(b.steps), bool(b.moving), bool(b.homed)
        m.limit_bits, m.fault_bits = int(b.limit_bits) & 0xFF, int(b.fault_bits) & 0xFFFF
    if session is None:
        m.link_state = int(LinkState.LINK_FAULT if refused else LinkState.LINK_DOWN)
        m.board_info = f'refused: {last_error}' if refused else ''     # e.g. a wrong key
    else:
        m.link_state = int(session.link_state())
        m.frames_lost, m.frames_bad = session.frames_lost() & 0xFFFFFFFF, session.frames_bad() & 0xFFFFFFFF
        m.board_info = session.refusal() or session.board_info
    return m


def joint_msg(axis: str, snap, session, calibration, now) -> JointState:
    """``joint_states`` of this joint: measured position, velocity from the board's
    step rate; stamped with the read time while moving (fast steps), else ``now`` (at
    rest the position holds until now)."""
    js = JointState(name=[axis], position=[float(snap.measured)],
                    velocity=[float(session.velocity(calibration))])
    js.header.stamp = stamp(snap.stamp) if snap.board.moving else now
    return js
