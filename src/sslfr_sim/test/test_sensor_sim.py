"""Simulated sensor boards and their protocol messages (no ROS, no pty)."""
import datetime as dt
import math
import random
from types import SimpleNamespace

import pytest
from hypothesis import given, strategies as st

from drivers_testutil import open_session
from sslfr_drivers.sensors import max6675

from sslfr_drivers.link import messages as m

from sslfr_drivers.sensors import nmea

from sslfr_drivers.sensors import veml7700
from sslfr_drivers.link.sensor_messages import AlsSample, NmeaChunk, SwitchSample, ThermocoupleSample
from sslfr_drivers.link.protocol import MAX_PAYLOAD, Framer, PayloadError
from sslfr_sim.world import Sky
from sslfr_sim.sensors import (AbsorberSim, GpsSim, IrradianceSim, WorldPublisher,
                                       read_axis_angles, write_axis_angle)

NOON = dt.datetime(2026, 6, 21, 12, 0, tzinfo=dt.timezone.utc).timestamp()


def _run(board, seconds, dt_=0.05):
    """Tick ``board`` for ``seconds`` of steady time; return the decoded messages it sent
    (in a session: boards send samples only to a host that opened one)."""
    if board._cur is None:
        open_session(board)
    framer, out = Framer(), []
    t = board.now
    for _ in range(int(seconds / dt_)):
        t += dt_
        board.tick(t)
        out += [m.decode(f) for f in framer.feed(board.take_output())]
    return out


def _outlets(msgs):
    return [max6675.decode(x.outlet).temperature for x in msgs if isinstance(x, ThermocoupleSample)]


def test_heating_depends_on_mirror_focus(tmp_path):
    """Focused mirrors heat the tube; the same sun with stowed mirrors does not."""
    lat, lon = 36.8381, -2.4597
    ideal = Sky(lat, lon, 60.0).sun(NOON + 60.0).transversal / 2   # mid-window
    temps = {}
    for name, angle in (('focused', ideal), ('off_by_1deg', ideal + math.radians(1.0)),
                        ('stowed', math.pi / 2)):
        world = str(tmp_path / f'{name}.json')
        write_axis_angle(world, 'mirrors', angle)
        b = AbsorberSim({'start_utc': NOON, 'speed': 60.0, 'noise': 0.0, 'world': world})
        # 2 simulated minutes (the sun's transversal angle moves ~0.5 deg meanwhile)
        temps[name] = _outlets(_run(b, 2.0))[-1]
    assert temps['focused'] > 45.0                          # from 25 degC ambient
    assert 30.0 < temps['off_by_1deg'] < temps['focused'] - 5.0
    assert temps['stowed'] <= 25.5


def test_stagnation_reaches_a_real_over_temperature():
    """Pump stopped (flow 0) at noon: the tube passes the seed's 150 degC limit."""
    b = AbsorberSim({'start_utc': NOON, 'speed': 600.0, 'noise': 0.0, 'flow': 0.0})
    temps = _outlets(_run(b, 6.0))                           # one simulated hour
    assert temps[-1] > 150.0
    assert all(b2 >= a - 0.5 for a, b2 in zip(temps, temps[1:]))  # monotone heating curve


def test_absorber_faults_and_switches(tmp_path):
    world = str(tmp_path / 'w.json')
    write_axis_angle(world, 'mirrors', math.pi / 2)
    write_axis_angle(world, 'mobile_structure', 0.0)
    write_axis_angle(world, 'secondary_reflector', 0.2)
    b = AbsorberSim({'start_utc': NOON, 'world': world})
    sw = [x for x in _run(b, 0.5) if isinstance(x, SwitchSample)]
    assert sw and sw[-1].bits == 0b01100                    # sleeping + longitudinal_1
    b.control({'cmd': 'fault', 'kind': 'thermocouple-open', 'target': 'inlet'})
    b.control({'cmd': 'fault', 'kind': 'overtemp', 'value': 175.0})
    th = [x for x in _run(b, 0.6) if isinstance(x, ThermocoupleSample)]
    assert max6675.decode(th[-1].inlet).fault == max6675.FAULT_OPEN
    assert max6675.decode(th[-1].outlet).temperature == pytest.approx(175.0, abs=0.5)
    assert not b.control({'cmd': 'fault', 'kind': 'thermocouple-open', 'target': 'middle'})['ok']
    assert not b.control({'cmd': 'fault', 'kind': 'no-such-fault'})['ok']


def test_world_publisher_and_reader(tmp_path):
    path = str(tmp_path / 'world.json')
    axis = SimpleNamespace(cfg=SimpleNamespace(axis='mirrors'), angle=0.25)
    WorldPublisher(path).update([axis, object()], now=1.0)
    assert read_axis_angles(path) == {'mirrors': 0.25}
    (tmp_path / 'bad.json').write_text('{not json')
    assert read_axis_angles(str(tmp_path / 'bad.json')) == {}
    assert read_axis_angles(None) == {}


def _write_many(path, axis, n):
    for k in range(n):
        write_axis_angle(path, axis, float(k))


def test_world_writers_in_several_processes_lose_no_update(tmp_path):
    """Three runner processes rewrite their own axis concurrently: every file read in
    between holds each axis' latest value or an older one, never a lost update at the end
    (before the lock a writer could put back another's older angle for a period)."""
    import multiprocessing
    path = str(tmp_path / 'world.json')
    n = 300
    procs = [multiprocessing.get_context('fork').Process(target=_write_many, args=(path, axis, n))
             for axis in ('mirrors', 'mobile_structure', 'secondary_reflector')]
    for p in procs:
        p.start()
    seen = {}
    while any(p.is_alive() for p in procs):
        for axis, angle in read_axis_angles(path).items():
            assert angle >= seen.get(axis, 0.0), (axis, angle, seen)   # never back in time
            seen[axis] = angle
    for p in procs:
        p.join()
        assert p.exitcode == 0
    assert read_axis_angles(path) == {'mirrors': n - 1, 'mobile_structure': n - 1, 'secondary_reflector': n - 1}


def test_gps_sim_protocol_and_raw_framing():
    b = GpsSim({'start_utc': NOON, 'ttff': 0.0})
    chunks = [x for x in _run(b, 2.5) if isinstance(x, NmeaChunk)]
    s = nmea.NmeaStream()
    recs = s.feed(b''.join(c.data for c in chunks))
    fixes = [r for r in recs if isinstance(r, nmea.FixRecord) and r.has_fix]
    assert len(fixes) == 3 and s.counters.bad_checksum == 0 and s.counters.truncated == 0
    assert fixes[0].utc == NOON
    raw = GpsSim({'start_utc': NOON, 'ttff': 0.0, 'framing': 'raw_nmea'})
    out = b''
    for k in range(50):
        raw.tick(0.05 * (k + 1))
        out += raw.take_output()
    assert b'\xa5\x5a' not in out and out.startswith(b'$GPRMC')   # no BOOT, no frames
    assert len(nmea.NmeaStream().feed(out)) == 6                 # 3 epochs: RMC + GGA
    with pytest.raises(ValueError):
        GpsSim({'framing': 'ubx'})


def test_irradiance_sim_measures_clear_sky_beam():
    b = IrradianceSim({'start_utc': NOON, 'noise': 0.0, 'period': 0.2})
    als = [x for x in _run(b, 2.0) if isinstance(x, AlsSample)]
    s = veml7700.decode(als[-1].count, als[-1].gain_code, als[-1].it_code)
    assert s.illuminance == pytest.approx(b.illuminance(), rel=0.001)
    assert 850.0 < s.illuminance / 104.0 < 1050.0           # clear-sky DNI at solstice noon
    b.control({'cmd': 'fault', 'kind': 'lux', 'value': 200000.0})
    als = [x for x in _run(b, 0.5) if isinstance(x, AlsSample)]
    assert veml7700.decode(als[-1].count, als[-1].gain_code, als[-1].it_code).saturated


def test_sensor_boards_refuse_get_status_and_identify():
    b = IrradianceSim({'start_utc': NOON})
    from sslfr_drivers.link.auth import HOST_TO_BOARD
    from sslfr_drivers.link.protocol import encode_frame
    s = open_session(b)
    b.receive(encode_frame(s.seal(HOST_TO_BOARD, 1, m.encode(m.GetStatus(), 0)))
              + encode_frame(s.seal(HOST_TO_BOARD, 2, m.encode(m.GetInfo(), 0))))
    out = [m.decode(f) for f in Framer().feed(b.take_output())]
    assert any(isinstance(x, m.Nack) and x.code == m.ErrorCode.UNKNOWN_TYPE for x in out)
    info = [x for x in out if isinstance(x, m.Info)][0]
    assert info.board_kind == m.BoardKind.IRRADIANCE and info.name_str == 'sim-irradiance'


@given(st.integers(0, 2**32 - 1), st.integers(0, 0xFFFF), st.integers(0, 0xFFFF))
def test_thermocouple_sample_roundtrip(ms, a, b):
    msg = ThermocoupleSample(ms, a, b)
    assert m.decode(m.encode(msg, 7)) == msg


@given(st.binary(min_size=1, max_size=MAX_PAYLOAD))
def test_nmea_chunk_roundtrip(data):
    assert m.decode(m.encode(NmeaChunk(data), 1)) == NmeaChunk(data)


def test_bad_sensor_payloads_raise_payload_error():
    with pytest.raises(PayloadError):
        NmeaChunk(b'').pack()
    with pytest.raises(PayloadError):
        NmeaChunk(b'x' * 89).pack()
    with pytest.raises(PayloadError):
        m.decode(m.encode(SwitchSample(1, 0x20), 1))        # a sixth switch does not exist
    from sslfr_drivers.link.protocol import Frame
    with pytest.raises(PayloadError):
        m.decode(Frame(AlsSample.TYPE, 1, b'\x00\x01'))
    assert all(0xC0 <= c.TYPE <= 0xDF for c in (NmeaChunk, ThermocoupleSample, SwitchSample, AlsSample))


def test_simulator_sky_against_pvlib():
    """The simulators' interpolated sun (the planner's SPA) agrees with pvlib's SPA."""
    import numpy as np
    import pandas as pd
    import pvlib
    lat, lon = 36.8352778, -2.4022222
    times = pd.date_range('2026-01-01', '2026-12-31', freq='7333min', tz='UTC')
    ref = pvlib.solarposition.get_solarposition(times, lat, lon, altitude=22.0, method='nrel_numpy')
    up = ref['apparent_zenith'].to_numpy() < 85.0
    sky = Sky(lat, lon, 22.0)
    mine = [sky.sun(t.timestamp()) for t in times]
    dz = np.degrees([s.zenith for s in mine]) - ref['apparent_zenith'].to_numpy()
    daz = (np.degrees([s.azimuth for s in mine]) - ref['azimuth'].to_numpy() + 180.0) % 360.0 - 180.0
    assert np.abs(dz[up]).max() < 0.02 and np.abs(daz[up]).max() < 0.05
    # transversal angle (seed 000 eq. 9): negative in the morning, positive in the afternoon
    assert sky.sun(NOON - 3 * 3600).transversal < 0 < sky.sun(NOON + 3 * 3600).transversal
    assert sky.dni(NOON - 12 * 3600) == 0.0 and 850.0 < sky.dni(NOON) < 1050.0


def test_runner_publishes_axis_angles_to_the_world_file(tmp_path, monkeypatch):
    """A sim_board runner with an axis board writes its joint angle where the absorber
    simulator reads it (SSLFR_SIM_WORLD)."""
    import time
    from sslfr_sim.axis import AxisSim
    from sslfr_sim.runner import SimThread
    world = tmp_path / 'world.json'
    monkeypatch.setenv('SSLFR_SIM_WORLD', str(world))
    with SimThread.plain(AxisSim.from_options({'axis': 'mirrors', 'initial_angle_deg': '30'},
                                              None)) as sim:
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and 'mirrors' not in read_axis_angles(str(world)):
            time.sleep(0.05)
        with sim.locked():
            true_angle = sim.board.angle
    assert read_axis_angles(str(world))['mirrors'] == pytest.approx(true_angle)
    assert true_angle == pytest.approx(math.radians(30.0))
    b = AbsorberSim({'start_utc': NOON, 'world': str(world)})
    assert b.axis_angles()['mirrors'] == pytest.approx(math.radians(30.0))


def test_absorber_counts_the_simulated_anemometer_on_the_pin_the_host_sets():
    """Issue 35: no pulse samples until SetPulseInput; then 4 Hz PulseSample whose counts
    follow the gusty wind (calm default 2 m/s, the `wind` fault's mean)."""
    from sslfr_drivers.link.auth import HOST_TO_BOARD
    from sslfr_drivers.link.protocol import encode_frame
    from sslfr_drivers.link.sensor_messages import PulseSample, SetPulseInput
    from sslfr_drivers.sensors import anemometer
    b = AbsorberSim({'start_utc': NOON, 'seed': 5})
    assert not [x for x in _run(b, 1.0) if isinstance(x, PulseSample)]
    s = open_session(b)
    b.receive(encode_frame(s.seal(HOST_TO_BOARD, 1, m.encode(SetPulseInput(9), 0)))
              + encode_frame(s.seal(HOST_TO_BOARD, 2, m.encode(SetPulseInput(7), 0))))
    out = [m.decode(f) for f in Framer().feed(b.take_output())]
    assert [type(x).__name__ for x in out] == ['Nack', 'Ack'] and out[0].code == m.ErrorCode.OUT_OF_RANGE

    def mean_speed(seconds):
        samples = [x for x in _run(b, seconds) if isinstance(x, PulseSample)]
        assert samples and all(x.pin == 7 for x in samples)
        counter, stats = anemometer.PulseCounter(), anemometer.WindStats()
        r = [stats.add(*iv) for x in samples if (iv := counter.add(x.board_ms, x.count))]
        return r[-1].mean, len(samples) / seconds
    calm, rate = mean_speed(60.0)
    assert calm == pytest.approx(2.0, abs=0.6) and rate == pytest.approx(4.0, abs=0.1)
    assert b.control({'cmd': 'fault', 'kind': 'wind', 'value': 18.0})['ok']
    assert mean_speed(60.0)[0] == pytest.approx(18.0, rel=0.15)
    assert not b.control({'cmd': 'fault', 'kind': 'wind', 'value': -3})['ok']
    b.control({'cmd': 'fault', 'kind': 'anemometer-silent', 'active': True})
    assert not [x for x in _run(b, 1.0) if isinstance(x, PulseSample)]


def test_simulated_gusty_wind_has_the_mean_and_a_usual_gust_factor():
    from sslfr_drivers.sensors import anemometer as an
    from sslfr_sim.world import GustyWind
    wind, stats = GustyWind(12.0, random.Random(3)), an.WindStats()
    count = 0.0
    last = 0
    for _ in range(4 * 600):
        count += an.frequency(wind.step(0.25)) * 0.25
        r = stats.add(0.25, int(count) - last)
        last = int(count)
    assert r.mean == pytest.approx(12.0, rel=0.15)
    assert 1.2 < r.gust / r.mean < 2.0


def test_a_held_clock_starts_at_the_anchor_the_control_socket_gives():
    """``anchor=hold``: the simulated UTC stays at start_utc until the runner's
    ``anchor T``, then runs as ``sslfr sim``'s /clock: start_utc + speed (now - T). The
    command reaches the boards that have a clock and refuses when none has."""
    from sslfr_sim.axis import AxisSim
    from sslfr_sim.base import FaultInjector
    from sslfr_sim.runner import PlainHost, Runner
    from sslfr_drivers.link.endpoint import PtyEndpoint
    b = GpsSim({'start_utc': NOON, 'speed': 60.0, 'anchor': 'hold', 'ttff': 0.0})
    b.now = 1000.0
    assert b.utc() == NOON
    b.now = 1500.0
    assert b.utc() == NOON                                # still held, however long
    runner = Runner(PtyEndpoint(None), PlainHost(b, FaultInjector()))
    try:
        assert runner.command('anchor 1600.5') == {'ok': True, 'anchored': 1}
        b.now = 1600.0
        assert b.utc() == NOON                            # before the anchor: start_utc
        b.now = 1610.5
        assert b.utc() == pytest.approx(NOON + 60.0 * 10.0)
        with pytest.raises(ValueError, match='finite'):   # the socket answers it as an error
            runner.command('anchor nan')
    finally:
        runner.close()
    axis = Runner(PtyEndpoint(None), PlainHost(AxisSim(), FaultInjector()))
    try:
        reply = axis.command('anchor 1.0')
        assert not reply['ok'] and 'no board with a simulated clock' in reply['error']
    finally:
        axis.close()
    fixed = GpsSim({'start_utc': NOON, 'speed': 2.0, 'anchor': '100'})
    fixed.now = 110.0
    assert fixed.utc() == NOON + 20.0                     # a numeric anchor: as before
