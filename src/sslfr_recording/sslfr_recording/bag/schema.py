"""Message definitions for MCAP schemas, built exactly as rosbag2_storage_mcap does.

rosbag2 stores each topic's type as an MCAP schema with encoding ``ros2msg``: the
``.msg`` file of the type, followed by every (transitively) referenced message type,
each introduced by a line of 80 ``=`` and ``MSG: pkg/Type``. Dependencies are found
with the same field-type regular expression, kept in a sorted set per message and
visited depth first, each emitted once. Definitions come from the ament index
(``<prefix>/share/<pkg>/msg/<Type>.msg`` for each prefix of ``AMENT_PREFIX_PATH``);
no rclpy and no rosidl_runtime_py are needed.

Type names are accepted as ``pkg/msg/Type`` (the ROS 2 form used in bags) or
``pkg/Type``.
"""
from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

from .typehash import type_hash
from .typenames import SEPARATOR, normalize_type, split_type  # noqa: F401 - SEPARATOR for users of schema

# Same pattern as rosbag2_storage_mcap's MSG_FIELD_TYPE_REGEX (first token of a line).
_FIELD_TYPE_RE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
PRIMITIVE_TYPES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string'})


class DefinitionNotFoundError(LookupError):
    """No ``.msg`` file for a type in any ament prefix."""


def parse_dependencies(text: str, package: str) -> set[str]:
    """Types referenced by the fields of a ``.msg`` text (rosbag2's rule).

    Unqualified names are resolved in ``package``; primitive types are skipped.
    """
    deps: set[str] = set()
    for match in _FIELD_TYPE_RE.finditer(text):
        typ = match.group(1)
        if typ in PRIMITIVE_TYPES:
            continue
        deps.add(typ if '/' in typ else f'{package}/{typ}')
    return deps


def ament_prefixes(env: dict | None = None) -> list[Path]:
    """Install prefixes of the ament index, in ``AMENT_PREFIX_PATH`` order."""
    value = (env if env is not None else os.environ).get('AMENT_PREFIX_PATH', '')
    return [Path(p) for p in value.split(os.pathsep) if p]


@dataclass
class DefinitionCache:
    """Loads ``.msg`` files from the ament index and builds full schema texts.

    Parameters
    ----------
    prefixes : list of Path, optional
        Install prefixes to search (default: ``AMENT_PREFIX_PATH``).
    """

    prefixes: list[Path] = field(default_factory=ament_prefixes)
    _texts: dict[str, str] = field(default_factory=dict, repr=False)

    def share_dir(self, package: str) -> Path:
        """``<prefix>/share/<package>`` of the first prefix that has it."""
        for prefix in self.prefixes:
            # ament index marker first (what ament_index_cpp checks), then the directory.
            marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / package
            share = prefix / 'share' / package
            if marker.exists() or share.is_dir():
                if share.is_dir():
                    return share
        raise DefinitionNotFoundError(f'package {package!r} not found in the ament index '
                                      f'({os.pathsep.join(map(str, self.prefixes)) or "empty AMENT_PREFIX_PATH"})')

    def msg_file(self, name: str) -> Path:
        """Path of the ``.msg`` file of a type."""
        pkg, ns, typ = split_type(name)
        path = self.share_dir(pkg) / ns / f'{typ}.msg'
        if not path.is_file():
            raise DefinitionNotFoundError(f'no definition file {path} for {name}')
        return path

    def text(self, name: str) -> str:
        """The raw ``.msg`` text of one type (cached)."""
        if name not in self._texts:
            self._texts[name] = self.msg_file(name).read_text(encoding='utf-8')
        return self._texts[name]

    def full_text(self, name: str, max_depth: int = 50) -> str:
        """The ``ros2msg`` schema text of ``name`` with all dependencies appended.

        Follows rosbag2_storage_mcap ``MessageDefinitionCache::get_full_text``:
        root text, then for each dependency (sorted, depth first, each once)
        ``"\\n" + "="*80 + "\\nMSG: pkg/Type\\n" + text``.
        """
        seen: set[str] = set()

        def append(type_name: str, depth: int) -> str:
            if depth <= 0:
                raise RecursionError(f'maximum recursion depth resolving {name}')
            text = self.text(type_name)
            pkg = split_type(type_name)[0]
            out = text
            for dep in sorted(parse_dependencies(text, pkg)):
                if dep not in seen:
                    seen.add(dep)
                    out += '\n' + SEPARATOR + f'MSG: {dep}\n' + append(dep, depth - 1)
            return out

        return append(name, max_depth)

    def type_hash(self, name: str) -> str:
        """The ``RIHS01_...`` type description hash of a message type.

        From the generated ``share/<pkg>/msg/<Type>.json`` when it exists (what the build
        computed), else computed from the ``.msg`` definitions
        (:func:`sslfr_recording.bag.typehash.type_hash`, rosidl's algorithm).

        Raises
        ------
        DefinitionNotFoundError
            When neither the ``.json`` nor the ``.msg`` definitions can be found.
        """
        full = normalize_type(name)
        pkg, ns, typ = split_type(name)
        try:
            path = self.share_dir(pkg) / ns / f'{typ}.json'
            data = json.loads(path.read_text(encoding='utf-8'))
            for entry in data.get('type_hashes', []):
                if entry.get('type_name') == full and str(entry.get('hash_string', '')).startswith('RIHS01_'):
                    return str(entry['hash_string'])
        except (OSError, ValueError, AttributeError, DefinitionNotFoundError):
            pass
        try:
            return type_hash(full, self.text)
        except (OSError, ValueError) as exc:
            raise DefinitionNotFoundError(f'cannot compute the type hash of {full}: {exc}') from exc
