"""The relay in front of the Foxglove server, over real sockets with an echo server
behind it: admitted clients are piped both ways, others (by address, or beyond the
connection caps) are closed at once and counted, and a flood from other loopback
addresses leaves an admitted client served. (WebSocket hostile clients against the
real server: test_foxglove_hostile.py.)"""
from __future__ import annotations

import socket
import threading
import time

import pytest

from gateway_fixtures import extra_loopbacks  # noqa: F401 - a fixture
from sslfr_common.netguard import Limits, OneLineLog
from sslfr_gateway.allow_relay import AllowRelay, client_ip

HEAD = b'GET / HTTP/1.1\r\nHost: x\r\n\r\n'


@pytest.fixture
def echo():
    """A TCP echo server on loopback: the relay's target."""
    srv = socket.socket()
    srv.bind(('127.0.0.1', 0))
    srv.listen(64)
    stop = threading.Event()

    def serve():
        srv.settimeout(0.1)
        while not stop.is_set():
            try:
                conn, _ = srv.accept()
            except OSError:
                continue
            threading.Thread(target=_echo, args=(conn,), daemon=True).start()
    t = threading.Thread(target=serve, daemon=True)
    t.start()
    yield srv.getsockname()[1]
    stop.set()
    t.join(2)
    srv.close()


def _echo(conn):
    with conn:
        try:
            while data := conn.recv(4096):
                conn.sendall(data)
        except OSError:
            pass


def _roundtrip(port: int, source: str = '127.0.0.1') -> bytes:
    with socket.socket() as s:
        s.settimeout(3)
        s.bind((source, 0))
        s.connect(('127.0.0.1', port))
        try:
            s.sendall(HEAD)
            return s.recv(64)
        except (ConnectionResetError, BrokenPipeError):
            return b''


def test_client_ip_normalises_mapped_addresses():
    assert client_ip(('::ffff:127.0.0.1', 5, 0, 0)) == '127.0.0.1'
    assert client_ip(('127.0.0.2', 5)) == '127.0.0.2'
    assert client_ip(None) == ''


def test_allowed_clients_are_relayed_others_closed_and_a_flood_does_not_starve_them(echo, extra_loopbacks):
    if '127.0.0.2' not in extra_loopbacks:
        pytest.skip('no 127.0.0.2 on this machine')
    relay = AllowRelay('127.0.0.1', 0, echo, ('127.0.0.1',), Limits(max_connections=3, max_connections_per_address=3),
                       OneLineLog(lambda level, text: None))
    port = relay.start()
    held = []
    try:
        assert _roundtrip(port) == HEAD
        assert _roundtrip(port, '127.0.0.2') == b''
        for addr in extra_loopbacks * 20:
            s = socket.socket()
            s.bind((addr, 0))
            s.connect(('127.0.0.1', port))
            held.append(s)
        deadline = time.monotonic() + 10
        while relay.counters['refused_address'] < 21 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert relay.counters['refused_address'] >= 21
        assert _roundtrip(port) == HEAD
        # admitted connections beyond max_connections are closed too
        deadline = time.monotonic() + 5
        while relay.active > 0 and time.monotonic() < deadline:    # the round trips above are over
            time.sleep(0.05)
        assert relay.active == 0
        keep = []
        for _ in range(3):
            s = socket.socket()
            s.connect(('127.0.0.1', port))
            keep.append(s)
        deadline = time.monotonic() + 5
        while relay.active < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _roundtrip(port) == b''
        assert relay.guard.counters['connections_refused'] >= 1
        for s in keep:
            s.close()
        deadline = time.monotonic() + 5
        while relay.active > 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _roundtrip(port) == HEAD
    finally:
        for s in held:
            s.close()
        relay.stop()
