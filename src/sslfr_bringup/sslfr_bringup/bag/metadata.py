"""rosbag2 ``metadata.yaml`` (version 9, as written by ROS 2 Jazzy) for MCAP bags.

Layout (key order as rosbag2 writes it)::

    rosbag2_bagfile_information:
      version: 9
      storage_identifier: mcap
      duration: {nanoseconds: N}
      starting_time: {nanoseconds_since_epoch: N}
      message_count: N
      topics_with_message_count:
        - topic_metadata: {name, type, serialization_format, offered_qos_profiles (YAML
            string), type_description_hash}
          message_count: N
      compression_format: ''
      compression_mode: ''
      relative_file_paths: [bag_0.mcap, ...]
      files: [{path, starting_time: {nanoseconds_since_epoch}, duration: {nanoseconds},
               message_count}, ...]
      custom_data: {str: str} or null
      ros_distro: jazzy

Times are integer nanoseconds since the Unix epoch (UTC). Compression in our bags is
MCAP chunk compression (storage level), so ``compression_format``/``compression_mode``
stay empty, as rosbag2 does for MCAP storage compression.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from .qos import dump_profiles, load_profiles, safe_yaml_dump

METADATA_FILENAME = 'metadata.yaml'
METADATA_VERSION = 9


class BagError(Exception):
    """A bag cannot be read or written (corrupt, missing, unsupported): the message says why."""


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
    """Everything ``metadata.yaml`` holds about a bag."""

    topics: dict[str, TopicInfo] = field(default_factory=dict)
    files: list[FileInfo] = field(default_factory=list)
    custom_data: dict[str, str] = field(default_factory=dict)
    ros_distro: str = 'jazzy'
    storage_identifier: str = 'mcap'
    version: int = METADATA_VERSION

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

    def to_dict(self) -> dict:
        """The YAML document (``rosbag2_bagfile_information`` mapping)."""
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
                    'offered_qos_profiles': dump_profiles(t.offered_qos_profiles),
                    'type_description_hash': t.type_description_hash,
                },
                 'message_count': t.message_count}
                for t in self.topics.values()],
            'compression_format': '',
            'compression_mode': '',
            'relative_file_paths': [f.path for f in self.files],
            'files': [
                {'path': f.path,
                 'starting_time': {'nanoseconds_since_epoch': f.starting_time_ns},
                 'duration': {'nanoseconds': f.duration_ns},
                 'message_count': f.message_count}
                for f in self.files],
            'custom_data': dict(self.custom_data),  # {} when empty: yaml-cpp needs a map
            'ros_distro': self.ros_distro,
        }
        return {'rosbag2_bagfile_information': info}

    def dumps(self) -> str:
        """The metadata as YAML text."""
        return safe_yaml_dump(self.to_dict())

    def serialized_for_mcap(self) -> str:
        """The inner mapping as YAML, for the MCAP ``rosbag2`` metadata record."""
        return safe_yaml_dump(self.to_dict()['rosbag2_bagfile_information'])


def write_metadata(directory: str | os.PathLike, meta: BagMetadata, fsync: bool = True) -> Path:
    """Write ``metadata.yaml`` atomically (temp file + rename) and return its path."""
    directory = Path(directory)
    path = directory / METADATA_FILENAME
    tmp = directory / (METADATA_FILENAME + '.tmp')
    with open(tmp, 'w', encoding='utf-8') as fh:
        fh.write(meta.dumps())
        fh.flush()
        if fsync:
            os.fsync(fh.fileno())
    os.replace(tmp, path)
    return path


def parse_metadata(text: str) -> BagMetadata:
    """Parse ``metadata.yaml`` text (versions 4..9) into :class:`BagMetadata`.

    Raises
    ------
    BagError
        On YAML errors or missing keys.
    """
    try:
        doc = yaml.safe_load(text)
        info = doc['rosbag2_bagfile_information']
        meta = BagMetadata(version=int(info.get('version', 0)),
                           storage_identifier=str(info.get('storage_identifier', '')),
                           ros_distro=str(info.get('ros_distro') or ''),
                           custom_data=dict(info.get('custom_data') or {}))
        for item in info.get('topics_with_message_count') or []:
            tm = item['topic_metadata']
            qos = tm.get('offered_qos_profiles', '')
            meta.topics[tm['name']] = TopicInfo(
                name=tm['name'], type=tm['type'],
                serialization_format=tm.get('serialization_format', 'cdr'),
                offered_qos_profiles=load_profiles(qos) if isinstance(qos, str) else list(qos or []),
                type_description_hash=str(tm.get('type_description_hash', '') or ''),
                message_count=int(item.get('message_count', 0)))
        files = info.get('files')
        if files:
            for f in files:
                meta.files.append(FileInfo(
                    path=f['path'],
                    starting_time_ns=int(f['starting_time']['nanoseconds_since_epoch']),
                    duration_ns=int(f['duration']['nanoseconds']),
                    message_count=int(f['message_count'])))
        else:
            for p in info.get('relative_file_paths') or []:
                meta.files.append(FileInfo(path=p))
        return meta
    except (yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
        raise BagError(f'metadata.yaml is not a valid rosbag2 metadata file: {exc}') from exc


def read_metadata(directory: str | os.PathLike) -> BagMetadata:
    """Read ``<directory>/metadata.yaml``."""
    path = Path(directory) / METADATA_FILENAME
    try:
        text = path.read_text(encoding='utf-8')
    except OSError as exc:
        raise BagError(f'cannot read {path}: {exc.strerror or exc}') from exc
    return parse_metadata(text)
