"""Pure-Python rosbag2/MCAP bag core (no rclpy): writing, reading, recovery, policies.

Modules: :mod:`.schema` (ros2msg definitions from the ament index), :mod:`.qos`
(offered QoS profiles, rosbag2 v9 YAML), :mod:`.metadata` (metadata.yaml v9),
:mod:`.writer` (crash-safe chunked writer with splitting), :mod:`.reader`,
:mod:`.recover` (``sslfr bag recover``), :mod:`.policy` (per-day naming, split,
free-disk guard), :mod:`.whatif` (decision comparison for what-if replays).
"""
from .metadata import BagError, BagMetadata, FileInfo, TopicInfo, read_metadata, write_metadata
from .policy import DiskGuard, SplitPolicy, bag_name, utc_day
from .qos import dump_profiles, load_profiles, profile
from .reader import BagReader, RawMessage
from .recover import recover_bag
from .schema import DefinitionCache, DefinitionNotFoundError, normalize_type
from .writer import BagWriter, WriterOptions

__all__ = ['BagError', 'BagMetadata', 'BagReader', 'BagWriter', 'DefinitionCache',
           'DefinitionNotFoundError', 'DiskGuard', 'FileInfo', 'RawMessage', 'SplitPolicy',
           'TopicInfo', 'WriterOptions', 'bag_name', 'dump_profiles', 'load_profiles',
           'normalize_type', 'profile', 'read_metadata', 'recover_bag', 'utc_day',
           'write_metadata']
