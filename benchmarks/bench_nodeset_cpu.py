"""Benchmark: CPU and memory of the whole node set at real time (issue 16's budget).

Runs ``./sslfr sim --speed 1`` (12:00 UTC at Almeria: the mirrors tracking, every
sensor reporting), waits until the set is up, then measures over ``--window`` wall
seconds the CPU time (user + system, psutil) of every node process and its threads
(the simulated boards excluded: they are not on the Pi), and their PSS at the end.
Prints CPU per node and in total as % of one core of this machine, the PSS sum, and
the ratio to the 119 % measured before the CPU work (issue 16: 9 processes, the same
command, 140 s). Goal: total <= 15 % of one core, PSS <= 200 MB.

``--confine F`` runs the node processes in a cgroup limited to F of one core (cgroup
v1 ``cpu.cfs_quota_us`` or v2 ``cpu.max``, root needed) - the Raspberry Pi 3 budget is
about 0.4 of one core of this machine - and ``--fault SPEC`` passes faults to the sim
(e.g. ``overtemp@12:01`` or ``kill:safety@12:01``; a restarted node process is put in
the cgroup too, but its CPU time is not in the figures: they follow the processes
present at the start of the window). ``--layout`` chooses the process
layout of the node set (composed, separate). With ``--json FILE`` the figures are also
written as JSON.

The deadlines are watched live from a ROS node of this script (in the sim's domain,
not counted in the CPU figures): the gaps of each ``axes/<axis>/status`` heartbeat, the
tracking error |measured - setpoint| of every status while following (in motor steps),
the over-temperature reaction (first outlet sample over the limit -> ``safety/state``
STOW -> mirrors status ``stowing``) and, after a killed safety supervisor, the last
``safety/state`` -> each axis status ``stopped`` (with ``--fault`` the drivers' status
runs at 20 Hz instead of 5 Hz: the observation adds at most 50 ms, and costs CPU). Load averages at start and end are printed:
CPU figures taken while other jobs load the machine must say so.

``--wall-clock`` measures the node set as it runs on a Pi: ``sslfr sim --wall-clock``
(the nodes on the system clock, no ``/clock`` messages, which only a simulation or a
replay publishes), at the latitude of Almeria and the longitude where the sun is near
its noon at the time of the run (a copy of the site config), so that the mirrors track
as at 12:00 UTC at Almeria. Fault times (``--fault kind@+SECONDS``) are then seconds
from the start of the run.

``--executor rclpy`` runs the nodes with rclpy's SingleThreadedExecutor instead of
sslfr_common's LeanExecutor; ``--peer`` runs both at once (two node sets, own domains,
same window) and prints the ratio, so that a loaded or throttled machine affects both.
``--peer-root DIR`` runs the same benchmark of another checkout (the previous code: a
``git worktree`` of the last release, set up with its own ``make setup``) at the same
time instead, and prints this code's total over that one's.

    python benchmarks/bench_nodeset_cpu.py [--window 140] [--confine 0.4] [--layout NAME] [--peer]
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[1]
BEFORE_TOTAL = 119.0      # [% of one core] issue 16, the node set before the CPU work


def node_processes(root_pid: int) -> dict[str, psutil.Process]:
    """Node processes under ``root_pid`` by their ROS node name(s) (``__node:=``);
    a process running several nodes is named after all of them."""
    out = {}
    try:
        procs = psutil.Process(root_pid).children(recursive=True)
    except psutil.Error:
        return out
    for p in procs:
        try:
            cmd = p.cmdline()
        except psutil.Error:
            continue
        if any('sim_board' in c or 'fwsim' in c or 'fw_board' in c for c in cmd[:3]) or 'setpriv' in cmd[0]:
            continue
        names = [m.group(1) for c in cmd for m in [re.match(r'__node:=(\S+)', c)] if m]
        if names:
            out['+'.join(names)] = p
        elif any(c.endswith(('/composed', '/nodeset_process')) for c in cmd[:2]):
            out[next((c for c in cmd if c.startswith('--group=')), 'composed')] = p
    return out


class Observer:
    """Watches the deadlines on the sim's topics (see the module docstring)."""

    def __init__(self, domain: int):
        import threading

        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from sensor_msgs.msg import Temperature
        from sslfr_common.contract import JOINTS, TEMPERATURE_LIMIT_C
        from sslfr_interfaces.msg import AxisStatus, SafetyState

        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node('bench_nodeset_observer', context=self.ctx)
        self.safety: list[tuple[float, int, tuple]] = []
        self.status: dict[str, list[tuple[float, str, float]]] = {a: [] for a in JOINTS}
        self.hot: list[float] = []
        now = time.monotonic

        def on_temp(m):
            if m.temperature > TEMPERATURE_LIMIT_C:
                self.hot.append(now())
        self.node.create_subscription(Temperature, 'absorber/outlet_temperature', on_temp, 10)
        self.node.create_subscription(SafetyState, 'safety/state',
                                      lambda m: self.safety.append((now(), m.level, tuple(m.reasons))), 10)
        for axis in JOINTS:
            self.node.create_subscription(
                AxisStatus, f'axes/{axis}/status',
                lambda m, a=axis: self.status[a].append((now(), m.state, m.error)), 10)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.limit = TEMPERATURE_LIMIT_C
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        while self.ctx.ok():
            try:
                self.executor.spin_once(timeout_sec=0.1)
            except Exception:  # noqa: BLE001 - context shut down
                return

    def close(self):
        import rclpy
        rclpy.try_shutdown(context=self.ctx)
        self._thread.join(2.0)

    def report(self, t0: float, t1: float) -> dict:
        """Deadlines seen between monotonic ``t0`` and ``t1``."""
        from sslfr_common.contract import STEP_ANGLE
        out: dict = {'status_gap_max_s': {}, 'tracking_error_steps': {}}
        for axis, rows in self.status.items():
            rows = [r for r in rows if t0 <= r[0] <= t1]
            t = [r[0] for r in rows]
            out['status_gap_max_s'][axis] = round(max((b - a for a, b in zip(t, t[1:])), default=float('nan')), 3)
            err = sorted(abs(r[2]) / STEP_ANGLE for r in rows if r[1] == 'following' and r[2] == r[2])
            if err:
                out['tracking_error_steps'][axis] = {'max': round(err[-1], 2),
                                                     'p99': round(err[int(0.99 * (len(err) - 1))], 2),
                                                     'n': len(err)}
        hot = [t for t in self.hot if t >= t0]
        if hot:
            stow = next((t for t, lvl, rs in self.safety if t >= hot[0] and lvl >= 2
                         and any('over-temperature' in r for r in rs)), None)
            mirrors = next((t for t, st, _ in self.status['mirrors'] if t >= hot[0] and st == 'stowing'), None)
            out['overtemp'] = {'sample_to_safety_stow_ms': None if stow is None else round(1000 * (stow - hot[0]), 1),
                               'sample_to_mirrors_stowing_ms':
                                   None if mirrors is None else round(1000 * (mirrors - hot[0]), 1)}
        arrivals = [t for t, _, _ in self.safety if t0 <= t <= t1]
        gaps = [(b - a, a) for a, b in zip(arrivals, arrivals[1:])]
        last = max(gaps)[1] if gaps and max(gaps)[0] > 1.0 else (arrivals[-1] if arrivals and arrivals[-1] < t1 - 2 else None)
        if last is not None:
            out['safety_silent'] = {a: next((round(t - last, 3) for t, st, _ in rows if t > last and st in ('stopped', 'stowing')),
                                            None) for a, rows in self.status.items()}
        return out


def noon_site(out: Path) -> Path:
    """A copy of the Almeria site config at the longitude where it is about solar noon
    now (+-4 deg: the equation of time is left out), for ``--wall-clock``."""
    utc_h = (time.time() % 86400) / 3600.0
    lon = ((12.0 - utc_h) * 15.0 + 180.0) % 360.0 - 180.0
    src = (ROOT / 'src/sslfr_bringup/config/almeria_sslfr.yaml').read_text()
    text = re.sub(r'site\.longitude_deg: -?[0-9.]+', f'site.longitude_deg: {lon:.4f}', src, count=1)
    path = out / 'noon_site.yaml'
    path.write_text(text)
    return path


def wall_fault(spec: str) -> str:
    """``kind@+SECONDS[+DURATION]`` -> ``kind@HH:MM:SS[+DURATION]`` (UTC, from now)."""
    m = re.match(r'(.*)@\+(\d+(?:\.\d+)?)(\+.*)?$', spec)
    if not m:
        raise SystemExit(f'bench: with --wall-clock a fault is kind@+SECONDS[+DURATION], got {spec!r}')
    at = time.strftime('%H:%M:%S', time.gmtime(time.time() + float(m.group(2))))
    return f'{m.group(1)}@{at}{m.group(3) or ""}'


def cpu_seconds(p: psutil.Process) -> float:
    t = p.cpu_times()
    return t.user + t.system


class Cgroup:
    """A CPU-limited cgroup (v2 cpu.max or v1 cpu.cfs_quota_us) for node processes."""

    def __init__(self, fraction: float):
        self.path = None
        name = f'sslfr-bench-{os.getpid()}'
        v2, v1 = Path('/sys/fs/cgroup'), Path('/sys/fs/cgroup/cpu')
        period = 100_000
        quota = int(fraction * period)
        if (v2 / 'cgroup.controllers').exists():
            self.path = v2 / name
            self.path.mkdir()
            (self.path / 'cpu.max').write_text(f'{quota} {period}')
        elif (v1 / 'cpu.cfs_quota_us').exists():
            self.path = v1 / name
            self.path.mkdir()
            (self.path / 'cpu.cfs_period_us').write_text(str(period))
            (self.path / 'cpu.cfs_quota_us').write_text(str(quota))
        else:
            raise OSError('no cgroup cpu controller')
        self.how = f'cgroup {"v2 cpu.max" if (v2 / "cgroup.controllers").exists() else "v1 cfs quota"} ' \
                   f'{quota}/{period} us'

    def add(self, pid: int) -> None:
        (self.path / 'cgroup.procs').write_text(str(pid))

    def throttled(self) -> str:
        try:
            stat = dict(line.split() for line in (self.path / 'cpu.stat').read_text().splitlines())
            return f'throttled {stat.get("nr_throttled", "?")} of {stat.get("nr_periods", "?")} periods'
        except OSError:
            return ''

    def remove(self) -> None:
        if self.path is None:
            return
        parent = self.path.parent
        for line in (self.path / 'cgroup.procs').read_text().split():
            try:
                (parent / 'cgroup.procs').write_text(line)
            except OSError:
                pass
        try:
            self.path.rmdir()
        except OSError:
            pass


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--window', type=float, default=140.0, help='measurement window [s wall]')
    ap.add_argument('--start', default='12:00', help='simulated start HH:MM UTC')
    ap.add_argument('--confine', type=float, default=None, help='CPU share of one core for the nodes')
    ap.add_argument('--fault', action='append', default=[], help='fault spec for the sim')
    ap.add_argument('--set', action='append', default=[], help='NODE:KEY=VALUE for the sim')
    ap.add_argument('--json', default=None, help='write the figures to this file')
    ap.add_argument('--keep', action='store_true', help='keep the sim output directory')
    ap.add_argument('--nodeset', default=None, help='node-set description for the sim (e.g. another sim.clock_rate)')
    ap.add_argument('--layout', default=None, help='process layout of the node set (composed, separate; '
                                                   'default: the node set\'s)')
    ap.add_argument('--executor', choices=('lean', 'rclpy'), default='lean',
                    help="the nodes' executor (SSLFR_EXECUTOR): sslfr_common's LeanExecutor or rclpy's")
    ap.add_argument('--wall-clock', action='store_true',
                    help='the node set on the system clock as on a Pi (sslfr sim --wall-clock, no /clock), '
                         'at a longitude where it is near solar noon now')
    ap.add_argument('--peer', action='store_true',
                    help="also run, at the same time and in its own domain, the same node set with rclpy's "
                         "SingleThreadedExecutor (the peer), and print the ratio of the two totals")
    ap.add_argument('--peer-root', default=None,
                    help='run the same benchmark of the checkout DIR (the previous code) at the same time, '
                         'in its own domain, and print the ratio of the two totals')
    args = ap.parse_args(argv)
    peer = None
    if args.peer or args.peer_root:
        given = list(sys.argv[1:] if argv is None else argv)
        rest = [a for i, a in enumerate(given) if a not in ('--peer', '--peer-root')
                and not (i and given[i - 1] == '--peer-root') and not a.startswith('--peer-root=')]
        peer_json = Path(tempfile.mkdtemp(prefix='bench-cpu-peer-')) / 'peer.json'
        if args.peer_root:
            root = Path(args.peer_root).resolve()
            cmd = ['bash', '-c', '. scripts/env.sh && exec python benchmarks/bench_nodeset_cpu.py "$@"', 'bench',
                   *rest, '--json', str(peer_json)]
            env = {k: v for k, v in os.environ.items() if k not in ('PYTHONPATH', 'AMENT_PREFIX_PATH', 'VIRTUAL_ENV')}
            peer = subprocess.Popen(cmd, cwd=root, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        else:
            peer = subprocess.Popen([sys.executable, __file__, *rest, '--executor', 'rclpy', '--json', str(peer_json)],
                                    stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    minutes = int(args.window // 60) + 3
    out = Path(tempfile.mkdtemp(prefix='bench-cpu-'))
    if args.wall_clock:
        t_end = time.gmtime(time.time() + 60 * minutes)
        if t_end.tm_yday != time.gmtime().tm_yday:
            print('bench: --wall-clock runs within one UTC day: start it before 23:' + f'{60 - minutes:02d}',
                  file=sys.stderr)
            return 2
        end = time.strftime('%H:%M:%S', t_end)
        cmd = [str(ROOT / 'sslfr'), 'sim', '--wall-clock', '--end', end, '--config', str(noon_site(out)),
               '--no-report', '--out', str(out)]
        args.fault = [wall_fault(f) for f in args.fault]
    else:
        h, m = (int(x) for x in args.start.split(':'))
        end = f'{(h + (m + minutes) // 60) % 24:02d}:{(m + minutes) % 60:02d}'
        cmd = [str(ROOT / 'sslfr'), 'sim', '--speed', '1', '--start', args.start, '--end', end,
               '--no-report', '--out', str(out)]
    if args.layout:
        cmd += ['--layout', args.layout]
    if args.nodeset:
        cmd += ['--nodeset', args.nodeset]
    for f in args.fault:
        cmd += ['--fault', f]
    for s in args.set:
        cmd += ['--set', s]
    if args.fault:        # a reaction to observe: the drivers' status at 20 Hz (50 ms resolution)
        for axis in ('mirrors', 'mobile_structure', 'secondary_reflector'):
            cmd += ['--set', f'{axis}_driver:status_rate=20.0']
    load0 = os.getloadavg()
    group = Cgroup(args.confine) if args.confine else None
    import threading
    done = threading.Event()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True, env=dict(os.environ, SSLFR_EXECUTOR=args.executor))
    lines: list[str] = []
    try:
        for line in proc.stdout:
            lines.append(line)
            if group is not None and 'nodes started at' in line:
                for p in node_processes(proc.pid).values():
                    group.add(p.pid)
            if 'sensors flowing at' in line or 'start-up failed' in line:
                break
        if proc.poll() is not None or 'start-up failed' in lines[-1]:
            print(''.join(lines[-40:]), file=sys.stderr)
            return 1
        if group is not None:              # nodes restarted since: confine them too
            for p in node_processes(proc.pid).values():
                group.add(p.pid)
        threading.Thread(target=lambda: [lines.append(ln) for ln in proc.stdout], daemon=True).start()
        domain = int(re.search(r'ROS_DOMAIN_ID=(\d+)', ''.join(lines)).group(1))
        observer = Observer(domain)
        if group is not None:             # a node process restarted later (a fault) is confined too
            def confine_restarted():
                while proc.poll() is None and not done.is_set():
                    for p in node_processes(proc.pid).values():
                        try:
                            group.add(p.pid)
                        except OSError:
                            pass
                    time.sleep(0.5)
            threading.Thread(target=confine_restarted, daemon=True).start()
        time.sleep(5.0)                   # settle: the first trajectory, first homing done
        procs = node_processes(proc.pid)
        t0 = time.monotonic()
        c0 = {n: cpu_seconds(p) for n, p in procs.items()}
        time.sleep(args.window)
        wall = time.monotonic() - t0
        deadlines = observer.report(t0, t0 + wall)
        observer.close()
        cpu, pss, rss = {}, {}, {}
        for n, p in procs.items():
            try:
                cpu[n] = 100.0 * (cpu_seconds(p) - c0[n]) / wall
                info = p.memory_full_info()
                pss[n], rss[n] = info.pss / 2**20, info.rss / 2**20
            except psutil.Error:
                cpu[n] = float('nan')
        throttled = group.throttled() if group is not None else ''
    finally:
        done.set()
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(60)
            except subprocess.TimeoutExpired:
                proc.kill()
        if group is not None:
            group.remove()
    total = sum(v for v in cpu.values() if v == v)
    load1 = os.getloadavg()
    how = ('sslfr sim --wall-clock: system clock, no /clock, near solar noon at Almeria\'s latitude'
           if args.wall_clock else f'sslfr sim --speed 1, {args.start} UTC Almeria')
    print(f'node set at real time ({how}, layout '
          f'{args.layout or "default"}, executor {args.executor}), {len(cpu)} processes, {wall:.0f} s window, load average (1/5/15 min) '
          f'{load0[0]:.1f}/{load0[1]:.1f}/{load0[2]:.1f} at start, {load1[0]:.1f}/{load1[1]:.1f}/{load1[2]:.1f} at end'
          + (f', confined to {args.confine:.2f} core ({group.how}; {throttled})' if group else ''))
    for n in sorted(cpu, key=lambda k: -cpu[k]):
        print(f'  {n:<44} CPU {cpu[n]:6.2f} %   PSS {pss.get(n, 0):6.1f} MB   RSS {rss.get(n, 0):6.1f} MB')
    print(f'total CPU {total:.1f} % of one core (goal <= 15 %); before: {BEFORE_TOTAL:.0f} % '
          f'-> ratio {BEFORE_TOTAL / total:.1f}x' if total else 'no CPU measured')
    print(f'PSS sum {sum(pss.values()):.0f} MB (goal <= 200 MB), RSS sum {sum(rss.values()):.0f} MB')
    if peer is not None:
        text, _ = peer.communicate(timeout=args.window + 300)
        try:
            other = json.loads(peer_json.read_text())
        except (OSError, ValueError):
            print('peer run failed:\n' + text[-3000:])
            return 1
        po = other['total_cpu_percent']
        who = (f'the code of {args.peer_root}' if args.peer_root else "rclpy's SingleThreadedExecutor")
        ratio = 'this code / that code' if args.peer_root else 'LeanExecutor / rclpy'
        print(f"peer in the same window ({who}, own domain): total CPU {po:.1f} % "
              f'({", ".join(f"{k} {v:.2f}" for k, v in sorted(other["cpu_percent"].items(), key=lambda kv: -kv[1]))}); '
              f'{ratio} = {total / po:.2f}' if po else 'peer: no CPU measured')
        for n in sorted(cpu):
            if n in other['cpu_percent'] and other['cpu_percent'][n]:
                print(f'  {n:<44} {cpu[n]:6.2f} % vs {other["cpu_percent"][n]:6.2f} %  '
                      f'({cpu[n] / other["cpu_percent"][n]:.2f})')
    print(f'status heartbeat, largest gap [s]: {deadlines["status_gap_max_s"]}')
    print(f'tracking error while following [motor steps] (bound: 1 step + sensor noise): '
          f'{deadlines["tracking_error_steps"]}')
    if 'overtemp' in deadlines:
        print(f'over-temperature (goal: stow frame <= 200 ms): {deadlines["overtemp"]}')
    if 'safety_silent' in deadlines:
        print(f'safety silent -> axis stopped [s] (goal <= 1.2 s): {deadlines["safety_silent"]}')
    sim = {}
    try:
        sim = json.loads((out / 'sim.json').read_text())
    except (OSError, ValueError):
        pass
    if args.json:
        Path(args.json).write_text(json.dumps({'cpu_percent': cpu, 'total_cpu_percent': total,
                                               'pss_mb': pss, 'rss_mb': rss, 'window_s': wall,
                                               'confine': args.confine, 'throttled': throttled,
                                               'layout': args.layout, 'executor': args.executor,
                                               'load_start': load0, 'load_end': load1,
                                               'deadlines': deadlines,
                                               'out': str(out), 'sim': sim}, indent=2))
    if not args.keep and not args.json:
        import shutil
        shutil.rmtree(out, ignore_errors=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
