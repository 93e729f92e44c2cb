"""The graph contract's facts are defined once (sslfr_common.contract) and agree with
the messages; no other product module defines them again."""
import ast
import math
from pathlib import Path

import pytest

from sslfr_common import contract as c

SRC = Path(__file__).resolve().parents[2]           # src/
CONTRACT = SRC / 'sslfr_common' / 'sslfr_common' / 'contract.py'


def test_codes_equal_the_message_constants():
    from sslfr_interfaces.msg import AxisStatus, LimitSwitches, SafetyState, TrackerPhase
    for p in c.Phase:
        assert getattr(TrackerPhase, p.name) == p.value
    for d in c.DayType:
        assert getattr(TrackerPhase, d.name) == d.value
    for lv in c.Level:
        assert getattr(SafetyState, lv.name) == lv.value
    for ls in c.LinkState:
        assert getattr(AxisStatus, ls.name) == ls.value
    # the switch table names exactly the booleans of LimitSwitches, in order
    fields = [f for f in LimitSwitches.get_fields_and_field_types() if f != 'header' and not f.endswith('_changed')]
    assert list(c.SWITCHES) == fields
    # every constant of the messages is in the contract
    def constants(msg):
        return {k for k in dir(msg) if k.isupper() and not k.startswith('_') and k != 'SLOT_TYPES'
                and isinstance(getattr(msg, k), int)}
    assert constants(TrackerPhase) == {p.name for p in c.Phase} | {d.name for d in c.DayType}
    assert constants(SafetyState) == {lv.name for lv in c.Level}
    assert constants(AxisStatus) == {ls.name for ls in c.LinkState}


def test_facts_are_consistent():
    assert set(c.JOINT_RANGE) == set(c.STOW_POSITION) == set(c.JOINTS)
    for j in c.JOINTS:
        lo, hi = c.JOINT_RANGE[j]
        assert lo < hi and lo <= c.STOW_POSITION[j] <= hi
    assert set(c.SWITCH_AXIS.values()) == set(c.JOINTS)
    for sw, joint in c.SWITCH_AXIS.items():
        lo, hi = c.JOINT_RANGE[joint]
        assert lo <= c.SWITCH_POSITION[sw] <= hi
    assert c.STEP_ANGLE == pytest.approx(math.radians(0.006))
    assert c.PHASE_NAMES[2] == 'TRACKING' and c.driver_node('mirrors') == 'mirrors_driver'


# ----------------------------------------------------------------- "defined once"
JOINT_SET = set(c.JOINTS)
SWITCH_SET = set(c.SWITCHES)
PHASE_SET = {p.name for p in c.Phase}
LEVEL_SET = {lv.name for lv in c.Level}


def _strings(nodes):
    return {n.value for n in nodes if isinstance(n, ast.Constant) and isinstance(n.value, str)}


def _redefinitions(tree: ast.AST) -> list[tuple[int, str]]:
    found = []
    for n in ast.walk(tree):
        if isinstance(n, (ast.Tuple, ast.List, ast.Set)) and len(n.elts) >= 3 \
                and JOINT_SET <= _strings(n.elts):
            found.append((n.lineno, 'the joint names'))
        elif isinstance(n, (ast.Tuple, ast.List, ast.Set)) and SWITCH_SET <= _strings(n.elts):
            found.append((n.lineno, 'the switch names'))
        elif isinstance(n, ast.Dict):
            keys = _strings(k for k in n.keys if k is not None)
            vals = _strings(n.values)
            if JOINT_SET <= keys:
                found.append((n.lineno, 'a per-joint table'))
            if SWITCH_SET <= keys:
                found.append((n.lineno, 'the switch table'))
            if {'NIGHT', 'TRACKING', 'STOWING'} <= vals:
                found.append((n.lineno, 'the phase names'))
            if {'OK', 'WARN', 'ESTOP'} <= vals:
                found.append((n.lineno, 'the safety level names'))
        elif isinstance(n, ast.Call) and getattr(n.func, 'attr', getattr(n.func, 'id', '')) in ('radians', 'deg2rad') \
                and n.args and isinstance(n.args[0], ast.Constant) and n.args[0].value == 0.006:
            found.append((n.lineno, 'the step angle'))
        elif isinstance(n, ast.ClassDef):
            attrs = {t.id for s in n.body if isinstance(s, ast.Assign) for t in s.targets if isinstance(t, ast.Name)}
            if LEVEL_SET <= attrs:
                found.append((n.lineno, 'the safety levels'))
            if {'NIGHT', 'PRE_DAWN', 'TRACKING'} <= attrs:
                found.append((n.lineno, 'the phase codes'))
        elif isinstance(n, ast.Assign):
            names = {t.id for t in n.targets if isinstance(t, ast.Name)}
            names |= {e.id for t in n.targets if isinstance(t, ast.Tuple) for e in t.elts if isinstance(e, ast.Name)}
            if {'NIGHT', 'TRACKING'} <= names or {'OK', 'ESTOP'} <= names:
                found.append((n.lineno, 'codes as module constants'))
    return found


def product_modules():
    for path in sorted(SRC.glob('*/*/**/*.py')):
        rel = path.relative_to(SRC)
        if rel.parts[1] == 'test' or path == CONTRACT or 'launch' in rel.parts:
            continue
        yield path


def test_no_product_module_defines_a_contract_fact_again():
    offenders = []
    for path in product_modules():
        for line, what in _redefinitions(ast.parse(path.read_text(), str(path))):
            offenders.append(f'{path.relative_to(SRC)}:{line}: defines {what} (use sslfr_common.contract)')
    assert not offenders, '\n'.join(offenders)


def test_the_detector_finds_each_kind():
    sample = '''
AXES = ('mirrors', 'mobile_structure', 'secondary_reflector')
LIM = {'mirrors': 1, 'mobile_structure': 2, 'secondary_reflector': 3}
SW = {'initial': 'a', 'last': 'a', 'sleeping': 'a', 'longitudinal_1': 'b', 'longitudinal_2': 'c'}
SWN = ('initial', 'last', 'sleeping', 'longitudinal_1', 'longitudinal_2')
LV = {0: 'OK', 1: 'WARN', 3: 'ESTOP'}
NAMES = {0: 'NIGHT', 2: 'TRACKING', 3: 'STOWING'}
STEP = math.radians(0.006)
class Level:
    OK = 0; WARN = 1; STOW = 2; ESTOP = 3
NIGHT, PRE_DAWN, TRACKING = range(3)
'''
    kinds = {what for _, what in _redefinitions(ast.parse(sample))}
    assert kinds == {'the joint names', 'a per-joint table', 'the switch table', 'the phase names',
                     'the switch names', 'the safety level names',
                     'the step angle', 'the safety levels', 'codes as module constants'}
