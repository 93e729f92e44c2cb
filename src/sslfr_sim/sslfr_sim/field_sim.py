"""``sslfr sim --collectors N``: a simulated field on this machine.

N collectors ``c1..cN``, each a whole ``sslfr sim`` (its own simulated boards, its own
node set in namespace ``/cK``, ``composed`` layout, on the system clock at real time
as on a Pi: N simulated clocks cannot share the absolute ``/clock``), all discovery
clients of the station's two Fast DDS discovery servers, and the station
(sslfr_field.station: discovery servers, gateway when installed, field recorder), all
supervised by one supervisor. Prints each collector's page and the station's
addresses as they come up; stops everything on Ctrl-C or at ``--end``.
"""
from __future__ import annotations

import os
import re
import socket
import sys
import time
from pathlib import Path

from sslfr_bringup import dds_profile
from sslfr_bringup import nodeset as nodeset_mod
from sslfr_bringup.host import acquire_domain
from sslfr_bringup.local_discovery import free_udp_ports
from sslfr_bringup.supervisor import Program
from sslfr_common.cliargs import one_line
from sslfr_field import field as field_mod
from sslfr_field import station as station_mod

#: the station's nodes that ``--set NODE:KEY=VALUE`` reaches (the rest go to every collector)
STATION_NODES = station_mod.STATION_NODES
#: [s] the ordered stop: each collector's own sim stops its node set (<= 5 s) first
FIELD_STOP_TIMEOUT = 15.0


def free_tcp_port() -> int:
    """A TCP port free on 127.0.0.1 now (the field page)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(('127.0.0.1', 0))
        return s.getsockname()[1]


def collector_argv(args, c: field_mod.Collector, f: field_mod.Field, domain: int, out: Path) -> list[str]:
    """The ``sslfr sim`` command of one simulated collector, a discovery client of ``f``'s servers."""
    # the station's processes get the station's profile (sslfr_field.station.station_environment);
    # a collector starts from the caller's own, as on its Pi
    own = os.environ.get(dds_profile.PROFILE_ENV)
    env = ['env', '-u', 'ROS_SUPER_CLIENT', '-u', 'ROS_AUTOMATIC_DISCOVERY_RANGE',
           *([f'{dds_profile.PROFILE_ENV}={own}'] if own else ['-u', dds_profile.PROFILE_ENV]),
           f'ROS_DISCOVERY_SERVER={field_mod.discovery_servers(f.station)}']
    argv = [*env, sys.executable, '-m', 'sslfr_bringup.cli', 'sim', '--wall-clock', '--namespace', c.namespace,
            '--layout', args.layout or 'composed', '--config', str(c.config), '--domain-id', str(domain),
            '--out', str(out / c.id), '--no-report', '--seed', str(args.seed + 101 * int(c.id[1:]))]
    if args.end:
        argv += ['--end', args.end]
    if getattr(args, 'flow', None) is not None:      # a collector with a flow meter pumps it
        argv += ['--flow', f'{args.flow:g}']
    for spec in args.fault:
        argv += ['--fault', spec]
    argv += ['--set', f'web:port={c.web_port}']
    for spec in args.set:
        if spec.partition(':')[0] not in STATION_NODES:
            argv += ['--set', spec]
    return argv


def run_field(args, stop, run: Path) -> int:
    """Run the simulated field until a stop signal or ``--end``; exit status as ``sslfr sim``."""
    if args.date or args.start or args.speed not in (None, 1.0) or args.namespace or args.boards != 'sim':
        print('sslfr sim: --collectors runs on the system clock at real time with the Python boards: '
              'no --date, --start, --speed, --namespace or --boards firmware', file=sys.stderr)
        return 2
    try:
        config = nodeset_mod.resolve_config(args.config, default=nodeset_mod.load(args.nodeset).config)
    except nodeset_mod.NodeSetError as exc:
        print(one_line('sslfr sim: ' + ' '.join(str(exc).split())), file=sys.stderr)
        return 2
    primary, backup = free_udp_ports(2)
    doc = field_mod.simulated(args.collectors, config, discovery_port=primary, backup_port=backup,
                              web_port=free_tcp_port())
    for c in doc['field']['collectors']:          # each collector's page on its own port, linked from the field page
        c['web_port'] = free_tcp_port()
    fpath = run / 'field.yaml'
    import yaml
    fpath.write_text(yaml.safe_dump(doc))
    try:
        f = station_mod.load_checked(str(fpath))
    except field_mod.FieldError as exc:
        print(f'sslfr sim: {exc.one_line()}', file=sys.stderr)
        return 2
    if args.domain_id is None:
        import os
        if os.environ.get('ROS_DOMAIN_ID'):
            args.domain_id = int(os.environ['ROS_DOMAIN_ID'])
        else:
            try:
                args.domain_id, _lock = acquire_domain()   # held for the run (the lock lives in _lock)
            except RuntimeError as exc:
                print(f'sslfr sim: {exc}: pass --domain-id', file=sys.stderr)
                return 1
    station_params: dict = {'modbus_gateway': {'port': 0}}   # any free port, printed
    # Foxglove live at the station: on with any --set foxglove_bridge:KEY=VALUE (its port 0: any free port, printed)
    for spec in args.set:              # --set field_page:KEY=VALUE etc.: the station's nodes
        node, _, rest = spec.partition(':')
        if node in STATION_NODES:
            key, eq, value = rest.partition('=')
            if not (key and eq):
                print(f'sslfr sim: --set {spec!r}: expected {node}:KEY=VALUE', file=sys.stderr)
                return 2
            station_params.setdefault(node, {})[key] = value
    if station_mod.FOXGLOVE[1] in station_params:
        station_params[station_mod.FOXGLOVE[1]].setdefault('port', 0)
    out = Path(args.out or 'out/sim-field').resolve()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(one_line(f'sslfr sim: --out {out}: {exc.strerror or exc}'), file=sys.stderr)
        return 2
    collectors = [Program(name=f'collector_{c.id}', argv=collector_argv(args, c, f, args.domain_id, out),
                          start=2, stop=0, restart=False) for c in f.collectors]
    station_args = type('A', (), {'out': str(out / 'station'), 'role': 'both', 'domain_id': args.domain_id,
                                  'print_only': False, 'params': station_params})()
    print(f'sslfr sim: field of {len(f.collectors)} collectors ({", ".join(f.namespaces)}), discovery servers '
          f'{field_mod.discovery_servers(f.station)}, ROS_DOMAIN_ID={args.domain_id}, out {out}', file=sys.stderr)
    pages: dict[str, str] = {}

    # what the station's processes print once they serve: (key, log file, pattern, what to say)
    faces = [('gateway', out / 'station' / 'logs' / f'{station_mod.GATEWAY[1]}.log',
              r'SunSpec Modbus TCP at (\S+)', 'SunSpec MODBUS TCP GATEWAY'),
             ('station', out / 'station' / 'logs' / 'field_page.log', r'field page at (\S+)', 'FIELD PAGE')]
    if station_mod.FOXGLOVE[1] in station_params:
        faces.append(('foxglove', out / 'station' / 'logs' / f'{station_mod.FOXGLOVE[1]}.log',
                      r'Foxglove WebSocket at (\S+)', 'FOXGLOVE WEBSOCKET'))
    faces += [(c.id, out / c.id / 'logs' / 'web.log', r'operator page at (\S+)',
               f'collector {c.id} ({c.namespace}): operator page') for c in f.collectors]

    def announce():
        for key, log, pattern, what in faces:
            if key in pages:
                continue
            try:
                m = re.search(pattern, log.read_text(errors='replace'))
            except OSError:
                continue
            if m:
                pages[key] = m.group(1)
                print(f'sslfr sim: {what} at {m.group(1)}', file=sys.stderr)
    t0 = time.monotonic()
    code = station_mod.run(f, station_args, stop, run, extra_programs=collectors, tick=announce,
                           stop_timeout=FIELD_STOP_TIMEOUT,
                           until=lambda sup: all(p.proc is not None and not p.alive() for p in collectors))
    print(f'sslfr sim: field stopped after {time.monotonic() - t0:.0f} s; collectors\' bags in '
          f'{out}/<id>/bags, the field recorder\'s in {out}/station/bags', file=sys.stderr)
    return code
