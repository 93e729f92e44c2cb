"""One stop path: every trigger that stops an axis (safety STOP of this axis, ESTOP
naming no axis, the operator e-stop, a lost safety/state heartbeat) is decided by
``SafetyWatch.verdict``, turned into a command by ``AxisSupervisor.stop`` and put on
the wire by ``AxisBoardSession.write``; the same STOP frame reaches the board (bytes
captured from the port) and the simulated motor stops. STOW goes the same way to a
MOVE_TO of the stow position. The driver's glue is replayed here as the node runs it
(``_on_safety``: the STOP at receipt, then ``receive``; ``_control_step``: read ->
tick -> write)."""
from __future__ import annotations

import math
import random
from types import SimpleNamespace

import pytest

from sslfr_common.contract import JOINT_RANGE, JOINTS, Level
from sslfr_drivers.axis import board_session as bs
from sslfr_drivers.axis.commands import STOP, Action, ActionKind
from sslfr_drivers.axis.joint import Calibration, SoftLimits
from sslfr_drivers.axis.safety_watch import SafetyVerdict, SafetyWatch
from sslfr_drivers.axis.supervisor import AxisSupervisor, AxisTuning
from sslfr_drivers.link import messages as m
from sslfr_drivers.link.protocol import Framer
from sslfr_drivers.link.transport import SerialTransport
from sslfr_sim.axis import AxisConfig, AxisSim
from sslfr_sim.base import FaultInjector
from sslfr_sim.runner import SimThread

from drivers_testutil import wait_for

PERIOD = 0.05          # [s] control period
CAL = Calibration()
STOW = 0.1             # [rad] stow position of this test's tuning (the jog goes to 0.3)


class RecordingTransport(SerialTransport):
    """The board's port, keeping every byte the host writes."""

    def __init__(self, *a, **kw):
        super().__init__(*a, **kw)
        self.sent = bytearray()

    def write(self, data: bytes) -> None:
        self.sent += data
        super().write(data)

    def messages(self) -> list:
        """The host's frames written so far, decoded (HELLO and the rest)."""
        out = []
        for frame in Framer().feed(bytes(self.sent)):
            try:
                out.append((frame.type, frame.payload, m.decode(frame)))
            except Exception:   # noqa: BLE001 - a HELLO of the null session decodes too; others skipped
                pass
        return out


@pytest.fixture
def rig(monkeypatch):
    board = AxisSim(AxisConfig.for_axis('mirrors'), rng=random.Random(3))
    sim = SimThread.plain(board, FaultInjector(rng=random.Random(4))).start()
    ports = []
    monkeypatch.setattr(bs, 'make_transport', lambda port, baud: ports.append(RecordingTransport(port, baud))
                        or ports[-1])
    session = bs.AxisBoardSession(sim.path, request_timeout=0.15, heartbeat=0.2)
    session.open()
    sim.command('set_angle 0')
    assert session.write(Action(ActionKind.SET_ZERO, 0)).ok
    path = []                                   # (what, detail) in call order
    _spy(monkeypatch, path, SafetyWatch, 'verdict', lambda res, a, kw: ('verdict', res[0]))
    _spy(monkeypatch, path, AxisSupervisor, 'stop', lambda res, a, kw: ('stop', a[2]))
    _spy(monkeypatch, path, bs.AxisBoardSession, 'write',
         lambda res, a, kw: ('write', a[1].kind, kw.get('wait', a[2] if len(a) > 2 else True)))
    yield SimpleNamespace(sim=sim, session=session, port=ports[0], path=path)
    session.close()
    sim.stop()


def _spy(monkeypatch, path: list, cls, name: str, describe) -> None:
    """Record ``describe(result, args, kwargs)`` in ``path`` at each call of ``cls.name``."""
    orig = getattr(cls, name)

    def spy(*a, **kw):
        res = orig(*a, **kw)
        path.append(describe(res, a, kw))
        return res
    monkeypatch.setattr(cls, name, spy)


def _sup():
    cfg = AxisTuning('mirrors', CAL, SoftLimits(*JOINT_RANGE['mirrors']), max_speed=0.5, min_speed=0.0005,
                     lead=PERIOD, stow_position=STOW, home_switch='sleep', home_position=math.pi / 2,
                     home_speed=0.02, use_sensor=False, auto_home=False)
    return AxisSupervisor(cfg)


class Driver:
    """The node's glue around the supervisor and the session, in the node's order."""

    def __init__(self, session):
        self.session, self.sup, self.t = session, _sup(), 100.0
        self.seq = 0

    def safety(self, level=Level.OK, stow=False, stopped=(), reasons=()):
        """axis_driver_node._on_safety."""
        self.seq += 1
        msg = SimpleNamespace(level=level, stow_required=stow, stopped_axes=list(stopped), reasons=list(reasons),
                              sequence=self.seq)
        if self.sup.safety.stop_at_receipt(self.t, msg) and self.session is not None:
            self.session.write(STOP, wait=False)
        self.sup.safety.receive(self.t, msg.level, msg.stow_required, msg.stopped_axes, msg.sequence, msg.reasons)

    def step(self, dt=PERIOD):
        """axis_driver_node._control_step at steady time advanced by ``dt`` [s]."""
        self.t += dt
        board = self.session.read(self.t, PERIOD).board
        act = self.sup.tick(self.t, self.t, board, True)
        if board is not None and act.kind != ActionKind.NONE:
            self.sup.record_write(act, *self.session.write(act))
        return act, board


def _moving(rig) -> Driver:
    """A driver following safety OK and jogging the axis: the motor turns."""
    d = Driver(rig.session)
    d.safety()
    d.sup.set_mode('maintenance')
    d.step()
    ok, why, _ = d.sup.request_jog(0.3, 0.0, d.step()[1], True, 1.0)
    assert ok, why
    assert d.step()[0].kind == ActionKind.MOVE
    assert wait_for(lambda: rig.session.read(d.t, PERIOD).board.moving, 2)
    rig.path.clear()
    return d


def _stops(rig) -> list:
    return [(t, p) for t, p, _ in rig.port.messages() if t == m.Stop.TYPE]


TRIGGERS = {
    'safety STOP of this axis': lambda d: d.safety(Level.ESTOP, True, ['mirrors'], ['switch:mirrors_low closed']),
    'safety ESTOP naming no axis': lambda d: d.safety(Level.ESTOP, False, [], ['ESTOP']),
    'operator e-stop (safety/estop)': lambda d: d.safety(Level.ESTOP, True, JOINTS,
                                                         ['operator e-stop (safety/estop): every axis stopped']),
    'safety/state heartbeat lost': lambda d: setattr(d, 't', d.t + d.sup.safety.timeout + 0.05),
}


def test_every_stop_trigger_takes_the_one_path_and_sends_the_same_frame(rig):
    frames, tick_paths = {}, {}
    for name, trigger in TRIGGERS.items():
        d = _moving(rig)
        before = len(_stops(rig))
        trigger(d)
        receipt = [e for e in rig.path if e[0] == 'write']
        del rig.path[:]
        act, _ = d.step(0.0)
        tick_paths[name] = [e for e in rig.path if e[0] in ('verdict', 'stop', 'write')]
        assert act == STOP and d.sup.state == 'stopped', name
        sent = _stops(rig)[before:]
        # the STOP at receipt (safety messages only), then the control tick's STOP
        if name == 'safety/state heartbeat lost':
            assert receipt == [] and len(sent) == 1, name
        else:
            assert receipt == [('write', ActionKind.STOP, False)] and len(sent) == 2, name
        frames[name] = set(sent)
        assert wait_for(lambda: not rig.session.read(d.t, PERIOD).board.moving, 2), name
    assert len(set(map(tuple, tick_paths.values()))) == 1, tick_paths
    assert next(iter(tick_paths.values())) == [('verdict', SafetyVerdict.STOP), ('stop', 'stopped'),
                                               ('write', ActionKind.STOP, True)]
    assert len(set.union(*frames.values())) == 1, frames          # one frame: STOP, empty payload
    assert set.union(*frames.values()) == {(m.Stop.TYPE, m.Stop().pack())}


def test_stow_takes_the_same_verdict_and_write_to_the_stow_position(rig):
    """STOW (the safety level, and the silence past ``timeout + silent_stow_after``): the
    same verdict and write, the frame a MOVE_TO of the stow position."""
    for stow in (lambda d: d.safety(Level.STOW, True, [], ['absorber hot']),
                 lambda d: setattr(d, 't', d.t + d.sup.safety.timeout + d.sup.safety.silent_stow_after + 0.05)):
        d = _moving(rig)
        stow(d)
        assert [e for e in rig.path if e[0] == 'write'] == []          # no STOP at receipt
        act, _ = d.step(0.0)
        assert rig.path[-2:] == [('verdict', SafetyVerdict.STOW), ('write', ActionKind.MOVE, True)]
        assert act == Action(ActionKind.MOVE, CAL.steps(STOW), act.speed) and d.sup.state == 'stowing'
        moves = [msg for t, _, msg in rig.port.messages() if t == m.MoveTo.TYPE]
        assert moves[-1].steps == CAL.steps(STOW)
