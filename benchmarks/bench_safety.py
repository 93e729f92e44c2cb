"""Benchmark: the safety supervisor.

1. Rules core (sslfr_safety.core + the rule table): one simulated hour of a
   tracking day at the real message rates (2 thermocouples at 4 Hz, switches at 10 Hz,
   3 axis statuses at 5 Hz (motion and driver report: two core events each),
   phase/beam/fix at 1 Hz) and a verdict at 20 Hz, on a fake clock: cost per event and
   per verdict, and the CPU share it would take at the real rates.
2. Node (optional, ``--node``; needs a build): the real ``safety`` process, N over-
   temperature samples published from this process -> time until the STOW verdict is
   received here (issue goal: STOW published within 200 ms of the sample's arrival).

Run: . scripts/env.sh && python benchmarks/bench_safety.py [--node] [-n 20]
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from sslfr_common.contract import JOINTS as AXES
from sslfr_common.contract import SWITCHES, LinkState
from sslfr_safety.core import FakeClock, SafetyConfig, SafetyCore

ROOT = Path(__file__).resolve().parents[1]


def bench_core(hours: float = 1.0) -> None:
    clock = FakeClock()
    core = SafetyCore(SafetyConfig(), clock)
    dt = 0.05                                   # 20 Hz verdicts
    steps = int(hours * 3600 / dt)
    open_ = dict.fromkeys(SWITCHES, False)
    events = verdicts = 0
    t0 = time.perf_counter()
    for k in range(steps):
        clock.advance(dt)
        if k % 5 == 0:                          # 4 Hz thermocouples
            core.on_temperature('inlet', 60.0 + 0.25 * (k % 3))
            core.on_temperature('outlet', 80.0 + 0.25 * (k % 2))
            events += 2
        if k % 2 == 0:                          # 10 Hz switches
            core.on_limit_switches(open_)
            events += 1
        if k % 4 == 0:                          # 5 Hz axis statuses
            for axis in AXES:
                core.on_axis_status(axis, False, 0.3, commanded=0.3)
                core.on_driver_state(axis, 'following', LinkState.LINK_UP, True)
            events += 6
        if k % 20 == 0:                         # 1 Hz phase, beam, fix
            core.on_phase(2, 'gps')
            core.on_beam(850.0)
            core.on_gps_fix(True)
            events += 3
        core.evaluate()
        verdicts += 1
    wall = time.perf_counter() - t0
    assert core.state.level == 0, core.state
    per = wall / (events + verdicts)
    print(f'core: {hours:.1f} h of traffic ({events} events, {verdicts} verdicts) in {wall:.2f} s: '
          f'{per * 1e6:.1f} us per call; CPU share at real rates {wall / (hours * 3600) * 100:.3f} %')


def bench_node(n: int) -> None:
    sys.path.insert(0, str(ROOT / 'tests'))
    from harness import RosHarness, acquire_test_domain, executable

    from sensor_msgs.msg import Temperature
    from std_srvs.srv import Trigger

    from sslfr_interfaces.msg import SafetyState
    dom, lock = acquire_test_domain()
    env = dict(os.environ, ROS_DOMAIN_ID=str(dom), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    # only over-temperature matters here: no site rule, one watchdog that never fires
    argv = [str(executable('sslfr_safety', 'safety')), '--ros-args',
            '-p', 'temperature.cool_hold:=0.0', '-p', 'temperature.hysteresis:=0.0',
            '-p', 'require_site_and_time:=false', '-p', 'watchdog.nodes:=["gps"]',
            '-p', 'watchdog.timeouts:=[1000.0]', '-p', 'watchdog.actions:=["WARN"]']
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ros = RosHarness(dom)
    try:
        got: list = []
        ros.node.create_subscription(SafetyState, 'safety/state', lambda m: got.append((time.monotonic(), m)), 10)
        pub = ros.node.create_publisher(Temperature, 'absorber/outlet_temperature', 10)
        client = ros.node.create_client(Trigger, 'safety/reset')
        assert ros.spin_until(lambda: got and client.service_is_ready(), 20), 'safety did not start'
        ros.spin_for(0.5)
        lat = []
        for _ in range(n):
            pub.publish(Temperature(temperature=100.0))
            ros.spin_for(0.1)
            k = len(got)
            t0 = time.monotonic()
            pub.publish(Temperature(temperature=151.0))
            ros.spin_until(lambda k=k: any(m.level >= 2 for _, m in got[k:]), 2.0)
            hit = [t for t, m in got[k:] if m.level >= 2]
            if hit:
                lat.append(hit[0] - t0)
            pub.publish(Temperature(temperature=100.0))
            ros.spin_for(0.1)
            fut = client.call_async(Trigger.Request())
            ros.spin_until(fut.done, 5.0)
        lat.sort()
        print(f'node: over-temperature sample published -> STOW received, {len(lat)}/{n} samples: '
              f'median {statistics.median(lat) * 1e3:.1f} ms, p90 {lat[int(0.9 * (len(lat) - 1))] * 1e3:.1f} ms, '
              f'max {lat[-1] * 1e3:.1f} ms (goal 200 ms)')
    finally:
        ros.close()
        proc.terminate()
        proc.wait(10)
        lock.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--node', action='store_true', help='also measure the real node process')
    ap.add_argument('-n', type=int, default=20, help='over-temperature samples for --node')
    args = ap.parse_args()
    bench_core()
    if args.node:
        bench_node(args.n)


if __name__ == '__main__':
    main()
