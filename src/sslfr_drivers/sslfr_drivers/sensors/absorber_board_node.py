"""``absorber_board``: absorber tube thermocouples and the five limit switches.

Seed 000 sections 3.5.1 and 3.5.3: two type-K thermocouples on MAX6675 converters at
the absorber tube's inlet and outlet (the safety limit, 150 degC, is the safety node's
business), and five limit switches (initial, last, sleeping, longitudinal 1 and 2).
The board sends raw MAX6675 words and raw switch bits; decoding
(:mod:`sslfr_drivers.sensors.max6675`) and debouncing (:mod:`sslfr_drivers.sensors.debounce`) are
done here, in the pure cores.

Publishes
    ``absorber/inlet_temperature``, ``absorber/outlet_temperature`` (sensor_msgs/
    Temperature, R10, ~4 Hz) [degC], variance [degC^2] from the 0.25 degC resolution,
    the converter and the type-K tolerance; an open thermocouple (MAX6675 bit D2) or an
    impossible word is published as NaN (variance 0 = unknown) and reported as a fault
    in diagnostics, never as a number.
    ``limit_switches`` (sslfr_interfaces/LimitSwitches, R10) at ``switch_rate`` and at
    once on every debounced change; ``*_changed`` = ROS time of the change (the first
    raw sample showing the new state, mapped through the board's millisecond clock).
    ``diagnostics``.
"""
from __future__ import annotations

import math
import sys

from rclpy.duration import Duration
from sensor_msgs.msg import Temperature

from sslfr_interfaces.msg import LimitSwitches

from sslfr_common.contract import SWITCHES
from sslfr_common.node import run_node
from sslfr_drivers.sensors import max6675
from sslfr_drivers.sensors.debounce import SwitchDebouncer
from sslfr_drivers.link.sensor_messages import SwitchSample, ThermocoupleSample
from sslfr_drivers.sensors.board_node import RateMeter, SensorBoardNode, board_status

PARAMS = {
    'port': ('', 'absorber board port: device path, pyserial URL or xbee:<dev>?addr=<hex>; '
                 'empty = no board (the node stays up and reports it) [-]', None),
    'baudrate': (115200, 'serial line speed [bit/s]', (1200, 921600)),
    'inlet_frame_id': ('absorber_inlet', 'frame_id of absorber/inlet_temperature [-]', None),
    'outlet_frame_id': ('absorber_outlet', 'frame_id of absorber/outlet_temperature [-]', None),
    'converter_error': (2.0, 'MAX6675 error bound, uniform [degC]', (0.0, 50.0)),
    'thermocouple_error': (2.5, 'type-K tolerance bound, absolute part, uniform [degC]', (0.0, 50.0)),
    'thermocouple_error_relative': (0.0075, 'type-K tolerance bound, relative part of |T| [-]',
                                    (0.0, 0.1)),
    'debounce_time': (0.03, 'a raw switch change must hold this long to count [s]', (0.0, 5.0)),
    'switch_rate': (10.0, 'limit_switches publication rate besides changes [Hz]', (0.5, 100.0)),
    'max_sample_age': (1.5, 'diagnostics WARN when no thermocouple sample for this long [s]',
                       (0.1, 3600.0)),
    'heartbeat': (0.5, 'board link PING period [s]', (0.05, 5.0)),
}


class _BoardClock:
    """Board millisecond tick -> continuous seconds (wrap-around and resets absorbed)."""

    def __init__(self):
        self._last: int | None = None
        self._offset = 0.0

    def seconds(self, ms: int) -> float:
        if self._last is not None and ms < self._last:
            if self._last - ms > 1 << 31:
                self._offset += (1 << 32) / 1000.0      # u32 wrap-around
            else:
                self._offset += (self._last - ms) / 1000.0  # board reset: stay continuous
        self._last = ms
        return ms / 1000.0 + self._offset


class AbsorberBoardNode(SensorBoardNode):
    """See the module docstring."""

    def __init__(self):
        super().__init__('absorber_board', PARAMS, queue_len=2000)
        self._model = self._error_model(self._values)
        self._debouncer = SwitchDebouncer(self._values['debounce_time'])
        self._board_clock = _BoardClock()
        self._switch_meter = RateMeter()
        self._faults = {'inlet': max6675.FAULT_NONE, 'outlet': max6675.FAULT_NONE}
        self._fault_counts = {'inlet': 0, 'outlet': 0}
        self._last_temp = {'inlet': math.nan, 'outlet': math.nan}
        self._changed_ros: dict[str, object] = {}
        self._pub_t = {s: self.create_publisher(Temperature, f'absorber/{s}_temperature', 10)
                       for s in ('inlet', 'outlet')}
        self._pub_sw = self.create_publisher(LimitSwitches, 'limit_switches', 10)
        self._start_board(drain_period=0.01)
        self._sw_timer = self.create_timer(1.0 / self._values['switch_rate'], self._publish_switches,
                                           clock=self._steady)
        self.get_logger().info(f'absorber_board: port {self._values["port"] or "(none)"}')

    # -------------------------------------------------------------- set-up
    @staticmethod
    def _error_model(v: dict) -> max6675.ErrorModel:
        return max6675.ErrorModel(v['converter_error'], v['thermocouple_error'],
                                  v['thermocouple_error_relative'])

    def _apply(self, new: dict) -> None:
        SwitchDebouncer(new['debounce_time'])  # raises ValueError if unusable
        self._reopen_if_changed(new)
        self._model = self._error_model(new)
        self._debouncer.hold_time = float(new['debounce_time'])
        if new['switch_rate'] != self._values['switch_rate']:
            self._sw_timer.cancel()
            self.destroy_timer(self._sw_timer)
            self._sw_timer = self.create_timer(1.0 / new['switch_rate'], self._publish_switches,
                                               clock=self._steady)

    # -------------------------------------------------------------- reader thread
    def _on_message(self, msg) -> None:
        if isinstance(msg, (ThermocoupleSample, SwitchSample)):
            self._enqueue(msg)

    # -------------------------------------------------------------- executor
    def _drain(self) -> None:
        while self._queue:
            msg, stamp = self._queue.popleft()
            if isinstance(msg, ThermocoupleSample):
                self._meter.tick()
                self._publish_temperature('inlet', msg.inlet, stamp)
                self._publish_temperature('outlet', msg.outlet, stamp)
            else:
                self._switch_meter.tick()
                t = self._board_clock.seconds(msg.board_ms)
                first = self._debouncer.states is None
                changed = self._debouncer.update(msg.bits, t)
                if first:  # initial states: "changed" at the first sample
                    self._changed_ros = {n: stamp for n in SWITCHES}
                    changed = list(SWITCHES)
                else:
                    for name in changed:
                        st = self._debouncer.states[name]
                        # ROS time of the first raw sample of the new state
                        back = Duration(seconds=max(0.0, t - st.changed))
                        # (ROS time cannot go below 0: at sim time ~0, before /clock, keep the stamp)
                        self._changed_ros[name] = stamp - back if stamp.nanoseconds >= back.nanoseconds else stamp
                        self.get_logger().info(f'limit switch {name} {"closed" if st.closed else "open"}')
                if changed:
                    self._publish_switches()

    def _publish_temperature(self, which: str, word: int, stamp) -> None:
        r = max6675.decode(word, self._model)
        msg = Temperature()
        msg.header.stamp = stamp.to_msg()
        msg.header.frame_id = self._values[f'{which}_frame_id']
        if r.ok:
            msg.temperature, msg.variance = r.temperature, r.variance
        else:
            msg.temperature, msg.variance = math.nan, 0.0
            if self._faults[which] != r.fault:
                self.get_logger().error(f'{which} thermocouple: {r.fault} (word {word:#06x})')
            self._fault_counts[which] += 1
        if r.ok and self._faults[which] != max6675.FAULT_NONE:
            self.get_logger().info(f'{which} thermocouple: reading again')
        self._faults[which] = r.fault
        self._last_temp[which] = r.temperature
        self._pub_t[which].publish(msg)

    def _publish_switches(self) -> None:
        d = self._debouncer
        if d.states is None:
            return
        msg = LimitSwitches()
        msg.header.stamp = self.get_clock().now().to_msg()
        for name in SWITCHES:
            setattr(msg, name, bool(d.states[name].closed))
            t = self._changed_ros.get(name)
            if t is not None:
                setattr(msg, f'{name}_changed', t.to_msg())
        self._pub_sw.publish(msg)

    def _diagnostics(self) -> None:
        faults = [f'{w} thermocouple: {f}' for w, f in self._faults.items() if f != max6675.FAULT_NONE]
        extra = {'inlet_degC': f'{self._last_temp["inlet"]:.2f}',
                 'outlet_degC': f'{self._last_temp["outlet"]:.2f}',
                 'inlet_faults': self._fault_counts['inlet'],
                 'outlet_faults': self._fault_counts['outlet'],
                 'switch_rate_hz': f'{self._switch_meter.rate():.1f}',
                 'switches': ','.join(n for n in SWITCHES
                                      if self._debouncer.states and self._debouncer.states[n].closed)
                 or 'none',
                 'switch_bounces': self._debouncer.bounces, 'queue_dropped': self._queue_dropped}
        st = board_status('absorber_board: board', self._source, self._meter,
                          self._values['max_sample_age'], faults, extra)
        self._publish_diagnostics(st)


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_drivers absorber_board``."""
    return run_node('absorber_board', AbsorberBoardNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
