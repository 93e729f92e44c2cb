"""The board link's state machine and heartbeat: re-read after a board reset, a
silence, an unplugged port, refusal of another protocol version; PING when idle
(:class:`LinkStateMachine` and :class:`Heartbeat` alone, and BoardLink against a
simulated board on a real pty)."""
import random
import time

import pytest

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.board_link import BoardLink, BoardLinkState, LinkDown, NackError
from sslfr_drivers.link.heartbeat import Heartbeat
from sslfr_drivers.link.link_state import LinkStateMachine
from sslfr_drivers.link.transport import SerialTransport
from sslfr_sim.axis import AxisConfig, AxisSim
from sslfr_sim.runner import SimThread

from drivers_testutil import wait_for
from link_fixtures import link, sim  # noqa: F401 - fixtures


def test_heartbeat_pings_when_idle_and_counts_silence():
    hb = Heartbeat(0.25, 1.0)
    hb.last_tx = hb.last_rx = 10.0
    assert not hb.ping_due(10.24) and hb.ping_due(10.25) and hb.next_ping() == 10.25
    assert not hb.unheard(11.0) and hb.unheard(11.01) and hb.next_unheard() == pytest.approx(11.001)
    assert not hb.quiet(11.0) and hb.quiet(11.01)
    off = Heartbeat(None, 1.0)
    assert not off.ping_due(1e9) and not off.unheard(1e9)


def test_state_listeners_are_told_before_the_state_shows():
    """A listener sees its state before ``shown`` (what BoardLink.state and wait_up
    show) changes; a change made by a listener wins over the one that called it."""
    pokes = []
    link = type('L', (), {'name': 'b', 'log_extra': {}, 'poke': lambda self, within=0.0: pokes.append(within)})()
    sm = LinkStateMachine(link, 0.1, 1.0)
    seen = []
    sm.listeners.append(lambda state, lk: seen.append((state, sm.shown)))
    sm.set(BoardLinkState.CONNECTING)
    assert seen == [(BoardLinkState.CONNECTING, BoardLinkState.DOWN)] and sm.shown == BoardLinkState.CONNECTING
    sm.set(BoardLinkState.CONNECTING)                       # no change, no call
    assert len(seen) == 1 and len(pokes) == 1
    sm.listeners.append(lambda state, lk: state == BoardLinkState.UP and sm.set(BoardLinkState.SILENT))
    sm.set(BoardLinkState.UP)
    assert sm.state == sm.shown == BoardLinkState.SILENT and not sm.wait_up(0.0)


def test_board_reset_detected_and_state_reread(sim, link):
    link.set_zero(100)
    resets = link.resets
    states = []
    link.add_state_listener(lambda s, lk: states.append(s))
    sim.command('reset')
    assert wait_for(lambda: link.resets > resets and link.state == BoardLinkState.UP, 3)
    st = link.last_status
    assert not st.homed and st.fault_bits & m.FaultBits.RESET and st.position == 0
    assert BoardLinkState.CONNECTING in states and states[-1] == BoardLinkState.UP
    with pytest.raises(NackError):
        link.move_to(50, 100)    # no move before re-homing


def test_silence_then_recovery(sim, link):
    sim.command('disconnect 1.6')
    assert wait_for(lambda: link.state == BoardLinkState.SILENT, 2.5)
    assert wait_for(lambda: link.state == BoardLinkState.UP, 4)
    assert link.get_status().fault_bits & m.FaultBits.RESET   # state re-read


def test_unplug_reconnects_with_backoff(tmp_path):
    board = AxisSim(AxisConfig.for_axis('mobile_structure'), rng=random.Random(5))
    link_path = str(tmp_path / 'ttySIM')
    with SimThread.plain(board, link=link_path) as sim:
        lk = BoardLink(SerialTransport(link_path), timeout=0.15, heartbeat=0.2,
                       backoff_min=0.05, backoff_max=0.4).start()
        try:
            assert lk.wait_up(3)
            lk.set_zero(0)
            sim.command('unplug 1.0')
            assert wait_for(lambda: lk.state == BoardLinkState.DOWN, 2)
            with pytest.raises(LinkDown):
                lk.ping()
            assert wait_for(lambda: lk.state == BoardLinkState.UP, 5)
            assert lk.reconnects == 1
            assert lk.get_status().homed       # same board, not reset: position kept
        finally:
            lk.stop()


def test_old_protocol_version_refused():
    board = AxisSim(rng=random.Random(1), protocol_version=7)
    with SimThread.plain(board) as sim:
        lk = BoardLink(SerialTransport(sim.path), timeout=0.1, retries=1).start()
        try:
            assert wait_for(lambda: lk.state == BoardLinkState.REFUSED, 3)
            assert 'protocol version 7' in str(lk.version_error)
            with pytest.raises(Exception, match='version 7'):
                lk.move_to(1, 1)
            assert not lk.wait_up(0.3)
        finally:
            lk.stop()


def test_version_1_board_is_read_for_info_and_refused_for_motion():
    """Issue 19: a board of protocol version 1 (no authentication) still tells what it
    is (INFO read with a version-1 request) and is refused for motion with the clear
    version message, whose text names both versions."""
    board = AxisSim(rng=random.Random(1), protocol_version=1)
    with SimThread.plain(board) as sim:
        lk = BoardLink(SerialTransport(sim.path), timeout=0.1, retries=1).start()
        try:
            assert wait_for(lambda: lk.state == BoardLinkState.REFUSED and lk.info is not None, 3)
            assert lk.info.protocol == 1 and lk.info.board_kind == m.BoardKind.AXIS_STEPPER
            assert lk.info.firmware == '1.0.0'
            assert 'protocol version 1, this host speaks version 2' in str(lk.version_error)
            with pytest.raises(Exception, match='protocol version 1'):
                lk.move_to(1, 1)
        finally:
            lk.stop()


class _CountingTransport:
    """Wraps a transport and counts its reads (each read is one reader wake-up)."""

    def __init__(self, inner):
        self.inner = inner
        self.name = inner.name
        self.reads = 0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def read(self, timeout):
        self.reads += 1
        return self.inner.read(timeout)


def test_idle_link_reader_sleeps_until_its_deadlines(sim):
    """The reader wakes for a frame or the link's next deadline (here the 0.2 s
    heartbeat), not every 20 ms: an idle link over 1.5 s costs about 8-16 reads, where
    the former fixed 20 ms poll cost 75 (issue 16). Its heartbeats keep the board's
    1 s watchdog quiet and it stays UP."""
    t = _CountingTransport(SerialTransport(sim.path))
    lk = BoardLink(t, timeout=0.15, retries=3, heartbeat=0.2).start()
    try:
        assert lk.wait_up(3)
        time.sleep(0.3)
        r0, sent0 = t.reads, lk.frames_sent
        time.sleep(1.5)
        reads, pings = t.reads - r0, lk.frames_sent - sent0
        assert lk.state == BoardLinkState.UP
        assert 5 <= pings <= 9, pings                 # a PING per 0.2 s of silence
        assert reads <= 4 * pings + 4, (reads, pings)  # PING, its answer, the deadline
    finally:
        lk.stop()
