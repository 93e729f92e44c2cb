"""rosbag2 ``metadata.yaml`` (version 9, as ROS 2 Jazzy writes and reads it) for MCAP bags.

Layout (key order and YAML kinds as rosbag2_storage ``yaml.hpp`` encodes them)::

    rosbag2_bagfile_information:
      version: 9
      storage_identifier: mcap
      duration: {nanoseconds: N}
      starting_time: {nanoseconds_since_epoch: N}
      message_count: N
      topics_with_message_count:
        - topic_metadata:
            name: /gps/fix
            type: sensor_msgs/msg/NavSatFix
            serialization_format: cdr
            offered_qos_profiles:          # a YAML sequence of QoS maps (v9), [] if none
              - history: keep_last
                depth: 10
                ...
            type_description_hash: RIHS01_...
          message_count: N
      compression_format: ""
      compression_mode: ""
      relative_file_paths: [bag_0.mcap, ...]
      files: [{path, starting_time: {nanoseconds_since_epoch}, duration: {nanoseconds},
               message_count}, ...]
      custom_data: ~                       # or a map of strings
      ros_distro: jazzy

The same mapping (without the ``rosbag2_bagfile_information`` key) is the
``serialized_metadata`` of the ``rosbag2`` metadata record in each ``.mcap``.
Times are integer nanoseconds since the Unix epoch (UTC). Compression in our bags is
MCAP chunk compression (storage level), so ``compression_format``/``compression_mode``
stay empty, as rosbag2 does for MCAP storage compression.

Reading (:func:`parse_metadata`) applies rosbag2's own decoding rules (``yaml.hpp``
decode, rules M01-M17 of :mod:`.rules`) through :mod:`.yamlcpp`, so a file rosbag2
would refuse is refused here too, with the key and line (:class:`MetadataError`).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from sslfr_common.files import atomic_write

from . import yamlcpp
from .qos import decode_profiles, load_profiles, to_yaml_list

METADATA_FILENAME = 'metadata.yaml'
METADATA_VERSION = 9


class BagError(Exception):
    """A bag cannot be read or written (corrupt, missing, unsupported): the message says why."""


class MetadataError(BagError):
    """metadata.yaml (or a ``rosbag2`` record) that rosbag2 would refuse: rule, key, line."""

    def __init__(self, source: str, refused: yamlcpp.Refused):
        self.source, self.rule, self.key, self.line = source, refused.rule, refused.key, refused.line
        self.message = refused.message
        where = f'{source}:{refused.line}' if refused.line else source
        super().__init__(f'{where}: {refused.key}: {refused.message} (rosbag2 would refuse it, '
                         f'rule {refused.rule})')


@dataclass
class TopicInfo:
    """One recorded topic: rosbag2 ``TopicMetadata`` plus its message count."""

    name: str
    type: str
    serialization_format: str = 'cdr'
    offered_qos_profiles: list[dict] = field(default_factory=list)
    type_description_hash: str = ''
    message_count: int = 0


@dataclass
class FileInfo:
    """One ``.mcap`` file of a bag; times [ns since the Unix epoch]."""

    path: str
    starting_time_ns: int = 0
    duration_ns: int = 0
    message_count: int = 0


@dataclass
class BagMetadata:
    """Everything ``metadata.yaml`` holds about a bag.

    ``message_count``, ``starting_time_ns`` and ``duration_ns`` are derived from the
    files when written; :func:`parse_metadata` keeps the values read in
    ``read_totals`` (for the conformance check, rule B05/B06).
    """

    topics: dict[str, TopicInfo] = field(default_factory=dict)
    files: list[FileInfo] = field(default_factory=list)
    custom_data: dict[str, str] = field(default_factory=dict)
    ros_distro: str = 'jazzy'
    storage_identifier: str = 'mcap'
    version: int = METADATA_VERSION
    relative_file_paths: list[str] | None = None
    compression_format: str = ''
    compression_mode: str = ''
    read_totals: tuple[int, int, int] | None = None  # (message_count, start, duration) as read

    @property
    def message_count(self) -> int:
        """Total message count (sum over files)."""
        return sum(f.message_count for f in self.files)

    @property
    def starting_time_ns(self) -> int:
        """Earliest message log time [ns], 0 for an empty bag."""
        starts = [f.starting_time_ns for f in self.files if f.message_count]
        return min(starts) if starts else 0

    @property
    def end_time_ns(self) -> int:
        """Latest message log time [ns], 0 for an empty bag."""
        ends = [f.starting_time_ns + f.duration_ns for f in self.files if f.message_count]
        return max(ends) if ends else 0

    @property
    def duration_ns(self) -> int:
        """end - start [ns]."""
        return max(0, self.end_time_ns - self.starting_time_ns)

    def file_paths(self) -> list[str]:
        """``relative_file_paths`` (as read, else the files' paths)."""
        if self.relative_file_paths is not None:
            return list(self.relative_file_paths)
        return [f.path for f in self.files]

    def to_dict(self) -> dict:
        """The YAML document (``rosbag2_bagfile_information`` mapping), yaml.hpp encode order."""
        info = {
            'version': self.version,
            'storage_identifier': self.storage_identifier,
            'duration': {'nanoseconds': self.duration_ns},
            'starting_time': {'nanoseconds_since_epoch': self.starting_time_ns},
            'message_count': self.message_count,
            'topics_with_message_count': [
                {'topic_metadata': {
                    'name': t.name,
                    'type': t.type,
                    'serialization_format': t.serialization_format,
                    'offered_qos_profiles': to_yaml_list(t.offered_qos_profiles),
                    'type_description_hash': t.type_description_hash,
                },
                 'message_count': t.message_count}
                for t in self.topics.values()],
            'compression_format': self.compression_format,
            'compression_mode': self.compression_mode,
            'relative_file_paths': [f.path for f in self.files],
            'files': [
                {'path': f.path,
                 'starting_time': {'nanoseconds_since_epoch': f.starting_time_ns},
                 'duration': {'nanoseconds': f.duration_ns},
                 'message_count': f.message_count}
                for f in self.files],
            # an empty unordered_map encodes as a null node (yaml.hpp 52-59): "~"
            'custom_data': dict(self.custom_data) if self.custom_data else None,
            'ros_distro': self.ros_distro,
        }
        return {'rosbag2_bagfile_information': info}

    def dumps(self) -> str:
        """The metadata as YAML text (metadata.yaml)."""
        return yamlcpp.dump(self.to_dict()) + '\n'

    def serialized_for_mcap(self) -> str:
        """The inner mapping as YAML, for the MCAP ``rosbag2`` metadata record."""
        return yamlcpp.dump(self.to_dict()['rosbag2_bagfile_information'])


def write_metadata(directory: str | os.PathLike, meta: BagMetadata, fsync: bool = True) -> Path:
    """Write ``metadata.yaml`` atomically (temp file + rename) and return its path."""
    return atomic_write(Path(directory) / METADATA_FILENAME, meta.dumps(), fsync=fsync)


def _time_ns(node: yamlcpp.Node, key: str) -> int:
    return node.get(key).as_uint64()


def _sequence(node: yamlcpp.Node, what: str) -> list[yamlcpp.Node]:
    """Items of a key that must be a YAML sequence (``as<std::vector<T>>`` refuses the rest)."""
    if node.kind != 'seq':
        if node.kind == 'undefined':
            node.as_str()  # raises "required key is missing"
        raise node.refuse(f'must be a YAML sequence of {what}, found a YAML {node.kind}')
    return node.elements()


def decode_info(info: yamlcpp.Node) -> BagMetadata:
    """``convert<BagMetadata>::decode`` of the inner mapping, in rosbag2's order.

    Raises
    ------
    yamlcpp.Refused
        At the first value rosbag2 would throw on (key path and line).
    """
    if info.kind not in ('map', 'null', 'undefined'):
        raise info.refuse(f'must be a map of bag metadata, found a YAML {info.kind}', 'M01')
    version = info.get('version', 'M02').as_int()
    meta = BagMetadata(version=version)
    meta.storage_identifier = info.get('storage_identifier', 'M03').as_str()
    duration = _time_ns(info.get('duration', 'M04'), 'nanoseconds')
    start = _time_ns(info.get('starting_time', 'M05'), 'nanoseconds_since_epoch')
    count = info.get('message_count', 'M06').as_uint64()
    meta.read_totals = (count, start, duration)
    for item in _sequence(info.get('topics_with_message_count', 'M07'), 'topic entries'):
        tm = item.get('topic_metadata', 'M07')
        if tm.kind == 'undefined':
            tm.as_str()
        name = tm.get('name', 'M08').as_str()
        info_t = TopicInfo(name=name, type=tm.get('type', 'M08').as_str(),
                           serialization_format=tm.get('serialization_format', 'M08').as_str())
        qos = tm.get('offered_qos_profiles', 'M09')
        if version >= 9:
            info_t.offered_qos_profiles = decode_profiles(qos)
        elif version >= 4:
            info_t.offered_qos_profiles = load_profiles(qos.as_str(), qos.path)
        if version >= 7:
            info_t.type_description_hash = tm.get('type_description_hash', 'M12').as_str()
        info_t.message_count = item.get('message_count', 'M07').as_uint64()
        meta.topics[name] = info_t
    meta.relative_file_paths = [p.as_str() for p in _sequence(info.get('relative_file_paths', 'M13'),
                                                               'file names')]
    if version >= 3:
        meta.compression_format = info.get('compression_format', 'M14').as_str()
        meta.compression_mode = info.get('compression_mode', 'M14').as_str()
    if version >= 5:
        for f in _sequence(info.get('files', 'M15'), 'file entries'):
            meta.files.append(FileInfo(
                path=f.get('path').as_str(),
                starting_time_ns=_time_ns(f.get('starting_time'), 'nanoseconds_since_epoch'),
                duration_ns=_time_ns(f.get('duration'), 'nanoseconds'),
                message_count=f.get('message_count').as_uint64()))
    else:
        meta.files = [FileInfo(path=p) for p in meta.relative_file_paths]
    if version >= 6:
        custom = info.get('custom_data', 'M16')
        if custom.kind == 'undefined':
            custom.as_str()
        if custom.kind == 'seq' and custom.elements():
            raise custom.refuse('must be a map of strings (or null), found a YAML sequence')
        meta.custom_data = {k.as_str(): v.as_str() for k, v in custom.items()}
    if version >= 8:
        meta.ros_distro = info.get('ros_distro', 'M17').as_str()
    else:
        meta.ros_distro = ''
    return meta


def parse_metadata(text: str, source: str = METADATA_FILENAME) -> BagMetadata:
    """Parse ``metadata.yaml`` text (versions 1..9) as rosbag2 Jazzy does.

    Raises
    ------
    MetadataError
        When rosbag2 would refuse the file (key, line and rule in the message).
    """
    try:
        doc = yamlcpp.Node.load(text, '', 'M01')
        if doc.kind != 'map':
            raise doc.refuse(f'must be a YAML map with key rosbag2_bagfile_information, '
                             f'found a YAML {doc.kind}')
        info = doc.get('rosbag2_bagfile_information', 'M01')
        if info.kind in ('undefined', 'null'):
            raise info.refuse('required key is missing')
        return decode_info(info)
    except yamlcpp.Refused as exc:
        raise MetadataError(source, exc) from None


def parse_serialized(text: str, source: str) -> BagMetadata:
    """Decode the ``serialized_metadata`` of a ``rosbag2`` MCAP record (no outer key)."""
    try:
        return decode_info(yamlcpp.Node.load(text, '', 'F11'))
    except yamlcpp.Refused as exc:
        raise MetadataError(source, exc) from None


def decode_text(data: bytes, source: str) -> str:
    """UTF-8 text of a metadata file, or MetadataError naming the first undecodable byte."""
    try:
        return data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise MetadataError(source, yamlcpp.Refused(
            'M01', 'document', 0, f'not a text file (byte 0x{data[exc.start]:02x} at offset '
            f'{exc.start} is not UTF-8)')) from None


def read_metadata(directory: str | os.PathLike) -> BagMetadata:
    """Read ``<directory>/metadata.yaml``.

    Raises
    ------
    BagError
        Unreadable file; :class:`MetadataError` when rosbag2 would refuse it.
    """
    path = Path(directory) / METADATA_FILENAME
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise BagError(f'cannot read {path}: {exc.strerror or exc}') from exc
    return parse_metadata(decode_text(data, str(path)), str(path))
