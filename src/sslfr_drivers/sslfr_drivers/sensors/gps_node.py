"""``gps``: NMEA from the GPS board -> gps/fix and gps/time_reference.

Seed 000 section 3.5.2: a GY-GPS6MV2 (u-blox NEO-6M) behind an Arduino gives the
site's position and UTC. The bytes come either in board-protocol NmeaChunk frames
(``framing: protocol``, also behind the XBee coordinator) or straight from a GPS module
on its own USB port (``framing: raw_nmea``). :class:`sslfr_drivers.sensors.nmea.NmeaStream`
does all the parsing; this node only converts its records to messages.

Publishes
    ``gps/fix`` (sensor_msgs/NavSatFix, R10) for every GGA: status / service / covariance
    per nmea_navsat_driver; a no-fix is STATUS_NO_FIX with NaN position, never a position.
    ``gps/time_reference`` (sensor_msgs/TimeReference, R10) for every RMC carrying date and
    time (``time_ref`` = receiver UTC, header.stamp = ROS time of reception); with RMC
    status V (no fix) only if ``time_ref_without_fix``.
    ``diagnostics``: link, rate, last-sample age, frames lost, NMEA error counters, time jumps.
"""
from __future__ import annotations

import math
import sys

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from sensor_msgs.msg import NavSatFix, NavSatStatus, TimeReference

from sslfr_drivers.sensors import nmea
from sslfr_drivers.link.sensor_messages import NmeaChunk
from sslfr_drivers.sensors.board_node import BoardSource, SensorBoardNode, board_status
from sslfr_common.node import run_node

assert (nmea.STATUS_NO_FIX, nmea.STATUS_FIX, nmea.STATUS_SBAS_FIX, nmea.STATUS_GBAS_FIX) == (
    NavSatStatus.STATUS_NO_FIX, NavSatStatus.STATUS_FIX, NavSatStatus.STATUS_SBAS_FIX,
    NavSatStatus.STATUS_GBAS_FIX)
assert nmea.SERVICE_GPS == NavSatStatus.SERVICE_GPS
assert nmea.COVARIANCE_TYPE_APPROXIMATED == NavSatFix.COVARIANCE_TYPE_APPROXIMATED

#: Every parameter: name -> (default, description with unit, bounds / choices).
PARAMS = {
    'port': ('', 'GPS board port: device path, pyserial URL or xbee:<dev>?addr=<hex>; '
                 'empty = no board (the node stays up and reports it) [-]', None),
    'framing': ('protocol', 'protocol: NMEA in board-protocol frames; raw_nmea: a bare GPS '
                            'module streaming NMEA text [-]', ('protocol', 'raw_nmea')),
    'baudrate': (115200, 'serial line speed [bit/s] (board protocol: 115200; a bare NEO-6M '
                         'module with framing raw_nmea: 9600)', (1200, 921600)),
    'frame_id': ('gps', 'frame_id of gps/fix (the antenna) [-]', None),
    'time_ref_source': ('gps', 'TimeReference.source [-]', None),
    'uere': (4.0, 'user-equivalent range error of an autonomous fix, GGA quality 1 '
                  '(nmea_navsat_driver epe_quality1) [m]', (0.01, 100.0)),
    'uere_sbas': (0.1, 'UERE for GGA quality 2 (DGPS/SBAS) [m]', (0.001, 100.0)),
    'time_jump_threshold': (2.0, 'step of (receiver UTC - ROS time) between RMCs flagged as '
                                 'a time jump [s]', (0.01, 1.0e9)),
    'time_ref_without_fix': (False, 'also publish gps/time_reference from RMC status V [-]', None),
    'max_sample_age': (3.0, 'diagnostics WARN when no NMEA sentence for this long [s]', (0.1, 3600.0)),
    'heartbeat': (0.5, 'board link PING period [s]', (0.05, 5.0)),
}


class GpsNode(SensorBoardNode):
    """See the module docstring."""

    SOURCE_KEYS = ('port', 'framing', 'baudrate', 'heartbeat')

    def __init__(self):
        super().__init__('gps', PARAMS, queue_len=1000)
        self._stream = nmea.NmeaStream(self._error_model(self._values),
                                       self._values['time_jump_threshold'])
        self._last_jump = 0.0
        self._last_fix_status = None
        self._last_fix: nmea.FixRecord | None = None
        self._fix_pub = self.create_publisher(NavSatFix, 'gps/fix', 10)
        self._time_pub = self.create_publisher(TimeReference, 'gps/time_reference', 10)
        self._start_board(drain_period=0.02)
        self.get_logger().info(
            f'gps: port {self._values["port"] or "(none)"} framing {self._values["framing"]}')

    # -------------------------------------------------------------- set-up
    @staticmethod
    def _error_model(v: dict) -> nmea.ReceiverErrorModel:
        """UERE [m] per GGA quality: 1, 2 from the parameters; 4 RTK fixed, 5 RTK
        float, 9 WAAS as nmea_navsat_driver."""
        return nmea.ReceiverErrorModel(uere={1: v['uere'], 2: v['uere_sbas'], 4: 0.02, 5: 4.0, 9: 3.0})

    def _make_source(self, v: dict) -> BoardSource:
        return BoardSource(v['port'], v['framing'], v['baudrate'], on_message=self._on_message,
                           on_bytes=self._on_bytes, heartbeat=v['heartbeat'])

    def _apply(self, new: dict) -> None:
        self._reopen_if_changed(new)
        if any(new[k] != self._values[k] for k in ('uere', 'uere_sbas', 'time_jump_threshold')):
            self._stream.error_model = self._error_model(new)
            self._stream.time_jump_threshold = new['time_jump_threshold']

    # -------------------------------------------------------------- reader thread
    def _on_message(self, msg) -> None:
        if isinstance(msg, NmeaChunk):
            self._on_bytes(msg.data)

    def _on_bytes(self, data: bytes) -> None:
        self._enqueue(data)

    # -------------------------------------------------------------- executor
    def _drain(self) -> None:
        while self._queue:
            data, stamp = self._queue.popleft()
            # ROS time 0: use_sim_time before the first /clock; no time-jump reference
            received = stamp.nanoseconds * 1e-9 if stamp.nanoseconds > 0 else math.nan
            for rec in self._stream.feed(data, received):
                self._meter.tick()
                if isinstance(rec, nmea.FixRecord):
                    self._publish_fix(rec, stamp)
                else:
                    self._publish_time(rec, stamp)

    def _publish_fix(self, rec: nmea.FixRecord, stamp) -> None:
        msg = NavSatFix()
        msg.header.stamp = stamp.to_msg()
        msg.header.frame_id = self._values['frame_id']
        msg.status.status = rec.status
        msg.status.service = rec.service
        msg.latitude, msg.longitude, msg.altitude = rec.latitude, rec.longitude, rec.altitude
        msg.position_covariance = [float(c) for c in rec.covariance]
        msg.position_covariance_type = rec.covariance_type
        self._fix_pub.publish(msg)
        self._last_fix = rec
        if rec.status != self._last_fix_status:
            self.get_logger().info('fix acquired' if rec.has_fix else 'no fix')
            self._last_fix_status = rec.status

    def _publish_time(self, rec: nmea.TimeRecord, stamp) -> None:
        if abs(rec.jump) > self._values['time_jump_threshold']:
            self._last_jump = rec.jump
            self.get_logger().warning(f'GPS time jumped by {rec.jump:+.3f} s against ROS time')
        if not rec.valid and not self._values['time_ref_without_fix']:
            return
        msg = TimeReference()
        msg.header.stamp = stamp.to_msg()
        sec = math.floor(rec.utc)
        msg.time_ref.sec = int(sec)
        msg.time_ref.nanosec = int(round((rec.utc - sec) * 1e9)) % 1_000_000_000
        msg.source = self._values['time_ref_source']
        self._time_pub.publish(msg)

    def _diagnostics(self) -> None:
        c = self._stream.counters
        faults = []
        st = board_status('gps: board', self._source, self._meter, self._values['max_sample_age'],
                          faults, {**c.as_dict(), 'last_time_jump_s': f'{self._last_jump:+.3f}',
                                   'chunks_dropped': self._queue_dropped})
        fix = DiagnosticStatus(name='gps: fix', hardware_id=self._values['port'] or '(none)')
        if self._last_fix_status is None or self._last_fix_status < 0:
            fix.level, fix.message = DiagnosticStatus.WARN, 'no fix'
        else:
            fix.level, fix.message = DiagnosticStatus.OK, 'fix'
        f = self._last_fix
        fix.values = [KeyValue(key='fixes', value=str(c.fixes)), KeyValue(key='no_fix', value=str(c.no_fix)),
                      KeyValue(key='satellites', value=str(f.satellites) if f else 'none'),
                      KeyValue(key='hdop', value=f'{f.hdop:.2f}' if f else 'none'),
                      KeyValue(key='quality', value=str(f.quality) if f else 'none'),
                      KeyValue(key='nav_mode', value=str(f.nav_mode) if f else 'none')]
        self._publish_diagnostics(st, fix)


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_drivers gps``."""
    return run_node('gps', GpsNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
