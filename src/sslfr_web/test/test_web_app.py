"""HTTP-level tests of the operator page's application (sslfr_web.app) over a
real aiohttp server on loopback. The ROS side is replaced by a backend that records
the service calls it is asked for (the graph itself is exercised by
tests/test_web_node.py and the browser test), so each test can assert that a refused
request called NOTHING."""
from __future__ import annotations

import asyncio
import io
import json
import zipfile

from pathlib import Path

import pytest
from aiohttp.test_utils import TestClient, TestServer

from sslfr_web import auth, params
from sslfr_web.app import COOKIE, OperatorApp
from sslfr_web.commands import JogLimits
from sslfr_web.live import DayBuffer, LiveState

PASSWORD = 'operator-pass-1'


class RecordingBackend:
    def __init__(self, bag_dir=None):
        self.state, self.buffer = LiveState(), DayBuffer(30.0)
        self.calls, self.logs, self._bag_dir = [], [], bag_dir

    def ros_time(self):
        return 1782030000.0

    def jog_limits(self):
        return {'mirrors': JogLimits(0.2, 0.1, -0.78, 1.57, 0.3)}

    def bag_dir(self):
        return self._bag_dir

    async def call(self, cmd):
        self.calls.append(cmd)
        return {'success': cmd.name != 'reset', 'message': 'refused: still hot' if cmd.name == 'reset' else 'ok'}

    def log(self, level, text):
        self.logs.append((level, text))


@pytest.fixture
def pwfile(tmp_path):
    return auth.write_password_file(tmp_path / 'pw', PASSWORD)


def run(tmp_path, pwfile, body, backend=None, **cfg):
    """Run ``body(client, backend, op)`` against a live server on 127.0.0.1."""
    backend = backend or RecordingBackend()
    conf = {**params.WEB_PARAMS.defaults(), 'password_file': str(pwfile), 'audit_file': str(tmp_path / 'audit.jsonl'),
            'report_dir': str(tmp_path / 'reports'), 'push_period': 0.05, **cfg}
    op = OperatorApp(conf, backend)

    async def main():
        async with TestClient(TestServer(op.application(), host='127.0.0.1')) as client:
            await body(client, backend, op)
    asyncio.run(main())
    return backend, op


async def login(client, password=PASSWORD):
    r = await client.post('/api/login', json={'password': password})
    return r, await r.json()


def test_page_assets_are_local_with_a_strict_content_security_policy(tmp_path, pwfile):
    async def body(client, backend, op):
        r = await client.get('/')
        html = await r.text()
        assert r.status == 200 and 'software stop' in html
        assert "default-src 'self'" in r.headers['Content-Security-Policy']
        assert 'http://' not in html and 'https://' not in html.replace('http://www.w3.org', '')
        for asset in ('app.js', 'style.css'):
            r = await client.get(f'/static/{asset}')
            text = await r.text()
            assert r.status == 200 and 'https://' not in text and '//cdn' not in text
        assert (await client.get('/static/..%2Fapp.py')).status == 404
        assert (await client.get('/static/nothing.js')).status == 404
    run(tmp_path, pwfile, body)


def test_commands_need_login_and_csrf_and_refusals_call_nothing(tmp_path, pwfile):
    async def body(client, backend, op):
        r = await client.post('/api/command/stow', json={})
        assert r.status == 401 and 'log in' in (await r.json())['message']
        r, j = await login(client, 'wrong password')
        assert r.status == 401 and j['message'] == 'wrong password'
        r, j = await login(client)
        assert r.status == 200 and j['csrf']
        cookie = r.headers['Set-Cookie']
        assert f'{COOKIE}=' in cookie and 'HttpOnly' in cookie and 'SameSite=Strict' in cookie
        assert (await client.post('/api/command/stow', json={})).status == 403                 # no CSRF token
        r = await client.post('/api/command/stow', json={}, headers={'X-CSRF-Token': 'forged'})
        assert r.status == 403
        assert backend.calls == []
        hdr = {'X-CSRF-Token': j['csrf']}
        r = await client.post('/api/command/stow', json={}, headers=hdr)
        res = await r.json()
        assert r.status == 200 and res['success'] and res['service'] == 'planner/set_mode'
        assert backend.calls[-1].request == {'mode': 'stow'}
        r = await client.post('/api/command/reset', headers=hdr)
        res = await r.json()
        assert r.status == 200 and res['success'] is False and res['message'] == 'refused: still hot'
        n = len(backend.calls)
        for path, data, status, why in [
            ('mode', b'{"mode": "turbo"}', 400, 'unknown mode'),
            ('mode', b'{"mode": ', 400, 'not valid JSON'),
            ('mode', b'[1]', 400, 'JSON object'),
            ('jog', b'{"axis": "mirrors", "delta": 0.5}', 400, 'beyond the jog limit'),
            ('jog', b'{"axis": "mirrors", "delta": 1e400}', 400, 'finite'),
            # a movement the collector lacks (the backend's jog limits: mirrors only)
            ('jog', b'{"axis": "mobile_structure", "delta": 0.01}', 400, "unknown axis 'mobile_structure'"),
            ('home', b'{"axis": "secondary_reflector"}', 400, 'expected one of mirrors'),
            ('selfdestruct', b'{}', 400, 'unknown command'),
            ('mode', b'{"mode": "' + b'a' * 20000 + b'"}', 413, 'too large'),
        ]:
            r = await client.post(f'/api/command/{path}', data=data,
                                  headers={**hdr, 'Content-Type': 'application/json'})
            assert r.status == status, (path, data[:40], await r.text())
            assert why in (await r.json())['message']
        assert len(backend.calls) == n, 'a refused request called a service'
        r = await client.post('/api/command/stow', json={}, headers={**hdr, 'Origin': 'http://evil.example'})
        assert r.status == 403 and len(backend.calls) == n
        r = await client.post('/api/command/stow', json={}, headers={**hdr, 'Sec-Fetch-Site': 'cross-site'})
        assert r.status == 403 and len(backend.calls) == n
        r = await client.post('/api/logout', headers=hdr)
        assert r.status == 200
        assert (await client.post('/api/command/stow', json={}, headers=hdr)).status == 401
    backend, op = run(tmp_path, pwfile, body)
    lines = [json.loads(x) for x in (tmp_path / 'audit.jsonl').read_text().splitlines()]
    assert all(x['origin'].startswith('127.0.0.1') for x in lines)
    done = [x for x in lines if x['command'] == 'stow' and x['success']]
    assert done and 'session' in done[0]['origin'] and done[0]['request'] == {'mode': 'stow'}
    assert sum(1 for x in lines if not x['success']) >= 10          # refusals are logged too
    assert any('command stow' in text and '127.0.0.1' in text for _, text in backend.logs)


def test_login_rate_limit_refuses_even_the_right_password(tmp_path, pwfile):
    async def body(client, backend, op):
        for _ in range(3):
            r, _ = await login(client, 'guess-guess')
            assert r.status == 401
        r, j = await login(client)
        assert r.status == 429 and j['retry_after'] > 0 and 'too many' in j['message']
        r = await client.post('/api/login', data=b'garbage', headers={'Content-Type': 'application/json'})
        assert r.status == 429
    _, op = run(tmp_path, pwfile, body, login_max_failures=3)
    assert op.counters['login_failures'] == 3 and op.counters['logins'] == 0


def test_no_password_set_commands_refused_with_how_to(tmp_path):
    async def body(client, backend, op):
        s = await (await client.get('/api/session')).json()
        assert s['password_set'] is False and 'web-password' in s['problem']
        r, j = await login(client, 'anything-at-all')
        assert r.status == 503 and 'web-password' in j['message']
    run(tmp_path, tmp_path / 'nonexistent', body)


def test_view_closed_when_open_view_is_off(tmp_path, pwfile):
    async def body(client, backend, op):
        for path in ('/api/state', '/api/history', '/api/events', '/api/bags'):
            assert (await client.get(path)).status == 401, path
        await login(client)
        assert (await client.get('/api/state')).status == 200
    run(tmp_path, pwfile, body, open_view=False)


def test_server_sent_events_push_changes_within_the_push_period(tmp_path, pwfile):
    from sslfr_interfaces.msg import Irradiance

    async def body(client, backend, op):
        r = await client.get('/api/events')
        assert r.headers['Content-Type'].startswith('text/event-stream')

        async def next_event():
            name = data = None
            while True:
                line = (await r.content.readline()).decode().rstrip('\n')
                if line.startswith('event: '):
                    name = line[7:]
                elif line.startswith('data: '):
                    data = json.loads(line[6:])
                elif line == '' and name:
                    return name, data
        name, first = await asyncio.wait_for(next_event(), 5)
        assert name == 'state' and 'beam' not in first
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        backend.state.on_beam(Irradiance(beam=777.0))
        while True:
            name, data = await asyncio.wait_for(next_event(), 5)
            if name == 'state' and data.get('beam'):
                break
        assert data['beam']['beam'] == 777.0 and loop.time() - t0 < 1.0
        r.close()
    run(tmp_path, pwfile, body)


def test_bag_download_is_a_zip_and_names_cannot_escape(tmp_path, pwfile):
    root = tmp_path / 'bags'
    (root / 'sslfr_2026-06-21').mkdir(parents=True)
    (root / 'sslfr_2026-06-21' / 'sslfr_2026-06-21_0.mcap').write_bytes(b'm' * 5000)
    (tmp_path / 'other.mcap').write_bytes(b'secret')

    async def body(client, backend, op):
        j = await (await client.get('/api/bags')).json()
        assert [b['name'] for b in j['bags']] == ['sslfr_2026-06-21']
        r = await client.get('/api/bags/sslfr_2026-06-21/download')
        assert r.status == 200 and 'attachment' in r.headers['Content-Disposition']
        zf = zipfile.ZipFile(io.BytesIO(await r.read()))
        assert zf.read('sslfr_2026-06-21/sslfr_2026-06-21_0.mcap') == b'm' * 5000
        for evil in ('..', '%2E%2E', '..%2Fother.mcap', 'nothing'):
            assert (await client.get(f'/api/bags/{evil}/download')).status == 404, evil
        assert (await client.get('/api/bags/sslfr_2026-06-21/report/..%2F..%2Fpw')).status == 404
    run(tmp_path, pwfile, body, backend=RecordingBackend(bag_dir=str(root)))


def test_recorded_day_listed_and_its_report_made_once_and_served(tmp_path, pwfile):
    from daybag import SUNRISE, write_day
    root = tmp_path / 'bags'
    write_day(root / 'sslfr_2026-06-21', SUNRISE - 900, SUNRISE + 1800)

    async def body(client, backend, op):
        j = await (await client.get('/api/bags')).json()
        (b,) = j['bags']
        assert b['name'] == 'sslfr_2026-06-21' and b['date'] == '2026-06-21' and b['problem'] == ''
        assert b['start'] == pytest.approx(SUNRISE - 900, abs=1) and b['messages'] > 1000
        r = await client.get('/api/bags/sslfr_2026-06-21/report')
        rep = await r.json()
        assert r.status == 200, rep
        assert 'sunrise' in rep['text'].lower() and rep['plots']
        made = (tmp_path / 'reports' / 'sslfr_2026-06-21' / 'report.txt').stat().st_mtime_ns
        png = await client.get(rep['plots'][0])
        assert png.status == 200 and (await png.read())[:8] == b'\x89PNG\r\n\x1a\n'
        again = await (await client.get('/api/bags/sslfr_2026-06-21/report')).json()
        assert again['text'] == rep['text']
        assert (tmp_path / 'reports' / 'sslfr_2026-06-21' / 'report.txt').stat().st_mtime_ns == made  # cached
    run(tmp_path, pwfile, body, backend=RecordingBackend(bag_dir=str(root)))


def test_recorded_day_report_is_of_the_running_collector(tmp_path, pwfile):
    """The page's report of a recorded day takes the node set's site config (the web
    node's params file): its collector description's movements, not seed 000's."""
    from daybag import SUNRISE, write_day
    root = tmp_path / 'bags'
    write_day(root / 'sslfr_2026-06-21', SUNRISE - 900, SUNRISE + 600)
    config = Path(__file__).resolve().parents[2] / 'sslfr_bringup' / 'config' / 'florianopolis_lepten.yaml'
    backend = RecordingBackend(bag_dir=str(root))
    backend.site_config = lambda: str(config)

    async def body(client, backend, op):
        r = await client.get('/api/bags/sslfr_2026-06-21/report')
        rep = await r.json()
        assert r.status == 200, rep
        assert 'collector       florianopolis_lepten: mirrors' in rep['text'], rep['text']
        assert 'mobile_structure' not in rep['text'].split('timeline (UTC)')[0]
    run(tmp_path, pwfile, body, backend=backend)
