"""The board link's requests: answers matched to requests, retries with the same
sequence number, time-outs and NACKs (:class:`RequestTable` alone, and BoardLink
against a simulated board on a real pty)."""
import random
import time
from concurrent.futures import Future

import pytest

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.board_link import BoardLink, LinkTimeout, NackError
from sslfr_drivers.link.link_errors import AuthError
from sslfr_drivers.link.requests import Pending, RequestTable
from sslfr_drivers.link.transport import SerialTransport
from sslfr_sim.axis import AxisConfig, AxisSim
from sslfr_sim.base import FaultInjector
from sslfr_sim.runner import SimThread

from drivers_testutil import wait_for
from link_fixtures import link, sim  # noqa: F401 - fixtures


def _pending(key, msg=None, timeout=0.1, retries=1, deadline=1.0, refused=''):
    seq = key[1] if isinstance(key, tuple) else key
    data = bytes([0, 0, 0, 0, 0, seq & 0xFF, seq >> 8 & 0xFF])
    return Pending(key, msg or m.Ping(1), data, Future(), timeout, retries, deadline, refused=refused)


def test_table_retries_with_the_same_bytes_then_times_out():
    t = RequestTable('b')
    p = _pending(7)
    t.add(p)
    assert t.next_deadline() == 1.0
    assert t.due(0.99) == ([], [])
    resend, expired = t.due(1.0)
    assert resend == [p] and expired == [] and p.deadline == pytest.approx(1.1) and t.retries_sent == 1
    resend, expired = t.due(1.1)
    assert resend == [] and expired == [p]
    t.expire(p)
    with pytest.raises(LinkTimeout, match=r'no answer to Ping \(seq 7\)'):
        p.future.result(0)
    assert t.timeouts == 1 and t.get(7) is None and t.next_deadline() == float('inf')


def test_table_a_refused_hello_ends_with_its_reason_not_a_timeout():
    t = RequestTable('b')
    p = _pending(('n', 3), m.Hello(bytes(8)), retries=0, refused='the board does not accept this key')
    t.add(p)
    t.expire(t.due(5.0)[1][0])
    with pytest.raises(AuthError, match='does not accept'):
        p.future.result(0)
    assert t.timeouts == 0


def test_table_answers_nacks_and_refusals():
    t = RequestTable('b')
    ok, nack, refusal = _pending(1), _pending(2), _pending(3)
    for p in (ok, nack, refusal):
        t.add(p)
    t.answer(ok, m.Ack(0))
    t.answer(nack, m.Nack(m.MoveTo.TYPE, m.ErrorCode.NOT_HOMED))
    t.answer(refusal, m.Nack(m.Ping.TYPE, m.ErrorCode.REPLAY))       # a forged copy refused: ours waits
    t.answer(None, m.Nack(m.Ping.TYPE, m.ErrorCode.AUTH))
    t.answer(None, m.Nack(m.Ping.TYPE, m.ErrorCode.NO_SESSION))
    assert isinstance(ok.future.result(0), m.Ack)
    with pytest.raises(NackError, match='NOT_HOMED'):
        nack.future.result(0)
    assert not refusal.future.done() and t.get(3) is refusal
    assert (t.nacks, t.auth_refusals) == (2, 2)


def test_table_session_requests_leave_for_a_new_session_hello_stays():
    t = RequestTable('b')
    a, b, hello = _pending(1), _pending(2), _pending(('n', 1), m.Hello(bytes(8)))
    for p in (a, b, hello):
        t.add(p)
    assert t.take_session() == [a, b]
    assert t.get(('n', 1)) is hello and t.get(1) is None
    t.fail_all(RuntimeError('x'), session_only=True)
    assert not hello.future.done()
    t.fail_all(RuntimeError('x'))
    assert hello.future.done()


def test_link_info_nack_home_move(sim, link):
    assert link.info.board_kind == m.BoardKind.AXIS_STEPPER and link.info.is_simulator
    assert not link.last_status.homed and link.last_status.fault_bits & m.FaultBits.RESET
    with pytest.raises(NackError) as err:
        link.move_to(1000, 1000)
    assert err.value.code == m.ErrorCode.NOT_HOMED and 'NOT_HOMED' in str(err.value)
    link.set_zero(15000)                     # at the sleep switch = +90 deg
    link.move_to(14000, 3000)
    assert wait_for(lambda: not link.get_status().moving, 3)
    st = link.get_status()
    assert st.position == 14000 and st.homed
    assert abs(st.sensor_angle - sim.board.angle) < 1e-3    # sensor noise 0.003 deg
    assert abs(sim.board.angle - m.DEFAULT_STEP_RAD * 14000) < 1e-9
    c = link.counters()
    assert c['nacks'] == 1 and c['frames_lost'] == 0 and c['timeouts'] == 0


def test_submit_is_nonblocking_future(link):
    fut = link.submit(m.GetStatus())
    assert isinstance(fut.result(1.0), m.Status)


def test_lost_answers_retried_not_reexecuted_and_loss_exact(sim, link):
    """1 % ... here 20 % of board frames corrupted: every request still answered,
    duplicates served from the board's cache, frames_lost == frames corrupted."""
    sim.command('set_angle 0')
    link.set_zero(0)
    sim.command('corrupt_frames 0.2')
    for i in range(60):
        link.move_to(10 * (i % 3), 2000)
    sim.command('corrupt_frames 0')
    link.ping()           # a clean frame after the last corrupted one closes the gap
    time.sleep(0.05)
    with sim.locked():
        corrupted = sim.faults.frames_corrupted
        dups = sim.board.requests_duplicate
    assert corrupted > 5
    assert link.frames_lost == corrupted
    assert link.retries_sent >= dups > 0
    assert link.counters()['timeouts'] == 0


def test_corrupted_host_bytes_never_move_wrongly(sim, link):
    sim.command('set_angle 0')
    link.set_zero(0)
    sim.command('corrupt 0.01')
    targets = [random.Random(9).randrange(-500, 500) for _ in range(40)]
    for tgt in targets:
        try:
            link.move_to(tgt, 3000)
        except Exception:   # noqa: BLE001 - a request may time out under corruption
            pass
        with sim.locked():
            assert round(sim.board.target) in targets or sim.board.target == 0
    sim.command('corrupt 0')


def test_a_request_deadline_is_kept_while_the_reader_sleeps(sim, link):
    """A request submitted while the reader sleeps (up to its 0.25 s read_timeout)
    with a shorter time-out than that pokes the read: the unanswered request is retried
    and ends at its own deadline, not at the end of the reader's sleep."""
    sim.command('disconnect 3')
    time.sleep(0.1)
    t0 = time.monotonic()
    fut = link.submit(m.Ping(1), timeout=0.05, retries=0)
    with pytest.raises(Exception, match='no answer'):
        fut.result(timeout=2.0)
    took = time.monotonic() - t0
    assert took < 0.2, f'time-out seen after {took:.3f} s (deadline 0.05 s)'


def test_loss_counter_exact_across_board_sequence_wrap():
    """Board sequence numbers run across 65535 -> 0 (the session's frame count into its
    second epoch, which the tags cover) while 5 % of board frames are corrupted:
    frames_lost stays exactly the corrupted count, and every frame verifies."""
    from sslfr_drivers.link.protocol import SequenceCounter
    board = AxisSim(AxisConfig.for_axis('mobile_structure'), rng=random.Random(8))
    with SimThread.plain(board, FaultInjector(rng=random.Random(9))) as sim:
        lk = BoardLink(SerialTransport(sim.path), timeout=0.1, retries=4).start()
        try:
            assert lk.wait_up(3)
            lk.set_zero(0)
            with sim.locked():                 # a long session: the board near its wrap
                sim.board._cur.tx = SequenceCounter(65450)
                lk.tracker.last = 65449
            sim.command('corrupt_frames 0.05')
            for i in range(150):
                lk.move_to(i, 3000)
            sim.command('corrupt_frames 0')
            lk.ping()
            with sim.locked():
                corrupted = sim.faults.frames_corrupted
                wrapped_to = sim.board._cur.tx.peek()
            assert wrapped_to < 1000               # the board's counter wrapped
            assert corrupted > 0
            assert lk.frames_lost == corrupted
            assert lk.counters()['auth_failures'] == 0
        finally:
            lk.stop()
