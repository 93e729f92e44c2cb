"""Benchmark: the operator page's node on the running node set, at real time.

Starts ``./sslfr sim --speed 1`` (the whole node set against simulated boards, real
time: the message rates of a real tracker), then measures the ``web`` node process:

- CPU [% of one core] over ``--seconds`` with no page open, then with ``--clients``
  pages connected (Server-Sent Events, one state push every push_period), and the
  planner's CPU over the same windows (a peer in the same run);
- memory: RSS and PSS [MB] (psutil; PSS divides shared libraries among processes);
- page load over HTTP: time to fetch / and its assets (what a browser downloads first)
  and their total size;
- topic-to-page delay is measured by tests/test_web_node.py (publication -> SSE event)
  and the browser's own delay by tests/test_web_browser.py.

    python benchmarks/bench_web.py [--seconds 30] [--clients 2]
"""
from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[1]


def find_node(root: int, name: str) -> psutil.Process | None:
    """The node process ``name`` started by the simulation ``root`` (not another run's)."""
    for p in psutil.Process(root).children(recursive=True):
        try:
            if f'__node:={name}' in p.cmdline():
                return p
        except psutil.Error:
            continue
    return None


def cpu_percent(procs: dict[str, psutil.Process], seconds: float) -> dict[str, float]:
    t0 = {k: p.cpu_times() for k, p in procs.items()}
    w0 = time.monotonic()
    time.sleep(seconds)
    wall = time.monotonic() - w0
    out = {}
    for k, p in procs.items():
        t1 = p.cpu_times()
        out[k] = 100.0 * ((t1.user - t0[k].user) + (t1.system - t0[k].system)) / wall
    return out


def sse_client(url: str, stop: threading.Event, counts: list) -> None:
    with urllib.request.urlopen(url + 'api/events', timeout=30) as r:
        for line in r:
            if line.startswith(b'event: state'):
                counts[0] += 1
            if stop.is_set():
                return


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--seconds', type=float, default=30.0)
    ap.add_argument('--clients', type=int, default=2)
    args = ap.parse_args()
    out = Path(tempfile.mkdtemp(prefix='bench-web-'))
    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', str(200 + os.getpid() % 30))
    dur = int(args.seconds * 2 + 120)
    end = time.strftime('%H:%M', time.gmtime(10 * 3600 + dur + 60))
    cmd = [str(ROOT / 'sslfr'), 'sim', '--speed', '1', '--start', '10:00', '--end', end, '--no-report',
           '--out', str(out),
           '--layout', 'separate']      # the web node in its own process: its CPU and memory alone
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT,
                            start_new_session=True)
    try:
        url = None
        deadline = time.monotonic() + 120
        while url is None and time.monotonic() < deadline and proc.poll() is None:
            log = out / 'logs' / 'web.log'
            m = re.search(r'operator page at (http://\S+/)', log.read_text()) if log.exists() else None
            url = m.group(1) if m else None
            time.sleep(0.5)
        web, planner = find_node(proc.pid, 'web'), find_node(proc.pid, 'planner')
        if not (url and web and planner):
            print('bench_web: the node set did not start (see', out / 'logs', ')', file=sys.stderr)
            return 1
        time.sleep(15.0)                                   # settle: start-up transients
        t0 = time.monotonic()
        sizes = 0
        for path in ('', 'static/app.js', 'static/style.css'):
            with urllib.request.urlopen(url + path, timeout=10) as r:
                sizes += len(r.read())
        load_ms = (time.monotonic() - t0) * 1000
        idle = cpu_percent({'web': web, 'planner': planner}, args.seconds)
        stop, counts = threading.Event(), [0]
        threads = [threading.Thread(target=sse_client, args=(url, stop, counts), daemon=True)
                   for _ in range(args.clients)]
        for t in threads:
            t.start()
        time.sleep(2.0)
        n0 = counts[0]
        busy = cpu_percent({'web': web, 'planner': planner}, args.seconds)
        rate = (counts[0] - n0) / args.seconds / max(1, args.clients)
        stop.set()
        mem = web.memory_full_info()
        load = os.getloadavg()
        print(f'web node, node set at real time (sim --speed 1), load average {load[0]:.1f} {load[1]:.1f}:')
        print(f'  CPU, no page open:          web {idle["web"]:.1f} %   planner {idle["planner"]:.1f} % of one core')
        print(f'  CPU, {args.clients} pages connected:     web {busy["web"]:.1f} %   planner {busy["planner"]:.1f} % '
              f'({rate:.1f} state pushes/s per page)')
        print(f'  memory: RSS {mem.rss / 2**20:.1f} MB, PSS {mem.pss / 2**20:.1f} MB, USS {mem.uss / 2**20:.1f} MB')
        print(f'  page + assets over HTTP: {load_ms:.0f} ms, {sizes / 1024:.1f} KiB')
        return 0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)


if __name__ == '__main__':
    sys.exit(main())
