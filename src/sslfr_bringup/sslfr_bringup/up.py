"""``sslfr up``: start the whole node set on real boards as supervised processes.

Reads the one node-set description (config/nodeset.yaml) and a site config (ROS
params file; default ``almeria_sslfr.yaml``), starts the nodes as processes of the node set's layout
(default ``separate``: every node its own process; ``--layout composed``: drivers and
sensors in one process, planner, web and recorder in another, safety alone),
drives the axis drivers' lifecycle to ``active``, restarts a crashed node with backoff
(a restart of the safety supervisor is reported loudly), kills and restarts a process
whose executor stops turning (no ``WATCHDOG=1`` beat within ``defaults.watchdog_timeout``)
and, on SIGINT/SIGTERM, stops
the axes first, then the rest, within 5 s. This is what the systemd unit runs.

Networking: ``ROS_DOMAIN_ID`` defaults to the node set's (42, never 0) and
``ROS_AUTOMATIC_DISCOVERY_RANGE`` to LOCALHOST; docs/deploy.md says how to open the
graph to a monitoring laptop. A collector of a field (``ROS_DISCOVERY_SERVER`` set, docs/field.md)
also runs its own discovery server (:mod:`sslfr_bringup.local_discovery`).
"""
from __future__ import annotations

import argparse
import os
import shlex
import sys
from collections.abc import Callable
from pathlib import Path

from sslfr_bringup import dds_profile, local_discovery
from sslfr_bringup import nodeset as nodeset_mod
from sslfr_bringup.host import find_executable
from sslfr_bringup.liveness import LivenessWatch
from sslfr_bringup.supervisor import Program, RosSide, StopSignals, Supervisor, supervised_main
from sslfr_common.sdnotify import Notifier
from sslfr_planner.cli_input import OneLineParser, bounded_int, one_line, output_dir, ros_namespace


def build_programs(ns: nodeset_mod.NodeSet, config: Path, *, run_dir: Path,
                   sim_ports: dict | None = None, use_sim_time: bool = False,
                   extra: dict | None = None, namespace: str | None = None,
                   finder=find_executable, layout: str | None = None,
                   params: dict | None = None) -> tuple[list[Program], list[str]]:
    """Programs for every process of ``layout`` (default: the node set's) whose
    executable is installed, and the list of missing ``package/executable`` (reported,
    never replaced by anything else).

    Each node's overrides (role parameters, port, use_sim_time, ``extra[name]``) are
    written to ``run_dir/<node>.params.yaml`` (the caller owns ``run_dir`` and
    removes it), passed after the site config so they win over its node section.
    Under a namespace the site config's node sections are moved with it
    (:func:`nodeset.site_config`). A composed process is the ``composed`` executable
    with each node's own arguments (:func:`nodeset.composed_args`); its Program is
    named after the group and lists its nodes (``nodes``, ``lifecycle_nodes``).
    """
    import yaml

    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    namespace = ns.namespace if namespace is None else namespace
    config, params = nodeset_mod.site_config(config, namespace, run_dir, ns, params)
    if namespace.strip('/') and any(n.name == 'recorder' for n in ns.nodes):
        # each collector's bag names its collector: <id>_YYYY-MM-DD (a field, docs/field.md)
        from sslfr_common.contract import CLOCK, DIAGNOSTICS, collector_id
        extra = {k: dict(v) for k, v in (extra or {}).items()}
        rec = extra.setdefault('recorder', {})
        rec.setdefault('prefix', collector_id(namespace))
        # the absolute /diagnostics carries every collector's statuses: subscribing to it
        # would connect each collector to all the others; the station records it
        rec.setdefault('exclude', [CLOCK.name, DIAGNOSTICS.name])
    programs, missing = [], []

    def node_args(node):
        overrides = nodeset_mod.node_overrides(ns, node, params, sim_ports, use_sim_time,
                                               (extra or {}).get(node.name), namespace=namespace)
        ofile = None
        if overrides:
            ofile = run_dir / f'{node.name}.params.yaml'
            ofile.write_text(yaml.safe_dump(nodeset_mod.overrides_document(ns, node, overrides, namespace)))
        return nodeset_mod.ros_args(ns, node, config, overrides_file=ofile, namespace=namespace)

    for proc in ns.processes(layout):
        package, executable = nodeset_mod.COMPOSED if proc.composed else \
            (proc.nodes[0].package, proc.nodes[0].executable)
        exe = finder(package, executable)
        if exe is None:
            missing.append(f'{proc.name} ({package}/{executable})')
            continue
        args = {n.name: node_args(n) for n in proc.nodes}
        argv = [str(exe), *(nodeset_mod.composed_args(proc, args) if proc.composed else args[proc.name])]
        programs.append(Program(name=proc.name, argv=argv, start=min(n.start for n in proc.nodes),
                                stop=min(n.stop for n in proc.nodes),
                                critical=any(n.critical for n in proc.nodes),
                                lifecycle=any(n.lifecycle for n in proc.nodes),
                                nodes=tuple(n.name for n in proc.nodes),
                                lifecycle_nodes=tuple(n.name for n in proc.nodes if n.lifecycle)))
    return programs, missing


def add_local_discovery(env: dict, programs: list, say: Callable[[str], None]) -> None:
    """A field collector (``ROS_DISCOVERY_SERVER`` set): its own discovery server
    first among ``programs``, appended to the servers of ``env`` and of this process
    (its ROS side) (sslfr_bringup.local_discovery)."""
    argv, servers, note = local_discovery.local_server(env)
    if note:
        say(note)
    if argv is not None:
        env['ROS_DISCOVERY_SERVER'] = os.environ['ROS_DISCOVERY_SERVER'] = servers
        programs.insert(0, Program(name=local_discovery.PROGRAM, argv=argv, start=-2, stop=9, restart=True,
                                   kind='service'))


def parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog='sslfr up', description=__doc__.split('\n\n')[0],
                                epilog='Stop with Ctrl-C or SIGTERM: axes first, then the rest (<= 5 s).')
    p.add_argument('--config', default=None,
                   help='site params file: a path or a name in sslfr_bringup/config (default: almeria_sslfr.yaml)')
    p.add_argument('--nodeset', default=None, help='node-set description (default: config/nodeset.yaml)')
    p.add_argument('--domain-id', type=bounded_int(1, 232), default=None,
                   help='ROS_DOMAIN_ID (default: $ROS_DOMAIN_ID, else the node set\'s, 42)')
    p.add_argument('--namespace', type=ros_namespace, default=None,
                   help='namespace of the whole tracker, e.g. /sslfr1 (the rules install-service checks)')
    p.add_argument('--layout', default=None,
                   help='process layout of the node set (config/nodeset.yaml layouts: composed, separate; '
                        'default: the node set\'s)')
    p.add_argument('--only', default='', help='comma-separated node names to run (default: all)')
    p.add_argument('--skip', default='', help='comma-separated node names not to run')
    p.add_argument('--log-dir', type=output_dir, default=None, help='write each node\'s output to DIR/<node>.log '
                                                   '(default: inherit stdout, i.e. the journal under systemd)')
    p.add_argument('--print', action='store_true', dest='print_only',
                   help='print the command lines and exit (nothing is started)')
    return p


def select(ns: nodeset_mod.NodeSet, only: str, skip: str) -> nodeset_mod.NodeSet:
    if only:
        ns = ns.only([s for s in only.split(',') if s])
    if skip:
        names = [s for s in skip.split(',') if s]
        for n in names:
            ns.node(n)
        ns = ns.without(names)
    return ns


def main(argv: list[str]) -> int:
    """``sslfr up``: exit 0 after a stop signal, 1 when the set cannot run (a node
    refused its configuration, the ROS side failed), 2 for bad arguments or configs.
    Every child started is ended whatever signal arrives and whenever (start-up
    included), and the run directory is removed."""
    return supervised_main('up', lambda stop, run_dir: _run(parser().parse_args(argv), stop, run_dir))


def _run(args, stop: StopSignals, run_dir: Path) -> int:
    try:
        ns = nodeset_mod.load(args.nodeset)
        config = nodeset_mod.resolve_config(args.config, default=ns.config)
        ns = select(nodeset_mod.for_config(ns, config, args.namespace), args.only, args.skip)
        programs, missing = build_programs(ns, config, namespace=args.namespace, run_dir=run_dir,
                                           layout=args.layout)
    except (nodeset_mod.NodeSetError, KeyError) as exc:
        print(f'sslfr up: {one_line(exc, keep_newlines=True)}', file=sys.stderr)
        return 2
    try:
        env = nodeset_mod.ros_environment(ns, domain_id=args.domain_id, run_dir=run_dir,
                                          namespace=ns.namespace if args.namespace is None else args.namespace)
        restart_wait = dds_profile.restart_wait(env)
        dds_profile.adopt_graph_partition(env)      # before this process's own ROS side starts
    except dds_profile.ProfileError as exc:
        print(f'sslfr up: {exc}', file=sys.stderr)
        return 2
    add_local_discovery(env, programs, lambda line: print(f'sslfr up: {line}', file=sys.stderr))
    domain = int(env['ROS_DOMAIN_ID'])
    print(f'sslfr up: config {config}, ROS_DOMAIN_ID={domain}, '
          + (f'ROS_DISCOVERY_SERVER={env["ROS_DISCOVERY_SERVER"]}' if env.get('ROS_DISCOVERY_SERVER') else
             f'ROS_AUTOMATIC_DISCOVERY_RANGE={env["ROS_AUTOMATIC_DISCOVERY_RANGE"]}'), file=sys.stderr)
    for m in missing:
        print(f'sslfr up: MISSING executable, node not started: {m} (run make setup?)', file=sys.stderr)
    if args.print_only:
        for prog in programs:
            print(f'{prog.name}: ' + ' '.join(shlex.quote(a) for a in prog.argv))
            files = [a for a in prog.argv if a.endswith('.params.yaml')]
            for f in files:
                print('    ' + Path(f).read_text().strip().replace('\n', '\n    '))
        return 0 if not missing else 1
    if not programs:
        print('sslfr up: nothing to run', file=sys.stderr)
        return 1
    # systemd (Type=notify, WatchdogSec=): this process beats from its first loop on
    notifier = Notifier.from_environ()
    notifier.beat()
    ros = RosSide(domain, namespace=args.namespace or ns.namespace)
    ros.start()
    try:
        failed = ros.wait_ready(stop, tick=notifier.beat)
        if failed:
            print(f'sslfr up: ROS side failed: {failed}', file=sys.stderr)
            return 1
        sup = Supervisor(programs, env, backoff=ns.restart_backoff, stable_after=ns.stable_after,
                         stop_timeout=ns.stop_timeout, log_dir=Path(args.log_dir) if args.log_dir else None,
                         ros=ros, liveness=LivenessWatch(ns.watchdog_timeout, ns.watchdog_startup),
                         notifier=notifier, restart_wait=restart_wait)
        why = sup.run(stop)
    finally:
        ros.shutdown()
    if why == 'fatal':
        print(f'sslfr up: stopped: {sup.fatal}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
