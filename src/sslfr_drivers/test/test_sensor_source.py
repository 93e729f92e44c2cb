"""The sensor nodes' plumbing without ROS: parameter tables, the board source (both
framings, over real ptys), the sample queue, diagnostics decisions, switch timing."""
import datetime as dt
import math
from types import SimpleNamespace

import pytest

from sslfr_drivers.link.sensor_messages import AlsSample
from sslfr_drivers.sensors import nmea
from sslfr_drivers.sensors.debounce import BoardClock, SwitchTracker
from sslfr_drivers.sensors.health import RateMeter, board_report, fix_report
from sslfr_drivers.sensors.sensor_params import ABSORBER_BOARD, GPS, IRRADIANCE, TABLES
from sslfr_drivers.sensors.source import BoardSource, SampleQueue
from sslfr_sim.runner import SimThread
from sslfr_sim.sensors import GpsSim, IrradianceSim

from drivers_testutil import wait_for

NOON = dt.datetime(2026, 3, 21, 12, 0, tzinfo=dt.timezone.utc).timestamp()

# ------------------------------------------------------------------ parameter tables
#: (node, name) -> (default, lo, hi, choices): the sensor nodes' parameters as they
#: were before the tables moved into sensor_params (names, defaults and ranges kept).
EXPECTED = {
    ('gps', 'port'): ('', None, None, ()),
    ('gps', 'framing'): ('protocol', None, None, ('protocol', 'raw_nmea')),
    ('gps', 'key_file'): ('', None, None, ()),
    ('gps', 'baudrate'): (115200, 1200, 921600, ()),
    ('gps', 'frame_id'): ('gps', None, None, ()),
    ('gps', 'time_ref_source'): ('gps', None, None, ()),
    ('gps', 'uere'): (4.0, 0.01, 100.0, ()),
    ('gps', 'uere_sbas'): (0.1, 0.001, 100.0, ()),
    ('gps', 'time_jump_threshold'): (2.0, 0.01, 1.0e9, ()),
    ('gps', 'time_ref_without_fix'): (False, None, None, ()),
    ('gps', 'max_sample_age'): (3.0, 0.1, 3600.0, ()),
    ('gps', 'heartbeat'): (0.5, 0.05, 5.0, ()),
    ('absorber_board', 'port'): ('', None, None, ()),
    ('absorber_board', 'key_file'): ('', None, None, ()),
    ('absorber_board', 'baudrate'): (115200, 1200, 921600, ()),
    ('absorber_board', 'inlet_frame_id'): ('absorber_inlet', None, None, ()),
    ('absorber_board', 'outlet_frame_id'): ('absorber_outlet', None, None, ()),
    ('absorber_board', 'converter_error'): (2.0, 0.0, 50.0, ()),
    ('absorber_board', 'thermocouple_error'): (2.5, 0.0, 50.0, ()),
    ('absorber_board', 'thermocouple_error_relative'): (0.0075, 0.0, 0.1, ()),
    ('absorber_board', 'debounce_time'): (0.03, 0.0, 5.0, ()),
    ('absorber_board', 'switch_rate'): (10.0, 0.5, 100.0, ()),
    ('absorber_board', 'anemometer_pin'): (-1, -1, 17, ()),
    ('absorber_board', 'anemometer_slope'): (0.765, 0.01, 20.0, ()),
    ('absorber_board', 'anemometer_offset'): (0.35, 0.0, 5.0, ()),
    ('absorber_board', 'wind_rate'): (1.0, 0.1, 10.0, ()),
    ('absorber_board', 'flow_meter_pin'): (-1, -1, 17, ()),
    ('absorber_board', 'flow_meter_k_factor'): (450.0, 0.1, 1.0e5, ()),
    ('absorber_board', 'flow_window'): (5.0, 0.5, 600.0, ()),
    ('absorber_board', 'aperture_area'): (0.0, 0.0, 1000.0, ()),
    ('absorber_board', 'efficiency_min_beam'): (100.0, 0.0, 1500.0, ()),
    ('absorber_board', 'beam_max_age'): (5.0, 0.5, 600.0, ()),
    ('absorber_board', 'max_sample_age'): (1.5, 0.1, 3600.0, ()),
    ('absorber_board', 'heartbeat'): (0.5, 0.05, 5.0, ()),
    ('irradiance', 'port'): ('', None, None, ()),
    ('irradiance', 'key_file'): ('', None, None, ()),
    ('irradiance', 'baudrate'): (115200, 1200, 921600, ()),
    ('irradiance', 'frame_id'): ('irradiance', None, None, ()),
    ('irradiance', 'luminous_efficacy'): (104.0, 50.0, 250.0, ()),
    ('irradiance', 'relative_uncertainty'): (0.1, 0.0, 1.0, ()),
    ('irradiance', 'max_sample_age'): (3.0, 0.1, 3600.0, ()),
    ('irradiance', 'heartbeat'): (0.5, 0.05, 5.0, ()),
}


def test_tables_keep_the_names_defaults_and_ranges():
    got = {(node, s.name): (s.default, s.lo, s.hi, s.choices)
           for node, table in TABLES.items() for s in table}
    assert got == EXPECTED
    for table in TABLES.values():
        assert table.validate(table.defaults()) == []
        for s in table:
            assert f'[{s.unit}]' in s.description, s.name       # the unit, stated once


@pytest.mark.parametrize('table, name, value, why', [
    (GPS, 'framing', 'ubx', "framing: 'ubx' is not one of protocol, raw_nmea"),
    (GPS, 'baudrate', 1199, 'baudrate: 1199 bit/s is outside [1200, 921600]'),
    (GPS, 'uere', math.nan, 'uere: nan is not a finite number'),
    (GPS, 'heartbeat', 0.04, 'heartbeat: 0.04 s is outside [0.05, 5.0]'),
    (ABSORBER_BOARD, 'debounce_time', -0.01, 'debounce_time: -0.01 s is outside [0.0, 5.0]'),
    (ABSORBER_BOARD, 'switch_rate', 0.4, 'switch_rate: 0.4 Hz is outside [0.5, 100.0]'),
    (IRRADIANCE, 'luminous_efficacy', -5.0, 'luminous_efficacy: -5.0 lm/W is outside [50.0, 250.0]'),
])
def test_tables_refuse_with_the_reason(table, name, value, why):
    assert table.validate({**table.defaults(), name: value}) == [why]


def test_site_config_section_checked_with_the_same_table():
    assert GPS.check_overrides({'framing': 'raw_nmea', 'baudrate': 9600}) == []
    errors = IRRADIANCE.check_overrides({'luminous_eficacy': 120.0})
    assert errors and 'did you mean luminous_efficacy' in errors[0]


# ------------------------------------------------------------------ board source
def test_unconfigured_and_bad_ports_are_reported_not_raised():
    s = BoardSource('').start()
    assert s.state == 'unconfigured' and 'no port configured' in s.error()
    s.stop()
    s = BoardSource('xbee:/dev/null').start()          # no ?addr=
    assert s.state == 'down' and s.error().startswith("bad port 'xbee:/dev/null'")
    assert s.counters() == {'bytes_received': 0, 'reconnects': 0}
    s.stop()


def test_raw_nmea_source_reads_and_reopens_an_unplugged_module(tmp_path):
    got = []
    link = str(tmp_path / 'gps0')
    with SimThread.plain(GpsSim({'start_utc': NOON, 'ttff': 0.0, 'framing': 'raw_nmea'}),
                         link=link) as sim:
        src = BoardSource(link, 'raw_nmea', 9600, on_bytes=got.append).start()
        try:
            assert wait_for(lambda: b'$GPGGA' in b''.join(got), 5)
            assert src.state == 'up' and src.counters()['reconnects'] == 0
            sim.command('unplug 0.5')
            assert wait_for(lambda: src.state == 'down', 3)
            n = len(got)
            assert wait_for(lambda: src.counters()['reconnects'] == 1 and len(got) > n, 6)
            assert src.state == 'up'
            assert src.counters()['bytes_received'] == sum(map(len, got))
            records = nmea.NmeaStream().feed(b''.join(got))
            assert any(isinstance(r, nmea.FixRecord) and r.has_fix for r in records)
        finally:
            src.stop()
    assert src.state == 'down'


def test_protocol_source_delivers_board_messages():
    got = []
    with SimThread.plain(IrradianceSim({'start_utc': NOON, 'period': 0.1, 'noise': 0.0})) as sim:
        src = BoardSource(sim.path, 'protocol', on_message=got.append, heartbeat=0.2).start()
        try:
            assert wait_for(lambda: src.state == 'up' and any(isinstance(m, AlsSample) for m in got), 5)
            c = src.counters()
            assert c['frames_received'] >= 2 and c['frames_lost'] == 0 and c['crc_errors'] == 0
            assert src.error() == ''
        finally:
            src.stop()


def test_sample_queue_keeps_order_and_counts_what_it_drops():
    q = SampleQueue(3)
    for i in range(5):
        q.put(i, 10.0 + i)
    assert q.dropped == 2 and len(q) == 3
    assert list(q.drain()) == [(2, 12.0), (3, 13.0), (4, 14.0)]
    assert len(q) == 0 and list(q.drain()) == []


def test_sample_queue_asks_for_a_wake_only_when_it_stops_being_empty():
    q = SampleQueue(4)
    assert q.put('a', 1.0) is True             # was empty: wake the consumer
    assert q.put('b', 2.0) is False            # a wake is already pending
    drained = q.drain()
    assert next(drained) == ('a', 1.0)
    assert q.put('c', 3.0) is False            # drained in the same pass
    assert list(drained) == [('b', 2.0), ('c', 3.0)]
    assert q.put('d', 4.0) is True             # empty again: a new wake


# ------------------------------------------------------------------ diagnostics
class ManualClock:
    def __init__(self, t=100.0):
        self.t = t

    def __call__(self):
        return self.t


def test_rate_meter():
    clk = ManualClock()
    meter = RateMeter(clk)
    assert math.isinf(meter.age())
    for _ in range(4):
        clk.t += 0.25
        meter.tick()
    assert meter.rate() == pytest.approx(4.0) and meter.total == 4
    clk.t += 2.0
    assert meter.age() == pytest.approx(2.0) and meter.rate() == 0.0


def _source(state, framing='protocol', error='', port='/dev/ttyUSB0'):
    return SimpleNamespace(state=state, framing=framing, port=port, error=lambda: error,
                           counters=lambda: {'frames_lost': 3, 'reconnects': 1})


@pytest.mark.parametrize('state, framing, faults, age, level, message', [
    ('unconfigured', 'protocol', [], 0.1, 'ERROR', 'board unconfigured: no port'),
    ('down', 'raw_nmea', [], 0.1, 'ERROR', 'board down: no port'),
    ('refused', 'protocol', [], 0.1, 'ERROR', 'board refused: no port'),
    ('up', 'protocol', ['VEML7700 saturated'], 0.1, 'ERROR', 'sensor fault: VEML7700 saturated'),
    ('silent', 'protocol', [], 0.1, 'WARN', 'link silent'),
    ('connecting', 'protocol', [], 0.1, 'WARN', 'link connecting'),
    ('up', 'protocol', [], 5.0, 'WARN', 'no sample for 5.0 s'),
    ('up', 'raw_nmea', [], 0.1, 'OK', 'ok'),
    ('up', 'protocol', [], 0.1, 'OK', 'ok'),
])
def test_board_report_levels(state, framing, faults, age, level, message):
    clk = ManualClock()
    meter = RateMeter(clk)
    meter.tick()
    clk.t += age
    r = board_report(_source(state, framing, 'no port'), meter, 3.0, faults, {'queue_dropped': 0})
    assert (r.level, r.message) == (level, message)
    assert r.values['link_state'] == state and r.values['frames_lost'] == '3'
    assert r.values['reconnects'] == '1' and r.values['queue_dropped'] == '0'
    assert r.values['samples'] == '1' and r.values['last_sample_age_s'] == f'{age:.2f}'


def test_board_report_before_any_sample():
    r = board_report(_source('up', port=''), RateMeter(ManualClock()), 3.0, [], {})
    assert r.level == 'WARN' and r.message == 'no sample for inf s'
    assert r.values['last_sample_age_s'] == 'never' and r.values['port'] == '(none)'


def test_fix_report():
    assert fix_report(None, 0, 0, None).level == 'WARN'
    r = fix_report(-1, 3, 3, None)
    assert (r.level, r.message, r.values['satellites']) == ('WARN', 'no fix', 'none')
    fix = SimpleNamespace(satellites=8, hdop=1.04, quality=1, nav_mode=3)
    r = fix_report(0, 10, 2, fix)
    assert (r.level, r.message) == ('OK', 'fix')
    assert r.values == {'fixes': '10', 'no_fix': '2', 'satellites': '8', 'hdop': '1.04',
                        'quality': '1', 'nav_mode': '3'}


# ------------------------------------------------------------------ switch timing
def test_board_clock_wrap_and_reset():
    c = BoardClock()
    assert c.seconds(0xFFFF_FF00) == pytest.approx(0xFFFF_FF00 / 1000)
    assert c.seconds(0x100) == pytest.approx((0x1_0000_0100) / 1000)     # wrapped: +2**32 ms
    t = c.seconds(5000)
    assert c.seconds(1000) == pytest.approx(t)                            # reset: continuous
    assert c.seconds(1500) == pytest.approx(t + 0.5)


def test_switch_tracker_dates_changes_at_the_first_raw_sample():
    s = SwitchTracker(0.03)
    assert s.states is None
    assert s.update(1000, 0b00000, 500.0) == list(s.debouncer.names)     # initial states
    assert set(s.changed_at.values()) == {500.0}
    # sleeping closes at board 1.100 s; held by 1.140 s, received (host) at 500.2 s
    assert s.update(1100, 0b00100, 500.15) == []
    assert s.update(1140, 0b00100, 500.2) == ['sleeping']
    assert s.states['sleeping'].closed
    assert s.changed_at['sleeping'] == pytest.approx(500.2 - 0.040)
    assert s.changed_at['initial'] == 500.0
    # near host time 0 (sim time before /clock) the lag is not subtracted
    s2 = SwitchTracker(0.05)
    s2.update(0, 0, 0.0)
    assert s2.update(100, 0b1, 0.001) == []
    assert s2.update(200, 0b1, 0.002) == ['initial']          # lag 0.1 s > 0.002 s
    assert s2.changed_at['initial'] == 0.002
