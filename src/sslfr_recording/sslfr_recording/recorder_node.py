"""``recorder`` node: record the tracker's topics to MCAP bags (rosbag2 layout).

Thin node over :class:`sslfr_recording.bag.session.RecordingSession` (pure core).
Generic subscriptions with ``raw=True`` deliver the serialized CDR bytes, which are
stored without decode/re-encode. Topics are discovered periodically (all topics
with a publisher, minus ``exclude``) or taken from ``topics``. Each subscription
asks for what every publisher offers (reliable only if all are reliable,
transient local only if all are, as rosbag2 does) and the publishers' offered QoS
profiles are stored in the bag. Log time = ROS time of reception (so
``use_sim_time`` days land in their day bag); publish time = the DDS source timestamp.

``/rosout`` (every node's log lines; a field's collector logs to ``<namespace>/rosout``,
sslfr_common.contract.namespace_remaps) is recorded too; the lines a publisher keeps
for late joiners (transient local) are recorded only when they are not older than the
recorder (:func:`.bag.recorder_config.log_line_kept`).

Diagnostics (``diagnostics``, 1 Hz, steady clock): OK while recording, ERROR with the
reason when the free-disk guard stopped recording or writes fail. The guard only
stops recording; it never touches another node.
"""
from __future__ import annotations

import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, ReliabilityPolicy
from sslfr_common.contract import DIAGNOSTICS, ROSOUT, collector_id
from sslfr_common.node import LeanEvents, ParameterGuard, declare_parameters, message_class, qos, run_node

from .bag import recorder_config as rc
from .bag.schema import DefinitionNotFoundError


class Recorder(LeanEvents, Node):
    """Record topics to per-day MCAP bags."""

    def __init__(self, **kwargs):
        super().__init__('recorder', **kwargs)
        cfg = declare_parameters(self, rc.TABLE)
        error = rc.output_error(cfg)
        if error:
            raise ValueError(error)
        self.cfg = cfg
        self.session = rc.make_session(cfg)
        self.params = ParameterGuard(self, rc.TABLE, cfg, self._apply)
        self._subs: dict[str, object] = {}
        self._bad_types: set[str] = set()
        self.received = 0
        self.written = 0        # messages written over the node's life (all sessions)
        self.written_data = 0   # of which not /rosout (sslfr record: a run that recorded only
                                # log lines, its own included, recorded nothing)
        self.write_errors = 0   # write errors over the node's life
        self.last_error = ''
        self.no_clock = 0
        self.old_log_lines = 0     # /rosout lines older than this recorder (already recorded)
        self._started_ns = time.time_ns()
        self._discover_timer = None
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._restart_discovery()
        self._poll_timer = self.create_timer(0.25, self._poll, clock=steady)
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, qos(DIAGNOSTICS))
        self._diag_timer = self.create_timer(1.0, self._publish_diagnostics, clock=steady)
        self.get_logger().info(
            f'recording to {self.session.root} ({"one bag per UTC day" if cfg["per_day"] else "one bag"}, '
            f'chunks <= {cfg["chunk_duration"]} s)')

    # -- parameters ------------------------------------------------------------------
    def _apply(self, new: dict) -> None:
        """A validated run-time change: an unwritable output_dir is refused (ValueError);
        writer settings apply from a new bag (the current one is closed cleanly)."""
        if new['output_dir'] != self.cfg['output_dir']:
            error = rc.output_error(new)
            if error:
                self.get_logger().error(f'parameter change refused: {error}')
                raise ValueError(error)
        old_cfg, self.cfg = self.cfg, new
        if rc.needs_new_bag(old_cfg, new):
            old = self.session
            self.session = rc.make_session(new)
            for name in old.topics:
                d = old._decls[name]  # noqa: SLF001 - same package
                self.session.add_topic(name, d.type_name, d.qos, d.type_hash)
            old.close()
        if new['discovery_period'] != old_cfg['discovery_period']:
            self._restart_discovery()

    # -- discovery and recording --------------------------------------------------------
    def _restart_discovery(self) -> None:
        if self._discover_timer is not None:
            self.destroy_timer(self._discover_timer)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._discover_timer = self.create_timer(float(self.cfg['discovery_period']),
                                                 self._discover, clock=steady)
        self._discover()

    def _wanted(self, topic: str) -> bool:
        return rc.wanted(topic, [self._resolve(t) for t in self.cfg['topics'] if t],
                         [self._resolve(t) for t in self.cfg['exclude'] if t])

    def _resolve(self, name: str) -> str:
        try:
            return self.resolve_topic_name(name)
        except Exception:  # noqa: BLE001 - invalid names are simply never matched
            return name if name.startswith('/') else '/' + name

    def _discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self._subs or not self._wanted(topic) or len(types) != 1:
                continue
            type_name = types[0]
            if type_name in self._bad_types:
                continue
            pubs = self.get_publishers_info_by_topic(topic)
            if not pubs:
                continue
            try:
                msg_cls = message_class(type_name)
                offered = [rc.qos_to_dict(p.qos_profile) for p in pubs]
                type_hash = ''
                try:
                    type_hash = str(pubs[0].topic_type_hash)
                except Exception:  # noqa: BLE001 - older rclpy
                    type_hash = ''
                self.session.add_topic(topic, type_name, offered,
                                       type_hash if type_hash.startswith('RIHS') else None)
            except (ImportError, AttributeError, ValueError, DefinitionNotFoundError) as exc:
                self._bad_types.add(type_name)
                self.get_logger().error(f'cannot record {topic} ({type_name}): {exc}')
                continue
            reliable, latched = rc.subscription_qos(
                [(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE,
                  p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL) for p in pubs])
            qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=int(self.cfg['queue_depth']),
                             reliability=ReliabilityPolicy.RELIABLE if reliable
                             else ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                             else DurabilityPolicy.VOLATILE,
                             liveliness=LivelinessPolicy.SYSTEM_DEFAULT)
            self._subs[topic] = self.create_subscription(
                msg_cls, topic, self._make_callback(topic), qos, raw=True)
            self.get_logger().info(f'recording {topic} [{type_name}]')

    def _make_callback(self, topic: str):
        clock = self.get_clock()
        session_ref = self
        started = self._started_ns if topic == self._resolve(ROSOUT.name) else None
        data_topic = int(started is None)

        def callback(data: bytes, info) -> None:
            session_ref.received += 1
            now = clock.now().nanoseconds
            if now <= 0:  # use_sim_time and no /clock yet: no valid log time
                session_ref.no_clock += 1
                return
            src = None
            if isinstance(info, dict):
                src = info.get('source_timestamp')
            if started is not None and not rc.log_line_kept(int(src or 0), started):
                session_ref.old_log_lines += 1
                return
            session = session_ref.session
            errors = session.stats.write_errors
            if session.write(topic, bytes(data), now, src if src else now,
                             int(info.get('publication_sequence_number', 0) or 0)
                             if isinstance(info, dict) else 0):
                session_ref.written += 1
                session_ref.written_data += data_topic
            elif session.stats.write_errors > errors:
                session_ref._on_write_error(session.stats.last_error)
        return callback

    def _on_write_error(self, error: str) -> None:
        """Count a write error; the first one (and every change of reason) is logged as ERROR."""
        self.write_errors += 1
        if error != self.last_error:
            self.get_logger().error(f'cannot record: {error}')
        self.last_error = error

    def _poll(self) -> None:
        was = self.session.recording
        status = self.session.poll()
        if status is not None and was != self.session.recording:
            if self.session.recording:
                self.get_logger().warn(f'disk space back: recording resumes ({status.message})')
            else:
                self.get_logger().error(status.message)

    def _publish_diagnostics(self) -> None:
        s = self.session
        st = DiagnosticStatus(name=f'{self.get_name()}: recording', hardware_id=collector_id(self.get_namespace()))
        if not s.recording:
            st.level = DiagnosticStatus.ERROR
            st.message = s.disk.message if s.disk else 'recording stopped by the disk guard'
        elif s.stats.write_errors:
            st.level = DiagnosticStatus.ERROR  # from the first write error on
            st.message = f'{s.stats.write_errors} write error(s): {s.stats.last_error}'
        else:
            st.level = DiagnosticStatus.OK
            st.message = f'recording {len(s.topics)} topics'
        kv = {'bag': str(s.bag_dir or ''), 'topics': len(s.topics), 'received': self.received,
              'written': s.stats.written, 'dropped_disk_full': s.stats.dropped_disk,
              'write_errors': s.stats.write_errors, 'dropped_no_clock': self.no_clock,
              'dropped_old_log_lines': self.old_log_lines,
              'free_bytes': s.disk.free_bytes if s.disk else -1}
        st.values = [KeyValue(key=k, value=str(v)) for k, v in kv.items()]
        arr = DiagnosticArray(status=[st])
        arr.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(arr)

    def on_exit(self) -> None:
        """Close the bag (last chunk, summary, metadata.yaml); called by run_node once
        spinning ends, with further signals ignored."""
        self.session.close()


def main(args=None, require_data: bool = False) -> int:
    """Run the recorder; with ``require_data`` (``sslfr record``) exit 1 when nothing
    was recorded. The bag is closed (metadata.yaml written atomically) in
    :meth:`Recorder.on_exit`, whatever signals arrive meanwhile (short of SIGKILL)."""
    built: list[Recorder] = []

    def make() -> Recorder:
        built.append(Recorder())
        return built[0]

    code = run_node('recorder', make, args=args)
    if code or not require_data or not built:
        return code
    node = built[0]
    if node.written_data == 0 or node.write_errors:
        why = (f'{node.write_errors} write error(s), last: {node.last_error}' if node.write_errors
               else f'no message received on {", ".join(node.cfg["topics"]) if any(node.cfg["topics"]) else "any topic"}')
        lines = node.written - node.written_data
        print(f'sslfr record: recorded {node.written_data} message(s)'
              + (f' and {lines} /rosout log line(s)' if lines else '') + f': {why}', file=sys.stderr, flush=True)
        return 1
    return 0
