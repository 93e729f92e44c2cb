"""The node set follows the collector description (issue 34 item 2): which nodes and
boards each shipped collector gets, the role parameters from its movements, a site
config contradicting them refused, and a fourth collector from a description alone."""
import math

import pytest
import yaml
from collectors_testutil import write_fourth_collector
from sslfr_bringup import nodeset
from sslfr_bringup.collector_set import driver_parameters
from sslfr_common.tracking_loss import from_flat
from sslfr_planner.analysis.ideal import loss_table
from sslfr_planner.description import load
from sslfr_safety.params import TABLE as SAFETY_TABLE, config_from

CONFIGS = {
    'almeria_sslfr.yaml': (['mirrors', 'mobile_structure', 'secondary_reflector'], {'gps'}, 'axis'),
    'florianopolis_lepten.yaml': (['mirrors'], set(), 'actuator'),
    'bucaramanga_single_axis.yaml': (['mirrors'], set(), 'axis_noswitch'),
}


def _narrowed(config):
    path = nodeset.resolve_config(config)
    return nodeset.for_config(nodeset.load(), path), path


@pytest.mark.parametrize('config', sorted(CONFIGS))
def test_each_shipped_collector_gets_the_nodes_and_boards_it_describes(config):
    joints, extra_boards, mirrors_sim = CONFIGS[config]
    ns, path = _narrowed(config)
    desc = load(ns.collector)
    drivers = [n for n in ns.nodes if n.parameters.get('axis')]
    assert [n.parameters['axis'] for n in drivers] == joints == list(desc.joints)
    for n in drivers:
        assert n.parameters == {**n.parameters, **driver_parameters(desc.movement(n.parameters['axis']))}
        assert n.lifecycle and n.stop == 0
    boards = {n.board for n in ns.nodes if n.board}
    assert boards == set(joints) | {'absorber', 'irradiance'} | extra_boards == set(ns.boards)
    sim = ns.boards['mirrors'].sim_args
    assert sim[sim.index('--kind') + 1] == mirrors_sim
    start = [a for a in sim if a.startswith('initial_angle_deg=')]
    assert start == [f'initial_angle_deg={math.degrees(desc.movement("mirrors").sleep):.6g}']
    # safety watches what exists: the collector's drivers and boards, never another's
    present = ns.node('safety').parameters['collector.nodes']
    cfg = config_from({**SAFETY_TABLE.defaults(), 'collector.nodes': present})
    assert cfg.joints == tuple(joints)
    assert set(cfg.watchdogs) == set(present)
    nodeset.checked_params(ns, path)         # the shipped config agrees with its description
    # the mirrors' driver quotes the collector's own loss table at the config's site
    planner = nodeset.node_params(nodeset.read_params(path), 'planner')
    table = from_flat(ns.node('mirrors_driver').parameters['accuracy.loss_table'])
    assert table and table == loss_table(desc, planner['site.latitude_deg'], planner['site.longitude_deg'],
                                         planner.get('site.elevation', 0.0))
    assert all('accuracy.loss_table' not in n.parameters for n in drivers[1:])


def test_a_site_value_contradicting_the_description_is_refused(tmp_path):
    src = nodeset.resolve_config('florianopolis_lepten.yaml')
    doc = nodeset.read_params(src)
    doc['planner']['ros__parameters']['collector.description'] = str(
        (src.parent / 'collectors' / 'florianopolis_lepten.yaml').resolve())
    doc['mirrors_driver'] = {'ros__parameters': {'upper_limit': 1.2, 'max_speed': 0.03}}
    cfg = tmp_path / 'site.yaml'
    cfg.write_text(yaml.safe_dump(doc))
    ns = nodeset.for_config(nodeset.load(), cfg)
    problems = nodeset.check_config(ns, nodeset.read_params(cfg), where=str(cfg))
    assert len(problems) == 1 and 'mirrors_driver: upper_limit: 1.2 contradicts the collector description' in problems[0]


def test_an_invalid_description_stops_the_node_set_before_anything_starts(tmp_path):
    src = nodeset.resolve_config('bucaramanga_single_axis.yaml')
    desc = yaml.safe_load((src.parent / 'collectors' / 'bucaramanga_single_axis.yaml').read_text())
    desc['movements']['mirrors']['drive'] = 'hydraulic'
    (tmp_path / 'broken.yaml').write_text(yaml.safe_dump(desc))
    doc = nodeset.read_params(src)
    doc['planner']['ros__parameters']['collector.description'] = 'broken.yaml'
    (tmp_path / 'site.yaml').write_text(yaml.safe_dump(doc))
    with pytest.raises(nodeset.NodeSetError, match=r'movements\.mirrors\.drive'):
        nodeset.for_config(nodeset.load(), tmp_path / 'site.yaml')


def test_a_fourth_collector_needs_only_a_description(tmp_path):
    cfg = write_fourth_collector(tmp_path)
    ns = nodeset.for_config(nodeset.load(), cfg)
    assert [n.name for n in ns.nodes if n.parameters.get('axis')] == ['mirrors_driver', 'mobile_structure_driver']
    p = ns.node('mirrors_driver').parameters
    assert p['drive'] == 'stepper_no_switches' and p['upper_limit'] == pytest.approx(math.radians(60.0))
    assert p['step_angle'] == pytest.approx(math.radians(0.05)) and p['auto_home'] is False
    p = ns.node('mobile_structure_driver').parameters      # seed 000's stepper, open loop (feedback: steps)
    assert p['drive'] == 'stepper_switches' and p['lower_limit'] == pytest.approx(math.radians(-30.0))
    assert p['use_sensor'] is False and 'auto_home' not in p
    assert 'gps' not in {n.name for n in ns.nodes}
    watched = ns.node('safety').parameters['collector.nodes']
    assert 'mobile_structure_driver' in watched and 'secondary_reflector_driver' not in watched and 'gps' not in watched
    assert load(ns.collector).longitudinal_law == 'eq16'
    nodeset.checked_params(ns, cfg)
