"""``web`` node: the operator page (issue 20), served by the tracker itself.

Thin node over :mod:`sslfr_web` (pure modules): it subscribes to the topics
the page shows and feeds :class:`~sslfr_web.live.LiveState`, samples the day
plots on ROS time, asks the other nodes for the limits the page needs
(:mod:`~sslfr_web.remote`), calls the existing services for the page's
commands and serves :mod:`~sslfr_web.app` (aiohttp) from its own thread.
Contract: docs/architecture.md, section "Operator page"; for people: docs/operator.md.
"""
from __future__ import annotations

import importlib
import sys

from rcl_interfaces.srv import GetParameters
from rclpy.clock import Clock, ClockType
from sensor_msgs.msg import NavSatFix, Temperature
from sslfr_interfaces.msg import AxisStatus, Irradiance, SafetyState, SunPosition, ThermalPower, TrackerPhase, Wind
from sslfr_common.contract import (ABSORBER_TEMPERATURE, AXIS_STATUS, GPS_FIX, IRRADIANCE_BEAM, JOINTS,
                                   SAFETY_ESTOP, SAFETY_STATE, THERMAL_POWER, THERMOCOUPLES, TRACKER_PHASE,
                                   TRACKER_SUN, WIND)
from sslfr_common.node import CONFIG_ERRORS, declare_parameters, qos, run_node, steady_now

from . import collector, commands, remote
from .app import OperatorApp
from .live import DayBuffer, LiveState
from .page_host import PageHost
from .params import WEB_PARAMS

REMOTE_RETRY, REMOTE_REFRESH = 2.0, 60.0       # [s, steady] get_parameters: until answered / then
SAMPLE_PERIOD = 0.5                            # [s, steady] check whether a day-plot sample is due
DISCOVERY_WAIT = 2.0                           # [s, wall] a service client's wait for its server


def _srv_class(type_name: str):
    pkg, _, name = type_name.split('/')
    return getattr(importlib.import_module(f'{pkg}.srv'), name)


class WebNode(PageHost):
    """Live view, day plots, commands through services, recorded days."""

    def __init__(self, **kwargs):
        super().__init__('web', **kwargs)
        self._ros_args = list(kwargs.get('cli_args') or sys.argv)     # composed: the node's own arguments
        self.cfg = declare_parameters(self, WEB_PARAMS)       # every one read-only; ValueError: exit 2
        self.state = LiveState(JOINTS)
        self.buffer = DayBuffer(float(self.cfg['plot_period']))
        st = self.state
        sub = self.create_subscription        # no QoS-event handlers: LeanEvents
        sub(TrackerPhase, TRACKER_PHASE.name, st.on_phase, qos(TRACKER_PHASE))
        sub(SafetyState, SAFETY_STATE.name, st.on_safety, qos(SAFETY_STATE))
        sub(SunPosition, TRACKER_SUN.name, st.on_sun, qos(TRACKER_SUN))
        sub(Irradiance, IRRADIANCE_BEAM.name, st.on_beam, qos(IRRADIANCE_BEAM))
        sub(NavSatFix, GPS_FIX.name, st.on_fix, qos(GPS_FIX))
        sub(Wind, WIND.name, st.on_wind, qos(WIND))
        sub(ThermalPower, THERMAL_POWER.name, st.on_thermal, qos(THERMAL_POWER))   # a flow meter only
        for name in THERMOCOUPLES:
            sub(Temperature, ABSORBER_TEMPERATURE.of(name), lambda m, n=name: st.on_temperature(n, m),
                qos(ABSORBER_TEMPERATURE))
        for axis in JOINTS:
            sub(AxisStatus, AXIS_STATUS.of(axis), st.on_axis, qos(AXIS_STATUS))
        # Service clients are made when first needed: every entity costs the executor
        # time at each wake-up (~45 messages/s), so idle clients are not kept around.
        # (the e-stop's client is made at once: no discovery wait when it is pressed)
        self._service_types = commands.all_service_names(JOINTS)
        self.clients_ = {SAFETY_ESTOP.name: self.create_client(_srv_class(SAFETY_ESTOP.type), SAFETY_ESTOP.name)}
        self._param_clients: dict = {}
        self._remote_asked: dict = {}
        self._remote_due = {n: 0.0 for n in remote.REMOTE_PARAMS}
        self._description = None              # the planner's collector.description loaded (or refused)
        self._steady = steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(SAMPLE_PERIOD, self._sample, clock=steady)
        self.create_timer(1.0, self._steady_tick, clock=steady)
        self.serve(OperatorApp(self.cfg, self))        # OSError (address in use ...) -> main
        self.get_logger().info(
            f'operator page at {self.url} (bind {self.cfg["bind_address"]}; view '
            f'{"open" if self.cfg["open_view"] else "after login"}; commands need the operator password'
            f'{"" if self.op.passwords.line() else ": NONE SET, run ./sslfr web-password"})')

    # ------------------------------------------------------------------ Backend (web thread)
    def bag_dir(self) -> str | None:
        return self.cfg['bag_dir'] or self.state.info.get('bag_dir')

    def site_config(self) -> str | None:
        """The site config this node set runs with (the first ``--params-file`` of the
        node's arguments, as ``sslfr up`` and the launch file pass it), for the day
        reports of the recorded days: their collector and site parameters."""
        files = collector.description_mod.params_files(self._ros_args)
        return files[0] if files else None

    def jog_limits(self) -> dict[str, commands.JogLimits]:
        """The jog bounds of each movement of the collector (its description's, once
        known; the page's commands name no other axis)."""
        info = self.state.info
        out = {}
        for axis in (info.get('collector') or {}).get('joints') or JOINTS:
            measured = (self.state.get('axes', axis) or {}).get('measured')
            out[axis] = commands.JogLimits(float(self.cfg['max_jog']), info.get(f'{axis}.max_jog'),
                                           info.get(f'{axis}.lower_limit'), info.get(f'{axis}.upper_limit'),
                                           measured)
        return out

    async def call(self, cmd: commands.Command) -> dict:
        client = self.clients_.get(cmd.service)
        if client is None:        # first use (from the web thread; rclpy's node calls are locked)
            client = self.clients_[cmd.service] = self.create_client(
                _srv_class(self._service_types[cmd.service][1]), cmd.service)
        return await self.call_service(client, client.srv_type.Request(**cmd.request),
                                       timeout=float(self.cfg['service_timeout']), discovery_wait=DISCOVERY_WAIT,
                                       resend_every=commands.RESEND_S if cmd.resend else None,
                                       missing='is its node running?')

    # ------------------------------------------------------------------ timers (ROS thread)
    def _sample(self) -> None:
        t = self.ros_time()
        if t is not None:
            self.buffer.maybe_sample(t, self.state)

    def _steady_tick(self) -> None:
        now = steady_now(self._steady)
        joints = (self.state.info.get('collector') or {}).get('joints')
        for node, due in self._remote_due.items():    # client made -> ready -> asked -> answered
            client = self._param_clients.get(node)
            if joints is not None and node.endswith('_driver') and node[:-len('_driver')] not in joints:
                if client is not None:                # a driver of a movement the collector lacks
                    self._drop_param_client(node)
                continue
            if now < due:
                continue
            if client is None:
                self._param_clients[node] = self.create_client(GetParameters, f'{node}/get_parameters')
                continue
            asked = self._remote_asked.get(node)
            if asked is None and client.service_is_ready():
                self._remote_asked[node] = now
                names = list(remote.REMOTE_PARAMS[node])
                fut = client.call_async(GetParameters.Request(names=names))
                fut.add_done_callback(lambda f, n=node, nm=names, t=now: self._on_remote(n, nm, f, t))
            elif asked is not None and now - asked > REMOTE_RETRY:      # no answer: start again
                self._drop_param_client(node)
        self._publish_diagnostics()

    def _drop_param_client(self, node: str) -> None:
        self._remote_asked.pop(node, None)
        client = self._param_clients.pop(node, None)
        if client is not None:
            self.destroy_client(client)

    def _on_remote(self, node: str, names: list[str], fut, asked: float) -> None:
        self._drop_param_client(node)
        try:
            values = fut.result().values
        except Exception as exc:  # noqa: BLE001 - retried at the next tick
            self.get_logger().warning(f'{node}/get_parameters failed: {exc}', throttle_duration_sec=30.0)
            return
        for key, value in remote.apply(node, names, values).items():
            self.state.set_info(key, value)
        self._remote_due[node] = asked + REMOTE_REFRESH
        if node == 'planner':
            self._load_collector(self.state.info.get('collector_description') or '')

    def _load_collector(self, name: str) -> None:
        """The collector description the planner names, once per name: the page draws it."""
        if name == self._description:
            return
        self._description = name
        try:
            desc = collector.load(name, self._ros_args)
        except ValueError as exc:          # DescriptionError: the planner refused it too
            self.get_logger().warning(f'collector description {name!r}: {exc}; the page draws the '
                                      "planner's geometry")
            return
        if desc is not None:
            self.buffer.ideal = collector.ideal_drive(desc)
            self.state.set_info('collector', collector.page_collector(desc))

    def _publish_diagnostics(self) -> None:
        password = self.op.passwords.line() is not None
        self.publish_page_status('operator page', password, f'serving {self.url}' if password
                                 else self.op.passwords.problem,
                                 {**self.op.guard.counters, 'streams': self.op.streams.count(),
                                  'locked_out_addresses': len(self.op.limiter.locked()),
                                  'day_samples': len(self.buffer.t)})


def main(args=None) -> int:
    """Entry point of ``ros2 run sslfr_web web``; a port that cannot be bound
    refuses to start (exit 2, one line)."""
    return run_node('web', WebNode, args=args, config_errors=CONFIG_ERRORS + (OSError,))


if __name__ == '__main__':
    sys.exit(main())
