"""Unit tests of the operator page's pure modules (sslfr_web): password hashing
and sessions, command validation, live state from the real message classes, the day
buffer, safety hints against the real safety core's texts, bag listing and zip."""
from __future__ import annotations

import base64
import hashlib
import io
import json
import math
import os
import stat
import zipfile
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sslfr_bringup import nodeset
from sslfr_web import auth, bags, commands, live, params, remote


# ------------------------------------------------------------------ auth
def test_password_hash_is_rfc7914_scrypt_and_verifies_in_constant_time_api():
    salt = bytes(range(16))
    line = auth.hash_password('correct horse', salt=salt)
    n, r, p, s, key = auth.parse_hash(line)
    assert (n, r, p, s) == (2 ** 14, 8, 1, salt)
    # the stored key is exactly hashlib.scrypt of the password (the standard KDF, not ours)
    assert key == hashlib.scrypt(b'correct horse', salt=salt, n=2 ** 14, r=8, p=1, dklen=32, maxmem=2 ** 28)
    assert auth.verify_password('correct horse', line)
    assert not auth.verify_password('correct hors', line)
    assert not auth.verify_password('Correct horse', line)
    assert auth.hash_password('correct horse') != auth.hash_password('correct horse')   # new salt each time


def test_rfc7914_test_vector_of_the_kdf_we_rely_on():
    # RFC 7914 section 12, second vector: P="password", S="NaCl", N=1024, r=8, p=16, dkLen=64
    dk = hashlib.scrypt(b'password', salt=b'NaCl', n=1024, r=8, p=16, dklen=64)
    assert dk.hex().startswith('fdbabe1c9d3472007856e7190d01e9fe7c6ad7cbc8237830e77376634b373162')


@pytest.mark.parametrize('bad', ['', 'short', ' ' * 12, 'abc\x00defghij'])
def test_weak_or_odd_passwords_are_refused(bad):
    with pytest.raises(auth.PasswordError):
        auth.hash_password(bad)


@pytest.mark.parametrize('line', ['', 'plain', 'scrypt$16384$8$1$!!$!!', 'scrypt$1000$8$1$AAAAAAAAAAA=$' + 'A' * 44,
                                  'md5$1$2$3$4$5', 'scrypt$16384$8$1$' + base64.b64encode(b'x' * 16).decode() + '$QUJD'])
def test_malformed_hash_lines_are_refused(line):
    with pytest.raises(auth.PasswordError):
        auth.parse_hash(line)


def test_password_file_mode_0600_atomic_and_reread_on_change(tmp_path):
    p = tmp_path / 'cfg' / 'pw'
    pf = auth.PasswordFile(p)
    assert pf.line() is None and 'web-password' in pf.problem
    auth.write_password_file(p, 'first password')
    assert stat.S_IMODE(os.stat(p).st_mode) == 0o600
    assert auth.verify_password('first password', pf.line())
    assert 'first password' not in p.read_text()
    auth.write_password_file(p, 'second password!')
    assert auth.verify_password('second password!', pf.line())
    p.write_text('garbage\n')
    assert pf.line() is None and 'unusable' in pf.problem
    assert not list(p.parent.glob('*.tmp'))


def test_sessions_expire_when_idle_and_csrf_must_match():
    now = [0.0]
    store = auth.SessionStore(timeout=100.0, clock=lambda: now[0])
    s = store.create('10.0.0.5')
    assert store.get(s.token) is s
    assert store.check_csrf(s, s.csrf)
    assert not store.check_csrf(s, s.csrf[:-1] + ('A' if s.csrf[-1] != 'A' else 'B'))
    assert not store.check_csrf(s, None) and not store.check_csrf(None, s.csrf)
    now[0] = 99.0
    assert store.get(s.token) is s            # used: idle timer restarts
    now[0] = 198.0
    assert store.get(s.token) is s
    now[0] = 299.0
    assert store.get(s.token) is None         # idle > 100 s
    assert store.get('forged') is None and store.get(None) is None and len(store) == 0
    s2 = store.create('x')
    store.end(s2.token)
    assert store.get(s2.token) is None


def test_session_store_is_bounded():
    store = auth.SessionStore(timeout=1e9, max_sessions=3)
    toks = [store.create(str(i)).token for i in range(5)]
    assert len(store) == 3 and store.get(toks[-1]) is not None


def test_login_limiter_per_address_sliding_window_and_global_bound():
    now = [0.0]
    lim = auth.LoginLimiter(max_failures=3, window=60.0, clock=lambda: now[0], global_factor=2)
    for _ in range(3):
        assert lim.retry_after('a') == 0.0
        lim.failure('a')
    assert lim.retry_after('a') == pytest.approx(60.0)
    assert lim.retry_after('b') == 0.0                  # other addresses unaffected
    now[0] = 30.0
    assert lim.retry_after('a') == pytest.approx(30.0)
    now[0] = 60.0
    assert lim.retry_after('a') == 0.0                  # the lockout (= window by default) is over
    for addr in 'cdefgh':                               # 6 in the window -> global 6 reached
        lim.failure(addr)
    assert lim.retry_after('zz') > 0.0
    lim.success('a')


def test_login_attempts_are_counted_before_the_check_and_lockouts_grow():
    now = [0.0]
    lim = auth.LoginLimiter(max_failures=3, window=600.0, clock=lambda: now[0], lockout=10.0, lockout_max=35.0)
    tickets = [lim.attempt('a') for _ in range(6)]      # six at once, none answered yet
    assert [w == 0.0 for w, _ in tickets] == [True] * 3 + [False] * 3
    assert lim.retry_after('a') == pytest.approx(10.0)
    now[0] = 10.0
    for _ in range(3):
        assert lim.attempt('a')[0] == 0.0
    assert lim.retry_after('a') == pytest.approx(20.0)  # the second lockout is twice as long
    now[0] = 30.0
    for _ in range(3):
        lim.attempt('a')
    assert lim.retry_after('a') == pytest.approx(35.0)  # capped at lockout_max
    now[0] = 65.0
    w, ticket = lim.attempt('a')
    assert w == 0.0
    lim.success('a', ticket)                            # the right password: all forgotten
    assert lim.retry_after('a') == 0.0 and not lim.locked()


def test_global_login_limit_never_refuses_trusted_networks_and_clear_unlocks():
    now = [0.0]
    lim = auth.LoginLimiter(max_failures=2, window=60.0, clock=lambda: now[0], global_factor=2,
                            trusted=lambda a: a.startswith('192.168.1.'))
    for addr in ('10.0.0.1', '10.0.0.2'):
        lim.attempt(addr)
    for addr in ('192.168.1.7', '192.168.1.8', '192.168.1.9'):
        lim.attempt(addr)                               # trusted: not in the global count
    assert lim.retry_after('10.0.0.3') == 0.0
    lim.attempt('10.0.0.3')
    lim.attempt('10.0.0.4')
    assert lim.retry_after('10.0.0.5') == pytest.approx(60.0)   # untrusted: global limit reached
    assert lim.retry_after('192.168.1.20') == 0.0               # the segment: only its own count
    lim.attempt('192.168.1.7')
    assert lim.retry_after('192.168.1.7') > 0.0                 # per-address limit holds for all
    lim.clear()
    assert lim.retry_after('192.168.1.7') == 0.0 and lim.retry_after('10.0.0.5') == 0.0


# ------------------------------------------------------------------ commands
LIMITS = {'mirrors': commands.JogLimits(page_max=0.2, driver_max=0.1, lower=-0.785, upper=1.5708, measured=1.5)}


@pytest.mark.parametrize('name,body,service,request_', [
    ('stow', {}, 'planner/set_mode', {'mode': 'stow'}),
    ('mode', {'mode': 'maintenance'}, 'planner/set_mode', {'mode': 'maintenance'}),
    ('mode', {'mode': 'auto'}, 'planner/set_mode', {'mode': 'auto'}),
    ('estop', {}, 'safety/estop', {'data': True}),
    ('release', {}, 'safety/estop', {'data': False}),
    ('reset', {}, 'safety/reset', {}),
    ('replan', {}, 'planner/replan', {}),
    ('home', {'axis': 'secondary_reflector'}, 'axes/secondary_reflector/home', {}),
    ('jog', {'axis': 'mirrors', 'delta': -0.05}, 'axes/mirrors/jog', {'delta': -0.05, 'speed': 0.0}),
])
def test_valid_commands_map_to_the_graphs_services(name, body, service, request_):
    cmd = commands.validate(name, body, LIMITS)
    assert cmd.service == service and dict(cmd.request) == request_
    assert service in commands.all_service_names()


@pytest.mark.parametrize('name,body,why', [
    ('mode', {'mode': 'turbo'}, 'unknown mode'),
    ('mode', {}, 'unknown mode'),
    ('mode', {'mode': 'auto', 'x': 1}, 'unknown field'),
    ('stow', {'now': True}, 'unknown field'),
    ('jog', {'axis': 'mirrors', 'delta': 0.15}, 'beyond the jog limit'),        # > driver max 0.1
    ('jog', {'axis': 'mirrors', 'delta': 0.09}, 'outside mirrors soft limits'),  # 1.5 + 0.09 > pi/2
    ('jog', {'axis': 'mobile_structure', 'delta': 0.01}, 'beyond the jog limit'),  # limits unknown: page max 0
    ('jog', {'axis': 'mirrors', 'delta': 'NaN'}, 'must be a number'),
    ('jog', {'axis': 'mirrors', 'delta': float('nan')}, 'must be finite'),
    ('jog', {'axis': 'mirrors', 'delta': True}, 'must be a number'),
    ('jog', {'axis': 'mirrors', 'delta': 0.0}, 'nothing to move'),
    ('jog', {'axis': 'mirrors', 'delta': -0.01, 'speed': 9}, 'speed'),
    ('jog', {'axis': 'moon', 'delta': 0.01}, 'unknown axis'),
    ('home', {}, 'unknown axis'),
    ('launch', {}, 'unknown command'),
])
def test_bad_commands_are_refused_with_the_reason(name, body, why):
    with pytest.raises(commands.CommandError, match=why):
        commands.validate(name, body, LIMITS)


@pytest.mark.parametrize('raw,why', [(b'{', 'not valid JSON'), (b'\xff\xfe', 'not valid JSON'),
                                     (b'[1, 2]', 'JSON object'), (b'"stow"', 'JSON object'), (b'null', 'JSON object')])
def test_garbage_bodies_are_refused(raw, why):
    with pytest.raises(commands.CommandError, match=why):
        commands.parse_body(raw)
    assert commands.parse_body(b'') == {} and commands.parse_body(b' {"a": 1} ') == {'a': 1}


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=200))
def test_any_bytes_either_parse_to_an_object_or_raise_command_error(raw):
    try:
        body = commands.parse_body(raw)
    except commands.CommandError:
        return
    assert isinstance(body, dict)
    for name in ('mode', 'jog', 'stow'):
        try:
            commands.validate(name, body, LIMITS)
        except commands.CommandError:
            pass


def test_only_commands_that_act_once_when_sent_twice_are_resent_checked_on_the_real_cores():
    from sslfr_planner.modes import request_mode
    resent = {n for n, b in [('stow', {}), ('mode', {'mode': 'auto'}), ('estop', {}), ('release', {}),
                             ('reset', {}), ('replan', {}), ('home', {'axis': 'mirrors'}),
                             ('jog', {'axis': 'mirrors', 'delta': -0.05})]
              if commands.validate(n, b, LIMITS).resend}
    assert resent == {'stow', 'mode', 'estop'}
    core, clock = _core()                       # the real safety core: engage twice = once
    clock.advance(1.0)
    assert core.estop(True)[0] and core.estop(True) == (True, 'e-stop already engaged')
    assert core.estop(False)[0] and core.estop(False)[0] is False    # a second release is refused: not resent
    for current in ('auto', 'stow', 'manual', 'maintenance'):        # the real planner rule: again = once
        for mode in ('auto', 'stow', 'manual', 'maintenance'):
            first = request_mode(current, mode)
            again = request_mode(first.mode, mode)
            assert again.mode == first.mode and (again.success or not first.success)


def _answers(delays: list[float | None]):
    """A ``send`` whose k-th request is answered after delays[k] s (None: its answer is lost)."""
    import asyncio
    sent: list = []

    def send():
        loop = asyncio.get_running_loop()
        fut = loop.create_future()
        delay = delays[len(sent)]
        if delay is not None:
            loop.call_later(delay, lambda k=len(sent): fut.done() or fut.set_result(f'answer {k}'))
        sent.append(fut)
        return fut
    return send, sent


@pytest.mark.parametrize('delays,timeout,every,answer,n', [
    ([0.0], 1.0, None, 'answer 0', 1),                       # answered at once: one request
    ([0.0], 1.0, 0.05, 'answer 0', 1),
    ([None, 0.0, 0.0], 2.0, 0.05, 'answer 1', 2),            # first answer lost: the second answers
    ([None, None, None, 0.0], 2.0, 0.05, 'answer 3', 4),
    ([0.12, None, None, None], 2.0, 0.05, 'answer 0', 3),    # a late first answer still counts
    ([None], 0.2, None, None, 1),                            # sent once: lost means no answer in time
    ([None] * 50, 0.2, 0.05, None, 4),                       # 0, .05, .10, .15 s: then the time is up
])
def test_first_answer_resends_only_when_asked_and_keeps_to_the_timeout(delays, timeout, every, answer, n):
    import asyncio
    import time
    send, sent = _answers(delays)
    t0 = time.monotonic()
    got, count = asyncio.run(commands.first_answer(send, timeout, every))
    took = time.monotonic() - t0
    assert got == answer and count == len(sent)
    assert count == 1 if every is None else n <= count <= timeout / every + 1
    assert took < timeout + 1.0 and (answer is not None or took >= timeout)
    assert all(f.done() for f in sent)                      # nothing left waiting


def test_jog_bound_is_the_smaller_of_page_and_driver_limits():
    lim = {'mirrors': commands.JogLimits(page_max=0.05, driver_max=0.2)}
    assert commands.validate('jog', {'axis': 'mirrors', 'delta': 0.05}, lim).request['delta'] == 0.05
    with pytest.raises(commands.CommandError):
        commands.validate('jog', {'axis': 'mirrors', 'delta': 0.0501}, lim)


# ------------------------------------------------------------------ live state
def _phase(**kw):
    from sslfr_interfaces.msg import TrackerPhase
    m = TrackerPhase(phase=2, phase_name='TRACKING', mode='auto', reason='day cycle', latitude=36.8,
                     longitude=-2.4, altitude=22.0, site_source='gps')
    m.sunrise.sec, m.solar_noon.sec, m.sunset.sec = 1782017445, 1782043885, 1782070325
    for k, v in kw.items():
        setattr(m, k, v)
    return m


def test_live_state_from_real_messages_is_json_without_nan():
    from sensor_msgs.msg import NavSatFix, Temperature
    from sslfr_interfaces.msg import AxisStatus, Irradiance, SafetyState, SunPosition
    wall = [1000.0]
    s = live.LiveState(wall=lambda: wall[0])
    s.on_phase(_phase())
    s.on_safety(SafetyState(level=2, stow_required=True, reasons=['outlet over-temperature: 152.0 degC > 150.0 '
                                                                  'degC (latched until reset)'], sequence=7))
    s.on_axis(AxisStatus(axis='mirrors', state='following', commanded=0.1, setpoint=0.1, measured=0.1001,
                         error=1e-4, link_state=AxisStatus.LINK_UP, frames_lost=3))
    s.on_axis(AxisStatus(axis='not_an_axis'))
    s.on_sun(SunPosition(zenith=0.5, azimuth=2.0, transversal=-0.3, longitudinal=0.1, above_horizon=True))
    s.on_temperature('outlet', Temperature(temperature=float('nan'), variance=0.0))
    s.on_beam(Irradiance(beam=812.5, illuminance=84500.0))
    fix = NavSatFix(latitude=36.8, longitude=-2.4, altitude=30.0)
    fix.status.status = -1
    s.on_fix(fix)
    wall[0] = 1002.5
    snap = s.snapshot(ros_time=1782030000.0)
    text = json.dumps(snap, allow_nan=False)                 # raises on NaN
    assert snap['phase']['name'] == 'TRACKING' and snap['phase']['sunrise'] == 1782017445
    assert snap['safety']['name'] == 'STOW' and 'Safety reset' in snap['safety']['reasons'][0]['hint']
    assert snap['axes']['mirrors']['link'] == 'LINK_UP' and snap['axes']['mirrors']['frames_lost'] == 3
    assert set(snap['axes']) == {'mirrors'}
    assert snap['sun']['elevation'] == pytest.approx(math.pi / 2 - 0.5)
    assert snap['temperatures']['outlet']['value'] is None
    assert snap['gps']['name'] == 'NO_FIX' and snap['gps']['horizontal_std'] is None
    assert snap['ages']['phase'] == pytest.approx(2.5) and snap['ages']['axes/mirrors'] == pytest.approx(2.5)
    assert 'NaN' not in text and s.version == 7      # 8 messages, one of an unknown axis


def _core():
    from sslfr_safety.core import FakeClock, SafetyConfig, SafetyCore
    clock = FakeClock()
    return SafetyCore(SafetyConfig(), clock), clock


def test_live_state_shows_each_axis_accuracy_alarm_with_the_drivers_thresholds():
    """The page's accuracy column: the driver's filter on the statuses the page receives,
    with the driver's thresholds once its parameters are read (remote.REMOTE_PARAMS)."""
    import json
    import math

    from sslfr_interfaces.msg import AxisStatus, TrackerPhase
    s = live.LiveState()
    assert remote.REMOTE_PARAMS['mirrors_driver']['accuracy.warn_threshold'] == 'mirrors.accuracy.warn_threshold'

    def status(t, err, state='following'):
        m = AxisStatus(axis='mirrors', state=state, setpoint=0.3, measured=0.3 + math.radians(err))
        m.header.stamp.sec = t
        return m
    s.on_axis(status(990, 0.5))
    assert s.snapshot()['accuracy']['mirrors']['tracking'] is False     # no phase yet: not judged
    s.on_phase(TrackerPhase(phase=TrackerPhase.TRACKING))
    for t in range(1000, 1010):
        s.on_axis(status(t, 0.01))
    snap = s.snapshot()
    assert snap['accuracy']['mirrors']['level'] == 'OK' and snap['accuracy']['mirrors']['tracking'] is True
    for t in range(1010, 1100):
        s.on_axis(status(t, 0.1))
    acc = s.snapshot()['accuracy']['mirrors']
    assert acc['level'] == 'WARN' and 'not estimated' in acc['estimated_loss'] and '> 0.060 deg' in acc['message']
    # the driver's loss table (a double array parameter): the alarm quotes its estimate
    s.set_info('mirrors.accuracy.loss_table', (0.0, 0.0, 0.0, math.radians(0.2), 1.0, 2.0))
    s.on_axis(status(1100, 0.1))
    acc = s.snapshot()['accuracy']['mirrors']
    assert acc['estimated_loss'] == 'estimated optical loss 0.5-1.0 %' and '0.5-1.0 %' in acc['message']
    # the driver's own thresholds, read from its parameters: 0.1 deg is now within
    s.set_info('mirrors.accuracy.warn_threshold', math.radians(0.2))
    s.on_axis(status(1101, 0.1))
    assert s.snapshot()['accuracy']['mirrors']['level'] == 'OK'
    s.set_info('mirrors.accuracy.error_threshold', math.radians(0.1))     # below warn: not applied
    assert s.accuracy['mirrors'].cfg.error == pytest.approx(math.radians(0.36))
    s.on_axis(status(1102, 0.1, state='stowing'))
    acc = s.snapshot()['accuracy']['mirrors']
    assert acc['tracking'] is False and acc['level'] == 'OK'
    json.dumps(s.snapshot(), allow_nan=False)


def test_every_safety_reason_of_the_real_core_gets_its_own_hint():
    from sslfr_common.contract import JOINTS as AXES
    core, clock = _core()
    clock.advance(30.0)                                       # past the start-up grace: watchdogs fire
    core.on_temperature('outlet', 180.0)
    core.estop(True)
    texts = list(core.evaluate().reasons)
    core.estop(False)
    texts += list(core.evaluate().reasons)
    core.on_temperature('inlet', float('nan'))
    texts += list(core.evaluate().reasons)
    for axis in AXES:
        core.on_axis_status(axis, False, 0.3)
    core.on_limit_switches({'initial': True, 'last': False, 'sleeping': False, 'longitudinal_1': False,
                            'longitudinal_2': False})
    texts += list(core.evaluate().reasons)
    core.on_driver_state('mobile_structure', 'unconfigured', 0, False)
    texts += list(core.evaluate().reasons)
    expected = {'over-temperature': 'cooled', 'operator e-stop': 'Release the e-stop',
                'e-stop released': 'stays stowed', 'thermocouple': 'wiring', 'heartbeat watchdog': 'not publishing',
                'limit switch initial tripped': 'home the axis', 'no site': 'GPS fix',
                'mobile_structure axis not ready': 'active and the axis homed'}
    for key, words in expected.items():
        found = [t for t in texts if key in t]
        assert found, (key, texts)
        assert words in live.clear_hint(found[0]), (found[0], live.clear_hint(found[0]))
    assert 'docs/operator.md' in live.clear_hint('something new')
    # one source: every reason the core gave has its rule's hint on the page
    from sslfr_safety.rules import hint_for
    assert all(live.clear_hint(t) == hint_for(t) != '' for t in texts), texts


def test_day_buffer_samples_per_period_and_clears_at_local_solar_midnight():
    from sslfr_interfaces.msg import AxisStatus, SunPosition
    s = live.LiveState()
    s.on_phase(_phase(longitude=-90.0))                        # local solar midnight = 06:00 UTC
    s.on_axis(AxisStatus(axis='mirrors', measured=0.2, setpoint=0.21))
    s.on_sun(SunPosition(zenith=0.5, transversal=-0.4, above_horizon=True))
    buf = live.DayBuffer(period=30.0)
    day0 = 1782000000 - 1782000000 % 86400                     # 00:00 UTC
    t = day0 + 5 * 3600.0
    assert buf.maybe_sample(t, s) and not buf.maybe_sample(t + 29.9, s) and buf.maybe_sample(t + 30.0, s)
    j = buf.to_json()
    assert j['t'] == [t, t + 30.0] and j['columns']['mirrors_measured'] == [0.2, 0.2]
    assert j['columns']['mirrors_ideal'] == [-0.2, -0.2]       # theta_t / 2, seed 000 eq. 11
    assert j['columns']['inlet'] == [None, None]
    assert buf.maybe_sample(day0 + 6 * 3600.0 + 1, s)          # new local solar day: cleared
    assert len(buf.to_json()['t']) == 1
    assert not buf.maybe_sample(float('nan'), s) and not buf.maybe_sample(0.0, s)
    assert buf.maxlen == 2882


# ------------------------------------------------------------------ params and remote facts
def test_params_defaults_valid_and_bad_values_named():
    table = params.WEB_PARAMS
    assert table.validate(table.defaults()) == []
    assert table.defaults()['bind_address'] == '127.0.0.1'              # never every interface by default
    bad = {**table.defaults(), 'bind_address': 'my-pi.local', 'port': 70000, 'push_period': 5.0}
    errs = ' '.join(table.validate(bad))
    assert 'bind_address' in errs and 'port' in errs and 'push_period' in errs
    assert table.coerce({'session_timeout': 60})['session_timeout'] == 60.0


def test_remote_parameter_nodes_exist_in_the_node_set_and_values_convert():
    from rcl_interfaces.msg import ParameterValue
    names = {n.name for n in nodeset.load().nodes}
    assert set(remote.REMOTE_PARAMS) <= names and 'web' in names
    got = remote.apply('safety', ['temperature.limit', 'temperature.hysteresis'],
                       [ParameterValue(type=3, double_value=150.0), ParameterValue(type=0)])
    assert got == {'temperature_limit': 150.0}
    got = remote.apply('recorder', ['output_dir'], [ParameterValue(type=4, string_value='/bags')])
    assert got == {'bag_dir': '/bags'}


# ------------------------------------------------------------------ bags
def _bag(root: Path, name: str, files: dict[str, bytes]) -> Path:
    d = root / name
    d.mkdir(parents=True)
    for f, data in files.items():
        (d / f).write_bytes(data)
    return d


def test_bag_listing_lookup_never_escapes_the_bag_directory(tmp_path):
    root = tmp_path / 'bags'
    _bag(root, 'sslfr_2026-06-21', {'sslfr_2026-06-21_0.mcap': b'\x89MCAP0\r\n' + b'x' * 100})
    _bag(root, 'notes', {'readme.txt': b'hi'})                  # no .mcap: not a bag
    (tmp_path / 'secret').mkdir()
    (tmp_path / 'secret' / 'a.mcap').write_bytes(b'x')
    (root / 'link').symlink_to(tmp_path / 'secret')
    listed = bags.list_bags(root)
    assert [e.name for e in listed] == ['sslfr_2026-06-21']
    assert listed[0].date == '2026-06-21' and 'metadata' in listed[0].problem and listed[0].size == 108
    assert bags.find_bag(root, 'sslfr_2026-06-21') == root / 'sslfr_2026-06-21'
    for evil in ('..', '../secret', 'link', 'notes', '/etc', 'sslfr_2026-06-21/../..', '', '.hidden'):
        assert bags.find_bag(root, evil) is None, evil
    assert bags.list_bags(tmp_path / 'missing') == []


def test_bag_zip_stream_is_a_valid_zip_with_every_file_byte_exact(tmp_path):
    big = os.urandom(3 * bags.CHUNK + 123)
    d = _bag(tmp_path, 'sslfr_2026-06-21', {'metadata.yaml': b'rosbag2_bagfile_information: {}\n',
                                            'sslfr_2026-06-21_0.mcap': big, 'sslfr_2026-06-21_1.mcap': b'small'})
    pieces = list(bags.iter_zip(d))
    assert len(pieces) > 3 and max(len(p) for p in pieces) <= bags.CHUNK + 4096     # streamed, not in one piece
    zf = zipfile.ZipFile(io.BytesIO(b''.join(pieces)))
    assert zf.testzip() is None
    assert sorted(zf.namelist()) == ['sslfr_2026-06-21/metadata.yaml', 'sslfr_2026-06-21/sslfr_2026-06-21_0.mcap',
                                     'sslfr_2026-06-21/sslfr_2026-06-21_1.mcap']
    assert zf.read('sslfr_2026-06-21/sslfr_2026-06-21_0.mcap') == big


def test_report_freshness_follows_the_bag(tmp_path):
    d = _bag(tmp_path, 'b', {'b_0.mcap': b'x'})
    out = tmp_path / 'rep'
    assert not bags.report_is_fresh(d, out)
    out.mkdir()
    (out / 'report.txt').write_text('r')
    assert bags.report_is_fresh(d, out)
    later = (out / 'report.txt').stat().st_mtime_ns + 10 ** 9
    os.utime(d / 'b_0.mcap', ns=(later, later))                  # the bag grew after the report
    assert not bags.report_is_fresh(d, out)


# ------------------------------------------------------------------ ./sslfr web-password
def test_web_password_cli_writes_a_hash_and_refuses_weak_passwords(tmp_path, monkeypatch, capsys):
    from sslfr_web import password_cli
    target = tmp_path / 'conf' / 'pw'
    monkeypatch.setattr('sys.stdin', io.StringIO('short\n'))
    assert password_cli.main(['--stdin', '--file', str(target)]) == 1
    assert not target.exists() and 'at least 8' in capsys.readouterr().err
    monkeypatch.setattr('sys.stdin', io.StringIO('a good passphrase\n'))
    assert password_cli.main(['--stdin', '--file', str(target)]) == 0
    assert auth.verify_password('a good passphrase', target.read_text())
    answers = iter(['another passphrase', 'another passphrasX'])
    monkeypatch.setattr('getpass.getpass', lambda prompt='': next(answers))
    assert password_cli.main(['--file', str(target)]) == 1                 # the two differ: unchanged
    assert auth.verify_password('a good passphrase', target.read_text())


def test_wind_stow_release_and_wind_shown_on_the_page():
    """Issue 35: the page shows the wind and a wind stow's time left (SafetyState
    wind_release_in: NaN none, inf not calm yet, else seconds)."""
    from sslfr_interfaces.msg import SafetyState, Wind
    assert live.wind_release(math.nan) is None
    assert live.wind_release(math.inf) == {'calm': False, 'release_in': None}
    assert live.wind_release(754.26) == {'calm': True, 'release_in': 754.3}
    st = live.LiveState(wall=lambda: 100.0)
    msg = SafetyState(level=2, stow_required=True, reasons=['wind gust 21.0 m/s > 20.0 m/s (3 s mean): wind stow'],
                      wind_stow=True, wind_release_in=600.0)
    st.on_safety(msg)
    st.on_wind(Wind(speed=21.0, gust=22.5, mean=9.0, window=600.0, pulse_rate=27.0))
    snap = json.loads(json.dumps(st.snapshot()))
    assert snap['safety']['wind_stow'] and snap['safety']['wind_release'] == {'calm': True, 'release_in': 600.0}
    assert 'release' in snap['safety']['reasons'][0]['hint'] or 'calm' in snap['safety']['reasons'][0]['hint']
    assert snap['wind'] == {'speed': 21.0, 'gust': 22.5, 'mean': 9.0, 'window': 600.0, 'stamp': None}


# ------------------------------------------------------------------ the described collector
def test_page_draws_the_described_collector_lines_and_movements():
    """Seed 004: one movement, ten lines at Table 1's offsets from the drive, the aim
    3.75 m up, no tilting; seed 000: three movements, 25 lines at psi_i / 2 (eq. 14);
    the day plots' ideal is the law's drive (seed 004: 0.4962 theta_T)."""
    from sslfr_planner import description
    from sslfr_web import collector
    cfg = Path(__file__).resolve().parents[2] / 'sslfr_bringup' / 'config'
    s004 = description.load(cfg / 'collectors' / 'florianopolis_lepten.yaml')
    c = collector.page_collector(s004)
    assert c['joints'] == ['mirrors'] and not c['tilting'] and c['aim_height'] == 3.75
    assert len(c['lines']) == 10 and c['lines'][0]['x'] < 0 < c['lines'][-1]['x']
    assert [math.degrees(line['offset']) for line in c['lines']] == pytest.approx(
        [15.8311, 12.8113, 9.4542, 5.8066, 1.9593, -1.9594, -5.8066, -9.4543, -12.8113, -15.8312], abs=1e-6)
    assert collector.ideal_drive(s004)(math.radians(30.0)) == pytest.approx(0.4962 * math.radians(30.0))
    s000 = description.load(cfg / 'collectors' / 'almeria_three_movement.yaml')
    c0 = collector.page_collector(s000)
    assert c0['joints'] == ['mirrors', 'mobile_structure', 'secondary_reflector'] and c0['tilting']
    assert len(c0['lines']) == 25 and c0['lines'][12] == {'x': 0.0, 'offset': 0.0}
    x1 = c0['lines'][13]['x']
    assert c0['lines'][13]['offset'] == pytest.approx(-math.atan(x1 / 1.5243) / 2, abs=1e-9)
    assert json.loads(json.dumps(c)) == c                     # JSON-ready
    # the day buffer's ideal follows the law once the description is known
    from sslfr_interfaces.msg import SunPosition
    s = live.LiveState()
    s.on_phase(_phase(longitude=-48.5))
    s.on_sun(SunPosition(zenith=0.5, transversal=0.4, above_horizon=True))
    buf = live.DayBuffer(period=30.0)
    buf.ideal = collector.ideal_drive(s004)
    assert buf.maybe_sample(1782000000.0, s)
    assert buf.to_json()['columns']['mirrors_ideal'] == [pytest.approx(0.4962 * 0.4, abs=1e-6)]
    assert remote.REMOTE_PARAMS['planner']['collector.description'] == 'collector_description'


def test_thermal_output_shown_on_the_page():
    """Issue 34: a collector with a flow meter: flow [L/h], thermal power [W] and the
    efficiency on the page (None when not computed: JSON has no NaN); none otherwise."""
    from sslfr_interfaces.msg import ThermalPower
    st = live.LiveState(wall=lambda: 100.0)
    assert 'thermal' not in json.loads(json.dumps(st.snapshot()))
    st.on_thermal(ThermalPower(volume_flow=150.0 / 3.6e6, power=523.4, beam=801.0, aperture=1.0,
                               efficiency=0.6534))
    snap = json.loads(json.dumps(st.snapshot()))
    assert snap['thermal'] == {'volume_flow': 4.1667e-05, 'lph': 150.0, 'power': 523.4, 'efficiency': 0.6534,
                               'beam': 801.0, 'aperture': 1.0, 'stamp': None}
    st.on_thermal(ThermalPower(volume_flow=150.0 / 3.6e6, power=12.0, beam=math.nan, aperture=1.0,
                               efficiency=math.nan))
    snap = json.loads(json.dumps(st.snapshot()))
    assert snap['thermal']['efficiency'] is None and snap['thermal']['beam'] is None
