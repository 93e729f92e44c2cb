"""The node set's Fast DDS profile and the restart wait after a node process's death
(sslfr_bringup.dds_profile; the deafness it prevents: docs/deploy.md "Restart after a
hang")."""
from __future__ import annotations

import pytest

from sslfr_bringup import dds_profile, nodeset

HEAD = '<?xml version="1.0"?><profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">'


def _profile(tmp_path, body: str):
    p = tmp_path / 'p.xml'
    p.write_text(HEAD + body + '</profiles>')
    return p


def _lease(sec: str, nsec: str = '0', default: str = ' is_default_profile="true"') -> str:
    return (f'<participant profile_name="x"{default}><rtps><builtin><discovery_config>'
            f'<leaseDuration><sec>{sec}</sec><nanosec>{nsec}</nanosec></leaseDuration>'
            '</discovery_config></builtin></rtps></participant>')


def test_the_node_sets_profile_has_a_7_5_s_lease_and_an_8_5_s_restart_wait():
    path = nodeset.config_dir() / dds_profile.PROFILE_FILE
    assert dds_profile.participant_lease(path) == 7.5
    assert dds_profile.restart_wait({dds_profile.PROFILE_ENV: str(path)}) == 8.5


def test_lease_from_a_profile(tmp_path):
    assert dds_profile.participant_lease(_profile(tmp_path, _lease('2', '500000000'))) == 2.5
    # the only participant profile counts even when not marked default
    assert dds_profile.participant_lease(_profile(tmp_path, _lease('7', default=''))) == 7.0
    # no profile, no lease in it, no participant profile: Fast DDS's 20 s
    assert dds_profile.participant_lease(None) == dds_profile.FASTDDS_DEFAULT_LEASE == 20.0
    assert dds_profile.participant_lease(_profile(tmp_path, '<participant profile_name="x" '
                                                  'is_default_profile="true"/>')) == 20.0
    assert dds_profile.participant_lease(_profile(tmp_path, '')) == 20.0
    assert dds_profile.restart_wait({}) == 21.0


def test_bad_profiles_are_refused_clearly(tmp_path):
    with pytest.raises(dds_profile.ProfileError, match='cannot read'):
        dds_profile.participant_lease(tmp_path / 'missing.xml')
    with pytest.raises(dds_profile.ProfileError, match='cannot read'):
        dds_profile.participant_lease(_profile(tmp_path, '<participant'))
    with pytest.raises(dds_profile.ProfileError, match='not a number'):
        dds_profile.participant_lease(_profile(tmp_path, _lease('soon')))
    with pytest.raises(dds_profile.ProfileError, match='positive'):
        dds_profile.participant_lease(_profile(tmp_path, _lease('0')))
    inf = _profile(tmp_path, _lease('DURATION_INFINITY'))
    assert dds_profile.participant_lease(inf) == float('inf')
    with pytest.raises(dds_profile.ProfileError, match='infinite'):
        dds_profile.restart_wait({dds_profile.PROFILE_ENV: str(inf)})


def test_with_profile_keeps_the_operators_own(tmp_path):
    assert dds_profile.with_profile({}, tmp_path)[dds_profile.PROFILE_ENV] == str(tmp_path / dds_profile.PROFILE_FILE)
    env = {dds_profile.PROFILE_ENV: '/etc/mine.xml'}
    assert dds_profile.with_profile(env, tmp_path)[dds_profile.PROFILE_ENV] == '/etc/mine.xml'


def _graph_partitions(path) -> dict[str, list[str]]:
    import xml.etree.ElementTree as ET
    out = {}
    for e in ET.parse(path).getroot():
        if e.get('profile_name') == dds_profile.GRAPH_TOPIC:
            out[e.tag.rsplit('}', 1)[-1]] = [n.text for n in e.iter() if n.tag.endswith('}name')]
    return out


def test_graph_partition_profile_keeps_the_lease_and_replaces_an_older_partition(tmp_path):
    base = nodeset.config_dir() / dds_profile.PROFILE_FILE
    c1 = dds_profile.graph_partition_profile(base, 'c1', tmp_path / 'c1.xml')
    assert dds_profile.participant_lease(c1) == 7.5
    assert _graph_partitions(c1) == {'data_writer': ['c1'], 'data_reader': ['c1']}
    again = dds_profile.graph_partition_profile(c1, '*', tmp_path / 'all.xml')
    assert _graph_partitions(again) == {'data_writer': ['*'], 'data_reader': ['*']}
    bare = dds_profile.graph_partition_profile(None, 'c2', tmp_path / 'bare.xml')
    assert dds_profile.participant_lease(bare) == 20.0 and _graph_partitions(bare)['data_reader'] == ['c2']
    with pytest.raises(dds_profile.ProfileError, match='cannot read'):
        dds_profile.graph_partition_profile(tmp_path / 'missing.xml', 'c1', tmp_path / 'x.xml')


def test_only_a_namespaced_field_client_gets_its_graph_partition(tmp_path):
    ns = nodeset.load()
    field = {'ROS_DISCOVERY_SERVER': '10.0.0.2:11811;10.0.0.3:11811'}
    env = nodeset.ros_environment(ns, base=field, namespace='/c1', run_dir=tmp_path)
    assert env[dds_profile.PROFILE_ENV] == str(tmp_path / dds_profile.FIELD_PROFILE_FILE)
    assert _graph_partitions(env[dds_profile.PROFILE_ENV])['data_writer'] == ['c1']
    assert dds_profile.restart_wait(env) == 8.5                       # the node set's lease kept
    own = str(nodeset.config_dir() / dds_profile.PROFILE_FILE)
    for base, namespace in (({}, '/c1'), (field, ''), ({**field, 'ROS_SUPER_CLIENT': 'TRUE'}, '/c1')):
        assert nodeset.ros_environment(ns, base=base, namespace=namespace, run_dir=tmp_path)[
            dds_profile.PROFILE_ENV] == own, (base, namespace)
