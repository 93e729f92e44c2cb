"""YAML as rosbag2 Jazzy writes and reads it (yaml-cpp 0.8), in pure Python.

Two halves:

- :func:`dump` emits block YAML the way yaml-cpp's emitter lays out rosbag2's
  metadata (2-space indentation, sequences indented under their key, ``[]`` for an
  empty sequence, ``~`` for null, ``""`` for an empty string). Strings are written
  plain only when every YAML reader reads them back as the same string; anything
  else is double-quoted (yaml-cpp's ``as<std::string>`` ignores quoting, so quoting
  never changes what rosbag2 reads).
- :class:`Node` wraps a PyYAML node tree (``yaml.compose``: no tag resolution, as
  yaml-cpp) and converts scalars with yaml-cpp's rules (``convert.h``: integers read
  by ``operator>>`` with the base auto-detected and nothing left over, unsigned
  types refuse a leading ``-``; ``convert.cpp``: booleans y/yes/true/on and
  n/no/false/off in flexible case; ``impl.h``: a null node reads as the string
  ``"null"``). A failed conversion raises :class:`Refused` with the key path and
  the 1-based line, as yaml-cpp's ``TypedBadConversion``/``InvalidNode`` would.
"""
from __future__ import annotations

import json
import re

import yaml

_PLAIN = re.compile(r'[A-Za-z_/][A-Za-z0-9_./-]*\Z')


def _scalar(value) -> str:
    if value is None:
        return '~'
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        raise TypeError('rosbag2 metadata holds no floating-point values')
    text = str(value)
    if _PLAIN.match(text):
        try:
            if yaml.safe_load(text) == text:
                return text
        except yaml.YAMLError:
            pass
    return json.dumps(text, ensure_ascii=True)


def _block(value, indent: int) -> list[str]:
    pad = ' ' * indent
    lines: list[str] = []
    if isinstance(value, dict):
        for key, item in value.items():
            if isinstance(item, (dict, list)) and item:
                lines.append(f'{pad}{_scalar(key)}:')
                lines += _block(item, indent + 2)
            else:
                lines.append(f'{pad}{_scalar(key)}: {_inline(item)}')
    else:
        for item in value:
            if isinstance(item, (dict, list)) and item:
                sub = _block(item, indent + 2)
                sub[0] = pad + '- ' + sub[0][indent + 2:]
                lines += sub
            else:
                lines.append(f'{pad}- {_inline(item)}')
    return lines


def _inline(value) -> str:
    if isinstance(value, dict):
        return '{}'
    if isinstance(value, list):
        return '[]'
    return _scalar(value)


def dump(value) -> str:
    """Block YAML of nested dicts/lists/str/int/bool/None, laid out as yaml-cpp does.

    The text has no trailing newline (``YAML::Dump``); files add one.
    """
    if isinstance(value, (dict, list)) and value:
        return '\n'.join(_block(value, 0))
    return _inline(value)


# -- reading -------------------------------------------------------------------------------
class Refused(ValueError):
    """rosbag2 would throw on this YAML: ``key`` path, ``line`` (1-based, 0 unknown), why.

    ``rule`` is the id of the rule in :mod:`sslfr_recording.bag.rules` that was broken.
    """

    def __init__(self, rule: str, key: str, line: int, message: str):
        self.rule, self.key, self.line, self.message = rule, key, line, message
        where = f'line {line}: ' if line else ''
        super().__init__(f'{where}{key}: {message}')


_NULL_TAG = 'tag:yaml.org,2002:null'
_TRUE = ('y', 'yes', 'true', 'on')
_FALSE = ('n', 'no', 'false', 'off')


def _flexible_case(text: str) -> bool:
    if not text or text.islower():
        return True
    rest = text[1:]
    return text[0].isupper() and (not rest or rest.islower() or rest.isupper())


def _stream_int(text: str, signed: bool, bits: int):
    """``std::stringstream >> T`` with ``unsetf(dec)`` (base auto-detected), else None."""
    if not signed and text.startswith('-'):
        return None
    m = re.fullmatch(r'([+-]?)(0[xX][0-9a-fA-F]+|0[0-7]*|[1-9][0-9]*)\s*', text)
    if not m:
        return None
    digits = m.group(2)
    if digits[:2] in ('0x', '0X'):
        value = int(digits, 16)
    elif digits.startswith('0') and len(digits) > 1:
        value = int(digits, 8)
    else:
        value = int(digits)
    if m.group(1) == '-':
        value = -value
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    return value if lo <= value <= hi else None


class Node:
    """A yaml-cpp-like view of one node: ``kind`` is map, seq, scalar, null or undefined."""

    def __init__(self, node, path: str, rule: str = ''):
        self._node = node
        self.path = path
        self.rule = rule

    @classmethod
    def load(cls, text: str, path: str = '', rule: str = 'yaml') -> Node:
        """Parse YAML text (one document) like ``YAML::Load``; syntax errors -> Refused."""
        try:
            node = yaml.compose(text, Loader=yaml.SafeLoader)
        except yaml.YAMLError as exc:
            mark = getattr(exc, 'problem_mark', None)
            line = mark.line + 1 if mark is not None else 0
            problem = getattr(exc, 'problem', None) or str(exc).splitlines()[0]
            raise Refused(rule, path or 'document', line, f'not valid YAML ({problem})') from None
        return cls(node, path, rule)

    @property
    def line(self) -> int:
        return self._node.start_mark.line + 1 if self._node is not None else 0

    @property
    def kind(self) -> str:
        n = self._node
        if n is None:
            return 'undefined'
        if isinstance(n, yaml.MappingNode):
            return 'map'
        if isinstance(n, yaml.SequenceNode):
            return 'seq'
        if n.tag == _NULL_TAG and n.style is None:
            return 'null'
        return 'scalar'

    def refuse(self, message: str, rule: str | None = None) -> Refused:
        return Refused(rule or self.rule, self.path or 'document', self.line, message)

    def with_rule(self, rule: str) -> Node:
        """The same node, reporting refusals under another rule id."""
        return Node(self._node, self.path, rule)

    def has(self, key: str) -> bool:
        return self.get(key).kind != 'undefined'

    def get(self, key: str, rule: str | None = None) -> Node:
        """``node[key]`` on a const node: undefined when absent or when this is not a map."""
        sub = f'{self.path}.{key}' if self.path else key
        if isinstance(self._node, yaml.MappingNode):
            for k, v in self._node.value:
                if isinstance(k, yaml.ScalarNode) and k.value == key:
                    return Node(v, sub, rule or self.rule)
        out = Node(None, sub, rule or self.rule)
        out._parent_line = self.line
        return out

    def items(self) -> list[tuple[Node, Node]]:
        """Key/value nodes of a map (empty for null, as yaml-cpp iterates a null node)."""
        if isinstance(self._node, yaml.MappingNode):
            return [(Node(k, f'{self.path}.<key>', self.rule), Node(v, f'{self.path}.{getattr(k, "value", "?")}', self.rule))
                    for k, v in self._node.value]
        return []

    def elements(self) -> list[Node]:
        """Items of a sequence."""
        if isinstance(self._node, yaml.SequenceNode):
            return [Node(v, f'{self.path}[{i}]', self.rule) for i, v in enumerate(self._node.value)]
        return []

    def _need_defined(self) -> None:
        if self._node is None:
            line = getattr(self, '_parent_line', 0)
            raise Refused(self.rule, self.path, line, 'required key is missing')

    def as_str(self) -> str:
        """``as<std::string>()``: any scalar; null reads as ``"null"``."""
        self._need_defined()
        kind = self.kind
        if kind == 'null':
            return 'null'
        if kind != 'scalar':
            raise self.refuse(f'must be a string, found a YAML {kind}')
        return self._node.value

    def _as_int(self, signed: bool, bits: int, what: str) -> int:
        self._need_defined()
        if self.kind != 'scalar':
            raise self.refuse(f'must be {what}, found a YAML {self.kind}')
        value = _stream_int(self._node.value, signed, bits)
        if value is None:
            raise self.refuse(f'must be {what}, found {self._node.value!r}')
        return value

    def as_int(self) -> int:
        """``as<int>()`` (32-bit signed)."""
        return self._as_int(True, 32, 'an integer')

    def as_int32(self) -> int:
        return self._as_int(True, 32, 'an integer')

    def as_uint32(self) -> int:
        return self._as_int(False, 32, 'an unsigned integer')

    def as_uint64(self) -> int:
        """``as<uint64_t>()``."""
        return self._as_int(False, 64, 'an unsigned integer')

    def is_int(self) -> bool:
        """``convert<int>::decode`` succeeds (used by rosbag2's v8/v9 QoS auto-detection)."""
        return self.kind == 'scalar' and _stream_int(self._node.value, True, 32) is not None

    def as_bool(self) -> bool:
        """``as<bool>()``: y/yes/true/on, n/no/false/off in flexible case."""
        self._need_defined()
        if self.kind != 'scalar':
            raise self.refuse(f'must be a boolean, found a YAML {self.kind}')
        text = self._node.value
        if _flexible_case(text):
            low = text.lower()
            if low in _TRUE:
                return True
            if low in _FALSE:
                return False
        raise self.refuse(f'must be a boolean (true/false), found {text!r}')
