"""Topic-level tests of the ``web`` node (operator page) against running nodes.

The real ``planner`` and ``safety`` nodes run as processes beside the ``web`` node;
the test publishes sensor topics, reads the page's HTTP API like a browser does (a
cookie jar, the CSRF token, Server-Sent Events) and watches the graph's topics:

- the page shows what is published, within 1 s of publication (measured here);
- the limits the page shows come from the nodes' own parameters;
- commands go through the real services: stow -> the planner's phase becomes STOW;
  e-stop -> safety/state ESTOP; a reset shows the safety node's refusal;
- refused requests (no login, unknown mode, jog beyond the limit, garbage JSON) change
  nothing on the graph.
"""
from __future__ import annotations

import http.cookiejar
import json
import re
import threading
import time
import urllib.error
import urllib.request

import pytest
from sslfr_common.contract import IRRADIANCE_BEAM, SAFETY_STATE, TRACKER_PHASE
from sslfr_common.node import qos

from sslfr_web import auth

PASSWORD = 'topic-level-pass'
LATCHED = qos(TRACKER_PHASE)


class Page:
    """What a browser does with the page's API: cookies, CSRF header, JSON."""

    def __init__(self, url: str):
        self.url = url.rstrip('/')
        self.opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))
        self.csrf = None

    def get(self, path: str):
        with self.opener.open(self.url + path, timeout=10) as r:
            return json.loads(r.read())

    def post(self, path: str, body: bytes | dict | None = None) -> tuple[int, dict]:
        data = body if isinstance(body, bytes) else json.dumps(body or {}).encode()
        req = urllib.request.Request(self.url + path, data=data, method='POST',
                                     headers={'Content-Type': 'application/json', 'X-CSRF-Token': self.csrf or ''})
        try:
            with self.opener.open(req, timeout=15) as r:
                return r.status, json.loads(r.read())
        except urllib.error.HTTPError as exc:
            return exc.code, json.loads(exc.read())

    def login(self, password: str = PASSWORD) -> tuple[int, dict]:
        status, j = self.post('/api/login', {'password': password})
        self.csrf = j.get('csrf')
        return status, j


class EventReader(threading.Thread):
    """Reads /api/events; records (wall time, beam) of every state event."""

    def __init__(self, url: str):
        super().__init__(daemon=True)
        self.resp = urllib.request.urlopen(url.rstrip('/') + '/api/events', timeout=30)
        self.seen: list[tuple[float, float | None]] = []

    def run(self):
        name = None
        try:
            for raw in self.resp:
                line = raw.decode().rstrip('\n')
                if line.startswith('event: '):
                    name = line[7:]
                elif line.startswith('data: ') and name == 'state':
                    beam = (json.loads(line[6:]).get('beam') or {}).get('beam')
                    self.seen.append((time.time(), beam))
        except Exception:  # noqa: BLE001 - closed by the test
            pass


@pytest.fixture
def graph(launch, ros, tmp_path):
    """planner + safety + web; returns (web process, Page)."""
    pw = auth.write_password_file(tmp_path / 'pw', PASSWORD)
    launch('sslfr_planner', 'planner', params={'state_dir': str(tmp_path / 'state')})
    launch('sslfr_safety', 'safety')
    web = launch('sslfr_web', 'web', params={'port': 0, 'password_file': str(pw),
                                                  'audit_file': str(tmp_path / 'audit.jsonl'),
                                                  'bag_dir': str(tmp_path / 'bags')})
    assert web.wait_for_output('operator page at', 30), web.output()
    url = re.search(r'operator page at (http://\S+/)', web.output()).group(1)
    return web, Page(url)


def test_live_view_follows_the_topics_within_one_second_and_shows_the_nodes_limits(graph, ros, tmp_path):
    from sslfr_interfaces.msg import Irradiance
    web, page = graph
    assert page.url.startswith('http://127.0.0.1:')               # the default bind: loopback only
    pub = ros.node.create_publisher(Irradiance, IRRADIANCE_BEAM.name, 10)
    phases = ros.collect(__import__('sslfr_interfaces.msg', fromlist=['TrackerPhase']).TrackerPhase,
                         TRACKER_PHASE.name, LATCHED)
    assert ros.spin_until(lambda: phases, 30), 'planner not publishing'
    reader = EventReader(page.url)
    reader.start()
    ros.spin_until(lambda: ros.node.count_subscribers(IRRADIANCE_BEAM.name) >= 2, 15)   # web + safety
    delays = []
    rng = __import__('random').Random(20)
    for k in range(10):
        ros.spin_for(rng.uniform(0.0, 0.3))                         # not in step with the page's pushes
        value = 500.0 + k
        t0 = time.time()
        pub.publish(Irradiance(beam=value, illuminance=value * 104.0))
        ros.spin_until(lambda: any(b == value for _, b in reader.seen), 3.0)
        arrived = [t for t, b in reader.seen if b == value]
        assert arrived, f'beam {value} never reached the page'
        delays.append(arrived[0] - t0)
    print(f'topic -> page (SSE) delay over {len(delays)} messages: median {sorted(delays)[5] * 1000:.0f} ms, '
          f'max {max(delays) * 1000:.0f} ms')
    assert max(delays) < 1.0
    snap = page.get('/api/state')
    assert snap['phase']['name'] == phases[-1].phase_name and snap['safety']['name'] in ('OK', 'WARN', 'STOW')
    # the limits the page shows are the nodes' own parameters (safety default 150 degC, seed 000)
    ros.spin_until(lambda: page.get('/api/state')['info'].get('temperature_limit') is not None
                   and 'n_per_side' in page.get('/api/state')['info'], 20)
    info = page.get('/api/state')['info']
    assert info['temperature_limit'] == 150.0 and info['n_per_side'] == 12 and info['receiver_height'] == 1.5


def test_page_takes_the_collector_the_planner_names(launch, ros, tmp_path):
    """The planner of seed 004's site config (collector description relative to the
    config): the page's info holds the described collector, one movement and ten lines
    at Table 1's offsets, for the drawing, the axes table and the jog list."""
    import math
    from pathlib import Path
    config = Path(__file__).resolve().parents[1] / 'src' / 'sslfr_bringup' / 'config' / 'florianopolis_lepten.yaml'
    launch('sslfr_planner', 'planner', params={'state_dir': str(tmp_path / 'state')},
           ros_args=['--params-file', str(config)])
    web = launch('sslfr_web', 'web', params={'port': 0, 'password_file': str(tmp_path / 'none'),
                                             'audit_file': str(tmp_path / 'audit.jsonl'),
                                             'bag_dir': str(tmp_path / 'bags')},
                 ros_args=['--params-file', str(config)])
    assert web.wait_for_output('operator page at', 30), web.output()
    page = Page(re.search(r'operator page at (http://\S+/)', web.output()).group(1))
    assert ros.spin_until(lambda: 'collector' in page.get('/api/state')['info'], 30), web.output()
    c = page.get('/api/state')['info']['collector']
    assert c['name'] == 'florianopolis_lepten' and c['joints'] == ['mirrors'] and not c['tilting']
    assert len(c['lines']) == 10 and math.degrees(c['lines'][0]['offset']) == pytest.approx(15.8311, abs=1e-6)


def test_commands_go_through_the_services_and_refusals_change_nothing(graph, ros, tmp_path):
    from sslfr_interfaces.msg import SafetyState, TrackerPhase
    web, page = graph
    phases = ros.collect(TrackerPhase, TRACKER_PHASE.name, LATCHED)
    safety = ros.collect(SafetyState, SAFETY_STATE.name)
    assert ros.spin_until(lambda: phases and safety, 30)
    mode0 = phases[-1].mode
    # no login: refused, nothing changes
    status, j = page.post('/api/command/stow')
    assert status == 401 and 'log in' in j['message']
    assert page.login('not the password')[0] == 401
    status, j = page.login()
    assert status == 200 and page.csrf
    for body, why in [({'mode': 'turbo'}, 'unknown mode'), (b'{"mode": auto}', 'not valid JSON')]:
        status, j = page.post('/api/command/mode', body)
        assert status == 400 and why in j['message']
    status, j = page.post('/api/command/jog', {'axis': 'mirrors', 'delta': 0.5})
    assert status == 400 and 'beyond the jog limit' in j['message']
    ros.spin_for(1.5)
    assert phases[-1].mode == mode0, 'a refused command changed the mode'
    # stow through planner/set_mode: the planner's phase becomes STOW
    status, j = page.post('/api/command/stow')
    assert status == 200 and j['success'] and j['mode'] == 'stow' and j['service'] == 'planner/set_mode', (status, j)
    assert ros.spin_until(lambda: phases[-1].phase_name == 'STOW' and phases[-1].mode == 'stow', 10)
    # a forbidden transition is the planner's refusal, shown with its reason
    status, j = page.post('/api/command/mode', {'mode': 'manual'})
    assert status == 200 and j['success'] is False and j['message'], (status, j)
    # e-stop (software) through safety/estop
    status, j = page.post('/api/command/estop')
    assert status == 200 and j['success'] and 'e-stop' in j['message'], (status, j)
    assert ros.spin_until(lambda: safety[-1].level == SafetyState.ESTOP, 5)
    status, j = page.post('/api/command/release')
    assert status == 200 and j['success'], (status, j)
    assert ros.spin_until(lambda: safety[-1].level != SafetyState.ESTOP, 5)
    status, j = page.post('/api/command/reset')
    assert status == 200 and isinstance(j['success'], bool) and j['message'], (status, j)
    # a jog with no driver running: the service is not there, said plainly
    status, j = page.post('/api/command/jog', {'axis': 'mirrors', 'delta': 0.01})
    assert status == 200 and j['success'] is False and 'not available' in j['message'], (status, j)
    audit = [json.loads(x) for x in (tmp_path / 'audit.jsonl').read_text().splitlines()]
    done = {x['command'] for x in audit if x['success']}
    assert {'login', 'stow', 'estop', 'release'} <= done
    assert all(x['origin'].startswith('127.0.0.1') for x in audit)
    assert 'command stow' in web.output() and 'from 127.0.0.1' in web.output()
