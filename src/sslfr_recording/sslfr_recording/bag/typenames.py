"""ROS type names and the schema delimiter, shared by :mod:`.schema` and :mod:`.typehash`.

Type names are accepted as ``pkg/msg/Type`` (the ROS 2 form used in bags) or ``pkg/Type``.
"""
from __future__ import annotations

import re

#: The delimiter line rosbag2 puts before each dependency (80 '=').
SEPARATOR = '=' * 80 + '\n'

_TYPENAME_RE = re.compile(r'^([a-zA-Z][a-zA-Z0-9_]*)/((?:msg|srv)/)?([a-zA-Z][a-zA-Z0-9_]*)$')


def split_type(name: str) -> tuple[str, str, str]:
    """Split ``pkg/msg/Type`` or ``pkg/Type`` into ``(pkg, 'msg', Type)``.

    Raises
    ------
    ValueError
        When the name is not a ROS message type name.
    """
    match = _TYPENAME_RE.match(name)
    if not match:
        raise ValueError(f'not a ROS message type name: {name!r}')
    return match.group(1), (match.group(2) or 'msg/').rstrip('/'), match.group(3)


def normalize_type(name: str) -> str:
    """Return the ROS 2 bag form ``pkg/msg/Type`` of a type name."""
    pkg, ns, typ = split_type(name)
    return f'{pkg}/{ns}/{typ}'
