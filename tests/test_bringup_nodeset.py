"""Bringup, pure parts: the node-set description, its loader, the launch file's
reading of it, `sslfr up --print`, the systemd unit."""
from __future__ import annotations

import importlib.util
import os
import py_compile
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import ROOT

sys.path.insert(0, str(ROOT / 'src/sslfr_bringup'))
from sslfr_bringup import dds_profile, nodeset, service, up  # noqa: E402

LAUNCH = ROOT / 'src/sslfr_bringup/launch/tracker.launch.py'
AXES = ('mirrors_driver', 'mobile_structure_driver', 'secondary_reflector_driver')


@pytest.fixture
def site(tmp_path):
    p = tmp_path / 'site.yaml'
    p.write_text(yaml.safe_dump({
        '/**': {'ros__parameters': {'site': {'latitude_deg': 36.835, 'longitude_deg': -2.402, 'elevation': 22.0}}},
        'gps': {'ros__parameters': {'port': '/dev/ttyAMA0', 'baudrate': 9600}},
        'planner': {'ros__parameters': {'collector': {'law': 'continuous'}}},
    }))
    return p


def test_default_node_set_is_the_tracker():
    ns = nodeset.load()
    names = [n.name for n in ns.nodes]
    assert sorted(names) == sorted(['gps', 'planner', *AXES, 'absorber_board', 'irradiance', 'safety', 'recorder', 'web'])
    assert [n.name for n in ns.lifecycle_nodes()] == list(AXES)
    assert {n.parameters['axis'] for n in ns.lifecycle_nodes()} == {'mirrors', 'mobile_structure', 'secondary_reflector'}
    groups = ns.stop_groups()
    assert [n.name for n in groups[0]] == list(AXES), 'axes are stopped first'
    assert [n.name for n in groups[-1]] == ['recorder'], 'the recorder records the stop'
    order = [n.name for n in ns.start_order()]
    assert order[0] == 'recorder' and order.index('safety') < order.index('mirrors_driver')
    assert ns.node('safety').critical
    assert 0 < ns.domain_id and ns.discovery_range == 'LOCALHOST'
    full = nodeset.for_config(ns, nodeset.resolve_config(ns.config))    # seed 000's collector: every node
    assert [n.name for n in full.nodes] == [n.name for n in ns.nodes]
    for node in full.nodes:
        if node.board:
            board = full.boards[node.board]
            assert board.device.startswith('/dev/sslfr/') and board.sim_executable


def test_every_node_class_builds_its_entities_without_qos_event_handlers():
    """Issue 16: rclpy's default QoS-event handlers (two per publisher/subscription) were
    most of the executor's work at every wake-up; every node class of the set drops them."""
    from sslfr_bringup.composed import node_class
    from sslfr_common.node import LeanEvents
    classes = {n.component for n in nodeset.load().nodes}
    assert len(classes) >= 8
    for component in classes:
        assert issubclass(node_class(component), LeanEvents), component


def test_overrides_port_precedence_sim_time_and_args(site):
    ns = nodeset.load()
    params = nodeset.read_params(site)
    assert 'port' not in nodeset.node_overrides(ns, ns.node('gps'), params), 'the site config sets the gps port'
    m = nodeset.node_overrides(ns, ns.node('mirrors_driver'), params, use_sim_time=True,
                               extra={'max_speed': 2.0, 'axis': 'mirrors'})
    assert m == {'axis': 'mirrors', 'port': '/dev/sslfr/mirrors', 'use_sim_time': True, 'max_speed': 2.0}
    sim = nodeset.node_overrides(ns, ns.node('gps'), params, sim_ports={'gps': '/tmp/x/gps.pty'})
    assert sim == {'port': '/tmp/x/gps.pty'}, 'in simulation the pty always wins'
    doc = nodeset.overrides_document(ns, ns.node('mirrors_driver'), m, namespace='/sslfr1')
    assert doc == {'/sslfr1/mirrors_driver': {'ros__parameters': m}}
    assert list(nodeset.overrides_document(ns, ns.node('planner'), {'a': 1})) == ['/planner']
    args = nodeset.ros_args(ns, ns.node('mirrors_driver'), site, overrides_file='/r/m.yaml', namespace='/sslfr1')
    assert args == ['--ros-args', '-r', '__node:=mirrors_driver', '-r', '__ns:=/sslfr1',
                    '--params-file', str(site), '--params-file', '/r/m.yaml',
                    '-r', '/rosout:=/sslfr1/rosout'], 'overrides file after the config; log lines in the namespace'
    root = nodeset.ros_args(ns, ns.node('mirrors_driver'), site)
    assert not any('rosout' in a for a in root), 'the root namespace logs to /rosout'


def test_overrides_file_beats_the_config_node_section_in_a_real_node(launch, ros, tmp_path):
    """Why overrides go in a node-specific params file: rclpy treats `-p` as `/**`,
    which the config's node section overrides; a later file naming the node wins."""
    from rcl_interfaces.srv import GetParameters
    site = tmp_path / 'site.yaml'
    site.write_text('recorder:\n  ros__parameters:\n    output_dir: /tmp/from_config\n'
                    '    max_file_size: 1000000\n')
    over = tmp_path / 'over.yaml'
    over.write_text('/recorder:\n  ros__parameters:\n    output_dir: %s\n' % (tmp_path / 'bags'))
    proc = launch('sslfr_recording', 'recorder', ros_args=['--params-file', str(site), '--params-file', str(over)])
    res = ros.call(GetParameters, 'recorder/get_parameters',
                   GetParameters.Request(names=['output_dir', 'max_file_size']), timeout=20)
    assert res.values[0].string_value == str(tmp_path / 'bags'), proc.output()
    assert res.values[1].integer_value == 1000000


def test_node_params_overlays_wildcard_and_node_section(site):
    params = nodeset.read_params(site)
    gps = nodeset.node_params(params, 'gps')
    assert gps['site.latitude_deg'] == 36.835 and gps['port'] == '/dev/ttyAMA0'
    assert 'port' not in nodeset.node_params(params, 'planner')


@pytest.mark.parametrize('doc,needle', [
    ({'nodes': []}, 'no nodes'),
    ({'nodes': [{'name': 'a', 'package': 'p'}]}, 'missing executable'),
    ({'nodes': [{'name': 'a', 'package': 'p', 'executable': 'e', 'board': 'nope'}]}, 'unknown board'),
    ({'nodes': [{'name': 'a', 'package': 'p', 'executable': 'e'}] * 2}, 'duplicate'),
    ({'defaults': {'domain_id': 0}, 'nodes': [{'name': 'a', 'package': 'p', 'executable': 'e'}]}, 'domain_id'),
    ([1, 2], 'mapping'),
])
def test_invalid_node_sets_are_refused_with_the_reason(doc, needle):
    with pytest.raises(nodeset.NodeSetError, match=needle):
        nodeset.parse(doc)


def test_bad_params_file_refused(tmp_path):
    p = tmp_path / 'bad.yaml'
    p.write_text('planner: {foo: 1}\n')
    with pytest.raises(nodeset.NodeSetError, match='ros__parameters'):
        nodeset.read_params(p)
    p.write_text('a: [\n')
    with pytest.raises(nodeset.NodeSetError, match='invalid YAML'):
        nodeset.read_params(p)
    with pytest.raises(nodeset.NodeSetError, match='not found'):
        nodeset.resolve_config('no_such_site')


def _launch_module():
    py_compile.compile(str(LAUNCH), doraise=True)
    spec = importlib.util.spec_from_file_location('tracker_launch', LAUNCH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)   # must not import `launch` at module level (not installable here)
    return mod


def test_launch_file_compiles_and_reads_the_description(site, tmp_path):
    mod = _launch_module()
    entries = mod._entries(str(site), '/sslfr1', str(tmp_path))
    assert [e['name'] for e in entries] == [n.name for n in nodeset.load().start_order()]
    by = {e['name']: e for e in entries}
    moved = str(tmp_path / 'site.params.yaml')      # the site config, moved under /sslfr1
    assert by['mirrors_driver']['lifecycle'] and not by['planner']['lifecycle']
    from sslfr_bringup.collector_set import driver_parameters, loss_table_param
    from sslfr_planner.description import load
    desc = load(nodeset.config_dir() / nodeset.load().collector)
    table = loss_table_param(desc, nodeset.node_params(nodeset.read_params(site), 'planner'))
    assert len(table) > 3                           # the collector's own loss table at the site
    assert by['mirrors_driver']['parameters'] == [moved, {**driver_parameters(desc.movement('mirrors')),
                                                          'accuracy.loss_table': table, 'port': '/dev/sslfr/mirrors'}]
    assert by['gps']['parameters'] == [moved]      # its port comes from the config's gps section
    assert all(e['namespace'] == '/sslfr1' for e in entries)
    assert all(('/rosout', '/sslfr1/rosout') in e['remappings'] for e in entries)
    # the node sections reach the namespaced nodes (rcl: a bare `planner:` is the root's only)
    doc = nodeset.read_params(moved)
    assert nodeset.node_params(doc, 'planner', '/sslfr1')['collector.law'] == 'continuous'
    assert nodeset.node_params(doc, 'gps', '/sslfr1')['port'] == '/dev/ttyAMA0'
    assert nodeset.node_params(doc, 'gps', '/sslfr1')['site.latitude_deg'] == 36.835
    root = {e['name']: e for e in mod._entries(str(site), '', None, True)}
    assert root['gps']['parameters'] == [str(site), {'use_sim_time': True}]
    with pytest.raises(ImportError):
        mod.generate_launch_description()   # needs ROS launch (on the Pi)
    # a site config a node would refuse starts nothing: the launch file judges it as
    # `sslfr up` does (the nodes' own parameter tables), naming the key
    bad = tmp_path / 'bad.yaml'
    bad.write_text('planner:\n  ros__parameters:\n    horizonn: 60.0\n'
                   'safety:\n  ros__parameters:\n    publish_rate: "fast"\n')
    with pytest.raises(nodeset.NodeSetError) as err:
        mod._entries(str(bad), '', None)
    assert 'horizonn' in str(err.value) and 'publish_rate' in str(err.value), err.value


def test_launch_environment_defaults_env_and_arguments(monkeypatch, tmp_path):
    mod = _launch_module()
    monkeypatch.delenv('ROS_DOMAIN_ID', raising=False)
    monkeypatch.delenv('ROS_AUTOMATIC_DISCOVERY_RANGE', raising=False)
    monkeypatch.delenv(dds_profile.PROFILE_ENV, raising=False)
    ns = nodeset.load()
    profile = str(nodeset.config_dir() / dds_profile.PROFILE_FILE)
    assert mod._environment('', '') == {'ROS_DOMAIN_ID': str(ns.domain_id),
                                         'ROS_AUTOMATIC_DISCOVERY_RANGE': ns.discovery_range,
                                         dds_profile.PROFILE_ENV: profile}
    # a node process is respawned after its DDS lease (7.5 s) + 1 s, not the 2 s of old
    assert mod._respawn_delay(mod._environment('', '')) == 8.5
    monkeypatch.setenv('ROS_DOMAIN_ID', '7')
    assert mod._environment('', '')['ROS_DOMAIN_ID'] == '7'
    assert mod._environment('9', 'SUBNET') == {'ROS_DOMAIN_ID': '9', 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET',
                                               dds_profile.PROFILE_ENV: profile}
    # a collector of a field (namespace:= and the station's servers): its graph partition, the
    # profile written to the launch's run directory, the lease kept
    monkeypatch.setenv('ROS_DISCOVERY_SERVER', '10.0.0.2:11811;10.0.0.3:11811')
    field = mod._environment('', '', '/c1', str(tmp_path))
    assert field[dds_profile.PROFILE_ENV] == str(tmp_path / dds_profile.FIELD_PROFILE_FILE)
    assert mod._respawn_delay(field) == 8.5
    assert '<name>c1</name>' in (tmp_path / dds_profile.FIELD_PROFILE_FILE).read_text()
    assert mod._environment('', '', '', str(tmp_path))[dds_profile.PROFILE_ENV] == profile


PARAMS_KEYS = {          # every key form rcl knows, one parameter each
    '/**': 'a', 'planner': 'b', '/planner': 'c', '/sslfr1/planner': 'd', '/**/planner': 'e',
    'sslfr1/planner': 'f', '/*/planner': 'g', '/sslfr1/*': 'h', '/a/**/planner': 'i',
}


@pytest.mark.parametrize('namespace', ['', '/sslfr1', '/a/b', '/a/b/c'])
def test_node_params_matches_rclpy_for_every_key_form(namespace, tmp_path, ros_domain):
    """nodeset.node_params must give exactly what rclpy gives a node from the same file."""
    import rclpy
    from rclpy.node import Node
    path = tmp_path / 'p.yaml'
    path.write_text(yaml.safe_dump({k: {'ros__parameters': {v: 1, 'order': v}}
                                    for k, v in PARAMS_KEYS.items()}, sort_keys=False))
    args = ['x', '--ros-args', '--params-file', str(path)] + (['-r', f'__ns:={namespace}'] if namespace else [])
    ctx = rclpy.Context()
    rclpy.init(context=ctx, args=args, domain_id=ros_domain)
    try:
        node = Node('planner', context=ctx, allow_undeclared_parameters=True,
                    automatically_declare_parameters_from_overrides=True)
        real = {k: v.value for k, v in node.get_parameters_by_prefix('').items()
                if k not in ('use_sim_time', 'start_type_description_service')}
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    assert nodeset.node_params(nodeset.read_params(path), 'planner', namespace) == real


def test_sim_board_argv_fills_placeholders():
    board = nodeset.BoardSpec('mirrors', '/dev/sslfr/mirrors', 'sslfr_drivers', 'sim_axis_board',
                              ('--axis', '{axis}', '--link', '{pty}'))
    assert nodeset.sim_board_argv(board, '/x/sim', {'axis': 'mirrors', 'pty': '/r/m.pty'}) == \
        ['/x/sim', '--axis', 'mirrors', '--link', '/r/m.pty']
    with pytest.raises(nodeset.NodeSetError, match='placeholder'):
        nodeset.sim_board_argv(board, '/x/sim', {'axis': 'mirrors'})


def test_build_programs_reports_missing_executables_and_never_fakes_them(site, tmp_path):
    ns = nodeset.load()
    fake_bin = tmp_path / 'bin'
    fake_bin.mkdir()

    def finder(pkg, exe):   # only the planner "is installed"
        return Path('/opt/x/planner') if exe == 'planner' else None
    programs, missing = up.build_programs(ns, site, finder=finder, run_dir=tmp_path / 'run')
    assert [p.name for p in programs] == ['planner']
    assert len(missing) == len(ns.nodes) - 1 and any('mirrors_driver (sslfr_drivers/axis_driver)' in m for m in missing)


def test_environment_defaults_non_zero_domain_and_localhost():
    ns = nodeset.load()
    env = nodeset.ros_environment(ns, base={})
    assert env['ROS_DOMAIN_ID'] == str(ns.domain_id) != '0'
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert nodeset.ros_environment(ns, base={'ROS_DOMAIN_ID': '7'})['ROS_DOMAIN_ID'] == '7'
    assert nodeset.ros_environment(ns, base={'ROS_DOMAIN_ID': '7'}, domain_id=9)['ROS_DOMAIN_ID'] == '9'
    # the node set's Fast DDS profile (a 7.5 s participant lease), unless one is named
    assert env[dds_profile.PROFILE_ENV] == str(nodeset.config_dir() / dds_profile.PROFILE_FILE)
    assert dds_profile.participant_lease(env[dds_profile.PROFILE_ENV]) == 7.5
    own = nodeset.ros_environment(ns, base={dds_profile.PROFILE_ENV: '/etc/my_fastdds.xml'})
    assert own[dds_profile.PROFILE_ENV] == '/etc/my_fastdds.xml'


def test_systemd_unit(tmp_path):
    text = service.render_unit(root=Path('/home/pi/sslfr'), config='/home/pi/sslfr/site.yaml', user='pi',
                               domain_id=42, discovery_range='LOCALHOST')
    assert 'ExecStart=/home/pi/sslfr/sslfr up --config /home/pi/sslfr/site.yaml' in text
    for line in ('Restart=on-failure', 'KillMode=mixed', 'SupplementaryGroups=dialout', 'User=pi',
                 'Environment=ROS_DOMAIN_ID=42', 'Environment=ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST',
                 'StandardOutput=journal', 'WantedBy=multi-user.target'):
        assert line in text.splitlines(), line
    open_text = service.render_unit(root=Path('/r'), config='c', user='u', domain_id=7,
                                    discovery_range='SUBNET', peers='192.168.1.20')
    assert 'Environment=ROS_STATIC_PEERS=192.168.1.20' in open_text


def test_systemd_unit_runs_the_chosen_layout():
    text = service.render_unit(root=Path('/r'), config='c', user='u', domain_id=7, discovery_range='LOCALHOST',
                               layout='composed')
    assert 'ExecStart=/r/sslfr up --config c --layout composed' in text.splitlines()


def test_install_service_dry_run_prints_and_writes_unit(tmp_path, site):
    env = dict(os.environ)
    out = subprocess.run([str(ROOT / 'sslfr'), 'install-service', '--dry-run', '--user', 'pi', '--config', str(site)],
                         capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode == 0, out.stderr
    assert '[Service]' in out.stdout and 'User=pi' in out.stdout and f'--config {site}' in out.stdout
    bad = subprocess.run([str(ROOT / 'sslfr'), 'install-service', '--dry-run', '--config', 'no_such_site'],
                         capture_output=True, text=True, timeout=60, env=env)
    assert bad.returncode == 2 and 'not found' in bad.stderr
    res = subprocess.run([str(ROOT / 'sslfr'), 'install-service', '--unit-dir', str(tmp_path), '--no-enable',
                          '--config', str(site)],
                         capture_output=True, text=True, timeout=60, env=env)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / service.UNIT_NAME).read_text().startswith('# sslfr-tracker.service')


# ------------------------------------------------------------- site configs checked
BAD_CONFIGS = {   # config text -> words the one refusal line must hold
    '/**:\n  ros__parameters:\n    site:\n      latitude_deg: north\n': ['planner', 'site.latitude_deg', "'north'"],
    '/**:\n  ros__parameters:\n    site:\n      latitude_deg: 95.0\n': ['site.latitude_deg', '95.0', '[-90.0, 90.0]'],
    '/**:\n  ros__parameters:\n    site:\n      latitude_deg: .nan\n': ['site.latitude_deg', 'not a finite'],
    'planner:\n  ros__parameters:\n    horizon: abc\n': ['horizon', "'abc'"],
    'planner:\n  ros__parameters:\n    horizon: -5.0\n': ['horizon', '-5.0'],
    'planner:\n  ros__parameters:\n    horizonn: 60.0\n': ['horizonn', 'did you mean horizon'],
    'planer:\n  ros__parameters:\n    horizon: 60.0\n': ['planer', 'applies to no node', 'did you mean planner'],
    'planner:\n  ros__parameters:\n    collector:\n      n_per_side: 12.5\n': ['collector.n_per_side', '12.5'],
    'safety:\n  ros__parameters:\n    publish_rate: 5\n': ['safety', 'publish_rate', 'write 5.0'],
    'safety:\n  ros__parameters:\n    temperature:\n      limit: hot\n': ['temperature.limit', "'hot'"],
    'irradiance:\n  ros__parameters:\n    luminous_efficacy: 1000.0\n': ['luminous_efficacy', '[50.0, 250.0]'],
    'mirrors_driver:\n  ros__parameters:\n    lower_limit: 1.6\n': ['mirrors_driver', 'lower_limit'],
    'recorder:\n  ros__parameters:\n    compression: gzip\n': ['recorder', 'compression', 'zstd'],
    'web:\n  ros__parameters:\n    port: 99999\n': ['web', 'port'],
    'planner:\n  ros__parameters: [1, 2]\n': ['ros__parameters must be a mapping'],
    'planner: 3\n': ['no ros__parameters'],
    '[1, 2]\n': ['mapping of node names'],
    'a: [\n': ['invalid YAML', 'line'],
}


@pytest.mark.parametrize('shipped', sorted(p.name for p in nodeset.config_dir().glob('*.yaml')
                                           if p.name != nodeset.NODESET_FILE))
def test_shipped_site_configs_pass_the_nodes_tables(shipped):
    ns = nodeset.load()
    path = nodeset.config_dir() / shipped          # where: also the base of its collector description
    assert nodeset.check_config(ns, nodeset.read_params(path), where=str(path)) == []


@pytest.mark.parametrize('text', list(BAD_CONFIGS), ids=range(len(BAD_CONFIGS)))
def test_bad_site_configs_are_refused_naming_the_key(text, tmp_path):
    path = tmp_path / 'site.yaml'
    path.write_text(text)
    ns = nodeset.load()
    try:
        problems = nodeset.check_config(ns, nodeset.read_params(path), where=str(path))
    except nodeset.NodeSetError as exc:
        problems = [str(exc)]
    assert problems, text
    joined = '\n'.join(problems)
    for word in BAD_CONFIGS[text]:
        assert word in joined, (word, joined)


@pytest.mark.parametrize('cmd', [['up'], ['sim', '--no-report'], ['doctor']])
def test_up_sim_doctor_refuse_a_bad_config_and_start_nothing(cmd, tmp_path, ros_env):
    path = tmp_path / 'site.yaml'
    path.write_text('planner:\n  ros__parameters:\n    horizonn: 60.0\n    horizon: -5.0\n')
    args = [str(ROOT / 'sslfr'), *cmd, '--config', str(path)] + (['--out', str(tmp_path / 'o')] if 'sim' in cmd else [])
    out = subprocess.run(args, env=ros_env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stdout + out.stderr
    assert 'horizonn' in out.stderr and 'did you mean horizon' in out.stderr and 'horizon: -5.0' in out.stderr
    assert 'Traceback' not in out.stderr
    assert not any(line.startswith('started ') for line in out.stderr.splitlines()), out.stderr


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.one_of(st.binary(max_size=300), st.text(max_size=300).map(str.encode),
                      st.recursive(st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=8),
                                   lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=8), c, max_size=3),
                                   max_leaves=12).map(lambda v: yaml.safe_dump(v).encode())))
def test_config_loader_never_raises_anything_but_a_refusal(data, tmp_path):
    path = tmp_path / 'random.yaml'
    path.write_bytes(data)
    ns = nodeset.load()
    try:
        nodeset.check_config(ns, nodeset.read_params(path))
    except nodeset.NodeSetError:
        pass


# ------------------------------------------------------------------ layouts (issue 16)
def test_layouts_compose_hardware_and_keep_safety_alone():
    ns = nodeset.load()
    assert ns.layout in ns.layouts and {'composed', 'separate'} <= set(ns.layouts)
    sep = ns.processes('separate')
    assert [p.name for p in sep] == [n.name for n in ns.start_order()] and not any(p.composed for p in sep)
    comp = {p.name: [n.name for n in p.nodes] for p in ns.processes('composed')}
    assert comp['safety'] == ['safety'] and comp['operations'] == ['planner', 'web', 'recorder']
    assert comp['hardware'][:3] == list(AXES), 'the drivers stop their motors first'
    assert {'gps', 'absorber_board', 'irradiance'} <= set(comp['hardware'])
    assert sorted(n for names in comp.values() for n in names) == sorted(n.name for n in ns.nodes)
    for p in ns.processes('composed'):
        assert not p.composed or not any(n.critical for n in p.nodes)
    # a selection keeps the groups' remaining nodes together; one left runs alone
    sel = {p.name: [n.name for n in p.nodes] for p in ns.only(['safety', 'gps', *AXES]).processes('composed')}
    assert sel == {'safety': ['safety'], 'hardware': [*AXES, 'gps']}
    assert [p.name for p in ns.only(['gps', 'planner']).processes('composed')] == ['gps', 'planner']
    with pytest.raises(KeyError, match='known: separate, composed'):
        ns.processes('clustered')


def _doc(layouts, **defaults):
    nodes = [{'name': 'a', 'package': 'p', 'executable': 'e', 'component': 'm:A'},
             {'name': 'b', 'package': 'p', 'executable': 'e', 'component': 'm:B'},
             {'name': 's', 'package': 'p', 'executable': 'e', 'component': 'm:S', 'critical': True},
             {'name': 'x', 'package': 'p', 'executable': 'e'}]
    return {'defaults': defaults, 'nodes': nodes, 'layouts': layouts}


@pytest.mark.parametrize('doc,needle', [
    (_doc({'c': {'g': ['a', 's']}}), 's is critical and must run in its own process'),
    (_doc({'c': {'g': ['a', 'zz']}}), "unknown node 'zz'"),
    (_doc({'c': {'g': ['a', 'b'], 'h': ['b']}}), "node 'b' is in two processes"),
    (_doc({'c': {'g': ['a', 'x']}}), 'x has no component'),
    (_doc({'c': {'a': ['b', 'x']}}), 'not named after a node'),
    (_doc({'c': ['a']}), 'mapping of process names'),
    (_doc({}, layout='c'), "defaults.layout 'c': no such layout"),
])
def test_invalid_layouts_are_refused_with_the_reason(doc, needle):
    with pytest.raises(nodeset.NodeSetError, match=needle):
        nodeset.parse(doc)


def test_composed_programs_and_launch_entries_give_each_node_its_own_arguments(site, tmp_path):
    ns = nodeset.load()
    programs, missing = up.build_programs(ns, site, finder=lambda pkg, exe: Path(f'/opt/{pkg}/{exe}'),
                                          run_dir=tmp_path / 'run', layout='composed')
    assert not missing
    by = {p.name: p for p in programs}
    hw = by['hardware']
    assert hw.argv[0] == '/opt/sslfr_bringup/composed' and hw.argv[1:3] == ['--process', 'hardware']
    assert hw.stop == 0 and not hw.critical and hw.lifecycle and hw.lifecycle_nodes == AXES
    assert hw.node_names[:3] == AXES and by['safety'].node_names == ('safety',) and by['safety'].critical
    from sslfr_bringup.composed import split_nodes
    name, specs = split_nodes(hw.argv[1:])
    assert name == 'hardware' and [c for c, _ in specs][:3] == ['sslfr_drivers.axis.axis_driver_node:AxisDriver'] * 3
    for node, (component, args) in zip(hw.node_names, specs):
        assert args[:3] == ['--ros-args', '-r', f'__node:={node}'] and str(site) in args
        if node != 'gps':                               # the site config gives the gps its port
            own = args[args.index(str(site)) + 2]       # its overrides file, after the site config
            assert list(yaml.safe_load(Path(own).read_text())) == [f'/{node}']
    assert yaml.safe_load(Path(specs[0][1][-1]).read_text())['/mirrors_driver']['ros__parameters'] == \
        {'axis': 'mirrors', 'port': '/dev/sslfr/mirrors'}
    (tmp_path / 'l').mkdir()
    entries = nodeset.launch_entries(ns, site, write_dir=tmp_path / 'l', layout='composed')
    e = {x['process']: x for x in entries}
    assert e['hardware']['executable'] == 'composed' and e['hardware']['name'] is None
    assert split_nodes(e['hardware']['arguments'])[0] == 'hardware' and e['safety']['name'] == 'safety'
    with pytest.raises(nodeset.NodeSetError, match='composed layout needs write_dir'):
        nodeset.launch_entries(ns, site, layout='composed')


@pytest.mark.parametrize('argv,needle', [
    ([], 'usage'), (['--process', 'g'], 'needs module:Class'), (['--process', 'g', 'x'], 'expected --node'),
    (['--process', 'g', '--node', '--ros-args'], 'module:Class'),
])
def test_composed_command_line_refused_with_the_reason(argv, needle):
    from sslfr_bringup.composed import split_nodes
    with pytest.raises(ValueError, match=needle):
        split_nodes(argv)


def test_composed_nodes_each_get_their_own_name_and_parameters(launch, ros, tmp_path):
    """Two recorders in one composed process: each its own name, params files and
    parameters (cli_args, use_global_arguments=False), as in their own processes."""
    from rcl_interfaces.srv import GetParameters
    site = tmp_path / 'site.yaml'
    site.write_text('/**:\n  ros__parameters:\n    max_file_size: 1000000\n')
    args = []
    for name in ('rec_a', 'rec_b'):
        own = tmp_path / f'{name}.yaml'
        own.write_text(f'/{name}:\n  ros__parameters:\n    output_dir: {tmp_path / name}\n')
        args += ['--node', 'sslfr_recording.recorder_node:Recorder', '--ros-args', '-r', f'__node:={name}',
                 '--params-file', str(site), '--params-file', str(own)]
    proc = launch('sslfr_bringup', 'composed', '--process', 'two', *args)
    for name in ('rec_a', 'rec_b'):
        res = ros.call(GetParameters, f'{name}/get_parameters',
                       GetParameters.Request(names=['output_dir', 'max_file_size']), timeout=20)
        assert res is not None, proc.output()
        assert res.values[0].string_value == str(tmp_path / name), proc.output()
        assert res.values[1].integer_value == 1000000
