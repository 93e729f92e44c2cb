"""A field collector's own discovery server (sslfr_bringup.local_discovery): when it
runs, its id and the servers list the node processes get. The restart it makes work
while the station is unreachable is tested in tests/test_field_netns.py."""
from __future__ import annotations

from sslfr_bringup import local_discovery as ld


def test_appended_after_the_station_servers_with_the_next_id():
    argv, servers, note = ld.local_server({'ROS_DISCOVERY_SERVER': '10.0.0.2:11811;10.0.0.3:11812'},
                                          port=40123, exe='/x/fast-discovery-server')
    assert servers == '10.0.0.2:11811;10.0.0.3:11812;127.0.0.1:40123'
    assert argv == ['env', '-u', 'ROS_DISCOVERY_SERVER', '/x/fast-discovery-server', '-i', '2', '-l', '127.0.0.1',
                    '-p', '40123']
    assert 'id 2' in note and '127.0.0.1:40123' in note
    # an empty position keeps its id (Fast DDS: the position is the id)
    assert ld.append_server(';10.0.0.3:11812', '127.0.0.1', 1) == (';10.0.0.3:11812;127.0.0.1:1', 2)


def test_none_outside_a_field_or_for_the_station_tools():
    assert ld.local_server({}, exe='/x/s') == (None, None, '')
    assert ld.local_server({'ROS_DISCOVERY_SERVER': '10.0.0.2:11811', 'ROS_SUPER_CLIENT': 'TRUE'},
                           exe='/x/s') == (None, None, '')


def test_missing_server_program_is_said_not_hidden():
    argv, servers, note = ld.local_server({'ROS_DISCOVERY_SERVER': '10.0.0.2:11811', 'PATH': '/nonexistent'})
    assert argv is None and servers is None and note.startswith('MISSING fast-discovery-server')


def test_free_port_is_bindable():
    import socket
    port = ld.free_udp_ports(1)[0]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(('127.0.0.1', port))
