"""The field description: loader and validator (pure), every problem named by file and key."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from sslfr_field import field as F

EXAMPLE = Path(__file__).resolve().parents[2] / 'sslfr_bringup' / 'config' / 'fields' / 'example_field.yaml'
CONFIGS = EXAMPLE.parent.parent


def write(tmp_path, doc) -> Path:
    p = tmp_path / 'field.yaml'
    p.write_text(yaml.safe_dump(doc))
    return p


def good(tmp_path, n=2) -> dict:
    return F.simulated(n, CONFIGS / 'almeria_sslfr.yaml')


def test_example_field_loads_and_passes_the_site_config_check():
    from sslfr_bringup import nodeset
    ns = nodeset.load()
    f = F.load(EXAMPLE, check_config=lambda cfg, nsp: nodeset.check_config(
        ns, nodeset.read_params(cfg), nsp, where=str(cfg)))
    assert f.ids == ('c1', 'c2', 'lepten')
    assert f.namespaces == ('/c1', '/c2', '/lepten')
    assert f.collector('lepten').config.name == 'florianopolis_lepten.yaml'
    assert F.discovery_servers(f.station) == '192.168.10.2:11811;192.168.10.3:11811'


def test_simulated_field_is_valid(tmp_path):
    f = F.parse(good(tmp_path, 4), tmp_path / 'f.yaml')
    assert f.ids == ('c1', 'c2', 'c3', 'c4')
    assert F.discovery_servers(f.station) == '127.0.0.1:11811;127.0.0.1:11812'


def problems(tmp_path, doc, **kw) -> list[str]:
    with pytest.raises(F.FieldError) as exc:
        F.load(write(tmp_path, doc), **kw)
    for p in exc.value.problems:
        assert p.startswith(str(tmp_path / 'field.yaml') + ': ')
    return exc.value.problems


def test_duplicate_ids_namespaces_and_bad_values_are_all_named(tmp_path):
    doc = good(tmp_path, 3)
    cols = doc['field']['collectors']
    cols[1]['id'] = 'c1'
    cols[1]['namespace'] = '/x/c1'
    cols[2]['namespace'] = '/c3/'          # trailing slash dropped: still /c3
    cols[2]['address'] = 'pi3.local'
    doc['field']['station']['discovery_port'] = 70000
    doc['field']['station']['address'] = '10.0.0.300'
    out = problems(tmp_path, doc)
    text = '\n'.join(out)
    assert "field.collectors[1].id: 'c1' is already the id of field.collectors[0]" in text
    assert 'field.collectors[2].address' in text and 'not an IP address literal' in text
    assert 'field.station.discovery_port: must be a port number 1..65535, got 70000' in text
    assert 'field.station.address' in text
    assert len(out) == 4


def test_namespace_rules(tmp_path):
    doc = good(tmp_path, 3)
    cols = doc['field']['collectors']
    cols[0]['namespace'] = '/c1//bad'
    cols[1]['namespace'] = '/row/c1x'      # last name must be the id
    cols[2]['namespace'] = 'c3'            # relative
    text = '\n'.join(problems(tmp_path, doc))
    assert 'field.collectors[0].namespace' in text
    assert "field.collectors[1].namespace: '/row/c1x': its last name must be the collector id 'c2'" in text
    assert 'field.collectors[2].namespace' in text


def test_duplicate_namespace(tmp_path):
    doc = good(tmp_path, 2)
    doc['field']['collectors'][1]['id'] = 'c1b'
    doc['field']['collectors'][1]['namespace'] = '/c1b'
    doc['field']['collectors'][0]['namespace'] = '/a/c1'
    doc['field']['collectors'].append({'id': 'c1', 'namespace': '/a/c1', 'address': '127.0.0.1',
                                       'config': doc['field']['collectors'][0]['config']})
    text = '\n'.join(problems(tmp_path, doc))
    assert 'field.collectors[2].id' in text and 'field.collectors[2].namespace' in text


def test_missing_config_and_the_site_config_check_are_reported(tmp_path):
    doc = good(tmp_path, 2)
    doc['field']['collectors'][0]['config'] = 'nowhere.yaml'
    seen = []
    text = '\n'.join(problems(tmp_path, doc, check_config=lambda cfg, nsp: seen.append(nsp) or ['planner: bad']))
    assert "field.collectors[0].config: 'nowhere.yaml': no such file" in text
    assert 'field.collectors[1].config: planner: bad' in text
    assert seen == ['/c2']


def test_backup_must_differ_and_unknown_keys(tmp_path):
    doc = good(tmp_path, 1)
    doc['field']['station']['backup_port'] = doc['field']['station']['discovery_port']
    doc['field']['station']['colour'] = 'red'
    doc['field']['collectors'][0]['site'] = 'x'
    text = '\n'.join(problems(tmp_path, doc))
    assert 'field.station.backup_port: the backup server needs its own address or port' in text
    assert 'field.station.colour: unknown key' in text
    assert 'field.collectors[0].site: unknown key' in text


@pytest.mark.parametrize('doc', [None, [], {'field': 3}, {'field': {}}, 'text',
                                 {'field': {'id': 'x', 'station': [], 'collectors': [3]}}])
def test_any_document_is_refused_with_named_problems(tmp_path, doc):
    assert problems(tmp_path, doc)


def test_unreadable_and_not_yaml(tmp_path):
    with pytest.raises(F.FieldError, match='cannot read'):
        F.load(tmp_path / 'missing.yaml')
    p = tmp_path / 'bad.yaml'
    p.write_text('field: [\n')
    with pytest.raises(F.FieldError, match='not YAML'):
        F.load(p)


def test_ipv6_discovery_string():
    st = F.Station('fd00::2', 11811, '127.0.0.1', 11812, 8090)
    assert F.discovery_servers(st) == '[fd00::2]:11811;127.0.0.1:11812'
