"""``modbus_gateway`` node: the collectors as SunSpec devices over Modbus TCP.

Wires, per collector namespace, `joint_states` (the mirrors' position),
`axes/mirrors/status` (setpoint, fault), `tracker/phase` (mode) and `irradiance/beam`
to :mod:`sslfr_gateway.sunspec` images served by :class:`ModbusGateway`; control
writes become `planner/set_mode` calls in that collector's namespace, the same service
the operator page calls. Images are re-encoded at most every 0.1 s (steady clock).
"""
from __future__ import annotations

import concurrent.futures
import math
import sys

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from sslfr_common.contract import (AXIS_STATUS, DIAGNOSTICS, IRRADIANCE_BEAM, JOINT_STATES, MIRRORS,
                                   PLANNER_SET_MODE, TRACKER_PHASE)
from sslfr_common.node import CONFIG_ERRORS, LeanEvents, declare_parameters, diagnostics_msg, qos, run_node
from sslfr_interfaces.msg import AxisStatus, Irradiance, TrackerPhase
from sslfr_interfaces.srv import SetMode

from . import params as gp
from . import sunspec
from .modbus_server import ModbusGateway


class _Collector:
    """What the gateway knows of one collector (ROS units: rad, W/m^2)."""

    def __init__(self, cid: str):
        self.id = cid
        self.position = None
        self.position_at = None      # steady-clock time of the last joint_states [s]
        self.stale = False           # no joint_states for stale_after: the position reads unknown
        self.setpoint = None
        self.fault = False
        self.mode = None
        self.beam = None

    def unit(self, unit_id: int, threshold: float) -> sunspec.Unit:
        deg = (lambda r: None if r is None or not math.isfinite(r) else math.degrees(r))
        position = None if self.stale else self.position
        tracker = sunspec.Tracker(self.id, deg(self.setpoint), deg(position),
                                  None if self.mode is None else self.mode == 'auto',
                                  sunspec.tracker_alarm(position, self.setpoint, threshold, self.fault))
        return sunspec.Unit(serial=self.id, unit_id=unit_id, trackers=[tracker], beam_wm2=self.beam)


class ModbusGatewayNode(LeanEvents, Node):
    def __init__(self, **kwargs):
        super().__init__('modbus_gateway', **kwargs)
        cfg = declare_parameters(self, gp.MODBUS_PARAMS)
        problem = gp.collectors_mismatch(cfg)
        if problem:
            raise ValueError(problem)
        self.cfg = cfg
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.collectors = [_Collector(i) for i in cfg['collector_ids']]
        self._dirty = set(range(len(self.collectors)))
        self._set_mode = []
        for k, ns in enumerate(cfg['collectors']):
            p = ns.rstrip('/') + '/' if ns else ''
            self.create_subscription(JointState, p + JOINT_STATES.name, lambda m, k=k: self._on_joints(k, m),
                                     qos(JOINT_STATES))
            self.create_subscription(AxisStatus, p + AXIS_STATUS.of(MIRRORS), lambda m, k=k: self._on_axis(k, m),
                                     qos(AXIS_STATUS))
            self.create_subscription(TrackerPhase, p + TRACKER_PHASE.name, lambda m, k=k: self._on_phase(k, m),
                                     qos(TRACKER_PHASE))
            self.create_subscription(Irradiance, p + IRRADIANCE_BEAM.name, lambda m, k=k: self._on_beam(k, m),
                                     qos(IRRADIANCE_BEAM))
            self._set_mode.append(self.create_client(SetMode, p + PLANNER_SET_MODE.name))
        self.gateway = ModbusGateway(
            [self._encode(k) for k in range(len(self.collectors))], [1] * len(self.collectors),
            self._command, bind_address=cfg['bind_address'], port=cfg['port'],
            write_allow=gp.allowed(cfg['write_allow']), max_connections=cfg['max_connections'],
            max_per_address=cfg['max_per_address'], idle_timeout=cfg['idle_timeout'],
            frame_timeout=cfg['frame_timeout'],
            command_timeout=cfg['service_timeout'], log=lambda s: self.get_logger().info(s))
        port = self.gateway.start()
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(0.1, self._refresh, clock=steady)
        self._diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, qos(DIAGNOSTICS))
        self.create_timer(1.0, self._diagnostics, clock=steady)
        writes = ', '.join(gp.allowed(cfg['write_allow'])) or 'none (read-only)'
        self.get_logger().info(f"SunSpec Modbus TCP at {cfg['bind_address']}:{port} "
                               f'({len(self.collectors)} unit(s); writes from: {writes})')

    # -- topics -----------------------------------------------------------------------
    def _on_joints(self, k: int, msg: JointState) -> None:
        for name, pos in zip(msg.name, msg.position):
            if name == MIRRORS:
                c = self.collectors[k]
                c.position, c.stale = float(pos), False
                c.position_at = self._steady.now().nanoseconds * 1e-9
                self._dirty.add(k)

    def _on_axis(self, k: int, msg: AxisStatus) -> None:
        c = self.collectors[k]
        c.setpoint, c.fault = float(msg.setpoint), msg.state == 'fault'
        self._dirty.add(k)

    def _on_phase(self, k: int, msg: TrackerPhase) -> None:
        self.collectors[k].mode = msg.mode
        self._dirty.add(k)

    def _on_beam(self, k: int, msg: Irradiance) -> None:
        self.collectors[k].beam = float(msg.beam)
        self._dirty.add(k)

    def _encode(self, k: int) -> list[int]:
        return sunspec.encode(self.collectors[k].unit(k + 1, self.cfg['setpoint_alarm']))

    def _refresh(self) -> None:
        now = self._steady.now().nanoseconds * 1e-9
        for k, c in enumerate(self.collectors):
            if not c.stale and c.position_at is not None and now - c.position_at > self.cfg['stale_after']:
                c.stale = True
                self._dirty.add(k)
        dirty, self._dirty = self._dirty, set()
        for k in dirty:
            self.gateway.set_image(k, self._encode(k))

    # -- commands (called from the Modbus thread) ---------------------------------------
    def _command(self, k: int, tracker: int | None, mode: str) -> concurrent.futures.Future:  # noqa: ARG002
        out: concurrent.futures.Future = concurrent.futures.Future()
        client = self._set_mode[k]
        if not client.service_is_ready():
            out.set_result((False, 'planner/set_mode not available'))
            return out
        fut = client.call_async(SetMode.Request(mode=mode))

        def done(f):
            try:
                r = f.result()
                out.set_result((bool(r.success), r.message))
            except Exception as exc:  # noqa: BLE001 - reported as a refusal
                out.set_result((False, repr(exc)))
        fut.add_done_callback(done)
        return out

    def _diagnostics(self) -> None:
        self._diag.publish(diagnostics_msg(f'{self.get_name()}: modbus', 0, 'serving', 'modbus_gateway',
                                           self.gateway.counters, self.get_clock().now().to_msg()))

    def on_exit(self) -> None:
        self.gateway.stop()


def main(args=None) -> int:
    return run_node('modbus_gateway', ModbusGatewayNode, args=args,
                    config_errors=CONFIG_ERRORS + (OSError,))


if __name__ == '__main__':
    sys.exit(main())
