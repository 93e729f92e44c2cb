"""Bag benchmarks: write, read and replay a full simulated day; recorder CPU at the
full graph's message rate.

    python benchmarks/bench_bag.py [--hours 24] [--skip-recorder]

Figures printed:
- writer: messages/s writing a day of 1 Hz + 10 Hz topics with BagWriter;
- reader: messages/s through BagReader (raw) and with decoding;
- conformance check and ``recover --dry-run`` of the day bag (every chunk scanned);
- replay: wall time of ``sslfr replay --rate 0`` (as fast as possible) of the full day,
  as a multiple of real time (goal >= 1000x), and at ``--rate 1000`` the lag;
- recorder: CPU share of the recorder process while a publisher process sends the
  full graph's message mix (~97 msg/s, docs/architecture.md), measured with psutil.

Measured 2026-11-21 on the 2-core x86 development VM, shared with other jobs
(figures vary with load):

    writer: 950400 messages (86400 s of 1 Hz + 10 Hz) in 66.8 s = 14,222 msg/s, 29.5 MB
    reader (raw): 950400 messages in 5.7 s = 167,195 msg/s
    reader (decoded via schema, mcap_ros2): 24,007 msg/s
    replay --rate 0 of 86400 s: 8.4 s wall = x10,313 real time (goal >= 1000x)
        [replayed 950400 messages in 6.75 s (x12797 real time), process start excluded]
    recorder CPU at the full graph rate (97 msg/s, 16 topics): 10.7 % of one core

2026-11-22, --hours 6, load average 18-24 on the 2 cores (so every figure slow):

    conformance check (rosbag2 rules, every chunk scanned): 1.7 s = 4.4 MB/s, 0 finding(s)
    recover --dry-run (full scan): 3.4 s
"""
from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: The full graph's topics and rates [Hz] from docs/architecture.md (3 axes).
GRAPH_RATES = {
    'gps/fix': ('sensor_msgs/msg/NavSatFix', 1), 'gps/time_reference': ('sensor_msgs/msg/TimeReference', 1),
    'tracker/sun': ('sslfr_interfaces/msg/SunPosition', 1), 'tracker/phase': ('sslfr_interfaces/msg/TrackerPhase', 1),
    'tracker/trajectory': ('trajectory_msgs/msg/JointTrajectory', 0.2),
    'joint_states': ('sensor_msgs/msg/JointState', 30),
    'axes/mirrors/status': ('sslfr_interfaces/msg/AxisStatus', 5),
    'axes/mobile_structure/status': ('sslfr_interfaces/msg/AxisStatus', 5),
    'axes/secondary_reflector/status': ('sslfr_interfaces/msg/AxisStatus', 5),
    'absorber/inlet_temperature': ('sensor_msgs/msg/Temperature', 4),
    'absorber/outlet_temperature': ('sensor_msgs/msg/Temperature', 4),
    'limit_switches': ('sslfr_interfaces/msg/LimitSwitches', 10),
    'irradiance/illuminance': ('sensor_msgs/msg/Illuminance', 1),
    'irradiance/beam': ('sslfr_interfaces/msg/Irradiance', 1),
    'safety/state': ('sslfr_interfaces/msg/SafetyState', 20),
    'diagnostics': ('diagnostic_msgs/msg/DiagnosticArray', 8),
}


def write_day(directory: Path, seconds: int, t0_ns: int = 1_782_000_000 * 10**9) -> int:
    """A day of /tracker/sun at 1 Hz and /joint_states at 10 Hz; return message count."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from sslfr_interfaces.msg import SunPosition

    from sslfr_recording.bag import BagWriter, WriterOptions, profile
    w = BagWriter(directory, WriterOptions(fsync=False))
    w.add_topic('/tracker/sun', 'sslfr_interfaces/msg/SunPosition', [profile()])
    w.add_topic('/joint_states', 'sensor_msgs/msg/JointState', [profile()])
    sun = SunPosition(algorithm='spa')
    js = JointState(name=['mirrors'], position=[0.0], velocity=[0.0])
    n = 0
    for s in range(seconds):
        t = t0_ns + s * 10**9
        sun.header.stamp.sec = t // 10**9
        sun.zenith = 0.5 + s * 1e-5
        w.write('/tracker/sun', serialize_message(sun), t)
        n += 1
        for k in range(10):
            tk = t + k * 100_000_000
            js.header.stamp.sec, js.header.stamp.nanosec = divmod(tk, 10**9)
            js.position[0] = 1e-5 * (s * 10 + k)
            w.write('/joint_states', serialize_message(js), tk)
            n += 1
    w.close()
    return n


def bench_replay(bag: Path, rate: float) -> tuple[float, str]:
    env = dict(os.environ, ROS_DOMAIN_ID=str(150 + os.getpid() % 50))
    t = time.monotonic()
    out = subprocess.run([str(ROOT / 'sslfr'), 'replay', str(bag), '--rate', str(rate), '--no-progress'],
                         env=env, capture_output=True, text=True, check=True)
    return time.monotonic() - t, out.stdout.strip()


def bench_recorder(seconds: float = 20.0) -> None:
    import psutil
    tmp = Path(tempfile.mkdtemp(prefix='bench_rec_'))
    env = dict(os.environ, ROS_DOMAIN_ID=str(200 + os.getpid() % 30))
    exe = ROOT / 'ros_ws/install/sslfr_recording/lib/sslfr_recording/recorder'
    rec = subprocess.Popen([str(exe), '--ros-args', '-p', f'output_dir:={tmp}'], env=env,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    pub_code = f'''
import importlib, time, rclpy
rates = {GRAPH_RATES!r}
rclpy.init(); n = rclpy.create_node("bench_graph")
pubs = []
for topic, (typ, hz) in rates.items():
    pkg, _, name = typ.split("/")
    cls = getattr(importlib.import_module(pkg + ".msg"), name)
    pubs.append((n.create_publisher(cls, topic, 10), cls(), 1.0 / hz))
t0 = time.monotonic(); due = [t0] * len(pubs); count = 0
while time.monotonic() - t0 < {seconds + 4}:
    now = time.monotonic()
    for i, (p, m, per) in enumerate(pubs):
        while due[i] <= now:
            p.publish(m); due[i] += per; count += 1
    time.sleep(0.005)
print(count / (time.monotonic() - t0))
'''
    pub = subprocess.Popen([sys.executable, '-c', pub_code], env=env, stdout=subprocess.PIPE, text=True)
    proc = psutil.Process(rec.pid)
    time.sleep(4.0)  # discovery
    c0 = proc.cpu_times()
    t0 = time.monotonic()
    time.sleep(seconds)
    c1 = proc.cpu_times()
    dt = time.monotonic() - t0
    rate = float(pub.communicate()[0].strip() or 0)
    os.killpg(rec.pid, signal.SIGINT)
    rec.wait(10)
    cpu = (c1.user - c0.user + c1.system - c0.system) / dt
    print(f'recorder CPU at the full graph rate ({rate:.0f} msg/s, {len(GRAPH_RATES)} topics): '
          f'{100 * cpu:.1f} % of one core (mean over {seconds:.0f} s)')
    out = subprocess.run([str(ROOT / 'sslfr'), 'bag', 'info', str(next(tmp.iterdir()))],
                         capture_output=True, text=True)
    print('  recorded:', [line for line in out.stdout.splitlines() if line.startswith('Messages')])
    shutil.rmtree(tmp, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument('--hours', type=float, default=24.0)
    ap.add_argument('--skip-recorder', action='store_true')
    ns = ap.parse_args()
    seconds = int(ns.hours * 3600)
    tmp = Path(tempfile.mkdtemp(prefix='bench_bag_'))
    bag = tmp / 'day'
    try:
        t = time.monotonic()
        n = write_day(bag, seconds)
        dt = time.monotonic() - t
        size = sum(p.stat().st_size for p in bag.glob('*.mcap'))
        print(f'writer: {n} messages ({seconds} s of 1 Hz + 10 Hz) in {dt:.1f} s = {n / dt:,.0f} msg/s, '
              f'{size / 1e6:.1f} MB')
        from sslfr_recording.bag import BagReader
        r = BagReader(bag)
        t = time.monotonic()
        k = sum(1 for _ in r.messages())
        dt = time.monotonic() - t
        print(f'reader (raw): {k} messages in {dt:.1f} s = {k / dt:,.0f} msg/s')
        from sslfr_recording.bag.conformance import check_bag
        from sslfr_recording.bag.recover import recover_bag
        t = time.monotonic()
        rep = check_bag(bag)
        dt = time.monotonic() - t
        print(f'conformance check (rosbag2 rules, every chunk scanned): {dt:.1f} s = '
              f'{size / 1e6 / dt:.1f} MB/s, {len(rep.findings)} finding(s)')
        t = time.monotonic()
        recover_bag(bag, write=False)
        dt = time.monotonic() - t
        print(f'recover --dry-run (full scan): {dt:.1f} s')
        t = time.monotonic()
        k = sum(1 for _ in r.decoded(['/tracker/sun']))
        dt = time.monotonic() - t
        print(f'reader (decoded via schema, mcap_ros2): {k / dt:,.0f} msg/s')
        wall, out = bench_replay(bag, 0)
        print(f'replay --rate 0 of {seconds} s: {wall:.1f} s wall = x{seconds / wall:,.0f} real time '
              f'(goal >= 1000x)  [{out}]')
        if seconds <= 3 * 3600:
            wall, out = bench_replay(bag, 1000)
            print(f'replay --rate 1000: {wall:.1f} s wall for {seconds / 1000:.1f} s nominal [{out}]')
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    if not ns.skip_recorder:
        bench_recorder()
    return 0


if __name__ == '__main__':
    sys.exit(main())
