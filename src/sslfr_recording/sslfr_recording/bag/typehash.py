"""REP-2011 type description hashes (``RIHS01_<sha256>``) computed from ``.msg`` texts.

rosbag2 stores each topic's type hash (``type_description_hash`` in metadata.yaml,
``topic_type_hash`` in the MCAP channel). The build writes it into the generated
``share/<pkg>/msg/<Type>.json``; where that file is missing (a stripped install, a
type known only from a bag's own ``ros2msg`` schema) it is computed here the way
rosidl does it, from the message definitions alone:

1. each ``.msg`` is read as rosidl_adapter reads it (``parser.py``
   ``parse_message_string``: ``#`` starts a comment, ``type name [default]`` is a
   field, ``type NAME=value`` a constant; constants and default values do not enter
   the hash) and its types mapped as ``msg/__init__.py`` ``MSG_TYPE_TO_IDL`` does
   (``char`` is uint8, ``byte`` octet, ``float32`` float, ...); a message without
   fields gets rosidl's ``uint8 structure_needs_at_least_one_member``;
2. every field becomes ``{name, type: {type_id, capacity, string_capacity,
   nested_type_name}}`` with the ids of ``type_description_interfaces/msg/FieldType``
   (array +48, bounded sequence +96, unbounded sequence +144);
3. the description is ``{type_description: {type_name, fields},
   referenced_type_descriptions: [...sorted by type name]}`` over every type reached
   (rosidl_generator_type_description ``extract_full_type_description``), serialised
   with ``json.dumps(separators=(', ', ': '))`` and hashed with SHA-256
   (``calculate_type_hash``).

Tested against the generated ``.json`` of every message type installed here.
"""
from __future__ import annotations

import hashlib
import json
from typing import Callable

from .typenames import SEPARATOR, normalize_type, split_type

#: .msg primitive -> FieldType id of the IDL type it maps to (rosidl_adapter MSG_TYPE_TO_IDL,
#: then type_description_interfaces/msg/FieldType.msg).
_PRIMITIVE_IDS = {
    'bool': 15, 'byte': 16, 'char': 3, 'float32': 10, 'float64': 11, 'int8': 2, 'uint8': 3,
    'int16': 4, 'uint16': 5, 'int32': 6, 'uint32': 7, 'int64': 8, 'uint64': 9,
    'string': 17, 'wstring': 18,
}
_NESTED = 1
_BOUNDED_STRING, _BOUNDED_WSTRING = 21, 22
_ARRAY, _BOUNDED_SEQ, _UNBOUNDED_SEQ = 48, 96, 144
EMPTY_MEMBER = 'structure_needs_at_least_one_member'


def _field_type(type_string: str, package: str) -> dict:
    """FieldType dict of one .msg field type (``float64[3]``, ``string<=8``, ``pkg/T[]``...)."""
    capacity = 0
    suffix = 0
    if type_string.endswith(']'):
        i = type_string.rindex('[')
        size = type_string[i + 1:-1]
        type_string = type_string[:i]
        if size == '':
            suffix = _UNBOUNDED_SEQ
        elif size.startswith('<='):
            suffix, capacity = _BOUNDED_SEQ, int(size[2:])
        else:
            suffix, capacity = _ARRAY, int(size)
    string_capacity = 0
    nested = ''
    if type_string in _PRIMITIVE_IDS:
        base = _PRIMITIVE_IDS[type_string]
    elif type_string.startswith(('string<=', 'wstring<=')):
        kind, bound = type_string.split('<=', 1)
        base = _BOUNDED_STRING if kind == 'string' else _BOUNDED_WSTRING
        string_capacity = int(bound)
    elif type_string in ('time', 'duration'):
        raise ValueError(f'the ROS 1 type {type_string!r} has no ROS 2 type description')
    else:
        pkg, typ = (type_string.split('/', 1) if '/' in type_string else (package, type_string))
        if '/' in typ or not pkg or not typ:
            raise ValueError(f'not a message type: {type_string!r}')
        base = _NESTED
        nested = f'{pkg}/msg/{typ}'
    return {'type_id': base + suffix, 'capacity': capacity, 'string_capacity': string_capacity,
            'nested_type_name': nested}


def individual_description(type_name: str, text: str) -> dict:
    """``{type_name, fields}`` of one message from its ``.msg`` text (no default values)."""
    pkg = split_type(type_name)[0]
    fields = []
    for raw in text.replace('\t', ' ').splitlines():
        line = raw.rstrip()
        if not line:
            continue
        hash_at = line.find('#')
        if hash_at >= 0:
            line = line[:hash_at].rstrip()
            if not line:
                continue
        type_string, _, rest = line.partition(' ')
        rest = rest.lstrip()
        if not rest:
            raise ValueError(f'{type_name}: cannot read the field line {raw!r}')
        if '=' in rest:
            continue  # a constant
        name = rest.partition(' ')[0]
        fields.append({'name': name, 'type': _field_type(type_string, pkg)})
    if not fields:
        fields.append({'name': EMPTY_MEMBER, 'type': _field_type('uint8', pkg)})
    return {'type_name': normalize_type(type_name), 'fields': fields}


def type_hash(type_name: str, text_of: Callable[[str], str]) -> str:
    """``RIHS01_...`` of ``type_name``; ``text_of(pkg/msg/Type)`` returns each ``.msg`` text.

    Raises
    ------
    KeyError, LookupError, ValueError
        When a referenced definition is missing or unreadable.
    """
    root = normalize_type(type_name)
    descs: dict[str, dict] = {}
    queue = [root]
    while queue:
        name = queue.pop()
        if name in descs:
            continue
        descs[name] = individual_description(name, text_of(name))
        queue += [f['type']['nested_type_name'] for f in descs[name]['fields']
                  if f['type']['nested_type_name']]
    full = {'type_description': descs[root],
            'referenced_type_descriptions': [descs[n] for n in sorted(descs) if n != root]}
    text = json.dumps(full, skipkeys=False, ensure_ascii=True, check_circular=True,
                      allow_nan=False, indent=None, separators=(', ', ': '), sort_keys=False)
    return 'RIHS01_' + hashlib.sha256(text.encode('utf-8')).hexdigest()


def split_schema(schema_text: str, type_name: str) -> dict[str, str]:
    """``ros2msg`` schema data -> {pkg/msg/Type: .msg text} (root first, then ``MSG:`` parts).

    Raises
    ------
    ValueError
        When a delimiter is not followed by a ``MSG: pkg/Type`` line.
    """
    parts = schema_text.split('\n' + SEPARATOR)
    out = {normalize_type(type_name): parts[0]}
    for part in parts[1:]:
        head, _, body = part.partition('\n')
        if not head.startswith('MSG: '):
            raise ValueError(f'a schema delimiter is not followed by "MSG: pkg/Type" ({head[:40]!r})')
        out[normalize_type(head[5:].strip())] = body
    return out


def schema_type_hash(schema_text: str, type_name: str) -> str:
    """RIHS01 hash of a type from its ``ros2msg`` schema text alone (a bag's own schema)."""
    texts = split_schema(schema_text, type_name)
    return type_hash(type_name, lambda n: texts[n])
