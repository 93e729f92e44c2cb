"""The topic table of the contract is the only place a topic or service name is
written: product code takes names and QoS from it, and docs/architecture.md's tables
say the same."""
import ast
import re
from pathlib import Path

import pytest

from sslfr_common import contract as c

HERE = Path(__file__).resolve()
SRC = next(p for p in HERE.parents if p.name == 'src')
ROOT = SRC.parent


def _family(name: str) -> str:
    """'axes/{axis}/status' -> 'axes/{}/status' (the shape an f-string has)."""
    return re.sub(r'\{\w*\}', '{}', name)


NAMES = set(c.topic_names()) | {s.of(a) if '{' in s.name else s.name for s in c.SERVICES for a in c.JOINTS}
FAMILIES = {_family(e.name) for e in (*c.TOPICS, *c.SERVICES) if '{' in e.name}


def _literal(node: ast.AST) -> str | None:
    """A string constant or an f-string's shape ('axes/{}/status'), else None."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return ''.join(v.value if isinstance(v, ast.Constant) else '{}' for v in node.values)
    return None


def spelled_names(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, text) of each string that is a topic or service name, a family of them,
    or a joint name."""
    found = []
    inner = {id(v) for n in ast.walk(tree) if isinstance(n, ast.JoinedStr) for v in n.values}
    for n in ast.walk(tree):
        if id(n) in inner:
            continue
        text = _literal(n)
        if text is None:
            continue
        bare = text[1:] if text.startswith('/') and text != c.CLOCK.name else text
        if bare in NAMES or _family(bare) in FAMILIES or text in c.JOINTS:
            found.append((n.lineno, n.col_offset, text))
    return [(line, text) for line, _, text in sorted(found)]


def product_modules():
    for path in sorted(SRC.glob('*/*/**/*.py')):
        rel = path.relative_to(SRC)
        if 'test' in rel.parts[1:2] or (path.name == 'contract.py' and path.parent.name == 'sslfr_common'):
            continue
        yield path


def test_no_topic_service_or_joint_name_spelled_outside_the_contract():
    offenders = [f'{p.relative_to(SRC)}:{line}: {text!r} (take it from sslfr_common.contract)'
                 for p in product_modules() for line, text in spelled_names(ast.parse(p.read_text(), str(p)))]
    assert not offenders, '\n'.join(offenders)


def test_the_scan_finds_each_kind():
    sample = '''
a = node.create_publisher(T, 'safety/state', 10)
b = reader.decoded(['/tracker/phase'])
d = f'axes/{axis}/status'
e = f'/axes/{axis}/jog'
f = 'planner/set_mode'
g = '/clock'
h = {'secondary_reflector': 1}
fine = f'safety/state silent for {age:.2f} s'
'''
    found = [text for _, text in spelled_names(ast.parse(sample))]
    assert found == ['safety/state', '/tracker/phase', 'axes/{}/status', '/axes/{}/jog', 'planner/set_mode',
                     '/clock', 'secondary_reflector']


# ----------------------------------------------------------------- the table itself
def test_table_is_consistent():
    names = [t.name for t in c.TOPICS] + [s.name for s in c.SERVICES]
    assert len(set(names)) == len(names)
    for e in (*c.TOPICS, *c.SERVICES):
        assert re.fullmatch(r'/?[a-z_]+(/[a-z_{}]+)*', e.name), e.name
        assert re.fullmatch(r'[a-z_]+/(msg|srv)/[A-Za-z]+', e.type), e.type
    assert {t.name for t in c.TOPICS if t.latched} == {'tracker/phase', 'tracker/trajectory'}
    assert c.AXIS_STATUS.of('mirrors') == 'axes/mirrors/status'
    assert c.ABSORBER_TEMPERATURE.of('inlet') == 'absorber/inlet_temperature'
    with pytest.raises(ValueError):
        c.GPS_FIX.of('x')


def test_every_type_exists_and_qos_profiles_are_the_documented_ones():
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sslfr_common.node import message_class, qos
    for e in (*c.TOPICS, *c.SERVICES):
        message_class(e.type)
    assert qos(c.GPS_FIX) == QoSProfile(depth=10)                      # what depth 10 means in rclpy
    be, tl1 = qos(c.Qos.BE), qos(c.TRACKER_PHASE)
    assert (be.reliability, be.durability, be.depth) == (ReliabilityPolicy.BEST_EFFORT,
                                                         DurabilityPolicy.VOLATILE, 10)
    assert (tl1.reliability, tl1.durability, tl1.depth) == (ReliabilityPolicy.RELIABLE,
                                                            DurabilityPolicy.TRANSIENT_LOCAL, 1)
    assert qos(c.TRACKER_TRAJECTORY) is tl1                               # built once


# ----------------------------------------------------------------- the document
def _doc_table(heading: str) -> list[list[str]]:
    text = (ROOT / 'docs' / 'architecture.md').read_text()
    section = text.split(f'\n## {heading}\n', 1)[1].split('\n#', 1)[0]
    rows = [line for line in section.splitlines() if line.startswith('| `')]
    return [[cell.strip() for cell in row.strip('|').split('|')] for row in rows]


def _doc_name(cell: str) -> str:
    return re.sub(r'<(\w+)>', r'{\1}', cell.strip('`'))


def _short(type_name: str) -> str:
    pkg, _, name = type_name.split('/')
    return f'{pkg}/{name}'


def test_the_documented_topic_table_is_the_contract():
    doc = {}
    for name, typ, _publisher, qos_, *_ in _doc_table('Topics'):
        for member in ([_doc_name(name).replace('{axis}', a) for a in c.JOINTS] if '<' in name
                       else [_doc_name(name)]):
            doc[member] = (typ, qos_)
    contract = {n: (_short(t.type), t.qos.value) for n, t in c.topic_names().items()}
    assert doc == contract


def test_the_documented_service_table_is_the_contract():
    doc = {_doc_name(name): typ for name, typ, *_ in _doc_table('Services')}
    assert doc == {s.name: _short(s.type) for s in c.SERVICES}
