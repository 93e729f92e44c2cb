"""The ``field_page`` node: the station's page over every collector of a field.

Subscribes, for each collector namespace of its ``collectors`` parameter, the
collector's ``tracker/phase`` (transient local), ``safety/state``,
``axes/<axis>/status``, the absorber temperatures, ``irradiance/beam`` and
``absorber/thermal_power`` (published where a flow meter counts) and ``tracker/sun``,
feeds :class:`sslfr_field.live.FieldState` (arrival times on the steady clock: link
health; the energy of the day on the messages' ROS stamps, the absorbed energy with the
optical model of each collector's ``collector_configs`` entry: :mod:`sslfr_field.energy`),
and serves :class:`sslfr_field.page.FieldApp`. Commands call the collector's own
``<namespace>/planner/set_mode``. Diagnostics: ``field_page: field page`` on
``/diagnostics`` (WARN while a collector is lost or no password is set).
"""
from __future__ import annotations

import sys

from rclpy.clock import Clock, ClockType
from sensor_msgs.msg import Temperature
from sslfr_interfaces.msg import AxisStatus, Irradiance, SafetyState, SunPosition, ThermalPower, TrackerPhase
from sslfr_interfaces.srv import SetMode
from sslfr_common.contract import (ABSORBER_TEMPERATURE, AXIS_STATUS, IRRADIANCE_BEAM, JOINTS, LEVEL_NAMES,
                                   PHASE_NAMES, SAFETY_STATE, THERMAL_POWER, THERMOCOUPLES, TRACKER_PHASE,
                                   TRACKER_SUN)
from sslfr_common.node import CONFIG_ERRORS, declare_parameters, qos, run_node, steady_now, to_sec
from sslfr_web import commands
from sslfr_web.page_host import PageHost

from .live import FieldState
from .page import FieldApp, field_page_params

#: [s] how long a command waits for the collector's service to be discovered
DISCOVERY_WAIT = 3.0


class FieldPageNode(PageHost):
    """Live state of every collector, the field page, commands through each collector's services."""

    def __init__(self, **kwargs):
        super().__init__('field_page', **kwargs)
        self.cfg = declare_parameters(self, field_page_params())
        nsp = [n.rstrip('/') for n in self.cfg['collectors'] if n]
        ids = [i for i in self.cfg['collector_ids'] if i]
        pages = [p for p in self.cfg['collector_pages'] if p] or [''] * len(nsp)
        self.namespaces = dict(zip(ids, nsp))
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.state = FieldState(zip(ids, nsp, pages), float(self.cfg['lost_after']),
                                self._models(ids, list(self.cfg['collector_configs'])))
        st, now = self.state, lambda: steady_now(self.steady)
        for cid, ns in self.namespaces.items():
            sub = self.create_subscription
            sub(TrackerPhase, f'{ns}/{TRACKER_PHASE.name}', lambda m, c=cid: st.on_phase(
                c, now(), PHASE_NAMES.get(m.phase, str(m.phase)), m.mode, m.reason), qos(TRACKER_PHASE))
            sub(SafetyState, f'{ns}/{SAFETY_STATE.name}', lambda m, c=cid: st.on_safety(
                c, now(), LEVEL_NAMES.get(m.level, str(m.level)), m.reasons), qos(SAFETY_STATE))
            sub(Irradiance, f'{ns}/{IRRADIANCE_BEAM.name}', lambda m, c=cid: st.on_beam(
                c, now(), m.beam, to_sec(m.header.stamp)), qos(IRRADIANCE_BEAM))
            sub(SunPosition, f'{ns}/{TRACKER_SUN.name}', lambda m, c=cid: st.on_sun(c, now(), m.zenith, m.azimuth),
                qos(TRACKER_SUN))
            sub(ThermalPower, f'{ns}/{THERMAL_POWER.name}', lambda m, c=cid: st.on_thermal(
                c, now(), m.volume_flow, m.power, to_sec(m.header.stamp)), qos(THERMAL_POWER))
            for which in THERMOCOUPLES:
                sub(Temperature, f'{ns}/{ABSORBER_TEMPERATURE.of(which)}',
                    lambda m, c=cid, w=which: st.on_temperature(c, now(), w, m.temperature), qos(ABSORBER_TEMPERATURE))
            for axis in JOINTS:
                sub(AxisStatus, f'{ns}/{AXIS_STATUS.of(axis)}', lambda m, c=cid, a=axis: st.on_axis(
                    c, now(), a, m.state, m.error, m.measured), qos(AXIS_STATUS))
        self.clients_: dict = {}
        self.serve(FieldApp(self.cfg, self, self.namespaces))   # OSError (address in use ...) -> main
        self.create_timer(1.0, self._publish_diagnostics, clock=self.steady)
        self.get_logger().info(f'field page at {self.url} ({len(nsp)} collectors: {", ".join(nsp)}; commands need '
                               f'the operator password{"" if self.op.passwords.line() else ": NONE SET"})')

    def _models(self, ids: list[str], configs: list[str]) -> dict:
        """The absorbed-power model of each collector with a site config; a config that
        cannot be used is logged and that collector shows no absorbed energy."""
        from .energy import absorbed_model
        models = {}
        for cid, cfg in zip(ids, configs if configs != [''] else []):
            if not cfg:
                continue
            try:
                models[cid] = absorbed_model(cfg)
            except Exception as exc:  # noqa: BLE001 - NodeSetError, ValueError, OSError: said, page runs on
                self.get_logger().error(f'{cid}: no absorbed energy of the day: {" ".join(str(exc).split())}')
        return models

    # ------------------------------------------------------------------ backend (web thread)
    def snapshot(self) -> dict:
        return self.state.snapshot(steady_now(self.steady), self.ros_time())

    async def call(self, cid: str, cmd: commands.Command) -> dict:
        """Call ``cmd`` (a planner/set_mode command) on collector ``cid``'s own service."""
        service = f'{self.namespaces[cid]}/{cmd.service}'
        client = self.clients_.get(service)
        if client is None:
            client = self.clients_[service] = self.create_client(SetMode, service)
        return await self.call_service(client, SetMode.Request(**cmd.request),
                                       timeout=float(self.cfg['service_timeout']), discovery_wait=DISCOVERY_WAIT,
                                       missing='collector lost?')

    # ------------------------------------------------------------------ diagnostics (ROS thread)
    def _publish_diagnostics(self) -> None:
        snap = self.snapshot()
        lost = [c['id'] for c in snap['collectors'] if c['link'] != 'ok']
        password = self.op.passwords.line() is not None
        self.publish_page_status('field page', password and not lost,
                                 (f'not heard: {", ".join(lost)}; ' if lost else '')
                                 + (f'serving {self.url}' if password else self.op.passwords.problem),
                                 {f'link.{c["id"]}': c['link'] for c in snap['collectors']})


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_field field_page``; a bad parameter or a port that
    cannot be bound: exit 2, one line."""
    return run_node('field_page', FieldPageNode, args=args, config_errors=CONFIG_ERRORS + (OSError,))


if __name__ == '__main__':
    sys.exit(main())
