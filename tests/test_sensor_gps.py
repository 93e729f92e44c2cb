"""Topic-level tests of the ``gps`` node against the simulated GPS board over a real pty.

The simulator runs in this process (SimThread: its own thread, a real pty, a stable
symlink that disappears while unplugged); the node is the installed executable.
"""
import datetime as dt
import math

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import NavSatFix, NavSatStatus, TimeReference

from sslfr_common.node import to_sec
from sslfr_sim.runner import SimThread
from sslfr_sim.sensors import GpsSim
from sslfr_common.contract import DIAGNOSTICS, GPS_FIX, GPS_TIME_REFERENCE

START = dt.datetime(2026, 3, 21, 11, 0, tzinfo=dt.timezone.utc).timestamp()
SITE = {'latitude_deg': 37.0931, 'longitude_deg': -2.3590, 'elevation': 510.0}


def _diag(arrays, name):
    for arr in reversed(arrays):
        for st in arr.status:
            if st.name == name:
                return st, {kv.key: kv.value for kv in st.values}
    return None, {}


@pytest.fixture
def gps_sim(tmp_path, request):
    opts = {'start_utc': START, 'ttff': 1.0, 'noise': 1.0, **SITE, **getattr(request, 'param', {})}
    sim = SimThread.plain(GpsSim(opts), link=str(tmp_path / 'gps0')).start()
    yield sim
    sim.stop()


def test_fix_time_loss_recovery_and_unplug(gps_sim, launch, ros, tmp_path):
    fixes = ros.collect(NavSatFix, GPS_FIX.name)
    times = ros.collect(TimeReference, GPS_TIME_REFERENCE.name)
    diags = ros.collect(DiagnosticArray, DIAGNOSTICS.name)
    node = launch('sslfr_drivers', 'gps', params={'port': str(tmp_path / 'gps0')})
    assert ros.spin_until(lambda: any(f.status.status == NavSatStatus.STATUS_FIX for f in fixes), 15), \
        node.output()
    good = [f for f in fixes if f.status.status == NavSatStatus.STATUS_FIX][-1]
    assert abs(good.latitude - SITE['latitude_deg']) < 1e-4
    assert abs(good.longitude - SITE['longitude_deg']) < 1e-4
    assert abs(good.altitude - SITE['elevation']) < 10.0          # ellipsoidal height
    assert good.status.service == NavSatStatus.SERVICE_GPS
    assert good.position_covariance_type == NavSatFix.COVARIANCE_TYPE_APPROXIMATED
    assert 4.0 < good.position_covariance[0] < 100.0               # (HDOP ~1.1 * 4 m)^2
    assert good.header.frame_id == 'gps'
    # the time reference is the simulated day's UTC (date + time), not the wall clock
    assert ros.spin_until(lambda: times, 5)
    t = to_sec(times[-1].time_ref)
    assert START <= t < START + 60 and times[-1].source == 'gps'

    # fix lost: NO_FIX with NaN position, never a stale position
    n = len(fixes)
    with gps_sim.locked():
        gps_sim.board.control({'cmd': 'fault', 'kind': 'gps-loss', 'active': True})
    assert ros.spin_until(lambda: any(f.status.status == NavSatStatus.STATUS_NO_FIX for f in fixes[n:]), 5)
    lost = [f for f in fixes[n:] if f.status.status == NavSatStatus.STATUS_NO_FIX][-1]
    assert math.isnan(lost.latitude) and math.isnan(lost.longitude)
    assert lost.position_covariance_type == NavSatFix.COVARIANCE_TYPE_UNKNOWN
    with gps_sim.locked():
        gps_sim.board.control({'cmd': 'fault', 'kind': 'gps-loss', 'active': False})
    n = len(fixes)
    assert ros.spin_until(lambda: any(f.status.status == NavSatStatus.STATUS_FIX for f in fixes[n:]), 8)

    # the board disappears (pty closed, symlink gone) and comes back
    gps_sim.command('unplug 1.5')
    ros.spin_for(2.0)
    n = len(fixes)
    assert ros.spin_until(lambda: len(fixes) > n + 1, 10), node.output()
    assert node.running()
    ros.spin_until(lambda: _diag(diags, 'gps: board')[1].get('reconnects', '0') != '0', 3)
    st, kv = _diag(diags, 'gps: board')
    assert st is not None and int(kv['reconnects']) >= 1
    assert float(kv['rate_hz']) >= 0.0 and kv['link_state'] == 'up'


@pytest.mark.parametrize('gps_sim', [{'framing': 'raw_nmea'}], indirect=True)
def test_raw_nmea_garbage_and_time_jump(gps_sim, launch, ros, tmp_path):
    fixes = ros.collect(NavSatFix, GPS_FIX.name)
    times = ros.collect(TimeReference, GPS_TIME_REFERENCE.name)
    diags = ros.collect(DiagnosticArray, DIAGNOSTICS.name)
    node = launch('sslfr_drivers', 'gps', params={'port': str(tmp_path / 'gps0'),
                                                  'framing': 'raw_nmea'})
    assert ros.spin_until(lambda: any(f.status.status == NavSatStatus.STATUS_FIX for f in fixes), 15), \
        node.output()
    # line noise, a bad checksum and a truncated sentence straight onto the wire
    with gps_sim.locked():
        gps_sim.board._out += (b'\x00\xff\xb5\x62garbage\r\n'
                               b'$GPGGA,110000.00,3705.586,N,00221.540,W,1,08,1.0,510.0,M,0.0,M,,*00\r\n'
                               b'$GPRMC,1100')
    # the receiver's clock jumps one day ahead
    with gps_sim.locked():
        gps_sim.board.control({'cmd': 'fault', 'kind': 'gps-clock', 'offset': 86400.0})
    assert ros.spin_until(
        lambda: times and times[-1].time_ref.sec > START + 86000, 6)
    assert ros.spin_until(lambda: int(_diag(diags, 'gps: board')[1].get('time_jumps', '0')) >= 1, 4)
    st, kv = _diag(diags, 'gps: board')
    assert int(kv['bad_checksum']) >= 1 and int(kv['garbage_bytes']) >= 4
    assert int(kv['truncated']) >= 1
    assert abs(float(kv['last_time_jump_s']) - 86400.0) < 5.0
    n = len(fixes)
    assert ros.spin_until(lambda: len(fixes) > n + 1, 5) and node.running()
    assert fixes[-1].status.status == NavSatStatus.STATUS_FIX
    # a bare module unplugged and plugged back: the raw reader reopens the port
    gps_sim.command('unplug 1.5')
    ros.spin_for(2.0)
    n = len(fixes)
    assert ros.spin_until(lambda: len(fixes) > n + 1, 10), node.output()
    assert ros.spin_until(lambda: int(_diag(diags, 'gps: board')[1].get('reconnects', '0')) >= 1, 3)


def test_invalid_startup_parameters_refused(launch):
    node = launch('sslfr_drivers', 'gps', params={'framing': 'ubx'})
    assert node.wait_for_output('invalid parameters', 20)
    assert node.proc.wait(20) == 2
    assert 'framing' in node.output() and 'Traceback' not in node.output()
