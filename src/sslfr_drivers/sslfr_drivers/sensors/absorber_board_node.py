"""``absorber_board``: absorber tube thermocouples and the five limit switches.

Seed 000 sections 3.5.1 and 3.5.3: two type-K thermocouples on MAX6675 converters at
the absorber tube's inlet and outlet (the safety limit, 150 degC, is the safety node's
business), and five limit switches (initial, last, sleeping, longitudinal 1 and 2).
The board sends raw MAX6675 words and raw switch bits, decoded and debounced here in
the pure cores (:mod:`~sslfr_drivers.sensors.max6675`, :mod:`~sslfr_drivers.sensors.debounce`).
The 20 Hz switch samples are debounced in the reader thread: only a change wakes the
executor (a wake-up per sample was most of this node's CPU).

Publishes
    ``absorber/inlet_temperature``, ``absorber/outlet_temperature`` (sensor_msgs/
    Temperature, R10, ~4 Hz) [degC], variance [degC^2] from the 0.25 degC resolution,
    the converter and the type-K tolerance; an open thermocouple (MAX6675 bit D2) or an
    impossible word is published as NaN (variance 0 = unknown) and reported as a fault
    in diagnostics, never as a number.
    ``limit_switches`` (sslfr_interfaces/LimitSwitches, R10) at ``switch_rate`` and at
    once on every debounced change; ``*_changed`` = ROS time of the change (the first
    raw sample showing the new state, mapped through the board's millisecond clock).
    ``wind`` (sslfr_interfaces/Wind, R10) when ``anemometer_pin`` names the board's pin
    of a cup anemometer: 3 s running mean, WMO gust and 10 min mean [m/s] of the 4 Hz
    pulse samples at ``wind_rate`` (:mod:`sslfr_drivers.sensors.anemometer`); the board
    is told the pin (SetPulseInput) every time its link comes up.
    ``absorber/flow`` (Flow) and ``absorber/thermal_power`` (ThermalPower), R10, 4 Hz,
    when ``flow_meter_pin`` names the pin of a pulse flow meter instead (one pulse input
    per board): the mean flow over ``flow_window`` [m^3/s], the useful power m_dot c_p
    (T_out - T_in) [W] and seed 003's efficiency against ``irradiance/beam`` (then
    subscribed) on ``aperture_area`` (:mod:`sslfr_drivers.sensors.thermal`).
    ``diagnostics``.
"""
from __future__ import annotations

import math
import sys
import threading
from dataclasses import dataclass

from sensor_msgs.msg import Temperature

from sslfr_interfaces.msg import Flow, Irradiance, LimitSwitches, ThermalPower, Wind

from sslfr_common.contract import (ABSORBER_FLOW, ABSORBER_TEMPERATURE, IRRADIANCE_BEAM, LIMIT_SWITCHES, SWITCHES,
                                   THERMAL_POWER, THERMOCOUPLES, WIND)
from sslfr_common.node import qos, run_node, stamp, to_sec
from sslfr_drivers.link.sensor_messages import PULSE_PIN_OFF, PulseSample, SetPulseInput, SwitchSample, ThermocoupleSample
from sslfr_drivers.sensors import anemometer, max6675, thermal
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
        self._pub_wind = self.create_publisher(Wind, WIND.name, qos(WIND))
        self._pulses = anemometer.PulseCounter()
        self._wind = anemometer.WindStats(self._values['anemometer_slope'], self._values['anemometer_offset'])
        self._wind_last, self._wind_gate = None, anemometer.PublishGate(self._values['wind_rate'])
        self._wind_counts = {'samples': 0, 'published': 0, 'restarts': 0, 'pin_refused': 0}
        self._pubs_thermal = None              # (flow, thermal) publishers: made with the first flow sample
        self._thermal = self._thermal_tracker(self._values)
        self._beam_sub = None
        self._subscribe_beam(self._values)
        self._start_board()
        self._sw_timer = self.create_timer(1.0 / self._values['switch_rate'], self._publish_switches,
                                           clock=self._steady)
        self.get_logger().info(f'absorber_board: port {self._values["port"] or "(none)"}')

    @staticmethod
    def _error_model(v: dict) -> max6675.ErrorModel:
        return max6675.ErrorModel(v['converter_error'], v['thermocouple_error'],
                                  v['thermocouple_error_relative'])

    @staticmethod
    def _thermal_tracker(v: dict) -> thermal.ThermalTracker:
        return thermal.ThermalTracker(v['flow_meter_k_factor'], v['flow_window'], v['aperture_area'],
                                      v['efficiency_min_beam'], v['beam_max_age'])

    def _subscribe_beam(self, v: dict) -> None:
        if v['flow_meter_pin'] >= 0 and self._beam_sub is None:
            self._beam_sub = self.create_subscription(Irradiance, IRRADIANCE_BEAM.name, self._on_beam,
                                                      qos(IRRADIANCE_BEAM))

    def _on_beam(self, msg: Irradiance) -> None:
        self._thermal.set_beam(msg.beam, self._steady.now().nanoseconds * 1e-9)

    def _apply(self, new: dict) -> None:
        self._model = self._error_model(new)
        keys = ('flow_meter_k_factor', 'flow_window', 'aperture_area', 'efficiency_min_beam', 'beam_max_age')
        if any(new[k] != self._values[k] for k in keys):
            self._thermal = self._thermal_tracker(new)
        self._subscribe_beam(new)
        if (new['anemometer_slope'], new['anemometer_offset']) != (self._values['anemometer_slope'],
                                                                   self._values['anemometer_offset']):
            self._wind = anemometer.WindStats(new['anemometer_slope'], new['anemometer_offset'])
        self._wind_gate.rate = new['wind_rate']
        if self._pulse_pin(new) != self._pulse_pin(self._values):
            link = self._source.link if self._source is not None else None
            if link is not None:
                self._set_pulse_input(link, self._pulse_pin(new))
        with self._sw_lock:
            self._switches.debouncer.hold_time = float(new['debounce_time'])
        if new['switch_rate'] != self._values['switch_rate']:
            self._sw_timer.cancel()
            self.destroy_timer(self._sw_timer)
            self._sw_timer = self.create_timer(1.0 / new['switch_rate'], self._publish_switches,
                                               clock=self._steady)

    def _on_link_up(self, link) -> None:
        """Reader thread: tell the board which pin counts the anemometer or flow meter."""
        if self._pulse_pin(self._values) >= 0:
            self._set_pulse_input(link, self._pulse_pin(self._values))

    @staticmethod
    def _pulse_pin(v: dict) -> int:
        """The board's one pulse input: the anemometer's or the flow meter's pin (-1: none)."""
        return v['anemometer_pin'] if v['anemometer_pin'] >= 0 else v['flow_meter_pin']

    def _set_pulse_input(self, link, pin: int) -> None:
        def done(fut):
            if fut.exception() is not None:
                self._wind_counts['pin_refused'] += 1
                self.get_logger().error(f'pulse input: the board did not take pin {pin}: {fut.exception()}')
            else:
                self.get_logger().info(f'pulse input: counting pulses on pin {pin}')
        link.submit(SetPulseInput(PULSE_PIN_OFF if pin < 0 else pin)).add_done_callback(done)

    def _on_message(self, msg) -> None:
        """Reader thread: temperatures are queued; switch samples are debounced here and
        only a debounced change is queued (with the receive time of its sample)."""
        if isinstance(msg, (ThermocoupleSample, PulseSample)):
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
            if isinstance(msg, PulseSample):
                if self._values['flow_meter_pin'] >= 0:
                    self._publish_flow(msg, received)
                else:
                    self._publish_wind(msg, received)
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
        self._thermal.set_temperature(which, r.temperature if r.ok else math.nan)
        self._pub_t[which].publish(msg)

    def _publish_wind(self, sample: PulseSample, received) -> None:
        """One pulse sample -> the running means -> ``wind`` (none after a start, reset or gap)."""
        if self._values['anemometer_pin'] < 0:
            return
        self._wind_counts['samples'] += 1
        interval = self._pulses.add(sample.board_ms, sample.count)
        if interval is None:
            self._wind_counts['restarts'] += 1
            self._wind.restart()
            self._wind_gate.restart()
            return
        t = to_sec(received)
        r = self._wind_last = self._wind.add(*interval, t=t)     # windows on ROS time (the stamp)
        if not self._wind_gate.due(t, r.gust):
            return
        self._wind_counts['published'] += 1
        msg = Wind()
        msg.header.stamp = received.to_msg()
        msg.header.frame_id = 'anemometer'
        msg.speed, msg.gust, msg.mean, msg.window, msg.pulse_rate = r.speed, r.gust, r.mean, r.window, r.pulse_rate
        self._pub_wind.publish(msg)

    def _publish_flow(self, sample: PulseSample, received) -> None:
        """One pulse sample -> ``absorber/flow`` and ``absorber/thermal_power`` (nothing
        for the first sample after a start, a board reset or a gap)."""
        out = self._thermal.add(sample.board_ms, sample.count, self._steady.now().nanoseconds * 1e-9)
        if out is None:
            return
        f, r = out
        if self._pubs_thermal is None:         # a collector without a flow meter has no such topics
            self._pubs_thermal = (self.create_publisher(Flow, ABSORBER_FLOW.name, qos(ABSORBER_FLOW)),
                                  self.create_publisher(ThermalPower, THERMAL_POWER.name, qos(THERMAL_POWER)))
        msg = Flow()
        msg.header.stamp = received.to_msg()
        msg.header.frame_id = 'flow_meter'
        msg.volume_flow, msg.window, msg.pulse_rate = f.volume_flow, f.window, f.pulse_rate
        self._pubs_thermal[0].publish(msg)
        tp = ThermalPower()
        tp.header = msg.header
        tp.volume_flow, tp.mass_flow, tp.specific_heat, tp.power = r.volume_flow, r.mass_flow, r.cp, r.power
        tp.inlet_temperature, tp.outlet_temperature = r.inlet, r.outlet
        tp.beam, tp.aperture, tp.efficiency = r.beam, r.aperture, r.efficiency
        self._pubs_thermal[1].publish(tp)

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
        if self._values['anemometer_pin'] >= 0:
            w = self._wind_last
            extra.update({'anemometer_pin': self._values['anemometer_pin'],
                          'wind_mps': 'none' if w is None else f'{w.speed:.2f}',
                          'wind_gust_mps': 'none' if w is None else f'{w.gust:.2f}',
                          'wind_mean_mps': 'none' if w is None else f'{w.mean:.2f} over {w.window:.0f} s',
                          **{f'wind_{k}': v for k, v in self._wind_counts.items()}})
        if self._values['flow_meter_pin'] >= 0:
            last = self._thermal.last
            extra.update({'flow_meter_pin': self._values['flow_meter_pin'],
                          'flow_lph': 'none' if last is None else f'{thermal.litres_per_hour(last[0].volume_flow):.1f}',
                          'thermal_power_W': 'none' if last is None else f'{last[1].power:.1f}',
                          'efficiency': 'none' if last is None else f'{last[1].efficiency:.4f}',
                          **{f'flow_{k}': v for k, v in self._thermal.counts.items()}})
        self._publish_diagnostics(faults, extra)


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_drivers absorber_board``."""
    return run_node('absorber_board', AbsorberBoardNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
