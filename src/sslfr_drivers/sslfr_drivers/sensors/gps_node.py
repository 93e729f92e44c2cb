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

from sensor_msgs.msg import NavSatFix, NavSatStatus, TimeReference

from sslfr_common.contract import GPS_FIX, GPS_TIME_REFERENCE
from sslfr_common.node import qos, run_node, stamp, to_sec
from sslfr_drivers.link.sensor_messages import NmeaChunk
from sslfr_drivers.sensors import nmea
from sslfr_drivers.sensors.health import fix_report
from sslfr_drivers.sensors.sensor_node import SensorBoardNode
from sslfr_drivers.sensors.sensor_params import GPS

assert (nmea.STATUS_NO_FIX, nmea.STATUS_FIX, nmea.STATUS_SBAS_FIX, nmea.STATUS_GBAS_FIX) == (
    NavSatStatus.STATUS_NO_FIX, NavSatStatus.STATUS_FIX, NavSatStatus.STATUS_SBAS_FIX,
    NavSatStatus.STATUS_GBAS_FIX)
assert nmea.SERVICE_GPS == NavSatStatus.SERVICE_GPS
assert nmea.COVARIANCE_TYPE_APPROXIMATED == NavSatFix.COVARIANCE_TYPE_APPROXIMATED


class GpsNode(SensorBoardNode):
    """See the module docstring; parameters: :data:`sensor_params.GPS`."""

    def __init__(self, **kwargs):
        super().__init__('gps', GPS, queue_len=1000, **kwargs)
        self._stream = nmea.NmeaStream(self._error_model(self._values),
                                       self._values['time_jump_threshold'])
        self._last_jump = 0.0
        self._last_fix_status = None
        self._last_fix: nmea.FixRecord | None = None
        self._fix_pub = self.create_publisher(NavSatFix, GPS_FIX.name, qos(GPS_FIX))
        self._time_pub = self.create_publisher(TimeReference, GPS_TIME_REFERENCE.name, qos(GPS_TIME_REFERENCE))
        self._start_board()
        self.get_logger().info(
            f'gps: port {self._values["port"] or "(none)"} framing {self._values["framing"]}')

    @staticmethod
    def _error_model(v: dict) -> nmea.ReceiverErrorModel:
        """UERE [m] per GGA quality: 1, 2 from the parameters; 4 RTK fixed, 5 RTK
        float, 9 WAAS as nmea_navsat_driver."""
        return nmea.ReceiverErrorModel(uere={1: v['uere'], 2: v['uere_sbas'], 4: 0.02, 5: 4.0, 9: 3.0})

    def _apply(self, new: dict) -> None:
        self._stream.error_model = self._error_model(new)
        self._stream.time_jump_threshold = new['time_jump_threshold']

    def _on_message(self, msg) -> None:
        if isinstance(msg, NmeaChunk):
            self._enqueue(msg.data)

    def _drain(self) -> None:
        for data, received in self._queue.drain():
            # ROS time 0: use_sim_time before the first /clock; no time-jump reference
            t = to_sec(received) if received.nanoseconds > 0 else math.nan
            for rec in self._stream.feed(data, t):
                self._meter.tick()
                if isinstance(rec, nmea.FixRecord):
                    self._publish_fix(rec, received)
                else:
                    self._publish_time(rec, received)

    def _publish_fix(self, rec: nmea.FixRecord, received) -> None:
        msg = NavSatFix()
        msg.header.stamp = received.to_msg()
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

    def _publish_time(self, rec: nmea.TimeRecord, received) -> None:
        if abs(rec.jump) > self._values['time_jump_threshold']:
            self._last_jump = rec.jump
            self.get_logger().warning(f'GPS time jumped by {rec.jump:+.3f} s against ROS time')
        if not rec.valid and not self._values['time_ref_without_fix']:
            return
        msg = TimeReference()
        msg.header.stamp = received.to_msg()
        msg.time_ref = stamp(rec.utc)
        msg.source = self._values['time_ref_source']
        self._time_pub.publish(msg)

    def _diagnostics(self) -> None:
        c = self._stream.counters
        self._publish_diagnostics(
            [], {**c.as_dict(), 'last_time_jump_s': f'{self._last_jump:+.3f}',
                 'chunks_dropped': self._queue.dropped},
            ('gps: fix', fix_report(self._last_fix_status, c.fixes, c.no_fix, self._last_fix)))


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_drivers gps``."""
    return run_node('gps', GpsNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
