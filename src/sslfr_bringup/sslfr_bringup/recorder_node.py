"""``recorder`` node: record the tracker's topics to MCAP bags (rosbag2 layout).

Thin node over :class:`sslfr_bringup.bag.session.RecordingSession` (pure core).
Generic subscriptions with ``raw=True`` deliver the serialized CDR bytes, which are
stored without decode/re-encode. Topics are discovered periodically (all topics
with a publisher, minus ``exclude``) or taken from ``topics``. Each subscription
asks for what every publisher offers (reliable only if all are reliable,
transient local only if all are, as rosbag2 does) and the publishers' offered QoS
profiles are stored in the bag. Log time = ROS time of reception (so
``use_sim_time`` days land in their day bag); publish time = the DDS source timestamp.

Diagnostics (``diagnostics``, 1 Hz, steady clock): OK while recording, ERROR with the
reason when the free-disk guard stopped recording or writes fail. The guard only
stops recording; it never touches another node.
"""
from __future__ import annotations

import importlib
import os
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, \
    SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from sslfr_common.node import run_node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, LivelinessPolicy, QoSProfile, \
    ReliabilityPolicy

from .bag.policy import DiskGuard, SplitPolicy
from .bag.qos import duration_dict
from .bag.schema import DefinitionNotFoundError
from .bag.session import RecordingSession, probe_output_dir
from .bag.writer import WriterOptions

_ALWAYS_EXCLUDED = ('/rosout', '/parameter_events')


def qos_to_dict(qos) -> dict:
    """rclpy QoSProfile -> rosbag2 v9 profile dict (durations as {sec, nsec})."""
    def name(enum_value) -> str:
        return getattr(enum_value, 'name', str(enum_value)).lower()

    def dur(d) -> dict:
        ns = getattr(d, 'nanoseconds', 0)
        return duration_dict(None) if ns >= 0x7FFFFFFFFFFFFFFF else duration_dict(ns / 1e9) \
            if ns >= 0 else duration_dict(0.0)

    return {'history': name(qos.history), 'depth': int(qos.depth),
            'reliability': name(qos.reliability), 'durability': name(qos.durability),
            'deadline': dur(qos.deadline), 'lifespan': dur(qos.lifespan),
            'liveliness': name(qos.liveliness),
            'liveliness_lease_duration': dur(qos.liveliness_lease_duration),
            'avoid_ros_namespace_conventions': bool(qos.avoid_ros_namespace_conventions)}


def import_message(type_name: str):
    """``pkg/msg/Type`` -> the generated Python message class."""
    pkg, _, typ = type_name.split('/')
    return getattr(importlib.import_module(f'{pkg}.msg'), typ)


class Recorder(Node):
    """Record topics to per-day MCAP bags."""

    PARAMS = {
        'output_dir': ('~/sslfr_bags', 'directory where bag directories are created', None),
        'prefix': ('sslfr', 'bag directory name prefix: <prefix>_YYYY-MM-DD', None),
        'topics': ([''], 'topics to record (relative names are resolved in the node '
                         'namespace); empty = every topic with a publisher', None),
        'exclude': (['/clock'], 'topics never recorded (besides /rosout, /parameter_events)', None),
        'discovery_period': (1.0, 'period of topic discovery [s]', (0.1, 60.0)),
        'per_day': (True, 'one bag per UTC day of ROS time (else one bag per run)', None),
        'max_file_size': (0, 'split the bag into a new .mcap at this size [bytes]; 0 = off',
                          (0, 2**62)),
        'max_file_duration': (0.0, 'split into a new .mcap after this much log time [s]; 0 = off',
                              (0.0, 1e7)),
        'chunk_duration': (2.0, 'max age of unwritten data [s]: bounds what a crash loses',
                           (0.05, 60.0)),
        'chunk_size': (1048576, 'MCAP chunk size [bytes]', (1024, 1 << 30)),
        'compression': ('zstd', 'MCAP chunk compression: zstd | lz4 | none', None),
        'fsync': (True, 'fsync every chunk (power-cut safety)', None),
        'min_free_bytes': (500 * 1024 * 1024, 'stop recording below this free space [bytes]',
                           (0, 2**62)),
        'min_free_fraction': (0.02, 'stop recording below this free fraction of the disk [-]',
                              (0.0, 0.99)),
        'disk_check_period': (5.0, 'period of the free-disk check [s]', (0.1, 3600.0)),
        'queue_depth': (100, 'subscription history depth [messages]', (1, 100000)),
    }

    def __init__(self):
        super().__init__('recorder')
        for pname, (default, text, rng) in self.PARAMS.items():
            desc = ParameterDescriptor(description=text)
            if rng is not None and isinstance(default, float):
                desc.floating_point_range = [FloatingPointRange(from_value=rng[0], to_value=rng[1])]
            elif rng is not None and isinstance(default, int) and not isinstance(default, bool):
                desc.integer_range = [IntegerRange(from_value=rng[0], to_value=min(rng[1], 2**62))]
            self.declare_parameter(pname, default, desc)
        cfg = {p: self.get_parameter(p).value for p in self.PARAMS}
        error = self._validate(cfg) or self._output_error(cfg)
        if error:
            raise ValueError(f'recorder: invalid parameters: {error}')
        self.cfg = cfg
        self.session = self._make_session(cfg)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._subs: dict[str, object] = {}
        self._bad_types: set[str] = set()
        self.received = 0
        self.written = 0        # messages written over the node's life (all sessions)
        self.write_errors = 0   # write errors over the node's life
        self.last_error = ''
        self.no_clock = 0
        self._discover_timer = None
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._restart_discovery()
        self._poll_timer = self.create_timer(0.25, self._poll, clock=steady)
        self._diag_pub = self.create_publisher(DiagnosticArray, 'diagnostics', 10)
        self._diag_timer = self.create_timer(1.0, self._publish_diagnostics, clock=steady)
        self.get_logger().info(
            f'recording to {self.session.root} ({"one bag per UTC day" if cfg["per_day"] else "one bag"}, '
            f'chunks <= {cfg["chunk_duration"]} s)')

    # -- parameters ------------------------------------------------------------------
    @staticmethod
    def _validate(cfg: dict) -> str:
        if cfg['compression'] not in ('zstd', 'lz4', 'none'):
            return f"compression must be zstd, lz4 or none (got {cfg['compression']!r})"
        if not str(cfg['output_dir']).strip():
            return 'output_dir is empty'
        if not cfg['prefix'] or '/' in cfg['prefix'] or '\0' in cfg['prefix'] \
                or cfg['prefix'] in ('.', '..'):
            return 'prefix must be a non-empty name without /'
        for key in ('discovery_period', 'chunk_duration', 'disk_check_period'):
            if not cfg[key] > 0:
                return f'{key} must be > 0'
        for key in ('max_file_size', 'max_file_duration', 'min_free_bytes', 'min_free_fraction'):
            if not cfg[key] >= 0:
                return f'{key} must be >= 0'
        return ''

    @staticmethod
    def _output_error(cfg: dict) -> str:
        why = probe_output_dir(os.path.expanduser(str(cfg['output_dir'])))
        return f'output_dir {cfg["output_dir"]!r}: {why}' if why else ''

    def _make_session(self, cfg: dict) -> RecordingSession:
        opts = WriterOptions(chunk_size=int(cfg['chunk_size']),
                             chunk_duration_s=float(cfg['chunk_duration']),
                             compression=cfg['compression'], fsync=bool(cfg['fsync']),
                             split=SplitPolicy(int(cfg['max_file_size']),
                                               float(cfg['max_file_duration'])))
        guard = DiskGuard(min_free_bytes=int(cfg['min_free_bytes']),
                          min_free_fraction=float(cfg['min_free_fraction']))
        return RecordingSession(os.path.expanduser(cfg['output_dir']), cfg['prefix'],
                                bool(cfg['per_day']), opts, guard,
                                float(cfg['disk_check_period']))

    def _on_set_parameters(self, params) -> SetParametersResult:
        new = dict(self.cfg)
        for p in params:
            if p.name in new:
                new[p.name] = p.value
        changed = {k for k in new if new[k] != self.cfg[k]}
        error = self._validate(new) or (self._output_error(new) if 'output_dir' in changed else '')
        if error:
            self.get_logger().error(f'parameter change refused: {error}')
            return SetParametersResult(successful=False, reason=error)
        self.cfg = new
        if changed & {'output_dir', 'prefix', 'per_day', 'max_file_size', 'max_file_duration',
                      'chunk_duration', 'chunk_size', 'compression', 'fsync', 'min_free_bytes',
                      'min_free_fraction', 'disk_check_period'}:
            # New writer settings apply from the next bag: close the current one now.
            old = self.session
            self.session = self._make_session(new)
            for name in old.topics:
                d = old._decls[name]  # noqa: SLF001 - same package
                self.session.add_topic(name, d.type_name, d.qos, d.type_hash)
            old.close()
        if 'discovery_period' in changed:
            self._restart_discovery()
        return SetParametersResult(successful=True)

    # -- discovery and recording --------------------------------------------------------
    def _restart_discovery(self) -> None:
        if self._discover_timer is not None:
            self.destroy_timer(self._discover_timer)
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._discover_timer = self.create_timer(float(self.cfg['discovery_period']),
                                                 self._discover, clock=steady)
        self._discover()

    def _wanted(self, topic: str) -> bool:
        if topic in _ALWAYS_EXCLUDED:
            return False
        excl = {self._resolve(t) for t in self.cfg['exclude'] if t}
        if topic in excl:
            return False
        listed = [self._resolve(t) for t in self.cfg['topics'] if t]
        return not listed or topic in listed

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
                msg_cls = import_message(type_name)
                offered = [qos_to_dict(p.qos_profile) for p in pubs]
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
            reliable = all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in pubs)
            latched = all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in pubs)
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

        def callback(data: bytes, info) -> None:
            session_ref.received += 1
            now = clock.now().nanoseconds
            if now <= 0:  # use_sim_time and no /clock yet: no valid log time
                session_ref.no_clock += 1
                return
            src = None
            if isinstance(info, dict):
                src = info.get('source_timestamp')
            session = session_ref.session
            errors = session.stats.write_errors
            if session.write(topic, bytes(data), now, src if src else now,
                             int(info.get('publication_sequence_number', 0) or 0)
                             if isinstance(info, dict) else 0):
                session_ref.written += 1
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
        st = DiagnosticStatus(name=f'{self.get_name()}: recording', hardware_id='recorder')
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
    if node.written == 0 or node.write_errors:
        why = (f'{node.write_errors} write error(s), last: {node.last_error}' if node.write_errors
               else f'no message received on {", ".join(node.cfg["topics"]) if any(node.cfg["topics"]) else "any topic"}')
        print(f'sslfr record: recorded {node.written} message(s): {why}', file=sys.stderr, flush=True)
        return 1
    return 0
