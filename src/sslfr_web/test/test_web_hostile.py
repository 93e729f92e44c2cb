"""The operator page under hostile clients, over real sockets on loopback.

The page is served by its real :class:`~sslfr_web.app.Server` (the
connection guard included) from its own thread; attackers are clients bound to
other loopback addresses (127.0.0.2, 127.0.0.3, ...) and the operator is 127.0.0.1.
Each test checks that the page keeps answering the operator while it is attacked,
that no request is answered 500 and that the log gets one line per kind of refusal,
never a traceback. The ROS side is a backend that records what it is asked.
"""
from __future__ import annotations

import asyncio
import contextlib
import json
import socket

import aiohttp
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sslfr_web import auth, params, password_cli
from sslfr_web.app import OperatorApp, Server
from sslfr_web.commands import JogLimits
from sslfr_web.live import DayBuffer, LiveState

PASSWORD = 'operator-pass-1'
OPERATOR = '127.0.0.1'


class Backend:
    def __init__(self):
        self.state, self.buffer = LiveState(), DayBuffer(30.0)
        self.calls, self.logs = [], []

    def ros_time(self):
        return 1782030000.0

    def jog_limits(self):
        return {'mirrors': JogLimits(0.2, 0.1, -0.78, 1.57, 0.3)}

    def bag_dir(self):
        return None

    async def call(self, cmd):
        self.calls.append(cmd)
        return {'success': True, 'message': 'ok'}

    def log(self, level, text):
        self.logs.append((level, text))


@contextlib.contextmanager
def serving(tmp_path, **cfg):
    pw = auth.write_password_file(tmp_path / 'pw', PASSWORD)
    backend = Backend()
    conf = {**params.WEB_PARAMS.defaults(), 'password_file': str(pw), 'audit_file': str(tmp_path / 'audit.jsonl'),
            'report_dir': str(tmp_path / 'reports'), 'push_period': 0.05, **cfg}
    assert params.WEB_PARAMS.validate(conf) == []
    op = OperatorApp(conf, backend)
    srv = Server(op, '127.0.0.1', 0)
    url = srv.start()
    try:
        yield url.rstrip('/'), op, backend
    finally:
        srv.stop()
    text = '\n'.join(t for _, t in backend.logs)
    assert 'Traceback' not in text and all('\n' not in t for _, t in backend.logs)


def client(addr: str, **kw) -> aiohttp.ClientSession:
    return aiohttp.ClientSession(connector=aiohttp.TCPConnector(local_addr=(addr, 0), force_close=True),
                                 cookie_jar=aiohttp.CookieJar(unsafe=True), timeout=aiohttp.ClientTimeout(total=kw.pop('timeout', 20)), **kw)


async def post(session, url, path, body: bytes | None = None, **kw):
    async with session.post(url + path, data=body, **kw) as r:
        text = await r.text()
        return r.status, text


async def login(session, url, password=PASSWORD):
    async with session.post(url + '/api/login', json={'password': password}) as r:
        return r.status, await r.json()


async def operator_answered(url) -> bool:
    async with client(OPERATOR) as s:
        async with s.get(url + '/api/state') as r:
            return r.status == 200 and 'axes' in await r.json()


def audit_lines(tmp_path):
    path = tmp_path / 'audit.jsonl'
    return [json.loads(x) for x in path.read_text().splitlines()] if path.exists() else []


# ---------------------------------------------------------------------------------- login
def test_concurrent_wrong_logins_from_one_address_are_limited(tmp_path):
    with serving(tmp_path, login_max_failures=3, login_lockout=60.0) as (url, op, backend):
        async def main():
            async with client('127.0.0.2') as s:
                answers = await asyncio.gather(*(login(s, url, 'wrong-guess-%d' % k) for k in range(12)))
            codes = sorted(c for c, _ in answers)
            assert codes.count(401) == 3 and codes.count(429) == 9, codes
            async with client('127.0.0.2') as s:
                code, j = await login(s, url)               # even the right password: locked out
                assert code == 429 and j['retry_after'] > 0
            async with client(OPERATOR) as s:
                assert (await login(s, url))[0] == 200       # another address is not affected
        asyncio.run(main())
        assert op.counters['login_failures'] == 3


def test_global_limit_cannot_lock_out_the_trusted_segment_and_unlock_restores(tmp_path):
    # trusted: the console address only (loopback is the "segment" here); attackers .2-.9 are outside
    with serving(tmp_path, login_max_failures=2, login_lockout=300.0,
                 login_trusted_networks='127.0.0.1/32') as (url, op, backend):
        async def attack(addr):
            async with client(addr) as s:
                return [(await login(s, url, 'wrong-guess'))[0] for _ in range(2)]

        async def main():
            codes = await asyncio.gather(*(attack(f'127.0.0.{k}') for k in range(2, 12)))
            assert sum(c.count(401) for c in codes) == 20      # global limit (20) reached
            async with client('127.0.0.20') as s:              # a fresh untrusted address: refused
                assert (await login(s, url))[0] == 429
            async with client(OPERATOR) as s:                  # the console: never globally limited
                for _ in range(1):
                    assert (await login(s, url, 'typo-typo'))[0] == 401
                assert (await login(s, url))[0] == 200
            async with client('127.0.0.2') as s:
                assert (await login(s, url))[0] == 429
            assert password_cli.main(['--unlock', '--file', str(tmp_path / 'pw')]) == 0
            async with client('127.0.0.2') as s:              # the local unlock ends every lockout
                assert (await login(s, url))[0] == 200
        asyncio.run(main())
        assert op.counters['unlocks'] == 1


# --------------------------------------------------------------------------- bodies
NESTED = b'[' * 50000 + b']' * 50000
DEEP_OBJ = b'{"password": ' + b'{"a": ' * 200 + b'1' + b'}' * 200 + b'}'


def test_malformed_oversized_and_nested_bodies_are_400_counted_and_audited(tmp_path):
    with serving(tmp_path, max_request_bytes=200000) as (url, op, backend):
        async def main():
            async with client('127.0.0.2') as s:
                for body in (NESTED, DEEP_OBJ, b'{"password": NaN}', b'\xff\xfe{', b'{"password": "x"',
                             b'{"password": ' + b'9' * 5000 + b'}', b'[]', b'"x"'):
                    code, text = await post(s, url, '/api/login', body, headers={'Content-Type': 'application/json'})
                    assert code == 400 and 'request body' in text or 'login: expected' in text, (body[:20], text)
                code, text = await post(s, url, '/api/login', b'x' * 300000)
                assert code == 413
            async with client(OPERATOR) as s:
                code, j = await login(s, url)
                assert code == 200
                for body in (NESTED, b'{"axis": "mirrors", "delta": [[[[[[[[[[[[1]]]]]]]]]]]]}', b'{"delta": 1e999}'):
                    code, text = await post(s, url, '/api/command/jog', body, headers={'X-CSRF-Token': j['csrf']})
                    assert code == 400, text
            assert await operator_answered(url)
        asyncio.run(main())
        refused = [a for a in audit_lines(tmp_path) if a['command'] == 'jog' and not a['success']]
        assert len(refused) == 3 and 'nested deeper' in refused[0]['message']
        assert op.counters['bad_requests'] >= 11 and op.counters['errors'] == 0
        assert not backend.calls


# ------------------------------------------------------------------------ connections
async def _raw(addr, port):
    return await asyncio.open_connection('127.0.0.1', port, local_addr=(addr, 0))


async def _closed_within(reader, seconds) -> bool:
    try:
        while True:
            data = await asyncio.wait_for(reader.read(4096), seconds)
            if not data:
                return True
    except (ConnectionResetError, BrokenPipeError):
        return True
    except asyncio.TimeoutError:
        return False


def test_slow_and_idle_connections_are_dropped_and_capped_per_address(tmp_path):
    with serving(tmp_path, header_timeout=1.0, idle_timeout=2.0, max_connections_per_address=8,
                 max_connections=40) as (url, op, backend):
        port = int(url.rsplit(':', 1)[1])

        async def main():
            slow = []
            for k in range(3):                                  # 3 addresses x 20 unfinished heads
                for _ in range(20):
                    r, w = await _raw(f'127.0.0.{k + 2}', port)
                    w.write(b'GET /api/state HTTP/1.1\r\nHost: x\r\nX-a: ')
                    slow.append((r, w))
            idle = [await _raw('127.0.0.9', port) for _ in range(3)]
            assert await operator_answered(url)                # answered while they hang on
            for k in range(3):
                assert op.guard.connections_of(f'127.0.0.{k + 2}') <= 8
            # header time-out 1 s: every unfinished head is closed well within 4 s
            assert all(await asyncio.gather(*(_closed_within(r, 4.0) for r, _ in slow)))
            assert all(await asyncio.gather(*(_closed_within(r, 4.0) for r, _ in idle)))
            for _, w in slow + idle:
                w.close()
            assert await operator_answered(url)
        asyncio.run(main())
        c = op.guard.counters
        assert c['connections_refused'] >= 36 and c['header_timeouts'] >= 1 and c['idle_timeouts'] >= 1
        lines = [t for _, t in backend.logs if 'refused' in t or 'closed' in t]
        assert len(lines) <= 6, lines                          # one line per kind per 10 s


def test_a_slow_body_is_refused_408_and_the_page_keeps_answering(tmp_path):
    with serving(tmp_path, body_timeout=0.5) as (url, op, backend):
        port = int(url.rsplit(':', 1)[1])

        async def main():
            r, w = await _raw('127.0.0.2', port)
            w.write(b'POST /api/login HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n'
                    b'Content-Length: 100\r\n\r\n{"pass')
            head = await asyncio.wait_for(r.read(200), 5.0)
            assert head.startswith(b'HTTP/1.1 408'), head
            w.close()
            assert await operator_answered(url)
        asyncio.run(main())
        assert op.counters['bad_requests'] == 1
        assert any('did not arrive' in a['message'] for a in audit_lines(tmp_path))


def test_event_streams_are_capped_per_address_and_in_total(tmp_path):
    with serving(tmp_path, max_streams_per_address=2, max_streams=5) as (url, op, backend):
        async def open_stream(s):
            r = await s.get(url + '/api/events')
            assert r.status == 200
            await r.content.readuntil(b'\n\n')                 # retry: line
            return r

        async def main():
            sessions = [client(f'127.0.0.{k}') for k in (2, 2, 2, 3, 3, 3, 4, 4, 4)]
            try:
                streams = [await open_stream(s) for s in sessions]
                assert op.streams.count('127.0.0.2') <= 2 and op.streams.count() <= 5
                async with client(OPERATOR) as s:              # the operator's page gets its stream
                    r = await open_stream(s)
                    assert op.streams.count(OPERATOR) == 1 and op.streams.count() <= 5
                    r.close()
                for r in streams:
                    r.close()
            finally:
                for s in sessions:
                    await s.close()
        asyncio.run(main())
        assert op.counters['streams_evicted'] >= 5


def test_a_flood_of_bad_requests_from_several_addresses_leaves_one_line_per_kind(tmp_path):
    with serving(tmp_path) as (url, op, backend):
        port = int(url.rsplit(':', 1)[1])
        garbage = [b'GARBAGE\r\n\r\n', b'GET / HTTP/1.1\r\nHost: x\r\nContent-Length: -1\r\n\r\n',
                   b'GET /' + b'a' * 20000 + b' HTTP/1.1\r\n\r\n', b'\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03',
                   b'POST /api/login HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\nzz\r\n']

        async def raw(addr, data):
            r, w = await _raw(addr, port)
            w.write(data)
            try:
                head = await asyncio.wait_for(r.read(200), 5.0)
            except ConnectionResetError:
                head = b''
            w.close()
            return head

        async def main():
            heads = await asyncio.gather(*(raw(f'127.0.0.{2 + k % 4}', garbage[k % len(garbage)]) for k in range(100)))
            assert not [h for h in heads if h.startswith(b'HTTP/1.1 5')]
            async def nested():
                try:
                    return (await post(s, url, '/api/login', b'[' * 8000 + b']' * 8000))[0]
                except aiohttp.ClientError:
                    return 0                                   # beyond the per-address cap: refused
            async with client('127.0.0.6') as s:
                codes = await asyncio.gather(*(nested() for _ in range(40)))
                assert set(codes) <= {0, 400} and codes.count(400) >= 16, codes
            assert await operator_answered(url)
        asyncio.run(main())
        assert len(backend.logs) <= 10, backend.logs


# ------------------------------------------------------------------------ property test
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(method=st.sampled_from(['GET', 'POST', 'PUT', 'DELETE', 'HEAD', 'OPTIONS', 'PATCH']),
       path=st.one_of(st.sampled_from(['/api/login', '/api/command/jog', '/api/command/mode', '/api/logout',
                                       '/api/events', '/api/bags/x/report', '/static/../app.py']),
                      st.text(alphabet=st.characters(min_codepoint=33, max_codepoint=126), max_size=60)
                      .map(lambda t: '/' + t)),
       body=st.one_of(st.binary(max_size=300), st.recursive(
           st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=20),
           lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=8), kids, max_size=4),
           max_leaves=30).map(lambda v: json.dumps(v).encode())),
       headers=st.dictionaries(st.sampled_from(['Content-Type', 'X-CSRF-Token', 'Origin', 'Cookie',
                                                'Sec-Fetch-Site', 'Content-Length']),
                               st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=30),
                               max_size=3))
def test_no_request_of_any_shape_is_answered_500(method, path, body, headers, page):
    url, op = page
    port = int(url.rsplit(':', 1)[1])
    head = f'{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n'
    head += ''.join(f'{k}: {v}\r\n' for k, v in headers.items() if k != 'Content-Length')
    head += f'Content-Length: {headers.get("Content-Length", len(body))}\r\n\r\n'
    with socket.create_connection(('127.0.0.1', port), timeout=10) as sock:
        sock.sendall(head.encode() + body)
        sock.shutdown(socket.SHUT_WR)
        data = b''
        try:
            while len(data) < 64:
                piece = sock.recv(4096)
                if not piece:
                    break
                data += piece
        except (ConnectionResetError, socket.timeout):
            pass
    assert not data.startswith(b'HTTP/1.1 500'), data[:200]
    assert op.counters['errors'] == 0


@pytest.fixture(scope='module')
def page(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('page')
    with serving(tmp, body_timeout=1.0, max_connections_per_address=1000) as (url, op, _):
        yield url, op
