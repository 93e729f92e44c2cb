"""Fixtures of the board-link tests (imported by name into the test modules): a
simulated mirrors board on a pty and a BoardLink UP with it."""
from __future__ import annotations

import random

import pytest

from sslfr_drivers.link.board_link import BoardLink
from sslfr_drivers.link.transport import SerialTransport
from sslfr_sim.axis import AxisConfig, AxisSim
from sslfr_sim.base import FaultInjector
from sslfr_sim.runner import SimThread




@pytest.fixture
def sim():
    board = AxisSim(AxisConfig.for_axis('mirrors'), rng=random.Random(3))
    s = SimThread.plain(board, FaultInjector(rng=random.Random(4))).start()
    yield s
    s.stop()


@pytest.fixture
def link(sim):
    lk = BoardLink(SerialTransport(sim.path), timeout=0.15, retries=3, heartbeat=0.2).start()
    assert lk.wait_up(3)
    yield lk
    lk.stop()
