"""``absorber_board``: absorber tube thermocouples and the five limit switches.

Seed 000 sections 3.5.1 and 3.5.3: two type-K thermocouples on MAX6675 converters at
the absorber tube's inlet and outlet (the safety limit, 150 degC, is the safety node's
business), and five limit switches (initial, last, sleeping, longitudinal 1 and 2).
The board sends raw MAX6675 words and raw switch bits; decoding
(:mod:`sslfr_drivers.sensors.max6675`) and debouncing (:mod:`sslfr_drivers.sensors.debounce`) are
done here, in the pure cores. The raw switch samples (20 Hz) are debounced in the
reader thread as they arrive; only a debounced change wakes the executor (issue 16: a
wake-up per sample was most of this node's CPU), the temperatures always do.

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
import threading
from dataclasses import dataclass

from sensor_msgs.msg import Temperature

from sslfr_interfaces.msg import LimitSwitches

from sslfr_common.contract import ABSORBER_TEMPERATURE, LIMIT_SWITCHES, SWITCHES, THERMOCOUPLES
from sslfr_common.node import qos, run_node, stamp, to_sec
from sslfr_drivers.link.sensor_messages import SwitchSample, ThermocoupleSample
from sslfr_drivers.sensors import max6675
from sslfr_drivers.sensors.debounce import SwitchTracker
from sslfr_drivers.sensors.health import RateMeter
from sslfr_drivers.sensors.sensor_node import SensorBoardNode
from sslfr_drivers.sensors.sensor_params import ABSORBER_BOARD


@dataclass(frozen=True)
class _SwitchChange:
    """Debounced switch changes found by the reader thread, for the executor."""
    names: tuple
    first: bool          # the first sample: every switch's initial state (not logged)


class AbsorberBoardNode(SensorBoardNode):
    """See the module docstring; parameters: :data:`sensor_params.ABSORBER_BOARD`."""

    def __init__(self, **kwargs):
        super().__init__('absorber_board', ABSORBER_BOARD, queue_len=2000, **kwargs)
        self._model = self._error_model(self._values)
        self._switches = SwitchTracker(self._values['debounce_time'])
        self._switch_meter = RateMeter()
        self._sw_lock = threading.Lock()     # the tracker: reader thread and executor
        self._faults = {w: max6675.FAULT_NONE for w in THERMOCOUPLES}
        self._fault_counts = {w: 0 for w in THERMOCOUPLES}
        self._last_temp = {w: math.nan for w in THERMOCOUPLES}
        self._pub_t = {s: self.create_publisher(Temperature, ABSORBER_TEMPERATURE.of(s), qos(ABSORBER_TEMPERATURE))
                       for s in THERMOCOUPLES}
        self._pub_sw = self.create_publisher(LimitSwitches, LIMIT_SWITCHES.name, qos(LIMIT_SWITCHES))
        self._start_board()
        self._sw_timer = self.create_timer(1.0 / self._values['switch_rate'], self._publish_switches,
                                           clock=self._steady)
        self.get_logger().info(f'absorber_board: port {self._values["port"] or "(none)"}')

    @staticmethod
    def _error_model(v: dict) -> max6675.ErrorModel:
        return max6675.ErrorModel(v['converter_error'], v['thermocouple_error'],
                                  v['thermocouple_error_relative'])

    def _apply(self, new: dict) -> None:
        self._model = self._error_model(new)
        with self._sw_lock:
            self._switches.debouncer.hold_time = float(new['debounce_time'])
        if new['switch_rate'] != self._values['switch_rate']:
            self._sw_timer.cancel()
            self.destroy_timer(self._sw_timer)
            self._sw_timer = self.create_timer(1.0 / new['switch_rate'], self._publish_switches,
                                               clock=self._steady)

    def _on_message(self, msg) -> None:
        """Reader thread: temperatures are queued; switch samples are debounced here and
        only a debounced change is queued (with the receive time of its sample)."""
        if isinstance(msg, ThermocoupleSample):
            self._enqueue(msg)
        elif isinstance(msg, SwitchSample):
            received = self.get_clock().now()
            with self._sw_lock:
                self._switch_meter.tick()
                first = self._switches.states is None
                changed = self._switches.update(msg.board_ms, msg.bits, to_sec(received))
            if changed:
                self._enqueue(_SwitchChange(tuple(changed), first))

    def _drain(self) -> None:
        for msg, received in self._queue.drain():
            if isinstance(msg, ThermocoupleSample):
                self._meter.tick()
                self._publish_temperature('inlet', msg.inlet, received)
                self._publish_temperature('outlet', msg.outlet, received)
                continue
            if not msg.first:
                with self._sw_lock:
                    closed = {name: self._switches.states[name].closed for name in msg.names}
                for name in msg.names:
                    self.get_logger().info(f'limit switch {name} {"closed" if closed[name] else "open"}')
            self._publish_switches()

    def _publish_temperature(self, which: str, word: int, received) -> None:
        r = max6675.decode(word, self._model)
        msg = Temperature()
        msg.header.stamp = received.to_msg()
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
        with self._sw_lock:
            states = self._switches.states
            if states is None:
                return
            closed = {name: bool(states[name].closed) for name in SWITCHES}
            changed_at = dict(self._switches.changed_at)
        msg = LimitSwitches()
        msg.header.stamp = self.get_clock().now().to_msg()
        for name in SWITCHES:
            setattr(msg, name, closed[name])
            t = changed_at.get(name)
            if t is not None:
                setattr(msg, f'{name}_changed', stamp(t))
        self._pub_sw.publish(msg)

    def _diagnostics(self) -> None:
        with self._sw_lock:
            states = self._switches.states
            closed = [n for n in SWITCHES if states and states[n].closed]
            bounces = self._switches.debouncer.bounces
            switch_rate = self._switch_meter.rate()
        faults = [f'{w} thermocouple: {f}' for w, f in self._faults.items() if f != max6675.FAULT_NONE]
        extra = {'inlet_degC': f'{self._last_temp["inlet"]:.2f}',
                 'outlet_degC': f'{self._last_temp["outlet"]:.2f}',
                 'inlet_faults': self._fault_counts['inlet'],
                 'outlet_faults': self._fault_counts['outlet'],
                 'switch_rate_hz': f'{switch_rate:.1f}',
                 'switches': ','.join(closed) or 'none',
                 'switch_bounces': bounces,
                 'queue_dropped': self._queue.dropped}
        self._publish_diagnostics(faults, extra)


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_drivers absorber_board``."""
    return run_node('absorber_board', AbsorberBoardNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
