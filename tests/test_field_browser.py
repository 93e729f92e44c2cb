"""The field page in a real browser (Debian's headless chromium via selenium, as
tests/test_web_browser.py) against ``./sslfr sim --collectors N`` (N = SSLFR_FIELD_N,
default 4): N simulated
collectors, each its own namespace, boards and composed node set on the system clock,
discovery clients of the station's two Fast DDS discovery servers, and the station.

The page shows every collector heard (link ok) with its phase, safety level and
temperatures; each collector's name links to its own operator page, which answers;
commands are refused without login; after login "Stow all" stows every collector
through its own ``planner/set_mode`` (each planner's phase becomes STOW), then one
collector is set back to auto alone. After the run each collector's bag is named after
it and holds its own nodes' log lines only (``/cK/rosout``); the station's field
recording holds every collector's statuses on the absolute
``/diagnostics`` with ``hardware_id`` = its id. Each row shows the energy of the day
absorbed (the optical model on the collector's beam, sun and measured axes). Foxglove
live at the station (``--set foxglove_bridge:...`` turns it on): a WebSocket client
speaking the Foxglove protocol decodes a ``/c1/joint_states`` message of a collector
through the station's one bridge. The station's SunSpec gateway, as a plant's SCADA sees
it: pysunspec2's device reader finds each collector's unit (its id in the common model and
the tracker), pymodbus reads each unit's mirrors position, equal to that collector's
``joint_states`` within one motor step, and a control write is refused (read-only by
default). A screenshot is kept in
out/test-artifacts/field-page.png.
"""
from __future__ import annotations

import datetime as dt
import math
import os
import re
import time
import urllib.request

import pytest

from conftest import ROOT, NodeProcess
from sslfr_recording.bag import BagReader
from sslfr_web import auth
from test_web_browser import ARTIFACTS, _require_browser, browser  # noqa: F401 - the fixture

PASSWORD = 'field-browser-pass'
N = int(os.environ.get('SSLFR_FIELD_N', '4'))
pytestmark = pytest.mark.slow


@pytest.fixture
def field(ros_env, tmp_path):
    _require_browser()
    pw = auth.write_password_file(tmp_path / 'pw', PASSWORD)
    out = tmp_path / 'field'
    end = (dt.datetime.now(dt.timezone.utc) + dt.timedelta(minutes=15)).strftime('%H:%M')
    cmd = [str(ROOT / 'sslfr'), 'sim', '--collectors', str(N), '--end', end, '--out', str(out),
           '--set', f'web:password_file={pw}', '--set', f'field_page:password_file={pw}',
           '--set', f'field_page:audit_file={tmp_path / "audit.jsonl"}',
           '--set', f'web:audit_file={tmp_path / "web_audit.jsonl"}', '--set', f'web:report_dir={tmp_path / "r"}',
           '--set', 'foxglove_bridge:discovery_period=0.5']
    proc = NodeProcess(cmd, ros_env, tmp_path / 'field.out')
    url, deadline = None, time.monotonic() + 120
    while time.monotonic() < deadline and proc.running() and url is None:
        m = re.search(r'FIELD PAGE at (http://\S+/)', proc.output())
        url = m.group(1) if m else None
        time.sleep(0.2)
    try:
        assert url, proc.output()[-3000:]
        yield url, proc, tmp_path
    finally:
        proc.stop(timeout=40)


def _wait(predicate, timeout, what, show=lambda: ''):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.2)
    pytest.fail(f'{what} not seen within {timeout} s {show()}')


def test_field_page_in_chromium_against_simulated_collectors(browser, field):  # noqa: F811 - fixture
    url, proc, tmp = field
    ids = [f'c{k}' for k in range(1, N + 1)]
    t0 = time.monotonic()
    browser.get(url)
    # the table is rebuilt every second: read it (and click in it) in one script, never stale
    rows = lambda: browser.execute_script(  # noqa: E731
        "return Object.fromEntries([...document.querySelectorAll('#field tbody tr')]"
        ".map(r => [r.id.slice('collector-'.length), r.innerText]))")
    _wait(lambda: set(rows()) == set(ids), 60, 'a row per collector', lambda: str(rows()))
    # every collector heard (the field page is a super client; each collector a plain client)
    _wait(lambda: all(re.search(r'\bok \(', t) and re.search(r'\b(TRACKING|NIGHT|PRE_DAWN|STOW) /', t)
                      for t in rows().values()),
          180, 'every collector heard with a phase', lambda: str(rows()))
    print(f'field page: {N} collectors seen with a phase {time.monotonic() - t0:.1f} s after the page opened')
    # the energy of the day: absorbed (beam, sun and the three measured axes heard); 0 at night
    _wait(lambda: all(re.search(r'absorbed \d+\.\d{3}', t) for t in rows().values()), 60,
          'every collector\'s absorbed energy of the day', lambda: str(rows()))
    # Foxglove live at the station: one bridge carries every collector's namespaced topics
    m = _wait(lambda: re.search(r'FOXGLOVE WEBSOCKET at ws://(\S+):(\d+)', proc.output()), 60,
              'the station\'s Foxglove WebSocket', lambda: proc.output()[-2000:])
    import asyncio

    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import JointState
    from test_gateway import _foxglove_one
    payload = asyncio.run(asyncio.wait_for(_foxglove_one(f'ws://{m.group(1)}:{m.group(2)}', '/c1/joint_states'), 60))
    joints = deserialize_message(payload, JointState)
    assert joints.name and all(n in ('mirrors', 'mobile_structure', 'secondary_reflector') for n in joints.name)
    # the plant's view: the station's SunSpec gateway, one unit per collector, read by a
    # generic SunSpec reader and a Modbus client; each unit's mirrors position is its own
    # collector's joint_states (heard through the Foxglove bridge just before and after)
    g = _wait(lambda: re.search(r'SunSpec MODBUS TCP GATEWAY at (\S+):(\d+)', proc.output()), 60,
              'the station\'s Modbus gateway address', lambda: proc.output()[-2000:])
    host, port = g.group(1), int(g.group(2))
    from pymodbus.client import ModbusTcpClient
    from sunspec2.modbus.client import SunSpecModbusClientDeviceTCP

    from sslfr_common.contract import STEP_ANGLE
    from sslfr_gateway import sunspec

    def mirrors_of(cid):                         # each axis driver publishes its own joint_states
        js = deserialize_message(asyncio.run(asyncio.wait_for(_foxglove_one(
            f'ws://{m.group(1)}:{m.group(2)}', f'/{cid}/joint_states',
            lambda p: 'mirrors' in deserialize_message(p, JointState).name), 30)), JointState)
        return js.position[list(js.name).index('mirrors')]

    addrs = sunspec.point_addresses(1)
    client = ModbusTcpClient(host, port=port, timeout=5)
    assert client.connect()
    try:
        for k, cid in enumerate(ids, start=1):
            d = SunSpecModbusClientDeviceTCP(slave_id=k, ipaddr=host, ipport=port, timeout=5)
            try:
                d.scan()
                assert [x for x in d.models if isinstance(x, int)] == [1, 601, 302], d.models
                assert d.common[0].SN.value == cid and d.tracker_controller[0].tracker[0].Id.value == cid
            finally:
                d.close()
            diffs = []
            for _ in range(5):                   # the mirrors may move between the reads: bracket the register
                before = mirrors_of(cid)
                r = client.read_holding_registers(addrs['601.tracker[0].ElPos'], count=2, device_id=k)
                assert not r.isError(), r
                el = math.radians(client.convert_from_registers(r.registers, client.DATATYPE.INT32) * 1e-3)
                after = mirrors_of(cid)
                diffs.append(min(abs(el - before), abs(el - after)))
                if diffs[-1] <= STEP_ANGLE:
                    break
            assert diffs[-1] <= STEP_ANGLE, (cid, [math.degrees(x) for x in diffs])
            r = client.write_register(addrs['601.tracker[0].Ctl'], 1, device_id=k)
            assert r.isError() and r.exception_code == 1, r                 # read-only unless allowed
    finally:
        client.close()
    print(f'SunSpec gateway at {host}:{port}: {len(ids)} units, each the mirrors position of its collector '
          f'within one motor step; writes refused (read-only by default)')
    # each collector's own page, one click away: the link answers with the operator page
    for cid in ids:
        link = browser.execute_script(f"return document.querySelector('#collector-{cid} a').href")
        with urllib.request.urlopen(link, timeout=10) as r:
            assert r.status == 200 and 'software stop' in r.read().decode()
    # without login: commands disabled, and the API refuses
    assert not browser.find_element('id', 'stow-all').is_enabled()
    status = browser.execute_async_script("""
        const done = arguments[arguments.length - 1];
        fetch('/api/command/stow', {method: 'POST', headers: {'Content-Type': 'application/json'},
              body: JSON.stringify({collector: 'all'})}).then(r => done(r.status));""")
    assert status == 401
    browser.find_element('id', 'password').send_keys(PASSWORD)
    browser.find_element('css selector', '#login button').click()
    _wait(lambda: browser.find_element('id', 'stow-all').is_enabled(), 20, 'the login')
    browser.find_element('id', 'stow-all').click()
    msg = lambda: browser.find_element('id', 'message').text  # noqa: E731
    _wait(lambda: all(f'{c}: done' in msg() for c in ids), 20, 'every collector answering the stow', msg)
    _wait(lambda: all('STOW / stow' in t for t in rows().values()), 20, 'every collector in STOW', lambda: str(rows()))
    # one collector back to auto, alone
    browser.execute_script("document.querySelector('#collector-c1 .cmd-auto').click()")
    _wait(lambda: 'c1: done' in msg() and '/ auto' in rows()['c1'], 20, 'c1 back to auto', lambda: str(rows()))
    assert all('STOW / stow' in rows()[c] for c in ids[1:])
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shot = ARTIFACTS / 'field-page.png'
    assert browser.save_screenshot(str(shot))
    print(f'screenshot: {shot}')
    audit = (tmp / 'audit.jsonl').read_text()
    assert '"c1: stow"' in audit and '"c1: mode"' in audit

    # after the run: each collector's bag names it; the station's field recording holds
    # every collector's statuses on the absolute /diagnostics, hardware_id = its id
    assert proc.stop(timeout=40) is not None
    out = tmp / 'field'
    for cid in ids:
        bags = [b.name for b in (out / cid / 'bags').iterdir()]
        assert bags and all(b.startswith(f'{cid}_') for b in bags), bags
        # ... and holds its own nodes' log lines only, on <namespace>/rosout (rcl's absolute
        # /rosout would have made each collector's recorder subscribe to the whole field's)
        loggers = set()
        for bag in (out / cid / 'bags').iterdir():
            if (bag / 'metadata.yaml').exists():
                reader = BagReader(bag)
                assert '/rosout' not in reader.topics, sorted(reader.topics)
                for raw in reader.messages([f'/{cid}/rosout']):
                    loggers.add(reader.decoder(raw.type)(raw.data).name)
        assert loggers and all(n.startswith(f'{cid}.') for n in loggers), (cid, sorted(loggers))
    station_bags = sorted(b for b in (out / 'station' / 'bags').iterdir() if (b / 'metadata.yaml').exists())
    assert station_bags                      # one per UTC day: a run across midnight has two
    seen: dict[str, set] = {}
    for bag in station_bags:
        reader = BagReader(bag)
        for raw in reader.messages(['/diagnostics']):
            for s in reader.decoder(raw.type)(raw.data).status:
                seen.setdefault(s.hardware_id, set()).add(s.name)
    for cid in ids:
        names = seen.get(cid, set())
        assert {'safety: safety supervisor', 'planner: day cycle', 'mirrors_driver: axis mirrors'} <= names, \
            (cid, sorted(names))
        assert all(': ' in n for n in names)
    assert 'field_page: field page' in set().union(*seen.values())
