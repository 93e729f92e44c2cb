"""The station's processes (sslfr_field.station) and the field report's sums (pure parts)."""
from __future__ import annotations

import math
from pathlib import Path

from sslfr_field import field as F
from sslfr_field import report, station

CONFIGS = Path(__file__).resolve().parents[2] / 'sslfr_bringup' / 'config'


def field(tmp_path, backup='127.0.0.1'):
    doc = F.simulated(2, CONFIGS / 'almeria_sslfr.yaml', address='192.168.10.2')
    doc['field']['station']['backup_address'] = backup
    return F.parse(doc, tmp_path / 'f.yaml')


def finder(installed):
    return lambda pkg, exe: f'/opt/{pkg}/{exe}' if (pkg, exe) in installed else None


def test_discovery_servers_here(tmp_path):
    f = field(tmp_path, backup='192.168.10.3')
    assert station.servers_here(f, 'auto', here={'127.0.0.1'}) == [(0, '192.168.10.2', 11811)]
    assert station.servers_here(f, 'auto', here={'192.168.10.3'}) == [(0, '192.168.10.2', 11811),
                                                                       (1, '192.168.10.3', 11812)]
    assert station.servers_here(f, 'backup') == [(1, '192.168.10.3', 11812)]
    f2 = field(tmp_path, backup='127.0.0.1')
    assert len(station.servers_here(f2, 'auto', here=set())) == 2       # a loopback backup runs here
    # a backup at the primary's address runs beside it, whatever the host name resolves to
    f3 = field(tmp_path, backup='192.168.10.2')
    assert station.servers_here(f3, 'auto', here={'127.0.0.1'}) == [(0, '192.168.10.2', 11811),
                                                                     (1, '192.168.10.2', 11812)]


def test_local_addresses_hold_every_interfaces_address():
    import psutil
    import socket
    here = station.local_addresses()
    ifaces = {a.address.split('%')[0] for addrs in psutil.net_if_addrs().values() for a in addrs
              if a.family in (socket.AF_INET, socket.AF_INET6)}
    assert ifaces and ifaces <= here and '127.0.0.1' in here


def test_programs_name_what_is_missing_and_pass_the_field(tmp_path):
    f = field(tmp_path)
    progs, missing = station.programs(f, role='both', run_dir=tmp_path, out_dir=tmp_path / 'out',
                                      finder=finder({('sslfr_field', 'field_page'), ('sslfr_recording', 'recorder')}))
    names = [p.name for p in progs]
    assert names[:2] == ['discovery_server_0', 'discovery_server_1'] or any('fast-discovery-server' in m for m in missing)
    assert 'field_page' in names and 'field_recorder' in names and 'modbus_gateway' not in names
    assert any('sslfr_gateway/modbus_gateway is not installed' in m for m in missing)
    page = next(p for p in progs if p.name == 'field_page')
    assert "collectors:=['/c1','/c2']" in page.argv and "collector_ids:=['c1','c2']" in page.argv
    rec = (tmp_path / 'field_recorder.params.yaml').read_text()
    assert '/c2/safety/state' in rec and '/diagnostics' in rec and 'prefix: sim_field' in rec
    progs, missing = station.programs(f, role='both', run_dir=tmp_path, out_dir=None,
                                      finder=finder({('sslfr_gateway', 'modbus_gateway'), ('sslfr_field', 'field_page')}),
                                      params={'modbus_gateway': {'port': 0}, 'field_page': {'open_view': 'false'}})
    gw = next(p for p in progs if p.name == 'modbus_gateway')
    assert "collectors:=['/c1','/c2']" in gw.argv and "collector_ids:=['c1','c2']" in gw.argv
    assert 'bind_address:=192.168.10.2' in gw.argv and 'port:=0' in gw.argv
    assert 'open_view:=false' in next(p for p in progs if p.name == 'field_page').argv


def test_environments(tmp_path):
    f = field(tmp_path)
    base = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_SUPER_CLIENT': 'TRUE', 'ROS_DOMAIN_ID': '7'}
    st = station.station_environment(f, base)
    assert st['ROS_DISCOVERY_SERVER'] == '192.168.10.2:11811;127.0.0.1:11812' and st['ROS_SUPER_CLIENT'] == 'TRUE'
    assert 'ROS_AUTOMATIC_DISCOVERY_RANGE' not in st and st['ROS_DOMAIN_ID'] == '7'
    col = station.collector_environment(f, base)
    assert 'ROS_SUPER_CLIENT' not in col and col['ROS_DISCOVERY_SERVER'] == st['ROS_DISCOVERY_SERVER']


def test_field_report_sums():
    nan = float('nan')
    rows = {'c1': {'tracking_h': 8.0, 'safety_stows': 1, 'commanded_stows': 0, 'max_temperature_degC': 120.0,
                   'beam_kwh_m2': 7.0, 'achieved_kwh': 10.0, 'ideal_kwh': 11.0, 'note': ''},
            'c2': {'tracking_h': 7.5, 'safety_stows': 0, 'commanded_stows': 2, 'max_temperature_degC': 151.0,
                   'beam_kwh_m2': 7.0, 'achieved_kwh': 9.0, 'ideal_kwh': 10.5, 'note': ''},
            'c3': {'tracking_h': 0.0, 'safety_stows': 0, 'commanded_stows': 0, 'max_temperature_degC': nan,
                   'beam_kwh_m2': nan, 'achieved_kwh': nan, 'ideal_kwh': nan, 'note': 'no beam'}}
    t = report.totals(rows)
    assert t['achieved_kwh'] == 19.0 and t['ideal_kwh'] == 21.5 and t['tracking_h'] == 15.5
    assert t['safety_stows'] == 1 and t['commanded_stows'] == 2 and t['max_temperature_degC'] == 151.0
    assert t['without_energy'] == ['c3']
    text = report.render(rows, t)
    assert 'c3' in text and '19.000' in text and 'not in the field' in text
    assert math.isnan(report.totals({'c3': rows['c3']})['achieved_kwh'])
    assert report.collector_of(Path('/x/c2_2026-06-21')) == 'c2'


def test_a_collector_node_set_under_its_namespace(tmp_path):
    """`sslfr up --namespace /c2`: the bag is named after the collector and the
    absolute /diagnostics is not recorded there; a discovery server replaces the range."""
    import yaml

    from sslfr_bringup import nodeset
    from sslfr_bringup.up import build_programs
    from sslfr_common.contract import collector_id
    ns = nodeset.load()
    progs, _ = build_programs(ns, CONFIGS / 'almeria_sslfr.yaml', namespace='/c2', run_dir=tmp_path,
                              finder=lambda pkg, exe: f'/x/{exe}')
    assert progs
    rec = yaml.safe_load((tmp_path / 'recorder.params.yaml').read_text())
    values = next(iter(rec.values()))['ros__parameters']
    assert values['prefix'] == 'c2' and '/diagnostics' in values['exclude'] and '/clock' in values['exclude']
    env = nodeset.ros_environment(ns, base={'ROS_DISCOVERY_SERVER': '10.0.0.2:11811;10.0.0.3:11811'})
    assert 'ROS_AUTOMATIC_DISCOVERY_RANGE' not in env
    assert nodeset.ros_environment(ns, base={})['ROS_AUTOMATIC_DISCOVERY_RANGE'] == ns.discovery_range
    assert [collector_id(n) for n in ('/c2', '/field/row1/', '', '/')] == ['c2', 'row1', 'sslfr', 'sslfr']


def test_foxglove_at_the_station_is_off_by_default_and_bound_to_the_station(tmp_path):
    f = field(tmp_path)
    everything = finder({('sslfr_field', 'field_page'), ('sslfr_gateway', 'modbus_gateway'),
                         ('sslfr_gateway', 'foxglove_bridge')})
    progs, _ = station.programs(f, role='both', run_dir=tmp_path, out_dir=None, finder=everything)
    assert 'foxglove_bridge' not in [p.name for p in progs]
    page = next(p for p in progs if p.name == 'field_page')
    assert f"collector_configs:=['{f.collectors[0].config}','{f.collectors[1].config}']" in page.argv
    progs, _ = station.programs(f, role='both', run_dir=tmp_path, out_dir=None, finder=everything, foxglove=True)
    fox = next(p for p in progs if p.name == 'foxglove_bridge')
    assert 'bind_address:=192.168.10.2' in fox.argv and '__node:=foxglove_bridge' in fox.argv
    # a parameter for it (e.g. the allow-list) turns it on too
    params = station.station_params(["foxglove_bridge:allow=['192.168.10.50']", 'foxglove_bridge:port=9000'])
    progs, _ = station.programs(f, role='both', run_dir=tmp_path, out_dir=None, finder=everything, params=params)
    fox = next(p for p in progs if p.name == 'foxglove_bridge')
    assert "allow:=['192.168.10.50']" in fox.argv and 'port:=9000' in fox.argv
    _, missing = station.programs(f, role='both', run_dir=tmp_path, out_dir=None, foxglove=True,
                                  finder=finder({('sslfr_field', 'field_page')}))
    assert any('foxglove_bridge is not installed' in m for m in missing)
    import pytest
    from sslfr_common.cliargs import CliError
    for bad in ('foxglove_bridge:port', 'planner:x=1', 'allow=1'):
        with pytest.raises(CliError, match='NODE:KEY=VALUE'):
            station.station_params([bad])
