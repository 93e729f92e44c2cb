"""``sslfr sim``: the node set against simulated boards over a simulated day.

The same node set as ``sslfr up`` (config/nodeset.yaml), with every board replaced by
its simulator (``sim_board`` processes speaking the board protocol on real ptys; the
pty path goes to the driver's ``port`` parameter, so the drivers are unchanged),
every node on ``use_sim_time``, a simulated clock published on ``/clock`` at
``--speed`` times real time, the recorder writing an MCAP bag, and at the end the
day report (``sslfr report``). Times are UTC.

Time. Simulated time is ``start + speed * max(0, t - anchor)`` with ``t`` the
system-wide CLOCK_MONOTONIC (shared by every process); the simulated sensor boards
get the same ``start``, ``speed`` and ``anchor`` (options ``start_utc``, ``speed``,
``anchor``), so GPS time, sun and ``/clock`` agree. The anchor is the instant the node
set is up (see the start-up sequence in :func:`main`); until then the sensor boards'
clocks are held at ``start``: nothing of the simulated window is lost to start-up, and
no board runs ahead of ``/clock``, however long the start-up took. Axis boards run their
steppers on the steady clock: at ``--speed X`` a joint must move X times faster than
in reality, so the drivers get a raised ``max_speed`` in simulation (nodeset.yaml
``sim.node_parameters``).

``--wall-clock`` runs the node set as on the Pi: on the system clock (no ``/clock``,
``use_sim_time`` false), at real time, from now until ``--end`` (UTC, today); the
simulated boards' clock is the system clock too. It is how the node set's CPU is
measured without the simulation's own ``/clock`` traffic (benchmarks/bench_nodeset_cpu.py
``--wall-clock``), and a dry run of a deployment before its boards exist.

Faults (``--fault SPEC``, grammar in :mod:`sslfr_sim.faults`) fire at their
simulated time through the simulators' control sockets (``kill:NODE`` through the
supervisor; ``hang:NODE`` SIGSTOPs the node's process, which the supervisor's
liveness watch then kills and restarts). A fault duration is simulated seconds; a link drop lasts
``SECONDS / speed`` wall seconds, so at high speed give it enough simulated seconds
to exceed the drivers' steady-clock link timeout (1 s wall).
"""
from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import json
import os
import shutil
import sys
import tempfile
import threading
import time
from pathlib import Path

from sslfr_sim import faults as faults_mod
from sslfr_bringup import dds_profile
from sslfr_bringup import nodeset as nodeset_mod
from sslfr_bringup.host import acquire_domain, find_executable
from sslfr_bringup.liveness import LivenessWatch
from sslfr_bringup.supervisor import Interrupted, Program, RosSide, StopSignals, Supervisor
from sslfr_bringup.up import select
from sslfr_common.contract import ABSORBER_TEMPERATURE, AXIS_HOME, AXIS_STATUS, GPS_FIX, IRRADIANCE_BEAM, DriveKind
from sslfr_planner.cli_input import CliError, OneLineParser, bounded_int, one_line, output_dir, ranged_float, ros_namespace


class SimClock:
    """Simulated time [s since the Unix epoch, UTC] from the monotonic clock.

    ``now(t) = start + speed * (t - anchor)``; before :meth:`set_anchor` (and before
    the anchor) it is ``start``.
    """

    def __init__(self, start: float, speed: float, anchor: float | None = None):
        if not speed > 0:
            raise ValueError('speed must be > 0')
        self.start, self.speed, self.anchor = float(start), float(speed), anchor

    def set_anchor(self, anchor: float) -> None:
        self.anchor = float(anchor)

    def published(self) -> float | None:
        """What /clock carries: None until the anchor is set (nothing published)."""
        return None if self.anchor is None else self.now()

    def now(self, mono: float | None = None) -> float:
        if self.anchor is None:
            return self.start
        t = time.monotonic() if mono is None else mono
        return self.start + self.speed * max(0.0, t - self.anchor)

    def wall_until(self, sim_t: float, mono: float | None = None) -> float:
        """Wall seconds from ``mono`` until sim time ``sim_t`` (>= 0)."""
        return max(0.0, (sim_t - self.now(mono)) / self.speed)


#: marks a directory ``sslfr sim`` made as its output: only there does a new run replace bags/ and logs/
SIM_MARK = '.sslfr-sim-output'


def parse_hhmm(text: str) -> float:
    """``HH:MM`` or ``HH:MM:SS`` (UTC) -> seconds after midnight."""
    parts = text.split(':')
    if len(parts) not in (2, 3):
        raise ValueError(f'time {text!r}: expected HH:MM or HH:MM:SS')
    h, m = int(parts[0]), int(parts[1])
    s = float(parts[2]) if len(parts) == 3 else 0.0
    if not (0 <= h <= 24 and 0 <= m < 60 and 0 <= s < 60) or (h == 24 and (m or s)):
        raise ValueError(f'time {text!r} is not a time of day')
    return h * 3600 + m * 60 + s


def day_epoch(date: str) -> float:
    """``YYYY-MM-DD`` -> Unix time of 00:00 UTC that day."""
    d = dt.date.fromisoformat(date)
    return dt.datetime(d.year, d.month, d.day, tzinfo=dt.timezone.utc).timestamp()


def site_of(params: dict) -> dict:
    """Site keys from a params file's ``/**`` section (defaults: seed 000 Almeria,
    36 deg 50' 07" N, 2 deg 24' 08" W, 22 m)."""
    p = nodeset_mod.node_params(params, '__sim__')
    return {'latitude_deg': float(p.get('site.latitude_deg', 36 + 50 / 60 + 7 / 3600)),
            'longitude_deg': float(p.get('site.longitude_deg', -(2 + 24 / 60 + 8 / 3600))),
            'elevation': float(p.get('site.elevation', 22.0))}


def fault_commands(f: faults_mod.Fault, what: str, speed: float) -> list[str]:
    """Control-socket lines that start (``what='start'``) or end a fault on its
    board's simulator (see ``sslfr_sim.runner`` and ``sim.sensors``)."""
    active = what == 'start'
    if f.kind == 'link-drop':
        return [f'disconnect {f.duration / speed:.3f}'] if active else []
    if f.kind == 'board-reset':
        return ['reset'] if active else []
    if f.kind == 'slip':     # the slip stays after its duration (the coupling is not repaired)
        return [f'slip {f.amount:g} {f.duration / speed:.3f}'] if active else []
    cmd = {'cmd': 'fault', 'kind': f.kind, 'active': active}
    if f.kind == 'thermocouple-open':
        cmd['target'] = f.target
    if f.kind == faults_mod.WIND_FAULT:
        cmd['value'] = float(f.target)
    return [json.dumps(cmd)]


#: [s wall] longest wait, once the node set is up, for every axis to be referenced
SETTLE_S = 20.0
#: [s wall] between anchoring the sensor simulators (their held clock starts) and the
#: anchor itself: room for the control commands to reach every board (a few ms each)
ANCHOR_LEAD = 0.2
#: [L/h] the flow through a simulated absorber with a flow meter (seed 003 section 3.2:
#: the hydro-dynamic tests pump the water at a constant 150 L/h)
FLOW_LPH = 150.0

def parse_set(text: str, nodes) -> tuple[str, str, object]:
    """``NODE:KEY=VALUE`` -> (node, key, value parsed as YAML); ValueError if malformed."""
    import yaml
    head, eq, value = text.partition('=')
    node, colon, key = head.partition(':')
    if not (eq and colon and node and key):
        raise ValueError(f'--set {text!r}: expected NODE:KEY=VALUE')
    if node not in nodes:
        raise ValueError(f'--set {text!r}: unknown node {node!r} (known: {", ".join(nodes)})')
    try:
        return node, key, yaml.safe_load(value)
    except RecursionError:
        raise ValueError(f'--set {text[:80]!r}: bad value: nested too deeply') from None
    except yaml.YAMLError as exc:
        raise ValueError(f'--set {text!r}: bad value: {" ".join(str(exc).split())}') from None


def _watch_topics(ns) -> dict:
    """Sensor topics whose first message tells the simulation that a node is fed."""
    from sensor_msgs.msg import NavSatFix, Temperature
    from sslfr_interfaces.msg import Irradiance
    by_node = {'gps': (GPS_FIX.name, NavSatFix), 'absorber_board': (ABSORBER_TEMPERATURE.of('outlet'), Temperature),
               'irradiance': (IRRADIANCE_BEAM.name, Irradiance)}
    return dict(by_node[n.name] for n in ns.nodes if n.name in by_node)


def _axis_status_topics(ns) -> dict:
    """Every axis driver's status topic: start-up waits for their ``homed``."""
    from sslfr_interfaces.msg import AxisStatus
    return {AXIS_STATUS.of(n.parameters['axis']): AxisStatus for n in ns.nodes if 'axis' in n.parameters}


#: Simulated days: ROS time is unsigned seconds since 1970 (a day before it cannot be
#: simulated) and builtin_interfaces/Time's sec is int32 (until 2038-01-19).
FIRST_DAY, LAST_DAY = dt.date(1970, 1, 2), dt.date(2038, 1, 18)


def sim_date(text: str) -> str:
    """argparse type: a simulated day YYYY-MM-DD within :data:`FIRST_DAY` .. :data:`LAST_DAY`."""
    try:
        d = dt.date.fromisoformat(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'must be a date YYYY-MM-DD, got {text!r}') from None
    if not FIRST_DAY <= d <= LAST_DAY:
        raise argparse.ArgumentTypeError(f'must be within {FIRST_DAY} .. {LAST_DAY} (ROS time), got {text}')
    return text


def parser() -> argparse.ArgumentParser:
    p = OneLineParser(
        prog='sslfr sim', description=__doc__.split('\n\n')[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='fault specs (times UTC, durations in simulated seconds):\n' + '\n'.join(
            '  ' + line for line in faults_mod.__doc__.split('::')[1].split('\n\nBOARD')[0].strip('\n').splitlines()))
    p.add_argument('--config', default=None, help='site params file (default: almeria_sslfr.yaml, seed 000)')
    p.add_argument('--nodeset', default=None, help='node-set description (default: config/nodeset.yaml)')
    p.add_argument('--date', type=sim_date, default=None, help='simulated day YYYY-MM-DD (default 2026-06-21)')
    p.add_argument('--start', default=None, help='start HH:MM UTC (default 04:00)')
    p.add_argument('--end', default=None, help='end HH:MM UTC (default 20:00; with --wall-clock the next such '
                                               'time, tomorrow\'s when not after now; default now + 10 min)')
    p.add_argument('--speed', type=ranged_float(0.0, 5000.0, lo_open=True), default=None,
                   help='simulated seconds per wall second, (0, 5000] (default 400)')
    p.add_argument('--record', type=output_dir, default=None, help='bag output directory (default OUT/bags)')
    p.add_argument('--out', type=output_dir, default=None,
                   help='output directory: logs, bags, report (default out/sim-DATE)')
    p.add_argument('--fault', action='append', default=[], metavar='SPEC', help='inject a fault (repeatable)')
    p.add_argument('--set', action='append', default=[], metavar='NODE:KEY=VALUE',
                   help='set a node parameter for this run (YAML value, after the site config), '
                        'e.g. mirrors_driver:status_rate=20 (repeatable)')
    p.add_argument('--layout', default=None,
                   help='process layout (config/nodeset.yaml layouts: composed, separate; default: the node set\'s)')
    p.add_argument('--namespace', type=ros_namespace, default=None,
                   help='namespace of the whole tracker, e.g. /c1 (default: the node set\'s)')
    p.add_argument('--collectors', type=bounded_int(1, 64), default=None, metavar='N',
                   help='a field: N simulated collectors /c1../cN (composed layout, on the system clock) '
                        'and their station (discovery servers, field recorder) on this machine (docs/field.md); '
                        '--set field_page:/modbus_gateway:/foxglove_bridge:KEY=VALUE go to the station '
                        '(any foxglove_bridge parameter starts Foxglove live there)')
    p.add_argument('--only', default='', help='comma-separated nodes to run (default: all)')
    p.add_argument('--skip', default='', help='comma-separated nodes not to run')
    p.add_argument('--domain-id', type=bounded_int(1, 232), default=None,
                   help='ROS_DOMAIN_ID (default: $ROS_DOMAIN_ID, else a free id of 215..232 held for the run)')
    p.add_argument('--seed', type=bounded_int(0, 2**31 - 1), default=1, help='random seed of the simulated boards')
    p.add_argument('--boards', choices=('sim', 'firmware'), default='sim',
                   help="'sim': the Python board simulators (fast); 'firmware': the boards' real firmware "
                        "in simavr (fw_board, docs/firmware.md; the AVRs run in real time)")
    p.add_argument('--flow', type=ranged_float(0.0, 1.0e5, unit='L/h'), default=FLOW_LPH, metavar='LPH',
                   help=f'water pumped through the absorber [L/h] when the site config counts a flow meter '
                        f'(absorber_board flow_meter_pin; default {FLOW_LPH:g}: seed 003 section 3.2; 0: pump stopped)')
    p.add_argument('--no-report', action='store_true', help='skip the day report at the end')
    p.add_argument('--wall-clock', action='store_true',
                   help='run on the system clock as on the Pi: from now (UTC) to --end (default: 10 min '
                        'from now) at real time, no /clock, the nodes on system time (not with --date, '
                        '--start or --speed)')
    return p


def _wait_links(paths: dict[str, Path], progs: dict[str, Program], timeout: float,
                stop: StopSignals) -> dict[str, float]:
    """Wait for each simulator's pty symlink; return board -> monotonic time it appeared."""
    seen: dict[str, float] = {}
    deadline = time.monotonic() + timeout
    offset = time.time() - time.monotonic()
    while len(seen) < len(paths) and time.monotonic() < deadline:
        for board, path in paths.items():
            if board in seen:
                continue
            try:
                st = os.lstat(path)
            except FileNotFoundError:
                if not progs[board].alive():
                    raise RuntimeError(f'simulated board {board} exited (code {progs[board].proc.returncode}); '
                                       f'see its log') from None
                continue
            seen[board] = min(time.monotonic(), st.st_mtime - offset)
        stop.wait(0.005)
    missing = set(paths) - set(seen)
    if missing:
        raise RuntimeError(f'simulated boards without a pty after {timeout:.0f} s: {", ".join(sorted(missing))}')
    return seen


def main(argv: list[str]) -> int:
    """``sslfr sim``: 0 at the end of the window (and a report), 1 when the node set
    cannot run (start-up failed, a node refused its configuration), 2 for bad
    arguments or configs, 130 when a stop signal ended the run. Every child started is
    ended whatever signal arrives and whenever (start-up included); the run directory
    is removed."""
    with StopSignals() as stop:
        run = Path(tempfile.mkdtemp(prefix='sslfr-sim-'))   # short paths: UNIX sockets <= 107 bytes
        try:
            args = parser().parse_args(argv)
            if args.collectors is not None:
                from sslfr_sim.field_sim import run_field
                return run_field(args, stop, run)
            return _main(args, stop, run)
        except CliError as exc:
            print(f'sslfr sim: error: {one_line(exc)}', file=sys.stderr)
            return 2
        except Interrupted as exc:
            print(f'sslfr sim: stopped by {exc} during start-up', file=sys.stderr)
            return 130
        finally:
            shutil.rmtree(run, ignore_errors=True)


def operator_references(ns, ros, say) -> None:
    """The simulated operator references each drive without switches (seed 003) once its
    driver is active, as the installer does on site: the simulated board starts at the
    description's sleeping position, which is its reference angle (``home`` service:
    "the axis is now at home_position"). RuntimeError when a driver refuses."""
    for node in ns.nodes:
        if node.parameters.get('drive') != DriveKind.STEPPER_NO_SWITCHES.value:
            continue
        axis = node.parameters['axis']
        ok, message = ros.trigger(AXIS_HOME.of(axis).lstrip('/'), 20.0)
        if not ok:
            raise RuntimeError(f'the operator reference of {axis} was refused: {message}')
        say(f'sslfr sim: simulated operator referenced {axis}: {message}')


def wall_clock_window(now: float, end: str | None) -> tuple[str, float, float]:
    """A ``--wall-clock`` run from ``now`` [s since the epoch]: (UTC date, start, end [s
    since that date's midnight]). ``end`` HH:MM[:SS] UTC is the next such time (tomorrow's
    when it is not after now: a run across midnight); None: 10 minutes."""
    date = dt.datetime.fromtimestamp(now, dt.timezone.utc).date().isoformat()
    start_s = now - day_epoch(date)
    end_s = parse_hhmm(end) if end else start_s + 600.0
    if end_s <= start_s:
        end_s += 86400.0
    return date, start_s, end_s


def _main(args, stop: StopSignals, run: Path) -> int:  # noqa: C901 - the sequence of a simulated day
    t_wall0 = time.monotonic()
    try:
        ns = nodeset_mod.load(args.nodeset)
        if args.namespace is not None:
            ns = dataclasses.replace(ns, namespace=args.namespace)
        config = nodeset_mod.resolve_config(args.config, default=ns.config)
        ns = select(nodeset_mod.for_config(ns, config), args.only, args.skip)
        ns.processes(args.layout)                    # an unknown layout: KeyError naming the known ones
        params = nodeset_mod.checked_params(ns, config)
        simcfg = ns.sim
        mono0 = time.monotonic()
        if args.wall_clock:
            if args.date or args.start or args.speed not in (None, 1.0):
                raise ValueError('--wall-clock runs from now at real time: no --date, --start or --speed')
            date, start_s, end_s = wall_clock_window(time.time() + (time.monotonic() - mono0), args.end)
            speed = 1.0
        else:
            date = args.date or str(simcfg.get('date', '2026-06-21'))
            start_s = parse_hhmm(args.start or str(simcfg.get('start', '04:00')))
            end_s = parse_hhmm(args.end or str(simcfg.get('end', '20:00')))
            speed = float(args.speed if args.speed is not None else simcfg.get('speed', 400.0))
        if end_s <= start_s:
            raise ValueError('--end must be after --start')
        if not 0 < speed <= 5000:
            raise ValueError('--speed must be in (0, 5000]')
        day0 = day_epoch(date)
        faults = [faults_mod.parse(s, boards=tuple(ns.boards), nodes=[n.name for n in ns.nodes])
                  for s in args.fault]
        sets = [parse_set(s, [n.name for n in ns.nodes]) for s in args.set]
    except (ValueError, KeyError) as exc:   # NodeSetError and FaultSpecError are ValueErrors
        print(f'sslfr sim: {one_line(exc, keep_newlines=True)}', file=sys.stderr)
        return 2
    for f in faults:
        if f.board is not None and f.board not in {n.board for n in ns.nodes}:
            print(f'sslfr sim: fault {f.spec}: board {f.board} is not simulated in this node set', file=sys.stderr)
            return 2
        if f.kind == 'slip' and args.boards == 'firmware':
            print(f'sslfr sim: fault {f.spec}: a slipping coupling is simulated by the Python boards only '
                  '(--boards sim), not by the firmware harness', file=sys.stderr)
            return 2
        if f.kind == faults_mod.WIND_FAULT and f.duration / speed < faults_mod.WIND_MIN_WALL_S:
            print(f'sslfr sim: warning: fault {f.spec} lasts {f.duration / speed:.2f} wall seconds at --speed '
                  f'{speed:g}, less than two of the absorber board\'s pulse samples (4 Hz, the board\'s clock): '
                  f'its wind is averaged with the calm around it; give it at least '
                  f'{faults_mod.WIND_MIN_WALL_S * speed:.0f} s or a lower --speed', file=sys.stderr)
    try:                      # the default output is checked as --out is (a read-only cwd ...)
        out = (args.out or output_dir(f'out/sim-{date}')).resolve()
    except argparse.ArgumentTypeError as exc:
        print(f'sslfr sim: error: output directory: {one_line(exc)}', file=sys.stderr)
        return 2
    bag_root = Path(args.record).resolve() if args.record else out / 'bags'
    # a new run replaces the sim's own bags/ and logs/, never someone else's (--out ~)
    foreign = [d for d in ([] if args.record else [bag_root]) + [out / 'logs']
               if d.exists() and args.out and not (out / SIM_MARK).exists()]
    if foreign:
        print(f'sslfr sim: error: argument --out: {out} already holds {", ".join(d.name for d in foreign)} '
              'that sslfr sim did not make (it would replace them): choose another directory', file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    (out / SIM_MARK).touch()
    if not args.record and bag_root.exists():   # the sim's own output: a new run replaces it
        shutil.rmtree(bag_root)
    bag_root.mkdir(parents=True, exist_ok=True)
    logs = out / 'logs'
    if logs.exists():
        shutil.rmtree(logs)
    logs.mkdir()
    # --wall-clock: simulated time is the system clock from the start (no anchor to wait for)
    clock = SimClock(day0 + start_s, speed, anchor=mono0 if args.wall_clock else None)
    site = site_of(params)
    domain_lock = None
    if args.domain_id is None and not os.environ.get('ROS_DOMAIN_ID'):
        try:   # a simulation must never share its domain (and /clock) with anything else
            args.domain_id, domain_lock = acquire_domain()
        except RuntimeError as exc:
            print(f'sslfr sim: {exc}: pass --domain-id', file=sys.stderr)
            return 1
    try:
        env = nodeset_mod.ros_environment(ns, domain_id=args.domain_id, namespace=ns.namespace, run_dir=run)
        restart_wait = dds_profile.restart_wait(env)
        dds_profile.adopt_graph_partition(env)      # before this process's own ROS side starts
    except dds_profile.ProfileError as exc:
        print(f'sslfr sim: {exc}', file=sys.stderr)
        return 2
    env['SSLFR_SIM_WORLD'] = str(run / 'world.json')
    domain = int(env['ROS_DOMAIN_ID'])
    say = print
    say(f'sslfr sim: {date} {_hhmm(start_s)}-{_hhmm(end_s)} UTC '
        + ('on the system clock (no /clock, as on a Pi)' if args.wall_clock else f'at {speed:g}x')
        + f', config {config.name}, site {site["latitude_deg"]:.4f}, {site["longitude_deg"]:.4f}, '
        f'ROS_DOMAIN_ID={domain}, out {out}')

    # ---- simulated boards
    boards_needed = [b for b in ns.boards if any(n.board == b for n in ns.nodes)]
    board_progs: dict[str, Program] = {}
    links: dict[str, Path] = {}
    controls: dict[str, str] = {}
    missing: list[str] = []
    if args.boards == 'firmware':
        from sslfr_drivers.firmware import prepare_backend
        problem = prepare_backend()
        if problem:
            print(f'sslfr sim: --boards firmware: {problem}', file=sys.stderr)
            return 2
    # a fresh installation key per run (mode 0600 in the run directory): the simulated
    # boards are provisioned with it and every node with a board link uses it
    from sslfr_drivers.link.keys import generate, write_key_file
    key_file = write_key_file(run / 'installation.key', generate())
    for bname in boards_needed:
        board = ns.boards[bname]
        exe_name = board.sim_executable or ''
        if args.boards == 'firmware':
            from sslfr_drivers.firmware import backend_executable
            exe_name = backend_executable(exe_name) or exe_name
        exe = find_executable(board.sim_package or '', exe_name)
        if exe is None:
            missing.append(f'simulated board {bname} ({board.sim_package}/{board.sim_executable})')
            continue
        links[bname] = run / f'{bname}.pty'
        controls[bname] = str(run / f'{bname}.sock')
        values = {'pty': links[bname], 'control': controls[bname], 'start': f'{clock.start:.3f}',
                  'speed': f'{speed:g}', 'anchor': '{anchor}', 'axis': bname, 'config': str(config),
                  'seed': args.seed + len(board_progs), 'world': run / 'world.json', 'key_file': key_file,
                  **site}
        argv = nodeset_mod.sim_board_argv(board, exe, values) + _flow_options(bname, params, ns.namespace, args.flow)
        board_progs[bname] = Program(name=f'sim_{bname}', argv=argv,
                                     start=-1, stop=3, restart=False, kind='board')
    # ---- nodes (ports = the simulators' pty links)
    extra = {name: dict(v) for name, v in (simcfg.get('node_parameters') or {}).items()}
    for node in ns.nodes:
        if node.board:
            extra.setdefault(node.name, {})['key_file'] = str(key_file)
    for node, key, value in sets:
        extra.setdefault(node, {})[key] = value
    if any(n.name == 'recorder' for n in ns.nodes):
        extra.setdefault('recorder', {})['output_dir'] = str(bag_root)
    if any(n.name == 'planner' for n in ns.nodes):   # persisted site: per run, not ~/.local/state
        extra.setdefault('planner', {})['state_dir'] = str(out / 'state')
    sim_ports = {b: str(p) for b, p in links.items()}
    no_sim = [n for n in ns.nodes if n.board and n.board not in links]
    for node in no_sim:
        missing.append(f'{node.name}: its board {node.board} has no simulator, node not started')
    node_progs, missing_nodes = _node_programs(ns.without(n.name for n in no_sim) if no_sim else ns,
                                               config, sim_ports, extra, run, args.layout, params,
                                               use_sim_time=not args.wall_clock)
    missing += missing_nodes
    for m in missing:
        print(f'sslfr sim: MISSING {m}', file=sys.stderr)
    if not node_progs:
        print('sslfr sim: no node can run', file=sys.stderr)
        return 1

    from sslfr_bringup.up import add_local_discovery
    service_progs: list[Program] = []          # a field collector's own discovery server
    add_local_discovery(env, service_progs, lambda line: print(f'sslfr sim: {line}', file=sys.stderr))
    watch = _watch_topics(ns)
    axes = _axis_status_topics(ns)
    ros = RosSide(domain, namespace=ns.namespace, clock_fn=(lambda: None) if args.wall_clock else clock.published,
                  clock_rate=float(simcfg.get('clock_rate', 20.0)), node_name='sslfr_sim', watch={**watch, **axes})
    ros.start()
    sup = None
    try:
        failed = ros.wait_ready(stop)
        if failed:
            print(f'sslfr sim: ROS side failed: {failed}', file=sys.stderr)
            return 1
        log_stream = open(out / 'supervisor.log', 'w')  # noqa: SIM115
        sup = Supervisor(service_progs + list(board_progs.values()) + node_progs, env, backoff=ns.restart_backoff,
                         stable_after=ns.stable_after, stop_timeout=ns.stop_timeout, log_dir=logs,
                         liveness=LivenessWatch(ns.watchdog_timeout, ns.watchdog_startup),
                         ros=ros, out=_Tee(log_stream, sys.stderr, quiet=('[sslfr up] started ', ': lifecycle active')),
                         restart_wait=restart_wait)
        schedule = faults_mod.Schedule(faults)
        fired: list[dict] = []
        end_epoch = day0 + end_s
        state = {'last_report': 0.0, 'max_gap': 0.0, 'last_tick': time.monotonic()}
        census = MemoryCensus(sup)

        # Start-up (nothing of the simulated day is lost to it, however loaded the machine):
        # 1. the time-dependent boards (sensors) with their clock held at --start
        # (sim.sensors anchor=hold) and the axis boards, 2. the nodes, 3. when every node is
        # in the ROS graph, the axes are active and the sensor topics flow, the sensor
        # boards and /clock (nothing is published before) are anchored at one instant.
        timed = {b for b, p in board_progs.items() if any('{anchor}' in a for a in p.argv)}

        def wait_until(pred, timeout, what):
            """Supervise until ``pred()``; a node that refused its configuration, a
            stop signal or the time-out ends the start-up (RuntimeError)."""
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                sup.step()
                if sup.fatal:
                    raise RuntimeError(sup.fatal)
                if pred():
                    return
                stop.wait(0.02)
            dead = [f'{p.name}: {sup.last_error(p)}' for p in node_progs if p.last_exit is not None]
            raise RuntimeError(f'{what()} not ready after {timeout:.0f} s'
                               + (f'; nodes that exited: {"; ".join(dead)}' if dead else ''))

        def start_boards(names):
            for b in names:
                sup._spawn(board_progs[b])   # noqa: SLF001 - same supervisor, boards first
            return _wait_links({b: links[b] for b in names}, {b: board_progs[b] for b in names}, 30.0, stop)

        from sslfr_sim.runner import SimControl   # imported now, not at the anchor or the first fault (~1 s loaded)
        try:
            # the sensor simulators start slowly (they tabulate the day's sun): first, in parallel
            held = f'{mono0:.6f}' if args.wall_clock else 'hold'
            for p in service_progs:
                sup._spawn(p)   # noqa: SLF001 - before every participant
            for b in sorted(timed):
                board_progs[b].argv = [a.replace('{anchor}', held) for a in board_progs[b].argv]
                sup._spawn(board_progs[b])   # noqa: SLF001 - same supervisor, boards first
            start_boards([b for b in board_progs if b not in timed])
            for p in node_progs:
                sup._spawn(p)  # noqa: SLF001
            sup.say(f'axis simulators up, nodes started at +{time.monotonic() - t_wall0:.1f} s: '
                    + ', '.join(p.name for p in node_progs))
            _wait_links({b: links[b] for b in timed}, {b: board_progs[b] for b in timed}, 60.0, stop)
            sup.say(f'sensor simulators up at +{time.monotonic() - t_wall0:.1f} s')
            names = {n for p in node_progs for n in p.node_names}
            wait_until(lambda: names <= ros.graph_nodes, 60.0,
                       lambda: 'nodes in the ROS graph: ' + ', '.join(sorted(names - ros.graph_nodes)))
            lifecycle = [p for p in node_progs if p.lifecycle]
            wait_until(lambda: all(p.lifecycle_state == 'active' for p in lifecycle)
                       and all(ros.seen.get(t) for t in watch), 60.0,
                       lambda: 'axes active ({}) / sensor topics ({})'.format(
                           ', '.join(p.name for p in lifecycle if p.lifecycle_state != 'active') or 'all',
                           ', '.join(t for t in watch if not ros.seen.get(t)) or 'all'))
            sup.say(f'nodes in the graph, axes active, sensors flowing at +{time.monotonic() - t_wall0:.1f} s')
            operator_references(ns, ros, say)
            if axes and not args.wall_clock:
                # the axes reference themselves on the steady clock (homing, the sensor's
                # SET_ZERO, the operator's reference): done before the window starts, so that
                # no start-up stow is charged to it (at 30x a 1.4 s homing is 41 s of the
                # window); bounded, for an axis that cannot be referenced
                def homed():
                    return all(getattr(ros.last.get(t), 'homed', False) for t in axes)
                deadline = time.monotonic() + SETTLE_S
                wait_until(lambda: homed() or time.monotonic() >= deadline or stop.requested.is_set(),
                           SETTLE_S + 5.0, lambda: 'axes referenced')
                sup.say(f'axes referenced at +{time.monotonic() - t_wall0:.1f} s' if homed() else
                        f'axes not all referenced after {SETTLE_S:.0f} s more, starting anyway: '
                        + ', '.join(t for t in axes if not getattr(ros.last.get(t), 'homed', False)))
            if not args.wall_clock:
                anchor = time.monotonic() + ANCHOR_LEAD
                for b in sorted(timed):
                    try:
                        SimControl(controls[b], timeout=5.0).cmd(f'anchor {anchor:.6f}')
                    except (OSError, ValueError, RuntimeError) as exc:
                        raise RuntimeError(f'sensor simulator {b} could not be anchored: {exc}') from exc
                clock.set_anchor(anchor)
        except RuntimeError as exc:
            print(f'sslfr sim: start-up failed: {exc}', file=sys.stderr)
            return 1
        url = _page_url(logs)
        if url:
            say(f'sslfr sim: operator page at {url} (docs/operator.md)')
        t_nodes = time.monotonic()
        state['last_tick'] = t_nodes


        def tick():
            now_sim = clock.now()
            t_tick = time.monotonic()
            state['max_gap'] = max(state['max_gap'], t_tick - state['last_tick'])
            state['last_tick'] = t_tick
            for f, what in schedule.due(now_sim - day0):
                rec = {'spec': f.spec, 'what': what, 'sim_time': now_sim, 'wall': time.monotonic() - t_wall0}
                try:
                    if f.kind == 'kill':
                        if what == 'start':
                            sup.kill(f.target, hold=True)
                        else:
                            sup.release(f.target)
                        rec['result'] = 'ok'
                    elif f.kind == 'hang':
                        sup.hang(f.target)
                        rec['result'] = 'ok'
                    else:
                        ctl = SimControl(controls[f.board], timeout=2.0)
                        rec['result'] = [ctl.cmd(line).get('ok', False) for line in fault_commands(f, what, speed)]
                except Exception as exc:  # noqa: BLE001 - a failed injection is reported, the day goes on
                    rec['result'] = f'FAILED: {exc}'
                    print(f'sslfr sim: fault {f.spec} ({what}) could not be injected: {exc}', file=sys.stderr)
                rec['took_s'] = round(time.monotonic() - t_wall0 - rec['wall'], 3)
                fired.append(rec)
                say(f'sslfr sim: fault {f.spec} {what} at {_hhmm(now_sim - day0)} UTC: {rec["result"]}')
            if time.monotonic() - state['last_report'] >= 10.0:
                state['last_report'] = time.monotonic()
                say(f'sslfr sim: {_hhmm(now_sim - day0)} UTC (wall {time.monotonic() - t_wall0:.0f} s)')

        census.start()
        try:
            why = sup.run(stop, until=lambda: clock.now() >= end_epoch, tick=tick, period=0.02)
        finally:
            census.stop()
        stop_reason = {'until': 'end of the simulated window', 'signal': 'interrupted',
                       'fatal': f'stopped: {sup.fatal}'}[why]
        took = sup.stop_took
        ros.shutdown()
        log_stream.close()
        wall = time.monotonic() - t_wall0
        summary = {'date': date, 'start_utc': clock.start, 'end_utc': end_epoch, 'speed': speed, 'boards': args.boards,
                   'config': str(config), 'wall_time_s': round(wall, 2), 'stop_s': round(took, 2),
                   'startup_s': round(t_nodes - t_wall0, 2),
                   'faults': fired, 'missing': missing,
                   'stop_reason': stop_reason, 'bags': str(bag_root), 'logs': str(logs),
                   'restarts': {p.name: p.restarts for p in sup.programs.values() if p.restarts},
                   # the supervisor's process events [wall s since the command's start, program,
                   # event, detail]: started, hang, hung (liveness kill, with its cause), exited, restart...
                   'process_events': [[round(t - t_wall0, 3), name, event, detail]
                                      for t, name, event, detail in sup.events],
                   'clock_messages': ros.clock_published,
                   # the fault timer's longest pass-to-pass gap [s wall] (nominal 0.02 s) and its
                   # memory census's longest pass: a late injection shows here
                   'fault_timer_max_gap_s': round(state['max_gap'], 3), 'memory_census_max_s': round(census.longest, 3),
                   **census.summary()}
        (out / 'sim.json').write_text(json.dumps(summary, indent=2))
        say(f'sslfr sim: {stop_reason}; wall time {wall:.1f} s (stop {took:.2f} s); peak RSS of the node set '
            f'{summary["peak_rss_nodes_mb"]:.0f} MB (PSS {summary["peak_pss_nodes_mb"]:.0f} MB; '
            f'{len(node_progs)} processes; simulated boards '
            f'{summary["peak_rss_sim_boards_mb"]:.0f} MB); bag(s) in {bag_root}; logs in {logs}')
        if missing:
            say('sslfr sim: ran WITHOUT: ' + '; '.join(missing))
        if why == 'fatal':
            print(f'sslfr sim: {stop_reason}', file=sys.stderr)
            return 1
        if args.no_report:
            return 0 if why == 'until' else 130
        return _report(bag_root, out, config)

    finally:
        if sup is not None and not sup.stopping:
            sup.stop()
        ros.shutdown()


class MemoryCensus(threading.Thread):
    """Peak memory of the node set and of the simulated boards, sampled every ``period``
    wall seconds in its own thread (``Supervisor.rss(full=True)``: PSS from each
    process's smaps_rollup). Not on the fault timer: on a loaded 2-core machine one
    census took up to 7.7 s, which held back the next fault injection by as much."""

    def __init__(self, sup, period: float = 2.0):
        super().__init__(daemon=True, name='memory-census')
        self.sup, self.period = sup, period
        self._halt = threading.Event()
        self.peak_nodes = self.peak_pss = self.peak_boards = 0
        self.peak_detail: dict[str, tuple[int, int]] = {}
        self.longest = 0.0                  # [s] the longest census

    def run(self) -> None:
        while not self._halt.wait(self.period):
            t0 = time.monotonic()
            mem = self.sup.rss(full=True)
            self.longest = max(self.longest, time.monotonic() - t0)
            nodes = {k: v for k, v in mem.items() if not k.startswith('sim_')}
            rss_nodes = sum(v[0] for v in nodes.values())
            if rss_nodes > self.peak_nodes:
                self.peak_nodes, self.peak_detail = rss_nodes, mem
            self.peak_pss = max(self.peak_pss, sum(v[1] for v in nodes.values()))
            self.peak_boards = max(self.peak_boards, sum(v[0] for k, v in mem.items() if k.startswith('sim_')))

    def stop(self) -> None:
        self._halt.set()
        if self.is_alive():
            self.join(10.0)

    def summary(self) -> dict:
        """The sim.json fields: peaks [MB]."""
        mb = 2.0 ** 20
        return {'peak_rss_nodes_mb': round(self.peak_nodes / mb, 1),
                'peak_pss_nodes_mb': round(self.peak_pss / mb, 1),
                'peak_rss_sim_boards_mb': round(self.peak_boards / mb, 1),
                'rss_pss_at_peak_mb': {k: [round(v[0] / mb, 1), round(v[1] / mb, 1)]
                                       for k, v in self.peak_detail.items()}}


def _flow_options(board: str, params, namespace: str, lph: float) -> list[str]:
    """The absorber simulator's flow meter options when the site config counts one
    (``absorber_board`` ``flow_meter_pin`` >= 0): ``lph`` [L/h] at the config's K-factor,
    and the collector description (its optics focus the sun: the thermal output is
    measured against its aperture)."""
    from sslfr_drivers.sensors.sensor_params import ABSORBER_BOARD
    namespace = namespace or ''
    if namespace.strip('/'):             # the config as its nodes get it (sslfr_bringup.nodeset.site_config)
        params = nodeset_mod.for_namespace(params, namespace)
    node = nodeset_mod.node_params(params, 'absorber_board', namespace)
    if board != 'absorber' or node.get('flow_meter_pin', -1) < 0:
        return []
    k = node.get('flow_meter_k_factor', ABSORBER_BOARD.defaults()['flow_meter_k_factor'])
    out = ['--opt', f'flow_lph={lph:g}', '--opt', f'flow_k_factor={float(k):g}']
    desc = nodeset_mod.node_params(params, 'planner', namespace).get(nodeset_mod.DESCRIPTION_KEY)
    return out + (['--opt', f'description={desc}'] if desc else [])


def _node_programs(ns, config, sim_ports, extra, run_dir, layout=None, params=None, use_sim_time=True):
    from sslfr_bringup.up import build_programs
    return build_programs(ns, config, sim_ports=sim_ports, use_sim_time=use_sim_time, extra=extra,
                          run_dir=run_dir, layout=layout, params=params)


def _report(bag_root: Path, out: Path, config: Path) -> int:
    """Run the day report on the newest bag under ``bag_root``, its ideal from the run's
    site ``config``."""
    bags = sorted((p for p in bag_root.iterdir() if (p / 'metadata.yaml').exists()),
                  key=lambda p: p.stat().st_mtime) if bag_root.exists() else []
    if not bags:
        print(f'sslfr sim: no bag was recorded in {bag_root}: no report', file=sys.stderr)
        return 1
    try:
        from sslfr_recording import report_cli
    except ImportError:
        print('sslfr sim: MISSING the report module (sslfr_recording.report_cli): no report', file=sys.stderr)
        return 1
    code = int(report_cli.main([str(bags[-1]), '--out', str(out / 'report'), '--config', str(config)]) or 0)
    print(f'plots: {out / "report"}/*.png')
    return code


def _page_url(logs: Path) -> str | None:
    """The operator page's address, as the ``web`` node logged it (port 0 in a sim)."""
    import re
    try:
        m = re.search(r'operator page at (\S+)', (logs / 'web.log').read_text(errors='replace'))
    except OSError:
        return None
    return m.group(1) if m else None


def _hhmm(sod: float) -> str:
    """HH:MM:SS of ``sod`` [s since the run's UTC midnight]; '(+N d)' past that day."""
    sod = max(0.0, sod)
    days, sod = divmod(sod, 86400.0)
    more = f' (+{int(days)} d)' if days else ''
    return f'{int(sod // 3600):02d}:{int(sod % 3600 // 60):02d}:{int(sod % 60):02d}{more}'


class _Tee:
    """Supervisor messages: all to the log file, the important ones also to stderr."""

    def __init__(self, fh, stream, quiet=()):
        self.fh, self.stream, self.quiet = fh, stream, quiet

    def write(self, text: str) -> None:
        self.fh.write(text)
        if text.strip() and not any(q in text for q in self.quiet):
            self.stream.write(text)

    def flush(self) -> None:
        self.fh.flush()
        self.stream.flush()


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
