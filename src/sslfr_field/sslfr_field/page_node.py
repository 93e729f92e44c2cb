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

import asyncio
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import Temperature
from sslfr_interfaces.msg import AxisStatus, Irradiance, SafetyState, SunPosition, ThermalPower, TrackerPhase
from sslfr_interfaces.srv import SetMode
from sslfr_common.contract import (ABSORBER_TEMPERATURE, AXIS_STATUS, DIAGNOSTICS, IRRADIANCE_BEAM, JOINTS,
                                   LEVEL_NAMES, PHASE_NAMES, SAFETY_STATE, THERMAL_POWER, THERMOCOUPLES,
                                   TRACKER_PHASE, TRACKER_SUN, collector_id)
from sslfr_common.node import CONFIG_ERRORS, LeanEvents, declare_parameters, qos, run_node, steady_now, to_sec
from sslfr_web import commands
from sslfr_web.app import Server

from .live import FieldState
from .page import FieldApp, field_page_params

#: [s] how long a command waits for the collector's service to be discovered
DISCOVERY_WAIT = 3.0


class FieldPageNode(LeanEvents, Node):
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
        self._diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, qos(DIAGNOSTICS))
        self.create_timer(1.0, self._publish_diagnostics, clock=self.steady)
        self.op = FieldApp(self.cfg, self, self.namespaces)
        self.server = Server(self.op, self.cfg['bind_address'], int(self.cfg['port']))
        self.url = self.server.start()                 # OSError (address in use ...) -> main
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

    def ros_time(self) -> float | None:
        t = self.get_clock().now().nanoseconds * 1e-9
        return t if t > 0 else None

    def log(self, level: str, text: str) -> None:
        logger = self.get_logger()
        if level == 'error':
            logger.error(text)
        elif level == 'warn':
            logger.warning(text)
        else:
            logger.info(text)

    async def call(self, cid: str, cmd: commands.Command) -> dict:
        """Call ``cmd`` (a planner/set_mode command) on collector ``cid``'s own service."""
        service = f'{self.namespaces[cid]}/{cmd.service}'
        client = self.clients_.get(service)
        if client is None:
            client = self.clients_[service] = self.create_client(SetMode, service)
        for _ in range(int(DISCOVERY_WAIT / 0.05)):
            if client.service_is_ready():
                break
            await asyncio.sleep(0.05)
        else:
            return {'success': False, 'message': f'service {service} is not available (collector lost?)'}
        loop = asyncio.get_running_loop()
        done = loop.create_future()
        fut = client.call_async(SetMode.Request(**cmd.request))
        fut.add_done_callback(lambda f: loop.call_soon_threadsafe(lambda: done.done() or done.set_result(f)))
        try:
            f = await asyncio.wait_for(done, float(self.cfg['service_timeout']))
        except asyncio.TimeoutError:
            client.remove_pending_request(fut)
            return {'success': False, 'message': f'no answer from {service} within {self.cfg["service_timeout"]:g} s'}
        resp = f.result()
        return {k: getattr(resp, k) for k in resp.get_fields_and_field_types()}

    # ------------------------------------------------------------------ diagnostics (ROS thread)
    def _publish_diagnostics(self) -> None:
        snap = self.snapshot()
        lost = [c['id'] for c in snap['collectors'] if c['link'] != 'ok']
        password = self.op.passwords.line() is not None
        s = DiagnosticStatus(name=f'{self.get_name()}: field page', hardware_id=collector_id(self.get_namespace()),
                             level=DiagnosticStatus.OK if password and not lost else DiagnosticStatus.WARN,
                             message=(f'not heard: {", ".join(lost)}; ' if lost else '')
                             + (f'serving {self.url}' if password else self.op.passwords.problem))
        s.values = [KeyValue(key=k, value=str(v)) for k, v in
                    {**self.op.counters, 'sessions': len(self.op.sessions), 'url': self.url,
                     **{f'link.{c["id"]}': c['link'] for c in snap['collectors']}}.items()]
        arr = DiagnosticArray(status=[s])
        arr.header.stamp = self.get_clock().now().to_msg()
        self._diag.publish(arr)

    def on_exit(self) -> None:
        self.server.stop()


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_field field_page``; a bad parameter or a port that
    cannot be bound: exit 2, one line."""
    return run_node('field_page', FieldPageNode, args=args, config_errors=CONFIG_ERRORS + (OSError,))


if __name__ == '__main__':
    sys.exit(main())
