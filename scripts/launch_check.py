#!/usr/bin/env python3
"""``python scripts/launch_check.py [--layout separate|composed] [--config FILE] [--keep DIR]``

The launch path's restart of a hung node process, checked with the REAL ``ros2 launch``
(docs/deploy.md "Restart after a hang"): ``ros2 launch sslfr_bringup tracker.launch.py``
runs the node set against the simulated boards (``sim_board`` on ptys, on the system
clock, as ``./sslfr sim --wall-clock`` starts them) in a private ROS domain, and

1. the axis drivers reach ``active``;
2. each process of ``--hang`` (default: safety, then mirrors_driver) is sent SIGSTOP:
   the launch's ``liveness_watchdog`` SIGKILLs it within the bound (``watchdog_timeout``
   of silence since its last beat) and prints the cause, launch respawns it after its
   ``respawn_delay``, the new process beats again (the watchdog watches its pid), the
   drivers are active again, safety is back to OK and the planner to its phase;
3. each process of ``--kill`` (default: planner) is sent SIGKILL and respawned after
   ``respawn_delay`` too.

Prints one line per step with its timings [s wall] and ends with ``N passed, N failed``.
Where ``ros2 launch`` is not installed (the PyPI wheels carry no launch) it says so and
exits 0 without checking anything: ``make test`` does not need it. Needs the project's
environment (``. scripts/env.sh``) and ROS 2's ``launch``/``launch_ros``/``ros2launch``
on the path (apt ``ros-jazzy-launch-ros``, or built from source).
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import yaml


def ros2_launch_missing() -> str | None:
    """Why ``ros2 launch`` cannot run here, or None when it can."""
    if shutil.which('ros2') is None:
        return 'no `ros2` on PATH'
    try:
        res = subprocess.run(['ros2', 'launch', '--help'], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f'`ros2 launch --help` failed: {exc}'
    if res.returncode != 0:
        return f'`ros2 launch --help` failed: {(res.stderr or res.stdout).strip().splitlines()[-1:]}'
    return None


class LaunchOutput(threading.Thread):
    """Reads the launch's merged output line by line, keeps every line with its arrival
    time [monotonic s] and copies it to ``log``."""

    def __init__(self, stream, log):
        super().__init__(daemon=True)
        self.stream, self.log = stream, log
        self.lines: list[tuple[float, str]] = []
        self.lock = threading.Lock()

    def run(self):
        for line in self.stream:
            with self.lock:
                self.lines.append((time.monotonic(), line.rstrip('\n')))
            self.log.write(line)
            self.log.flush()

    def find(self, pattern: str, after: float = 0.0) -> tuple[float, str] | None:
        rx = re.compile(pattern)
        with self.lock:
            for t, line in self.lines:
                if t >= after and rx.search(line):
                    return t, line
        return None


def wait_for(pred, timeout: float, step: float = 0.05):
    """``pred()``'s first true value within ``timeout`` [s], else None."""
    deadline = time.monotonic() + timeout
    while True:
        value = pred()
        if value:
            return value
        if time.monotonic() >= deadline:
            return None
        time.sleep(step)


def start_boards(ns, config: Path, run: Path, env: dict) -> tuple[list[subprocess.Popen], dict[str, str], Path]:
    """The node set's simulated boards on ptys, on the system clock (start = now, speed
    1), provisioned with a fresh installation key: (processes, board -> pty, key file)."""
    from sslfr_bringup import nodeset
    from sslfr_bringup.host import find_executable
    from sslfr_drivers.link.keys import generate, write_key_file
    from sslfr_sim.sim_cli import site_of

    params = nodeset.checked_params(ns, config)
    key_file = write_key_file(run / 'installation.key', generate())
    site = site_of(params)
    now, mono = time.time(), time.monotonic()
    procs, links = [], {}
    for i, bname in enumerate(b for b in ns.boards if any(n.board == b for n in ns.nodes)):
        board = ns.boards[bname]
        exe = find_executable(board.sim_package or '', board.sim_executable or '')
        if exe is None:
            raise RuntimeError(f'the simulator of board {bname} is not installed: run make setup')
        link = run / f'{bname}.pty'
        values = {'pty': link, 'control': run / f'{bname}.sock', 'start': f'{now:.3f}', 'speed': '1',
                  'anchor': f'{mono:.6f}', 'axis': bname, 'config': str(config), 'seed': i,
                  'world': run / 'world.json', 'key_file': key_file, **site}
        log = open(run / f'sim_{bname}.log', 'w')  # noqa: SIM115 - closed with the process
        procs.append(subprocess.Popen(nodeset.sim_board_argv(board, exe, values), env=env, stdout=log,
                                      stderr=subprocess.STDOUT, start_new_session=True))
        links[bname] = str(link)
    if not wait_for(lambda: all(Path(p).exists() for p in links.values()), 60.0):
        raise RuntimeError('simulated boards not up after 60 s: ' + ', '.join(
            b for b, p in links.items() if not Path(p).exists()))
    return procs, links, key_file


def site_config(ns, config: Path, run: Path, links: dict[str, str], key_file: Path) -> Path:
    """The site config with each board node's ``port`` (its simulator's pty) and
    ``key_file``, the recorder's and planner's directories in ``run`` and the page on a
    free port: what ``./sslfr sim`` gives the nodes as overrides, here in the one params
    file launch takes."""
    from sslfr_bringup import nodeset
    from sslfr_planner import description as desc_mod

    doc = yaml.safe_load(config.read_text())
    planner = doc.setdefault('planner', {}).setdefault('ros__parameters', {})
    name = planner.get(nodeset.DESCRIPTION_KEY)
    if isinstance(name, str) and name:       # the description relative to the original config
        planner[nodeset.DESCRIPTION_KEY] = str(desc_mod.resolve(name, config.parent))
    planner['state_dir'] = str(run / 'state')
    for node in ns.nodes:
        section = doc.setdefault(node.name, {}).setdefault('ros__parameters', {})
        if node.board:
            section.update(port=links[node.board], key_file=str(key_file))
    doc.setdefault('recorder', {}).setdefault('ros__parameters', {})['output_dir'] = str(run / 'bags')
    doc.setdefault('web', {}).setdefault('ros__parameters', {})['port'] = 0
    out = run / 'site.yaml'
    out.write_text(yaml.safe_dump(doc, sort_keys=False))
    return out


class Observer:
    """A ROS node in the launch's domain: the last ``safety/state`` level and the axis
    drivers' lifecycle states."""

    def __init__(self, domain: int):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from sslfr_interfaces.msg import SafetyState, TrackerPhase

        from sslfr_common.contract import SAFETY_STATE, TRACKER_PHASE
        from sslfr_common.node import qos

        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx, domain_id=domain)
        self.node = rclpy.create_node('sslfr_launch_check', context=self.ctx)
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.safety: list[tuple[float, int, list[str]]] = []
        self.phase: list[tuple[float, str]] = []
        self.node.create_subscription(SafetyState, SAFETY_STATE.name, self._on_safety, 10)
        self.node.create_subscription(TrackerPhase, TRACKER_PHASE.name,
                                      lambda m: self.phase.append((time.monotonic(), m.phase_name)),
                                      qos(TRACKER_PHASE))
        self.lock = threading.Lock()
        self._stop = False
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()

    def _spin(self):
        while not self._stop:
            with self.lock:
                self.executor.spin_once(timeout_sec=0.05)

    def _on_safety(self, msg):
        self.safety.append((time.monotonic(), msg.level, list(msg.reasons)))

    def phase_name(self) -> str | None:
        return self.phase[-1][1] if self.phase else None

    def reasons_naming(self, node: str, start: float, end: float) -> tuple[int, str] | None:
        """The highest safety level in [start, end] whose reasons name ``node``, with
        that reason."""
        hits = [(level, r) for t, level, reasons in self.safety if start <= t <= end
                for r in reasons if node in r]
        return max(hits) if hits else None

    def safety_level(self, since: float = 0.0) -> int | None:
        last = [s for s in self.safety if s[0] >= since]
        return last[-1][1] if last else None

    def lifecycle(self, name: str) -> str | None:
        from sslfr_drivers.axis.lifecycle_ctl import get_state
        with self.lock:                  # the spin thread waits: get_state spins the executor
            return get_state(self.node, name, timeout=1.0, executor=self.executor)

    def close(self):
        import rclpy
        self._stop = True
        self.thread.join(2.0)
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)


def node_processes(launch_pid: int, node: str) -> list[int]:
    """Pids of the launch's children that run ``node`` (its own process, or the
    composed process that holds it)."""
    import psutil
    out = []
    for p in psutil.Process(launch_pid).children(recursive=True):
        try:
            cmd = p.cmdline()
        except psutil.Error:
            continue
        if f'__node:={node}' in cmd:
            out.append(p.pid)
    return out


def main(argv=None) -> int:  # noqa: C901 - one sequence of checks
    p = argparse.ArgumentParser(prog='launch_check', description=__doc__.split('\n\n')[0])
    p.add_argument('--layout', default='separate', help='layout:= of the launch (default separate)')
    p.add_argument('--config', default=None, help='site params file (default: the node set\'s)')
    p.add_argument('--hang', default='safety,mirrors_driver', help='nodes whose process is SIGSTOPped, in turn')
    p.add_argument('--kill', default='planner', help='nodes whose process is SIGKILLed, in turn')
    p.add_argument('--no-kill-watchdog', dest='kill_watchdog', action='store_false',
                   help='leave the liveness_watchdog alone (default: SIGKILL it first: respawned, it watches again)')
    p.add_argument('--keep', default=None, help='keep the run directory (launch output, board logs) here')
    args = p.parse_args(argv)

    why = ros2_launch_missing()
    if why:
        print(f'launch_check: skipped: ros2 launch is not installed ({why})')
        return 0

    import psutil

    from sslfr_bringup import dds_profile, nodeset
    from sslfr_bringup.host import acquire_domain

    ns0 = nodeset.load()
    config = nodeset.resolve_config(args.config, default=ns0.config)
    ns = nodeset.for_config(ns0, config)
    domain, _lock = acquire_domain()
    run = Path(args.keep).resolve() if args.keep else Path(tempfile.mkdtemp(prefix='sslfr-launch-check-'))
    run.mkdir(parents=True, exist_ok=True)
    env = nodeset.ros_environment(ns, domain_id=domain)
    env['ROS_LOG_DIR'] = str(run / 'roslog')
    bound = ns.watchdog_timeout
    delay = max(2.0, dds_profile.restart_wait(env))     # what tracker.launch.py gives respawn_delay
    results: list[tuple[bool, str]] = []

    def check(ok: bool, text: str):
        results.append((bool(ok), text))
        print(f'launch_check: {"ok  " if ok else "FAIL"} {text}', flush=True)

    print(f'launch_check: ROS_DOMAIN_ID={domain}, layout {args.layout}, bound {bound:g} s, '
          f'respawn_delay {delay:g} s, run directory {run}', flush=True)
    boards, launch, out, obs = [], None, None, None
    try:
        boards, links, key_file = start_boards(ns, config, run, env)
        site = site_config(ns, config, run, links, key_file)
        log = open(run / 'launch.log', 'w')  # noqa: SIM115
        t0 = time.monotonic()
        launch = subprocess.Popen(['ros2', 'launch', 'sslfr_bringup', 'tracker.launch.py', f'config:={site}',
                                   f'domain_id:={domain}', f'layout:={args.layout}'],
                                  env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                  start_new_session=True)
        out = LaunchOutput(launch.stdout, log)
        out.start()
        obs = Observer(domain)
        drivers = [n.name for n in ns.lifecycle_nodes()]

        def watched(since: float) -> set[str]:
            """The pids the watchdog announced it watches since ``since``."""
            with out.lock:
                lines = [line for t, line in out.lines if t >= since]
            return {m.group(1) for line in lines for m in [re.search(r'watching pid (\d+)', line)] if m}

        def all_active():
            return all(obs.lifecycle(d) == 'active' for d in drivers)
        ok = wait_for(all_active, 120.0, 0.5)
        check(ok, f'started: drivers {", ".join(drivers)} active at +{time.monotonic() - t0:.1f} s')
        if not ok:
            return 1
        # the start-up's stow (axes referencing, nodes not heard yet) cleared: safety OK
        # and the planner's phase past the start-up's STOW (it follows safety's OK a moment later)
        wait_for(lambda: obs.safety_level(time.monotonic() - 1.0) == 0 and obs.phase_name() not in (None, 'STOW'),
                 60.0)
        before = obs.safety_level()
        phase = obs.phase_name()
        check(before == 0 and phase, f'safety OK after the start-up, level {before} {obs.safety[-1][2] if obs.safety else ""}; '
              f'phase {phase}')
        # every process beats: the watchdog watches as many pids as there are processes
        nprocs = len(ns.processes(args.layout))
        ok = wait_for(lambda: len(watched(0.0)) >= nprocs, 60.0)
        check(ok, f'the liveness_watchdog watches every node process ({nprocs})')

        if args.kill_watchdog:
            # the watchdog itself: launch respawns it (respawn_delay 1 s); the new one binds the
            # same socket and learns every node process again from its next beat
            wd = [q for q in psutil.Process(launch.pid).children(recursive=True)
                  if any(a.endswith('liveness_watchdog') for a in q.cmdline()[:2])]
            if len(wd) != 1:
                check(False, f'kill liveness_watchdog: {len(wd)} watchdog processes')
            else:
                ts = time.monotonic()
                wd[0].kill()
                again = wait_for(lambda: len(watched(ts)) >= nprocs, 30.0)
                check(again, f'kill liveness_watchdog: respawned, watching every node process again '
                      f'{time.monotonic() - ts:.1f} s after its death' if again
                      else f'kill liveness_watchdog: the new watchdog watches {len(watched(ts))} of {nprocs} '
                      'processes after 30 s')

        for kind, names in (('hang', args.hang), ('kill', args.kill)):
            for node in [n for n in names.split(',') if n]:
                pids = node_processes(launch.pid, node)
                if len(pids) != 1:
                    check(False, f'{kind} {node}: {len(pids)} processes run it')
                    continue
                pid = pids[0]
                ts = time.monotonic()
                os.kill(pid, signal.SIGSTOP if kind == 'hang' else signal.SIGKILL)
                killed = None
                if kind == 'hang':
                    killed = wait_for(lambda: out.find(rf'\(pid {pid}\): .*killed \(SIGKILL\)', ts), bound + 10.0)
                    check(killed and bound - 1.0 <= killed[0] - ts <= bound + 1.5,
                          f'hang {node} (pid {pid}): killed by the liveness_watchdog after '
                          f'{killed[0] - ts:.1f} s (bound {bound:g} s): {killed[1].strip()}' if killed
                          else f'hang {node} (pid {pid}): not killed within {bound + 10:g} s')
                    if not killed:
                        os.kill(pid, signal.SIGKILL)
                died = wait_for(lambda: out.find(rf'process has died \[pid {pid}', ts), 15.0)
                check(died, f'{kind} {node}: launch saw the exit at +{died[0] - ts:.1f} s: {died[1].strip()}'
                      if died else f'{kind} {node}: launch did not report the exit of pid {pid}')
                t_dead = died[0] if died else time.monotonic()
                new = wait_for(lambda: [q for q in node_processes(launch.pid, node) if q != pid], 30.0, 0.02)
                t_new = time.monotonic()
                check(new and delay - 0.2 <= t_new - t_dead <= delay + 3.0,
                      f'{kind} {node}: respawned (pid {new[0]}) {t_new - t_dead:.1f} s after the exit '
                      f'(respawn_delay {delay:g} s)' if new else f'{kind} {node}: not respawned within 30 s')
                if not new:
                    continue
                beat = wait_for(lambda: out.find(rf'watching pid {new[0]}\b', ts), 60.0)
                check(beat, f'{kind} {node}: the new process beats (watched) at +{beat[0] - t_new:.1f} s after '
                      'its respawn' if beat else f'{kind} {node}: no beat from the new process within 60 s')
                # the phase as before (or the day's next one: the stow, only if it was stowed before)
                back = wait_for(lambda: all_active() and obs.safety_level(time.monotonic() - 0.5) == before
                                and (obs.phase_name() == phase or 'STOW' not in (obs.phase_name(), phase)),
                                60.0, 0.5)
                if node not in ('safety', 'recorder', 'web'):    # safety watches the others
                    said = obs.reasons_naming(node, ts, time.monotonic())
                    check(said, f'{kind} {node}: safety level {said[0]} while it was away: {said[1]!r}' if said
                          else f'{kind} {node}: no safety reason named it while it was away')
                check(back, f'{kind} {node}: drivers active, safety level {before} and phase {obs.phase_name()} again '
                      f'{time.monotonic() - t_new:.1f} s after the respawn' if back
                      else f'{kind} {node}: not recovered within 60 s (safety {obs.safety_level()}: '
                      f'{obs.safety[-1][2] if obs.safety else ""})')
        # the stop: SIGINT as from a terminal; every process ends, the run directory goes
        sock = out.find(r'listening on (\S+)/notify\.sock')
        children = psutil.Process(launch.pid).children(recursive=True)
        ts = time.monotonic()
        os.killpg(launch.pid, signal.SIGINT)
        code = launch.wait(60)
        left = [q.pid for q in children if q.is_running() and q.status() != psutil.STATUS_ZOMBIE]
        check(not left, f'stop (SIGINT): launch exited ({code}) after {time.monotonic() - ts:.1f} s'
              + (f'; processes left: {left}' if left else ', no process left'))
        run_dir = re.search(r'listening on (\S+)/notify\.sock', sock[1]).group(1) if sock else None
        check(run_dir and not Path(run_dir).exists(), f'the launch\'s run directory {run_dir} removed at its stop')
    except Exception as exc:  # noqa: BLE001 - reported as a failed check
        check(False, f'{type(exc).__name__}: {exc}')
    finally:
        if obs is not None:
            obs.close()
        if launch is not None and launch.poll() is None:
            os.killpg(launch.pid, signal.SIGINT)
            try:
                launch.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(launch.pid, signal.SIGKILL)
                launch.wait(5)
        for b in boards:
            if b.poll() is None:
                b.terminate()
                b.wait(10)
        if out is not None:
            out.join(5)
        if not args.keep:
            shutil.rmtree(run, ignore_errors=True)
    passed = sum(ok for ok, _ in results)
    print(f'{passed} passed, {len(results) - passed} failed')
    return 0 if results and passed == len(results) else 1


if __name__ == '__main__':
    sys.exit(main())
