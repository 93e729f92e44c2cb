#!/usr/bin/env python3
"""Soak the topic-level tests: run them N times and print, per test, runs, failures
and the slowest duration (``make soak N=5``; ``make soak N=3 BUSY=1``).

The tests run as ``make test`` runs them: on two pytest-xdist workers, a test file
per worker at a time (``--workers``). With ``--busy`` a busy loop occupies one of the
machine's cores for the whole soak (a process spinning in pure Python, pinned to the
last CPU when the machine allows it) and the tests run on one worker by default, i.e.
on the one core left, to show that the tests' deadlines follow from the graph's
contract and not from an idle machine. Each round is a separate ``pytest`` process
writing JUnit XML; a round that fails does not stop the soak. Exit status: 0 when every
run of every test passed, 1 otherwise.
"""
from __future__ import annotations

import argparse
import multiprocessing
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _busy_loop() -> None:             # pragma: no cover - runs in a child process
    try:
        os.sched_setaffinity(0, {max(os.sched_getaffinity(0))})
    except (AttributeError, OSError):
        pass
    while True:
        pass


def _cases(xml_path: Path):
    """(nodeid, seconds, outcome) of each test case in a JUnit XML file."""
    tree = ET.parse(xml_path)
    for case in tree.iter('testcase'):
        cls, name = case.get('classname', ''), case.get('name', '')
        nodeid = cls.replace('.', '/') + '.py::' + name if cls else name
        outcome = 'passed'
        for child in case:
            if child.tag in ('failure', 'error'):
                outcome = 'failed'
            elif child.tag == 'skipped' and outcome == 'passed':
                outcome = 'skipped'
        yield nodeid, float(case.get('time', 0.0)), outcome


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('-n', '--rounds', type=int, default=5, help='rounds of the test paths (default 5)')
    ap.add_argument('--busy', action='store_true', help='keep one core busy during the soak')
    ap.add_argument('--workers', type=int, default=None,
                    help='pytest-xdist workers (default 2 as in make test; 1 with --busy)')
    ap.add_argument('--logs', default=str(ROOT / 'out' / 'soak'),
                    help='directory for each round\'s pytest output (default out/soak)')
    ap.add_argument('paths', nargs='*', default=['tests', '--ignore-glob=tests/test_fw_*'],
                    help='test paths (default: tests/ without the firmware-in-the-loop tests '
                         'test_fw_*, which `make test` runs alone after the others)')
    args = ap.parse_args(argv)
    if args.rounds < 1:
        ap.error('--rounds must be >= 1')
    workers = args.workers or (1 if args.busy else 2)
    if workers < 1:
        ap.error('--workers must be >= 1')
    parallel = ['-n', str(workers), '--dist', 'loadfile'] if workers > 1 else []

    busy = None
    if args.busy:
        busy = multiprocessing.Process(target=_busy_loop, daemon=True)
        busy.start()
    runs: dict[str, int] = defaultdict(int)
    fails: dict[str, int] = defaultdict(int)
    slowest: dict[str, float] = defaultdict(float)
    t_start = time.monotonic()
    logs = Path(args.logs)
    logs.mkdir(parents=True, exist_ok=True)
    try:
        with tempfile.TemporaryDirectory(prefix='sslfr-soak-') as tmp:
            for k in range(1, args.rounds + 1):
                xml = Path(tmp) / f'round{k}.xml'
                t0 = time.monotonic()
                proc = subprocess.run([sys.executable, '-m', 'pytest', '-q', '-p', 'no:randomly', *parallel,
                                       f'--junitxml={xml}', *args.paths], cwd=ROOT,
                                      stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
                summary = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else ''
                (logs / f'round{k}.log').write_text(proc.stdout)
                load = os.getloadavg()[0]
                print(f'round {k}/{args.rounds}: {summary} ({time.monotonic() - t0:.0f} s, '
                      f'load average {load:.1f}; output {logs / f"round{k}.log"})', flush=True)
                if not xml.exists():
                    print(proc.stdout[-3000:])
                    return 1
                for nodeid, secs, outcome in _cases(xml):
                    if outcome == 'skipped':
                        continue
                    runs[nodeid] += 1
                    slowest[nodeid] = max(slowest[nodeid], secs)
                    if outcome == 'failed':
                        fails[nodeid] += 1
                if proc.returncode not in (0, 1):
                    print(proc.stdout[-3000:])
    finally:
        if busy is not None:
            busy.terminate()
            busy.join(5)
    width = max((len(n) for n in runs), default=10)
    print(f'\n{"test":<{width}}  runs  failures  slowest [s]')
    for nodeid in sorted(runs):
        print(f'{nodeid:<{width}}  {runs[nodeid]:>4}  {fails[nodeid]:>8}  {slowest[nodeid]:>11.1f}')
    total_fail = sum(fails.values())
    print(f'\n{len(runs)} tests x {args.rounds} rounds{" with one core busy" if args.busy else ""}, '
          f'{workers} worker(s): '
          f'{sum(runs.values())} runs, {total_fail} failures, '
          f'{(time.monotonic() - t_start) / 60:.1f} min')
    return 1 if total_fail else 0


if __name__ == '__main__':
    sys.exit(main())
