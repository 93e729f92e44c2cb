"""The rosbag2 Jazzy rules our bags are checked against, each with the source it comes from.

Written from rosbag2's own reading and writing code (branch ``jazzy``), the rmw QoS
string conversions it calls, yaml-cpp 0.8 (the YAML library rosbag2 decodes with),
the MCAP specification and its ``ros2`` profile (foxglove/mcap), and rosidl's type
description hashing (REP-2011). Nothing here is copied code: each rule restates what
the cited lines do, and :mod:`.conformance` / :mod:`.metadata` apply it.

Severity:

- ``refuse``: rosbag2 throws (``ros2 bag info`` / ``ros2 bag play`` stop with an error);
- ``play``: rosbag2 opens the bag but ``ros2 bag play`` misbehaves (file-order
  playback, a publisher that cannot be created);
- ``differs``: rosbag2 opens and plays it, but the bag differs from what rosbag2
  writes or from its own data (counts, times, hashes).
"""
from __future__ import annotations

from dataclasses import dataclass

#: Sources, as ``repository@commit path`` (the commit read when the rules were written).
SOURCES = {
    'yaml.hpp': 'ros2/rosbag2@64717ee8 (jazzy) rosbag2_storage/include/rosbag2_storage/yaml.hpp',
    'qos.cpp': 'ros2/rosbag2@64717ee8 (jazzy) rosbag2_storage/src/rosbag2_storage/qos.cpp',
    'qos.hpp': 'ros2/rosbag2@64717ee8 (jazzy) rosbag2_storage/include/rosbag2_storage/qos.hpp',
    'metadata_io.cpp': 'ros2/rosbag2@64717ee8 (jazzy) rosbag2_storage/src/rosbag2_storage/metadata_io.cpp',
    'mcap_storage.cpp': 'ros2/rosbag2@64717ee8 (jazzy) rosbag2_storage_mcap/src/mcap_storage.cpp',
    'info.cpp': 'ros2/rosbag2@64717ee8 (jazzy) rosbag2_cpp/src/rosbag2_cpp/info.cpp',
    'sequential_reader.cpp': 'ros2/rosbag2@64717ee8 (jazzy) rosbag2_cpp/src/rosbag2_cpp/readers/sequential_reader.cpp',
    'sequential_writer.cpp': 'ros2/rosbag2@64717ee8 (jazzy) rosbag2_cpp/src/rosbag2_cpp/writers/sequential_writer.cpp',
    'qos_string_conversions.c': 'ros2/rmw@c90c297 (jazzy) rmw/src/qos_string_conversions.c',
    'convert.h': 'jbeder/yaml-cpp@0.8.0 include/yaml-cpp/node/convert.h',
    'registry.md': 'foxglove/mcap@95d06735 website/docs/spec/registry.md',
    'spec.md': 'foxglove/mcap@95d06735 website/docs/spec/index.md',
    'reader.inl': 'foxglove/mcap@95d06735 cpp/mcap/include/mcap/reader.inl',
    'type_description': 'ros2/rosidl@1d92ce39 (jazzy) rosidl_generator_type_description/'
                        'rosidl_generator_type_description/__init__.py',
}


@dataclass(frozen=True)
class Rule:
    """One checked rule: what it demands and where rosbag2 / the spec says so."""

    id: str
    severity: str
    text: str
    cites: tuple[tuple[str, str], ...]

    def citation(self) -> str:
        """``file:lines; file:lines`` (short names; :data:`SOURCES` has the full paths)."""
        return '; '.join(f'{src}:{lines}' for src, lines in self.cites)


_RULES = [
    # -- metadata.yaml and the serialized metadata of the MCAP `rosbag2` record -------------
    Rule('M01', 'refuse', 'metadata.yaml is a YAML document whose top level maps '
         '`rosbag2_bagfile_information` to the bag metadata',
         (('metadata_io.cpp', '43-44'), ('metadata_io.cpp', '53-54'))),
    Rule('M02', 'refuse', '`version` is an int (yaml-cpp operator>> rules)',
         (('yaml.hpp', '279'), ('convert.h', '179-210'))),
    Rule('M03', 'refuse', '`storage_identifier` is a scalar string',
         (('yaml.hpp', '280'),)),
    Rule('M04', 'refuse', '`duration` is a map with `nanoseconds` (uint64)',
         (('yaml.hpp', '281'), ('yaml.hpp', '228-232'))),
    Rule('M05', 'refuse', '`starting_time` is a map with `nanoseconds_since_epoch` (uint64)',
         (('yaml.hpp', '282-283'), ('yaml.hpp', '245-251'))),
    Rule('M06', 'refuse', '`message_count` is a uint64', (('yaml.hpp', '284'),)),
    Rule('M07', 'refuse', '`topics_with_message_count` is a sequence of maps with '
         '`topic_metadata` and `message_count` (uint64)',
         (('yaml.hpp', '285-287'), ('yaml.hpp', '179-191'), ('yaml.hpp', '158-163'))),
    Rule('M08', 'refuse', '`topic_metadata` has `name`, `type`, `serialization_format` '
         '(scalar strings)', (('yaml.hpp', '125-129'),)),
    Rule('M09', 'refuse', '`offered_qos_profiles` is a YAML sequence of QoS maps for '
         'version >= 9, and a string holding such a sequence for versions 4..8',
         (('yaml.hpp', '130-136'), ('qos.cpp', '260-275'), ('qos.cpp', '447-452'),
          ('qos.hpp', '101-115'))),
    Rule('M10', 'refuse', 'each QoS map has history, depth (int, read when keep_last), '
         'reliability, durability, liveliness (v9 names, or v8 integers when history is '
         'an int 0..3), deadline, lifespan, liveliness_lease_duration ({sec, nsec} uint64) '
         'and avoid_ros_namespace_conventions (bool)',
         (('qos.cpp', '167-213'), ('qos.cpp', '137-149'))),
    Rule('M11', 'play', 'reliability, durability and liveliness names are ones rmw knows '
         '(reliable/best_effort, transient_local/volatile, automatic/manual_by_topic, or '
         'system_default/best_available): any other string decodes to UNKNOWN, which no '
         'publisher accepts at play time; history may be `unknown` (rosbag2 records it so, '
         'playback replaces it by keep_last)',
         (('qos.cpp', '57-61'), ('qos.cpp', '45-55'), ('qos.cpp', '413-422'),
          ('qos_string_conversions.c', '153-200'))),
    Rule('M12', 'refuse', '`type_description_hash` is a scalar string (version >= 7)',
         (('yaml.hpp', '137-141'),)),
    Rule('M13', 'refuse', '`relative_file_paths` is a sequence of strings',
         (('yaml.hpp', '289'),)),
    Rule('M14', 'refuse', '`compression_format` and `compression_mode` are strings '
         '(version >= 3)', (('yaml.hpp', '291-294'),)),
    Rule('M15', 'refuse', '`files` is a sequence of maps with `path`, '
         '`starting_time.nanoseconds_since_epoch`, `duration.nanoseconds`, `message_count` '
         '(version >= 5)', (('yaml.hpp', '295-298'), ('yaml.hpp', '207-215'))),
    Rule('M16', 'refuse', '`custom_data` is a map of strings to strings, or null '
         '(version >= 6)', (('yaml.hpp', '300-302'), ('yaml.hpp', '61-67'))),
    Rule('M17', 'refuse', '`ros_distro` is a scalar string (version >= 8)',
         (('yaml.hpp', '303-305'),)),
    Rule('M18', 'differs', 'version 9 is written with the QoS as a sequence of maps, policy '
         'names as rmw strings, and every key of the version',
         (('yaml.hpp', '108-123'), ('yaml.hpp', '257-275'), ('qos.cpp', '45-55'),
          ('qos.cpp', '151-165'))),
    # -- each .mcap file ------------------------------------------------------------------
    Rule('F01', 'refuse', 'the file opens as MCAP (magic, header)',
         (('mcap_storage.cpp', '362-377'), ('reader.inl', '301-351'), ('spec.md', '40'),
          ('spec.md', '48'))),
    Rule('F02', 'refuse', 'the summary can be read, or else the whole data section scans '
         'cleanly (rosbag2 reads with AllowFallbackScan: a cut or damaged record fails it)',
         (('mcap_storage.cpp', '699-708'), ('reader.inl', '397-427'), ('reader.inl', '515-588'),
          ('spec.md', '143'))),
    Rule('F03', 'refuse', 'the summary has a Statistics record',
         (('mcap_storage.cpp', '459-463'),)),
    Rule('F04', 'differs', 'the header profile is `ros2`', (('registry.md', '240-242'),)),
    Rule('F05', 'refuse', 'every channel has its schema', (('mcap_storage.cpp', '470-474'),
                                                          ('spec.md', '242'))),
    Rule('F06', 'refuse', 'channel message encoding is `cdr`, the same for every topic',
         (('registry.md', '244-246'), ('sequential_reader.cpp', '135-136'),
          ('sequential_reader.cpp', '315-326'))),
    Rule('F07', 'refuse', 'channel metadata `offered_qos_profiles` is present and is the '
         'YAML text of a sequence of QoS maps (rules M09-M11); rosbag2 writes `[]` when '
         'there is none', (('registry.md', '247-249'), ('mcap_storage.cpp', '483-488'),
                           ('mcap_storage.cpp', '935-937'), ('qos.cpp', '441-452'))),
    Rule('F08', 'differs', 'channel metadata `topic_type_hash`, when present, is the RIHS01 '
         'hash of the schema\'s type description (rosbag2 writes it, readers do not require it)',
         (('mcap_storage.cpp', '489-492'), ('mcap_storage.cpp', '938'),
          ('type_description', '26-33'))),
    Rule('F09', 'refuse', 'schema encoding is `ros2msg` and the name a package resource '
         'name pkg/msg/Type', (('registry.md', '269-271'), ('registry.md', '108-112'))),
    Rule('F10', 'refuse', '`ros2msg` schema data: the top-level definition first, every '
         'further one after a line of 80 `=` and a line `MSG: pkg/Type`, and a definition '
         'for every message type used', (('registry.md', '99-106'), ('registry.md', '114'))),
    Rule('F11', 'refuse', 'the `rosbag2` metadata record is in the metadata index, has '
         '`serialized_metadata`, and that text decodes as bag metadata (rules M02-M17)',
         (('mcap_storage.cpp', '414-443'), ('sequential_writer.cpp', '168'),
          ('sequential_writer.cpp', '185-189'))),
    Rule('F12', 'play', 'every chunk has message indexes (chunk index '
         '`message_index_length` > 0): without them rosbag2 cannot read in log-time order '
         'and plays in file order', (('mcap_storage.cpp', '711-739'),
                                     ('sequential_reader.cpp', '113-119'),
                                     ('spec.md', '215'), ('spec.md', '228'))),
    Rule('F13', 'differs', 'the Statistics record (message count, per-channel counts, '
         'first and last log time) equals the messages in the chunks',
         (('spec.md', '304-320'), ('mcap_storage.cpp', '459-499'))),
    Rule('F14', 'refuse', 'every chunk is intact (CRC-32 of its records, decompression)',
         (('spec.md', '196-209'),)),
    # -- the bag directory ------------------------------------------------------------------
    Rule('B01', 'refuse', 'a bag directory has a metadata.yaml',
         (('info.cpp', '44-51'), ('sequential_reader.cpp', '93-108'))),
    Rule('B02', 'refuse', 'every file of `relative_file_paths` exists in the directory',
         (('sequential_reader.cpp', '104-107'), ('sequential_reader.cpp', '261-274'))),
    Rule('B03', 'refuse', '`storage_identifier` names the plugin: `mcap`',
         (('sequential_reader.cpp', '96-99'), ('mcap_storage.cpp', '455'))),
    Rule('B04', 'differs', '`relative_file_paths` lists the files of `files`, in order',
         (('sequential_writer.cpp', '350-360'),)),
    Rule('B05', 'differs', 'counts equal the data: message_count = sum of the topics\' '
         'counts = sum of the files\' counts; each topic\'s and file\'s count equals its '
         'messages', (('sequential_writer.cpp', '502-517'), ('sequential_writer.cpp', '428-430'))),
    Rule('B06', 'differs', 'times equal the data: starting_time and duration span the '
         'first and last log time; each file\'s starting_time/duration its own messages',
         (('sequential_writer.cpp', '403-426'),)),
    Rule('B07', 'differs', 'the topics of metadata.yaml are the channels of the files, with '
         'type = schema name and serialization_format = message encoding, and '
         '`type_description_hash` filled', (('sequential_writer.cpp', '502-517'),
                                            ('mcap_storage.cpp', '466-499'),
                                            ('type_description', '467-490'))),
]

RULES: dict[str, Rule] = {r.id: r for r in _RULES}


def describe() -> str:
    """The rule list as text (``sslfr bag check --rules``; docs/bags.md)."""
    lines = []
    for r in _RULES:
        lines.append(f'{r.id} [{r.severity}] {r.text}  ({r.citation()})')
    return '\n'.join(lines)
