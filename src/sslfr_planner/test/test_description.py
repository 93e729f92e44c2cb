"""Collector descriptions (docs/collectors.md): the shipped ones load and agree with the
seeds and the contract; every kind of broken description is refused naming file and key."""
import math
from pathlib import Path

import pytest
import yaml

from sslfr_common import contract
from sslfr_planner import description as d
from sslfr_planner.collector import FieldGeometry
from sslfr_planner.prototype import field_geometry, line_positions

DIR = Path(__file__).resolve().parents[2] / 'sslfr_bringup' / 'config' / 'collectors'
SEED000, SEED003, SEED004 = (DIR / f'{n}.yaml' for n in
                             ('almeria_three_movement', 'bucaramanga_single_axis', 'florianopolis_lepten'))


def test_every_shipped_description_loads():
    names = sorted(p.name for p in DIR.glob('*.yaml'))
    assert names == ['almeria_three_movement.yaml', 'bucaramanga_single_axis.yaml', 'florianopolis_lepten.yaml']
    for p in DIR.glob('*.yaml'):
        assert d.load(p).name == p.stem


def test_seed000_equals_the_contract_and_the_planner_defaults():
    desc = d.load(SEED000)
    assert desc.joints == contract.JOINTS
    for j in contract.JOINTS:
        m = desc.movement(j)
        assert m.range == pytest.approx(contract.JOINT_RANGE[j])
        assert m.stow == pytest.approx(contract.STOW_POSITION[j])
        assert m.step == pytest.approx(contract.STEP_ANGLE)
        for sw, angle in m.switches.items():
            assert contract.SWITCH_AXIS[sw] == j and angle == pytest.approx(contract.SWITCH_POSITION[sw])
    assert sorted(sw for j in contract.JOINTS for sw in desc.movement(j).switches) == sorted(contract.SWITCHES)
    g, ref = field_geometry(desc), FieldGeometry()
    for k in ('n_per_side', 'mirror_width', 'mirror_length', 'gap', 'tube_diameter', 'tube_left', 'tube_right',
              'central_mirror'):
        assert getattr(g, k) == pytest.approx(getattr(ref, k)), k
    assert g.receiver_height == pytest.approx(ref.receiver_height)       # f = 1.5 m (Table 3)
    assert desc.longitudinal_law == 'continuous'


def test_seed003_numbers():
    desc = d.load(SEED003)
    assert desc.joints == ('mirrors',) and desc.longitudinal_law == 'horizontal'
    m = desc.movement('mirrors')
    assert m.drive == 'stepper_no_switches' and m.reference is not None and not m.switches
    assert math.degrees(m.law_params['max_inclination']) == 72.0 and m.law_params['step_s'] == 900.0
    x = line_positions(desc)
    assert x.size == 10 and 0.0 not in x                               # 10 mirrors, no central one
    assert x == pytest.approx([-0.675, -0.525, -0.375, -0.225, -0.075, 0.075, 0.225, 0.375, 0.525, 0.675])
    # the drive range keeps the outer mirror (offset atan(0.675/0.75)/2) within 72 deg
    assert math.degrees(m.range[1]) + math.degrees(math.atan(0.675 / 0.75)) / 2 == pytest.approx(72.0, abs=0.01)
    o = desc.optics
    area = o.lines * o.line_width * o.line_length
    assert area == pytest.approx(1.0)                                   # seed 003 eq. 6: A_a = 1 m^2
    assert area / (o.tube_diameter * 2.03) == pytest.approx(18.8, abs=0.05)  # Table 5: concentration factor 18.8
    assert set(desc.boards) == {'mirrors', 'absorber', 'irradiance'} and desc.sensors['clock'].kind == 'rtc'


def test_seed004_numbers():
    desc = d.load(SEED004)
    m = desc.movement('mirrors')
    assert m.drive == 'linear_actuator_inclinometer' and m.feedback == 'inclinometer' and m.feedback_line == 2
    assert m.law_params['pace'] == 0.4962
    assert [round(math.degrees(b), 4) for b in m.law_params['offsets']] == [
        15.8311, 12.8113, 9.4542, 5.8066, 1.9593, -1.9594, -5.8066, -9.4543, -12.8113, -15.8312]   # Table 1
    o = desc.optics
    assert o.lines * o.line_width * o.line_length == pytest.approx(54.0)     # abstract: 54 m^2 of mirrors
    assert math.degrees(o.azimuth) == pytest.approx(4.6) and o.rotation_radius == 0.065
    assert o.line_width + o.gap == pytest.approx(0.5097, abs=1e-4)         # the pitch behind Table 1 (test_lepten)
    # the lever drive (assumed sizes): the stroke the +/-40 deg range needs, law of cosines
    geo = d.lever_geometry(m)
    assert geo.length(m.range[0]) == pytest.approx(0.32460, abs=1e-5)
    assert geo.length(m.range[1]) == pytest.approx(0.50954, abs=1e-5)
    assert m.actuator['max_speed'] == 0.005 and m.actuator['stall_window'] == 2.0
    assert math.degrees(m.inclinometer['noise']) == pytest.approx(0.01)


# ------------------------------------------------------------------ refusals
def _broken(tmp_path, edit):
    data = yaml.safe_load({4: SEED004, 3: SEED003, 0: SEED000}[edit[0]].read_text())
    edit[1](data)
    p = tmp_path / 'broken.yaml'
    p.write_text(yaml.safe_dump(data))
    with pytest.raises(d.DescriptionError) as exc:
        d.load(p)
    return str(exc.value), p


@pytest.mark.parametrize('seed, change, key, text', [
    (4, lambda x: x['movements']['mirrors'].update(drive='hydraulic_ram'), 'movements.mirrors.drive',
     'unknown drive kind'),
    (0, lambda x: x['movements'].pop('secondary_reflector'), 'movements.mobile_structure.law',
     'the continuous law needs the secondary_reflector movement, which this collector lacks'),
    (0, lambda x: x['movements'].pop('mobile_structure'), 'movements.secondary_reflector.law',
     'the continuous law needs the mobile_structure movement, which this collector lacks'),
    (0, lambda x: (x['movements'].pop('mobile_structure'), x['movements']['secondary_reflector'].update(law='eq16')),
     'movements.secondary_reflector.law', 'the eq16 law needs the mobile_structure movement'),
    (0, lambda x: x['movements']['secondary_reflector'].update(law='eq16'), 'movements.mobile_structure.law',
     "'continuous' differs from movements.secondary_reflector.law 'eq16': the two move together"),
    (0, lambda x: x['movements']['mobile_structure'].update(range_deg=[-120.0, 90.0]),
     'movements.mobile_structure.range_deg', 'outside the mechanics'),
    (0, lambda x: x['movements']['mirrors'].update(sleep_deg=120.0), 'movements.mirrors.sleep_deg',
     'outside range_deg'),
    (0, lambda x: x['boards'].append(dict(x['boards'][3])), 'boards[6].name', "duplicate name 'gps'"),
    (0, lambda x: x['sensors'].append(dict(x['sensors'][0])), 'sensors[9].name', "duplicate name 'inlet'"),
    (0, lambda x: x['optics'].update(lines='25'), 'optics.lines', 'must be an integer'),
    (0, lambda x: x['optics'].update(central_line='yes'), 'optics.central_line', 'must be true or false'),
    (0, lambda x: x['movements']['mirrors'].update(step_deg=[0.006]), 'movements.mirrors.step_deg',
     'must be a finite number'),
    (0, lambda x: x['movements']['mirrors'].update(stepsize_deg=0.006), 'movements.mirrors.stepsize_deg',
     'unknown key'),
    (0, lambda x: x.update(colour='blue'), 'colour', 'unknown key'),
    (0, lambda x: x['optics'].update(lines=24), 'optics.lines', 'must be odd'),
    (0, lambda x: x['movements']['mirrors'].update(law='continuous'), 'movements.mirrors.law',
     'not of mirrors'),
    (0, lambda x: x['movements']['mirrors'].update(feedback='inclinometer'), 'movements.mirrors.feedback',
     'not a position feedback'),
    (0, lambda x: x['movements'].update(turret=x['movements']['mirrors']), 'movements.turret', 'unknown movement'),
    (4, lambda x: x['movements']['mirrors']['law_params'].update(offsets_deg=[1.0, 2.0]),
     'movements.mirrors.law_params.offsets_deg', '2 offsets for 10 lines'),
    (4, lambda x: x['movements']['mirrors'].update(range_deg=[-30.0, 30.0], sleep_deg=30.0, stow_deg=30.0),
     'movements.mirrors.range_deg', 'outside the range'),
    (4, lambda x: x['movements']['mirrors'].update(step_deg=0.1), 'movements.mirrors.step_deg',
     'not a property of a linear_actuator_inclinometer drive'),
    (4, lambda x: x['sensors'][0].update(board='actuator'), 'sensors[0].board', 'not a board'),
    (4, lambda x: x['movements']['mirrors'].pop('actuator'), 'movements.mirrors.actuator',
     'a linear_actuator_inclinometer drive needs it'),
    (4, lambda x: x['movements']['mirrors']['actuator'].update(stroke_m=[0.35, 0.53]), 'movements.mirrors.actuator',
     'outside stroke_m [0.35, 0.53]'),
    (4, lambda x: x['movements']['mirrors']['actuator'].update(mount_angle_deg=30.0), 'movements.mirrors.actuator',
     'within (5, 175) deg'),
    (4, lambda x: x['movements']['mirrors']['actuator'].update(min_duty=1.0), 'movements.mirrors.actuator.min_duty',
     'must be in [0, 1)'),
    (4, lambda x: x['movements']['mirrors']['actuator'].update(move_timeout_s=1.0),
     'movements.mirrors.actuator.move_timeout_s', 'must exceed stall_window_s'),
    (4, lambda x: x['movements']['mirrors']['actuator'].pop('lever_m'), 'movements.mirrors.actuator.lever_m',
     'missing'),
    (4, lambda x: x['movements']['mirrors']['inclinometer'].update(noise_deg=0.03),
     'movements.mirrors.inclinometer.noise_deg', 'below half the deadband'),
    (3, lambda x: x['movements']['mirrors'].update(inclinometer={'offset_deg': 0.0, 'noise_deg': 0.0,
                                                                'resolution_deg': 0.0}),
     'movements.mirrors.inclinometer', 'not a property of a stepper_no_switches drive'),
])
def test_refused_naming_file_and_key(tmp_path, seed, change, key, text):
    msg, path = _broken(tmp_path, (seed, change))
    assert f'{path}: {key}: ' in msg and text in msg, msg


@pytest.mark.parametrize('law', ['eq16', 'optimum_fixed', 'daily'])
def test_rows_alone_tilt_under_a_law_of_the_mobile_structure(tmp_path, law):
    """Seed 000 without its secondary_reflector movement: eq16, optimum_fixed and daily set
    the rows' tilt alone (seed 001 eq. 3), the receiver stays fixed; continuous is refused above."""
    data = yaml.safe_load(SEED000.read_text())
    data['movements'].pop('secondary_reflector')
    data['movements']['mobile_structure']['law'] = law
    data['boards'] = [b for b in data['boards'] if b['name'] != 'secondary_reflector']
    data['sensors'] = [x for x in data['sensors'] if x['board'] != 'secondary_reflector']
    p = tmp_path / 'two.yaml'
    p.write_text(yaml.safe_dump(data))
    desc = d.load(p)
    assert desc.joints == ('mirrors', 'mobile_structure') and desc.longitudinal_law == law
    assert d.LAW_NEEDS[law] == ('mobile_structure',) and d.LAW_NEEDS['continuous'] == contract.LONGITUDINAL_JOINTS


def test_duplicate_yaml_keys_and_bad_files_refused(tmp_path):
    p = tmp_path / 'dup.yaml'
    p.write_text(SEED000.read_text().replace('  mobile_structure:', '  mirrors:', 1))
    with pytest.raises(d.DescriptionError, match=r"dup.yaml: duplicate key 'mirrors' at line \d+"):
        d.load(p)
    with pytest.raises(d.DescriptionError, match='cannot read'):
        d.load(tmp_path / 'missing.yaml')
    p.write_text('[1, 2')
    with pytest.raises(d.DescriptionError, match='dup.yaml'):
        d.load(p)


def test_every_problem_is_listed_at_once(tmp_path):
    data = yaml.safe_load(SEED000.read_text())
    data['movements']['mirrors']['drive'] = 'x'
    data['optics']['gap'] = -1.0
    data['boards'][0]['kind'] = 'robot'
    p = tmp_path / 'many.yaml'
    p.write_text(yaml.safe_dump(data))
    with pytest.raises(d.DescriptionError) as exc:
        d.load(p)
    assert len(exc.value.problems) >= 3


def test_any_document_is_refused_cleanly_or_accepted():
    """Whatever YAML arrives, parse() either accepts it or raises DescriptionError."""
    from hypothesis import given, settings
    from hypothesis import strategies as st
    base = yaml.safe_load(SEED004.read_text())
    leaf = st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=6)
    value = st.recursive(leaf, lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=6), c, max_size=3),
                         max_leaves=8)
    paths = st.sampled_from([('movements', 'mirrors'), ('movements', 'mirrors', 'law_params'), ('optics',),
                             ('boards',), ('sensors',), ('movements',), ()])

    @settings(max_examples=150, deadline=None)
    @given(path=paths, key=st.text(max_size=12) | st.sampled_from(['drive', 'law', 'range_deg', 'lines', 'pace',
                                                                  'offsets_deg', 'name', 'gap', 'mirrors']),
           v=value)
    def check(path, key, v):
        import copy
        doc = copy.deepcopy(base)
        node = doc
        for k in path:
            node = node[k]
        if isinstance(node, dict):
            node[key] = v
        else:
            node.append(v)
        try:
            d.parse(doc, 'fuzz.yaml')
        except d.DescriptionError as exc:
            assert all(p.startswith('fuzz.yaml: ') for p in exc.problems)
    check()
    for junk in (None, 3, 'text', [], [1, 2]):
        with pytest.raises(d.DescriptionError):
            d.parse(junk, 'junk.yaml')
