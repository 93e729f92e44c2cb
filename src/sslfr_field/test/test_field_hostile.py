"""The field page under hostile clients, over real sockets from several loopback
addresses (127.0.0.2 and up): malformed, oversized and nested bodies, unfinished
request heads, and a flood of wrong logins; the operator at 127.0.0.1 keeps being
answered and nothing reaches a collector. The page is the operator page's server and
limits (sslfr_web.app.Server, sslfr_common.netguard) with the field's routes."""
from __future__ import annotations

import asyncio
import contextlib
import json

import aiohttp

from sslfr_field import page
from field_fixtures import PASSWORD, Backend
from sslfr_web import auth
from sslfr_web.app import Server

OPERATOR = '127.0.0.1'
NESTED = b'[' * 5000 + b']' * 5000


@contextlib.contextmanager
def serving(tmp_path, **cfg):
    pw = auth.write_password_file(tmp_path / 'pw', PASSWORD)
    conf = {**page.field_page_params().defaults(), 'collectors': ['/c1', '/c2'], 'collector_ids': ['c1', 'c2'],
            'password_file': str(pw), 'audit_file': str(tmp_path / 'audit.jsonl'), **cfg}
    backend = Backend()
    op = page.FieldApp(conf, backend, {'c1': '/c1', 'c2': '/c2'})
    srv = Server(op, '127.0.0.1', 0)
    url = srv.start().rstrip('/')
    try:
        yield url, op, backend
    finally:
        srv.stop()
    text = '\n'.join(t for _, t in backend.logs)
    assert 'Traceback' not in text and all('\n' not in t for _, t in backend.logs)


def client(addr: str) -> aiohttp.ClientSession:
    return aiohttp.ClientSession(connector=aiohttp.TCPConnector(local_addr=(addr, 0), force_close=True),
                                 cookie_jar=aiohttp.CookieJar(unsafe=True), timeout=aiohttp.ClientTimeout(total=20))


async def operator_answered(url) -> bool:
    async with client(OPERATOR) as s:
        async with s.get(url + '/api/field') as r:
            return r.status == 200 and 'collectors' in await r.json()


def test_bad_bodies_slow_heads_and_a_login_flood_leave_the_operator_answered(tmp_path):
    with serving(tmp_path, max_request_bytes=200000, header_timeout=1.0, max_connections_per_address=8,
                 max_connections=40, login_max_failures=3) as (url, op, backend):
        port = int(url.rsplit(':', 1)[1])

        async def main():
            async with client('127.0.0.2') as s:
                for body in (NESTED, b'{"password": NaN}', b'\xff\xfe{', b'{"password": "x"', b'[]'):
                    async with s.post(url + '/api/login', data=body,
                                      headers={'Content-Type': 'application/json'}) as r:
                        assert r.status == 400, (body[:20], await r.text())
                async with s.post(url + '/api/login', data=b'x' * 300000) as r:
                    assert r.status == 413
            # wrong logins at once from three addresses: each address is locked out, none gets in
            async def guess(addr):
                async with client(addr) as s:
                    codes = []
                    for _ in range(6):
                        async with s.post(url + '/api/login', json={'password': 'wrong-guess'}) as r:
                            codes.append(r.status)
                    return codes
            floods = await asyncio.gather(*(guess(f'127.0.0.{k}') for k in (3, 4, 5)))
            assert all(set(c) <= {401, 429} and 429 in c for c in floods), floods
            # unfinished request heads from two addresses: capped per address, closed by the time-out
            slow = []
            for k in (6, 7):
                for _ in range(15):
                    r, w = await asyncio.open_connection('127.0.0.1', port, local_addr=(f'127.0.0.{k}', 0))
                    w.write(b'GET /api/field HTTP/1.1\r\nHost: x\r\nX-a: ')
                    slow.append((r, w))
            assert await operator_answered(url)
            assert op.guard.connections_of('127.0.0.6') <= 8
            for r, w in slow:
                with contextlib.suppress(ConnectionError, asyncio.TimeoutError):
                    await asyncio.wait_for(r.read(), 4.0)
                w.close()
            # the operator, from the trusted segment, still logs in and commands
            async with client(OPERATOR) as s:
                async with s.post(url + '/api/login', json={'password': PASSWORD}) as r:
                    assert r.status == 200
                    csrf = (await r.json())['csrf']
                async with s.post(url + '/api/command/stow', json={'collector': 'all'},
                                  headers={'X-CSRF-Token': csrf, 'Content-Type': 'application/json'}) as r:
                    assert r.status == 200 and (await r.json())['success'] is True
                async with s.post(url + '/api/command/stow', data=NESTED,
                                  headers={'X-CSRF-Token': csrf, 'Content-Type': 'application/json'}) as r:
                    assert r.status == 400
        asyncio.run(main())
        assert sorted(c[:2] for c in backend.calls) == [('c1', 'planner/set_mode'), ('c2', 'planner/set_mode')]
        assert op.counters['errors'] == 0 and op.counters['bad_requests'] >= 6 and op.counters['commands_refused'] >= 1
        assert op.guard.counters['connections_refused'] >= 14
        audit = [json.loads(x) for x in (tmp_path / 'audit.jsonl').read_text().splitlines()]
        assert any(a['command'] == 'stow' and not a['success'] for a in audit)   # the nested command
