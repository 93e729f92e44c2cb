"""A field description: the collectors of one site and their operations station.

Pure loader and validator (no rclpy). The YAML file (docs/field.md)::

    field:
      id: test_field
      station:
        address: 192.168.10.2        # the station's IP: its discovery server listens here
        discovery_port: 11811        # Fast DDS Discovery Server (primary)
        backup_address: 192.168.10.3 # the backup discovery server (another machine, or the same)
        backup_port: 11812
        web_port: 8090               # the field page (optional, default 8090)
      collectors:
        - id: c1                     # names the collector: hardware_id of its diagnostics
          namespace: /c1             # optional, default /<id>; its last name is the id
          address: 192.168.10.21     # the collector's Pi
          config: ../almeria_sslfr.yaml   # its site config (names its collector description)
          web_port: 8080             # its operator page (optional, default 8080)

Every problem is collected (not only the first) and each names the file and the key
(``field.yaml: field.collectors[1].namespace: ...``). A collector's id is the last name
of its namespace because every node derives the ``hardware_id`` of its diagnostics from
its namespace (:func:`sslfr_common.contract.collector_id`), so the field page and the
aggregated ``/diagnostics`` name the same collector.
"""
from __future__ import annotations

import ipaddress
import os
import re
from dataclasses import dataclass
from pathlib import Path
from sslfr_common.files import user_path
from typing import Any, Mapping

#: Fast DDS Discovery Server's default UDP port (eProsima documentation)
DISCOVERY_PORT = 11811
DEFAULT_BACKUP_PORT = 11812
DEFAULT_STATION_WEB_PORT = 8090
DEFAULT_COLLECTOR_WEB_PORT = 8080
_ID = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')


class FieldError(ValueError):
    """A field description that cannot be used; ``problems`` lists every reason, each
    naming the file and the key."""

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        super().__init__('invalid field description:\n  ' + '\n  '.join(self.problems))

    def one_line(self) -> str:
        """Every problem on one line (a CLI's exit-2 message)."""
        from sslfr_common.cliargs import one_line
        return one_line('invalid field description: ' + '; '.join(self.problems))


@dataclass(frozen=True)
class Station:
    address: str
    discovery_port: int
    backup_address: str
    backup_port: int
    web_port: int


@dataclass(frozen=True)
class Collector:
    id: str
    namespace: str
    address: str
    config: Path          # absolute path of its site config
    web_port: int


@dataclass(frozen=True)
class Field:
    id: str
    station: Station
    collectors: tuple[Collector, ...]
    path: Path

    def collector(self, cid: str) -> Collector:
        for c in self.collectors:
            if c.id == cid:
                return c
        raise KeyError(f'no collector {cid!r} in field {self.id} (known: {", ".join(self.ids)})')

    @property
    def ids(self) -> tuple[str, ...]:
        return tuple(c.id for c in self.collectors)

    @property
    def namespaces(self) -> tuple[str, ...]:
        return tuple(c.namespace for c in self.collectors)


def namespace_error(text: str) -> str:
    """Why ``text`` is not an absolute ROS namespace ('' when it is): the check of
    ``sslfr up --namespace`` (rcl's topic-name rules)."""
    import argparse

    from sslfr_planner.cli_input import ros_namespace
    if not isinstance(text, str) or not text.strip('/'):
        return 'must be an absolute namespace such as /c1 (not the root)'
    try:
        ros_namespace(text)
    except argparse.ArgumentTypeError as exc:
        return str(exc)
    return ''


def _ip(value: Any) -> str:
    """'' when ``value`` is an IPv4/IPv6 literal, else why not."""
    if not isinstance(value, str):
        return f'must be an IP address literal, got {value!r}'
    try:
        ipaddress.ip_address(value)
    except ValueError:
        return f'{value!r} is not an IP address literal (names are not resolved: give the address)'
    return ''


def _port(value: Any) -> str:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 65535:
        return f'must be a port number 1..65535, got {value!r}'
    return ''


def parse(doc: Any, path: str | os.PathLike, *, check_config=None) -> Field:
    """The :class:`Field` of the parsed YAML ``doc`` read from ``path`` (relative
    config paths are relative to its directory). ``check_config(config_path,
    namespace) -> list[str]`` judges each collector's site config (the node set's
    check, :func:`sslfr_bringup.nodeset.check_config`); None skips that check.
    Raises FieldError with every problem."""
    path = Path(path)
    where = str(path)
    problems: list[str] = []

    def bad(key: str, why: str) -> None:
        problems.append(f'{where}: {key}: {why}')

    if not isinstance(doc, Mapping) or not isinstance(doc.get('field'), Mapping):
        raise FieldError([f'{where}: field: missing (the file must hold a mapping "field:")'])
    f = doc['field']
    for key in f:
        if key not in ('id', 'station', 'collectors'):
            bad(f'field.{key}', 'unknown key (known: id, station, collectors)')
    fid = f.get('id')
    if not isinstance(fid, str) or not _ID.match(fid):
        bad('field.id', f'must be a name of letters, digits and _ starting with a letter, got {fid!r}')
    st = f.get('station')
    station = None
    if not isinstance(st, Mapping):
        bad('field.station', 'missing or not a mapping')
    else:
        known = ('address', 'discovery_port', 'backup_address', 'backup_port', 'web_port')
        for key in st:
            if key not in known:
                bad(f'field.station.{key}', f'unknown key (known: {", ".join(known)})')
        values = {'address': st.get('address'), 'backup_address': st.get('backup_address', st.get('address')),
                  'discovery_port': st.get('discovery_port', DISCOVERY_PORT),
                  'backup_port': st.get('backup_port', DEFAULT_BACKUP_PORT),
                  'web_port': st.get('web_port', DEFAULT_STATION_WEB_PORT)}
        n0 = len(problems)
        for key in ('address', 'backup_address'):
            why = _ip(values[key])
            if why:
                bad(f'field.station.{key}', why)
        for key in ('discovery_port', 'backup_port', 'web_port'):
            why = _port(values[key])
            if why:
                bad(f'field.station.{key}', why)
        if len(problems) == n0:
            if (values['address'], values['discovery_port']) == (values['backup_address'], values['backup_port']):
                bad('field.station.backup_port', 'the backup server needs its own address or port')
            station = Station(**values)
    cols = f.get('collectors')
    collectors: list[Collector] = []
    if not isinstance(cols, list) or not cols:
        bad('field.collectors', 'missing or empty: a list of collectors')
        cols = []
    ids: dict[str, int] = {}
    spaces: dict[str, int] = {}
    for i, c in enumerate(cols):
        key = f'field.collectors[{i}]'
        if not isinstance(c, Mapping):
            bad(key, 'must be a mapping with id, address, config')
            continue
        known = ('id', 'namespace', 'address', 'config', 'web_port')
        for k in c:
            if k not in known:
                bad(f'{key}.{k}', f'unknown key (known: {", ".join(known)})')
        n0 = len(problems)
        cid = c.get('id')
        if not isinstance(cid, str) or not _ID.match(cid):
            bad(f'{key}.id', f'must be a name of letters, digits and _ starting with a letter, got {cid!r}')
            cid = None
        elif cid in ids:
            bad(f'{key}.id', f'{cid!r} is already the id of field.collectors[{ids[cid]}]')
        else:
            ids[cid] = i
        nsp = c.get('namespace', f'/{cid}' if cid else None)
        why = namespace_error(nsp)
        if why:
            bad(f'{key}.namespace', why)
        else:
            nsp = nsp.rstrip('/')
            if cid and nsp.rsplit('/', 1)[-1] != cid:
                bad(f'{key}.namespace', f'{nsp!r}: its last name must be the collector id {cid!r} '
                                        '(the hardware_id of its diagnostics comes from the namespace)')
            elif nsp in spaces:
                bad(f'{key}.namespace', f'{nsp!r} is already the namespace of field.collectors[{spaces[nsp]}]')
            else:
                spaces[nsp] = i
        why = _ip(c.get('address'))
        if why:
            bad(f'{key}.address', why)
        web_port = c.get('web_port', DEFAULT_COLLECTOR_WEB_PORT)
        why = _port(web_port)
        if why:
            bad(f'{key}.web_port', why)
        cfg = c.get('config')
        config = None
        if not isinstance(cfg, str) or not cfg:
            bad(f'{key}.config', 'missing: the path of the collector\'s site config')
        else:
            p = user_path(cfg)
            p = p if p.is_absolute() else path.resolve().parent / p
            if not p.is_file():
                bad(f'{key}.config', f'{cfg!r}: no such file ({p})')
            else:
                config = p.resolve()
                if check_config is not None and not namespace_error(nsp):
                    for line in check_config(config, nsp):
                        bad(f'{key}.config', line)
        if len(problems) == n0:
            collectors.append(Collector(id=cid, namespace=nsp, address=c['address'], config=config,
                                        web_port=web_port))
    if problems:
        raise FieldError(problems)
    return Field(id=fid, station=station, collectors=tuple(collectors), path=path.resolve())


def load(path: str | os.PathLike, *, check_config=None) -> Field:
    """Read and validate the field description at ``path`` (see :func:`parse`)."""
    import yaml
    try:
        text = Path(path).read_text()
    except (OSError, ValueError) as exc:
        raise FieldError([f'{path}: cannot read: {exc}']) from None
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise FieldError([f'{path}: not YAML: {exc}']) from None
    return parse(doc, path, check_config=check_config)


def discovery_servers(station: Station) -> str:
    """``ROS_DISCOVERY_SERVER`` for the collectors and the station's own tools: the
    primary at position 0 (server id 0) and the backup at position 1 (server id 1),
    ``address:port;address:port`` (Fast DDS: the position in the list is the server's
    id; a client connects to both and keeps working with either)."""
    def one(addr, port):
        return f'[{addr}]:{port}' if ':' in addr else f'{addr}:{port}'
    return f'{one(station.address, station.discovery_port)};{one(station.backup_address, station.backup_port)}'


def simulated(n: int, config: str | os.PathLike, *, address: str = '127.0.0.1', field_id: str = 'sim_field',
              discovery_port: int = DISCOVERY_PORT, backup_port: int = DEFAULT_BACKUP_PORT,
              web_port: int = 0) -> dict:
    """The field document of ``n`` simulated collectors ``c1..cN`` on one machine
    (``sslfr sim --collectors N``): every collector and the station at ``address``,
    all with the same site config. Web ports 0: each page picks a free port."""
    if not 1 <= int(n) <= 64:
        raise ValueError(f'--collectors must be in 1..64, got {n}')
    return {'field': {'id': field_id,
                      'station': {'address': address, 'discovery_port': discovery_port,
                                  'backup_address': address, 'backup_port': backup_port,
                                  'web_port': web_port or DEFAULT_STATION_WEB_PORT},
                      'collectors': [{'id': f'c{k}', 'namespace': f'/c{k}', 'address': address,
                                      'config': str(Path(config).resolve())} for k in range(1, int(n) + 1)]}}
