"""``irradiance``: VEML7700 illuminance -> beam irradiance.

Seed 000 section 3.5.5: a VEML7700 (0-120,000 lx, 16-bit) on the irradiance PCB;
beam irradiance = illuminance / 104 lm/W. The board does the auto gain / integration
time ranging and sends the raw count with the register codes used; the conversion
is :mod:`sslfr_drivers.sensors.veml7700`.

Publishes
    ``irradiance/illuminance`` (sensor_msgs/Illuminance, R10, ~1 Hz) [lx], variance [lx^2].
    ``irradiance/beam`` (sslfr_interfaces/Irradiance, R10) [W/m^2], with the efficacy used
    and ``saturated`` (counter at full scale or above 120 klx: the value is a lower bound).
    ``diagnostics`` (saturation and invalid samples are sensor faults).
"""
from __future__ import annotations

import sys

from sensor_msgs.msg import Illuminance

from sslfr_interfaces.msg import Irradiance

from sslfr_common.contract import IRRADIANCE_BEAM, IRRADIANCE_ILLUMINANCE
from sslfr_common.node import qos, run_node
from sslfr_drivers.link.sensor_messages import AlsSample
from sslfr_drivers.sensors import veml7700
from sslfr_drivers.sensors.sensor_node import SensorBoardNode
from sslfr_drivers.sensors.sensor_params import IRRADIANCE


class IrradianceNode(SensorBoardNode):
    """See the module docstring; parameters: :data:`sensor_params.IRRADIANCE`."""

    def __init__(self, **kwargs):
        super().__init__('irradiance', IRRADIANCE, queue_len=1000, **kwargs)
        self._saturated = False
        self._saturated_count = 0
        self._invalid = 0
        self._last: veml7700.Sample | None = None
        self._pub_lux = self.create_publisher(Illuminance, IRRADIANCE_ILLUMINANCE.name, qos(IRRADIANCE_ILLUMINANCE))
        self._pub_beam = self.create_publisher(Irradiance, IRRADIANCE_BEAM.name, qos(IRRADIANCE_BEAM))
        self._start_board()
        self.get_logger().info(f'irradiance: port {self._values["port"] or "(none)"}, '
                               f'efficacy {self._values["luminous_efficacy"]:.1f} lm/W')

    def _on_message(self, msg) -> None:
        if isinstance(msg, AlsSample):
            self._enqueue(msg)

    def _drain(self) -> None:
        for msg, received in self._queue.drain():
            s = veml7700.decode(msg.count, msg.gain_code, msg.it_code,
                                self._values['relative_uncertainty'])
            if not s.valid:
                self._invalid += 1
                self.get_logger().warning(
                    f'invalid VEML7700 sample: count {msg.count}, gain code {msg.gain_code}, '
                    f'IT code {msg.it_code}', throttle_duration_sec=10.0)
                continue
            self._meter.tick()
            self._last = s
            if s.saturated and not self._saturated:
                self.get_logger().warning(f'VEML7700 saturated ({s.illuminance:.0f} lx is a lower bound)')
            self._saturated = s.saturated
            self._saturated_count += int(s.saturated)
            eff = self._values['luminous_efficacy']
            beam, var = veml7700.beam_irradiance(s.illuminance, s.variance, eff)
            lux = Illuminance()
            lux.header.stamp = received.to_msg()
            lux.header.frame_id = self._values['frame_id']
            lux.illuminance, lux.variance = s.illuminance, s.variance
            self._pub_lux.publish(lux)
            b = Irradiance()
            b.header = lux.header
            b.beam, b.variance, b.illuminance = beam, var, s.illuminance
            b.luminous_efficacy, b.saturated = eff, s.saturated
            self._pub_beam.publish(b)

    def _diagnostics(self) -> None:
        faults = ['VEML7700 saturated'] if self._saturated else []
        s = self._last
        extra = {'illuminance_lx': f'{s.illuminance:.1f}' if s else 'none',
                 'gain': f'{s.gain:g}' if s else 'none',
                 'integration_time_s': f'{s.integration_time:g}' if s else 'none',
                 'saturated_samples': self._saturated_count, 'invalid_samples': self._invalid,
                 'queue_dropped': self._queue.dropped}
        self._publish_diagnostics(faults, extra)


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_drivers irradiance``."""
    return run_node('irradiance', IrradianceNode, args=args)


if __name__ == '__main__':
    sys.exit(main())
