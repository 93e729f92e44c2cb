"""The field page's pure parts: the live state of every collector (sslfr_field.live) and
the HTTP application (sslfr_field.page) over a real aiohttp server on loopback, with a
backend that records the service calls (the graph: tests/test_field_sim.py)."""
from __future__ import annotations

import asyncio
import json

import pytest
from aiohttp.test_utils import TestClient, TestServer

from sslfr_field import page
from sslfr_field.live import FieldState
from field_fixtures import PASSWORD, Backend
from sslfr_web import auth



def test_live_state_link_health_and_values():
    st = FieldState([('c1', '/c1', 'http://10.0.0.21:8080/'), ('c2', '/c2', '')], lost_after=5.0)
    assert st.snapshot(0.0)['links'] == {'never': 2}
    st.on_phase('c1', 10.0, 'TRACKING', 'auto', '')
    st.on_safety('c1', 10.5, 'STOW', ['temperature: outlet 152.0 degC > 150'])
    st.on_axis('c1', 10.6, 'mirrors', 'following', 0.001, float('nan'))
    st.on_axis('c1', 10.6, 'not_a_joint', 'x', 0.0, 0.0)        # ignored
    st.on_temperature('c1', 10.7, 'outlet', 152.0)
    st.on_beam('c1', 10.8, float('inf'))
    st.on_thermal('c1', 10.8, 150.0 / 3.6e6, float('nan'))         # a flow meter; power unknown
    snap = st.snapshot(12.0)
    c1, c2 = snap['collectors']
    assert c1['link'] == 'ok' and c1['last_heard_s'] == pytest.approx(1.2)
    assert c1['phase_age_s'] == pytest.approx(2.0) and c2['phase_age_s'] is None   # the planner's last phase
    assert c1['safety_age_s'] == pytest.approx(1.5) and c2['safety_age_s'] is None
    assert c1['phase'] == 'TRACKING' and c1['safety_level'] == 'STOW' and c1['safety_reasons'][0].startswith('temp')
    assert c1['axes'] == {'mirrors': {'state': 'following', 'error': 0.001, 'measured': None}}
    assert c1['temperatures'] == {'outlet': 152.0} and c1['beam'] is None
    assert c1['page'] == 'http://10.0.0.21:8080/'
    assert c1['flow'] == pytest.approx(150.0 / 3.6e6) and c1['thermal_power'] is None
    assert c2['link'] == 'never' and c2['last_heard_s'] is None
    assert c2['flow'] is None and c2['thermal_power'] is None        # no flow meter: nothing shown
    assert st.snapshot(15.81)['collectors'][0]['link'] == 'lost'      # 5.01 s after the last message
    json.dumps(snap, allow_nan=False)                                  # strict JSON: no NaN


def test_parameters_are_checked():
    table = page.field_page_params()
    ok = {**table.defaults(), 'collectors': ['/c1', '/c2'], 'collector_ids': ['c1', 'c2']}
    assert not page._check_lists(ok)
    assert page._check_lists({**ok, 'collector_ids': ['c1']})
    assert page._check_lists({**ok, 'collector_ids': ['c1', 'c1']})
    assert page._check_lists({**ok, 'collectors': ['']})
    assert page._check_lists({**ok, 'collector_pages': ['http://x/']})


def run(tmp_path, body, **cfg):
    pw = auth.write_password_file(tmp_path / 'pw', PASSWORD)
    conf = {**page.field_page_params().defaults(), 'collectors': ['/c1', '/c2'], 'collector_ids': ['c1', 'c2'],
            'password_file': str(pw), 'audit_file': str(tmp_path / 'audit.jsonl'), **cfg}
    backend = Backend(('c2',))
    op = page.FieldApp(conf, backend, {'c1': '/c1', 'c2': '/c2'})

    async def main():
        async with TestClient(TestServer(op.application(), host='127.0.0.1')) as client:
            await body(client, backend)
    asyncio.run(main())
    return backend


def test_view_commands_need_login_and_csrf_then_reach_each_collector(tmp_path):
    async def body(client, backend):
        r = await client.get('/')
        assert r.status == 200 and 'Stow all' in await r.text()
        assert "default-src 'self'" in r.headers['Content-Security-Policy']
        for asset in ('field.js', 'field.css'):
            assert (await client.get(f'/static/{asset}')).status == 200
        assert (await client.get('/static/../page.py')).status == 404
        j = await (await client.get('/api/field')).json()
        assert [c['id'] for c in j['collectors']] == ['c1', 'c2']
        # no login: refused, nothing called
        r = await client.post('/api/command/stow', json={'collector': 'all'})
        assert r.status == 401 and backend.calls == []
        r = await client.post('/api/login', json={'password': 'wrong-password'})
        assert r.status == 401
        r = await client.post('/api/login', json={'password': PASSWORD})
        csrf = (await r.json())['csrf']
        # logged in, no CSRF token: refused
        r = await client.post('/api/command/stow', json={'collector': 'all'})
        assert r.status == 403 and backend.calls == []
        h = {'X-CSRF-Token': csrf}
        # a cross-site POST is refused even with the token
        r = await client.post('/api/command/stow', json={'collector': 'c1'},
                              headers={**h, 'Origin': 'http://evil.example'})
        assert r.status == 403 and backend.calls == []
        for bad in ({'collector': 'c9'}, {}, {'collector': 'all', 'extra': 1}):
            r = await client.post('/api/command/stow', json=bad, headers=h)
            assert r.status == 400, bad
        r = await client.post('/api/command/estop', json={'collector': 'c1'}, headers=h)
        assert r.status == 400 and 'not a field command' in (await r.json())['message']
        assert backend.calls == []
        r = await client.post('/api/command/stow', json={'collector': 'c1'}, headers=h)
        j = await r.json()
        assert r.status == 200 and j['success'] is True
        assert backend.calls == [('c1', 'planner/set_mode', {'mode': 'stow'})]
        backend.calls.clear()
        r = await client.post('/api/command/mode', json={'collector': 'all', 'mode': 'auto'}, headers=h)
        j = await r.json()
        assert j['success'] is False and 'c2: refused: refused: maintenance' in j['message']
        assert sorted(backend.calls) == [('c1', 'planner/set_mode', {'mode': 'auto'}),
                                         ('c2', 'planner/set_mode', {'mode': 'auto'})]
    run(tmp_path, body)
    audit = [json.loads(line) for line in (tmp_path / 'audit.jsonl').read_text().splitlines()]
    assert any(a['command'] == 'c2: mode' and a['success'] is False for a in audit)
    assert any(a['command'] == 'c1: stow' and a['success'] is True for a in audit)


def test_closed_view_needs_login(tmp_path):
    async def body(client, backend):
        assert (await client.get('/api/field')).status == 401
    run(tmp_path, body, open_view=False)


def test_login_rate_limit_is_the_collector_pages(tmp_path):
    async def body(client, backend):
        for _ in range(2):
            assert (await client.post('/api/login', json={'password': 'nope-nope'})).status == 401
        assert (await client.post('/api/login', json={'password': PASSWORD})).status == 429
    run(tmp_path, body, login_max_failures=2)
