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
