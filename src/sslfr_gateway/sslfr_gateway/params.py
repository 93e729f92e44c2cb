"""Parameters of the gateway nodes (pure): one ParamTable per node.

Every parameter is read-only (the servers bind once); a bad value stops the node at
start-up with one line naming each bad parameter (exit code 2).
"""
from __future__ import annotations

import ipaddress
import re

from sslfr_common.netguard import Limits, ip_address_error, limit_params
from sslfr_common.params import ParamSpec, ParamTable

_NAMESPACE = re.compile(r'^(/[A-Za-z][A-Za-z0-9_]*)+$')


def ip_list_error(addrs: list[str]) -> str | None:
    """None when every non-empty entry is a literal IP address ('' entries are ignored:
    a ROS string array cannot be empty in a params file)."""
    for a in addrs:
        if a and ip_address_error(a):
            return ip_address_error(a)
    return None


def namespaces_error(names: list[str]) -> str | None:
    """None for a list of '' (the node's own namespace, one collector) or absolute
    namespaces such as /c1; each at most once."""
    if not names:
        return 'at least one collector'
    for n in names:
        if n and not _NAMESPACE.match(n):
            return f'{n!r} is not a namespace (e.g. /c1; "" for the node\'s own)'
    if len(set(names)) != len(names):
        return 'a namespace is listed twice'
    return None


def ids_error(ids: list[str]) -> str | None:
    if any(not i or len(i) > 16 for i in ids):
        return 'every collector id is 1..16 characters (SunSpec SN, Id)'
    if len(set(ids)) != len(ids):
        return 'a collector id is listed twice'
    return None


def collectors_mismatch(cfg: dict) -> str | None:
    """The one cross-parameter rule: as many ids as namespaces, at most 247 units."""
    if len(cfg['collectors']) != len(cfg['collector_ids']):
        return (f"collectors ({len(cfg['collectors'])}) and collector_ids "
                f"({len(cfg['collector_ids'])}) differ in length")
    if len(cfg['collectors']) > 247:
        return 'at most 247 collectors (Modbus unit ids 1..247)'
    return None


def allowed(addrs: list[str]) -> tuple[str, ...]:
    """The non-empty entries, normalised (``::ffff:127.0.0.1`` stays as given)."""
    return tuple(str(ipaddress.ip_address(a)) for a in addrs if a)


_COLLECTORS = (
    ParamSpec('collectors', [''],
              "Namespaces of the collectors served, one Modbus unit each in this order "
              "(unit id 1, 2, ...); [''] = the node's own namespace (one collector)",
              read_only=True, validator=namespaces_error),
    ParamSpec('collector_ids', ['c1'],
              'Id of each collector (same length as collectors): SunSpec serial number and '
              'tracker id', read_only=True, validator=ids_error),
)

MODBUS_PARAMS = ParamTable(_COLLECTORS + (
    ParamSpec('bind_address', '127.0.0.1',
              'IP address the Modbus TCP server listens on (127.0.0.1: this machine only; the '
              "station's LAN address for a SCADA)", read_only=True, validator=ip_address_error),
    ParamSpec('port', 1502, 'TCP port of the Modbus server (502 needs root; 0: any free port, logged)',
              '-', 0, 65535, read_only=True),
    ParamSpec('write_allow', [''],
              "Client IP addresses allowed to write the control registers ([''] = none: "
              'read-only, writes refused with Modbus exception 01)', read_only=True,
              validator=ip_list_error),
    ParamSpec('setpoint_alarm', 0.035,
              "SunSpec 601 SetPoint alarm when the mirrors' |measured - setpoint| exceeds this [rad]",
              'rad', 0.0, 3.1416, read_only=True),
    ParamSpec('stale_after', 5.0,
              "No joint_states from a collector for this long: its positions read 'not "
              "implemented' (unknown) until the next one [s, steady clock]", 's', 0.5, 3600.0,
              read_only=True),
    ParamSpec('max_connections', 32, 'Most simultaneous Modbus connections [-]', '-', 1, 1024,
              read_only=True),
    ParamSpec('max_per_address', 4, 'Most simultaneous connections from one IP address [-]', '-',
              1, 1024, read_only=True),
    ParamSpec('idle_timeout', 60.0, 'A connection silent this long is closed [s, wall]', 's',
              1.0, 3600.0, read_only=True),
    ParamSpec('frame_timeout', 5.0,
              'A request not complete this long after its first byte closes its connection '
              '[s, wall]', 's', 0.5, 60.0, read_only=True),
    ParamSpec('service_timeout', 5.0, 'Longest wait for planner/set_mode [s, wall]', 's', 0.5, 60.0,
              read_only=True),
), integers_for_floats=True)

FOXGLOVE_PARAMS = ParamTable((
    ParamSpec('bind_address', '127.0.0.1',
              'IP address the Foxglove WebSocket server listens on (127.0.0.1: this machine only)',
              read_only=True, validator=ip_address_error),
    ParamSpec('port', 8765, 'TCP port of the Foxglove WebSocket server (0: any free port, logged)',
              '-', 0, 65535, read_only=True),
    ParamSpec('allow', ['127.0.0.1', '::1'],
              'Client IP addresses allowed to connect; others are closed at once', read_only=True,
              validator=ip_list_error),
    ParamSpec('topics', [''],
              "Topics carried ([''] = every topic with a publisher, found every discovery_period)",
              read_only=True),
    ParamSpec('discovery_period', 2.0, 'Topic discovery period [s, wall]', 's', 0.2, 60.0,
              read_only=True),
    *limit_params(Limits(max_connections_per_address=4, max_connections=16, header_timeout=10.0,
                         idle_timeout=10.0)),
    ParamSpec('max_message_bytes', 65536,
              'Largest client message (a subscribe list); a larger one closes the connection '
              '(WebSocket close 1009) [bytes]', 'bytes', 1024, 16777216, read_only=True),
    ParamSpec('max_messages_per_s', 50.0,
              'Client messages per second sustained (bursts of twice this); more close the '
              'connection (WebSocket close 1008) [1/s]', '1/s', 1.0, 10000.0, read_only=True),
    ParamSpec('message_backlog', 256,
              'Messages queued per client by the server; a client that does not read loses the '
              'oldest [-]', '-', 16, 4096, read_only=True),
), integers_for_floats=True)
