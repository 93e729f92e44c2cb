"""NMEA 0183 stream decoder: capture file, conventions, time handling, fuzzing."""
import datetime as dt
import math
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from sslfr_drivers.sensors import nmea
from sslfr_sim.world import GpsReceiver

CAPTURE = Path(__file__).parent / 'data' / 'gps_capture.nmea'
# The capture: 60 one-second epochs (RMC, GGA, GSA, GSV) of the simulated receiver at
# 36.8383 N, 2.4597 W (2026-03-21 10:30:00 UTC), no fix for the first 3 s (TTFF), sky
# blocked from 10:30:30 to 10:30:37 and 3 s re-acquisition; then hand-edited:
# a GGA with one digit changed (bad checksum), an RMC cut short, a GSA cut and run into
# the next sentence, UBX binary bytes, a 166-character TXT line, a well-formed unknown
# sentence, a GGA with a good checksum but garbage fields, a $PUBX proprietary sentence
# and a burst of line noise.


def _run(data: bytes, chunk: int):
    s = nmea.NmeaStream()
    out = []
    for i in range(0, len(data), chunk):
        out += s.feed(data[i:i + chunk], 1000.0 + i / 1000.0)
    return s, out


@pytest.mark.parametrize('chunk', [1, 7, 64, 100000])
def test_capture_file_counts(chunk):
    s, recs = _run(CAPTURE.read_bytes(), chunk)
    c = s.counters
    assert c.bad_checksum == 1
    assert c.truncated == 3
    assert c.parse_errors == 1
    assert c.garbage_bytes > 20
    fixes = [r for r in recs if isinstance(r, nmea.FixRecord)]
    times = [r for r in recs if isinstance(r, nmea.TimeRecord)]
    assert len(fixes) == 59 and len(times) == 59      # one GGA / one RMC lost to corruption
    assert sum(not f.has_fix for f in fixes) == 3 + 8 + 3
    assert sum(t.valid for t in times) == 45
    assert c.time_jumps == 0


def test_capture_fix_values_and_conventions():
    _, recs = _run(CAPTURE.read_bytes(), 50)
    fixes = [r for r in recs if isinstance(r, nmea.FixRecord)]
    good = [f for f in fixes if f.has_fix]
    for f in good:
        assert abs(f.latitude - 36.8383) < 1e-4 and abs(f.longitude + 2.4597) < 1e-4
        assert f.status == nmea.STATUS_FIX and f.service == nmea.SERVICE_GPS
        assert f.covariance_type == nmea.COVARIANCE_TYPE_APPROXIMATED
        # ellipsoidal height = MSL 60 m (+ noise) + geoid separation 50.4 m
        assert abs(f.altitude - 110.4) < 15.0
        assert f.covariance[0] == pytest.approx((f.hdop * 4.0) ** 2)
        assert f.covariance[0] == f.covariance[4] and f.covariance[1] == 0.0
        assert f.satellites == 8
    for f in fixes:
        if not f.has_fix:  # no-fix is never a position
            assert math.isnan(f.latitude) and math.isnan(f.longitude) and math.isnan(f.altitude)
            assert f.status == nmea.STATUS_NO_FIX
            assert f.covariance_type == nmea.COVARIANCE_TYPE_UNKNOWN
    t0 = dt.datetime(2026, 3, 21, 10, 30, tzinfo=dt.timezone.utc).timestamp()
    assert fixes[0].utc == t0
    times = [r for r in recs if isinstance(r, nmea.TimeRecord)]
    assert times[0].utc == t0 and times[-1].utc == t0 + 59


def test_against_pynmeagps_fields():
    """The records agree with pynmeagps' own parse of the same GGA (independent path)."""
    from pynmeagps import NMEAReader
    raw = nmea.format_gga(1774094400.25, -33.918861, 18.4233, 12.3, 2, 11, 0.9, -31.0)
    msg = NMEAReader.parse(raw)
    s = nmea.NmeaStream()
    (f,) = s.feed(raw)
    assert f.latitude == pytest.approx(msg.lat) and f.longitude == pytest.approx(msg.lon)
    assert f.latitude == pytest.approx(-33.918861, abs=1e-7)
    assert f.status == nmea.STATUS_SBAS_FIX and f.altitude == pytest.approx(12.3 - 31.0)
    assert f.covariance[8] == pytest.approx((2 * 0.9 * 0.1) ** 2)  # no GSA yet: 2 * HDOP
    assert math.isnan(f.utc)  # no RMC date yet: time of day alone is not a time


def test_gsa_vdop_used_and_quality_table():
    s = nmea.NmeaStream()
    s.feed(nmea.format_gsa(3, [1, 2, 3, 4], 2.0, 1.0, 1.5))
    (f,) = s.feed(nmea.format_gga(0.0, 10.0, 20.0, 5.0, 1, 4, 1.0))
    assert f.covariance[8] == pytest.approx((1.5 * 4.0) ** 2) and f.vdop == 1.5
    for q, status in [(4, nmea.STATUS_GBAS_FIX), (5, nmea.STATUS_GBAS_FIX), (9, nmea.STATUS_GBAS_FIX),
                      (6, nmea.STATUS_NO_FIX), (0, nmea.STATUS_NO_FIX)]:
        (f,) = s.feed(nmea.format_gga(0.0, 10.0, 20.0, 5.0, q, 4, 1.0))
        assert f.status == status


def test_midnight_rollover_uses_rmc_date():
    s = nmea.NmeaStream()
    t = dt.datetime(2026, 6, 30, 23, 59, 59, tzinfo=dt.timezone.utc).timestamp()
    (r,) = s.feed(nmea.format_rmc(t, 1.0, 1.0, True))
    (f,) = s.feed(nmea.format_gga(t + 1, 1.0, 1.0, 0.0, 1, 5, 1.0))  # 00:00:00 next day
    assert r.utc == t and f.utc == t + 1
    (r2,) = s.feed(nmea.format_rmc(t + 1, 1.0, 1.0, True))
    assert r2.utc == t + 1


def test_time_jump_flagged():
    g = GpsReceiver(36.8, -2.4, ttff=0.0)
    s = nmea.NmeaStream(time_jump_threshold=2.0)
    t0 = 1774094400.0
    jumps = []
    for k in range(6):
        if k == 3:
            g.clock_offset = -86400.0 * 400  # receiver reports a date 400 days off
        for r in s.feed(g.epoch(t0 + k), received=50.0 + k):
            if isinstance(r, nmea.TimeRecord):
                jumps.append(r.jump)
    assert jumps[:3] == [0.0, 0.0, 0.0] and jumps[3] == pytest.approx(-86400.0 * 400)
    assert jumps[4] == 0.0 and s.counters.time_jumps == 1


def test_no_fix_rmc_without_date_is_not_a_time():
    s = nmea.NmeaStream()
    assert s.feed(nmea.sentence('GPRMC,,V,,,,,,,,,,N')) == []
    assert s.counters.times == 0 and s.counters.parsed == 1


@settings(max_examples=150, deadline=None)
@given(st.binary(max_size=600), st.lists(st.integers(1, 64), min_size=1, max_size=8))
def test_fuzz_random_bytes_never_crash(data, cuts):
    s = nmea.NmeaStream()
    i = k = 0
    while i < len(data):
        n = cuts[k % len(cuts)]
        for r in s.feed(data[i:i + n], 0.0):
            assert isinstance(r, (nmea.FixRecord, nmea.TimeRecord))
        i += n
        k += 1


_fields = st.lists(st.text(alphabet='0123456789.,-NSEWAVMabc*$', max_size=12), max_size=16)


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(['GPGGA', 'GPRMC', 'GPGSA', 'GNGGA', 'GNRMC', 'GPGSV']), _fields)
def test_fuzz_wellformed_garbage_sentences(kind, parts):
    """Sentences with a correct checksum and random fields: a record or a count, no crash,
    and a fix record never carries a non-finite position."""
    s = nmea.NmeaStream()
    body = ','.join([kind] + parts)
    for r in s.feed(nmea.sentence(body.replace('$', '').replace('*', '')), 0.0):
        if isinstance(r, nmea.FixRecord) and r.has_fix:
            assert math.isfinite(r.latitude) and math.isfinite(r.longitude)
            assert all(math.isfinite(v) for v in r.covariance)
    c = s.counters
    assert c.sentences + c.truncated + c.bad_checksum >= 1


def test_unknown_receive_time_is_no_jump_reference():
    """RMCs received before the local clock is known (NaN) do not count as time jumps."""
    s = nmea.NmeaStream(time_jump_threshold=2.0)
    t = 1774094400.0
    (r0,) = s.feed(nmea.format_rmc(t, 1.0, 1.0, True), received=math.nan)
    (r1,) = s.feed(nmea.format_rmc(t + 1, 1.0, 1.0, True), received=500.0)
    (r2,) = s.feed(nmea.format_rmc(t + 2, 1.0, 1.0, True), received=501.0)
    assert r0.jump == r1.jump == r2.jump == 0.0 and s.counters.time_jumps == 0
