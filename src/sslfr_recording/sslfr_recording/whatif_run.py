"""Orchestration of ``sslfr replay BAG --what-if`` (processes + player + comparison).

On a private ROS domain (held with the machine's domain lock, :mod:`.host`): start a
recorder for the decisions (``use_sim_time``), a fresh ``planner`` (sslfr_planner) and
``safety`` (sslfr_safety) with ``use_sim_time:=true`` and the site config, play only
the sensor inputs of the bag with /clock (:mod:`.player`), stop the nodes (SIGINT),
then compare the decisions the fresh nodes recorded with the ones in the bag
(:mod:`sslfr_recording.bag.whatif`). Deciding nodes that are not installed are reported
and skipped.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sslfr_bringup.host import acquire_domain, find_executable, install_prefix
from sslfr_common.contract import (ABSORBER_TEMPERATURE, AXIS_STATUS, GPS_FIX, GPS_TIME_REFERENCE, IRRADIANCE_BEAM,
                                   IRRADIANCE_ILLUMINANCE, JOINT_STATES, JOINTS, LIMIT_SWITCHES, SAFETY_STATE,
                                   THERMOCOUPLES, TRACKER_PHASE, TRACKER_TRAJECTORY)

from .bag.metadata import BagError
from .bag.playback import absolute
from .bag.reader import BagReader
from .bag.whatif import compare_bags
from .player import run_player

#: Inputs played in what-if mode (relative names): the sensors (GPS, absorber
#: temperatures, irradiance, limit switches) and the axes' measured state, which the
#: safety supervisor watches (heartbeat watchdogs) and the planner does not produce.
WHATIF_INPUTS = [GPS_FIX.name, GPS_TIME_REFERENCE.name, *(ABSORBER_TEMPERATURE.of(s) for s in THERMOCOUPLES),
                 IRRADIANCE_BEAM.name, IRRADIANCE_ILLUMINANCE.name, LIMIT_SWITCHES.name, JOINT_STATES.name,
                 *(AXIS_STATUS.of(a) for a in JOINTS)]
#: (package, executable, decisions it publishes) of the deciding nodes started fresh.
DECIDERS = [('sslfr_planner', 'planner', [TRACKER_PHASE.name, TRACKER_TRAJECTORY.name]),
            ('sslfr_safety', 'safety', [SAFETY_STATE.name])]
#: Node name of the decisions' recorder.
RECORDER_NODE = 'whatif_recorder'
#: Decisions recorded and compared in what-if mode.
WHATIF_DECISIONS = [t for _, _, decisions in DECIDERS for t in decisions]


def default_config() -> Path | None:
    """The default site config (share/sslfr_bringup/config/almeria_sslfr.yaml) if installed."""
    prefix = install_prefix()
    p = prefix / 'sslfr_bringup' / 'share' / 'sslfr_bringup' / 'config' / 'almeria_sslfr.yaml' if prefix else None
    return p if p is not None and p.exists() else None


def _start(argv, env, log: Path) -> subprocess.Popen:
    fh = open(log, 'wb')  # noqa: SIM115 - owned by the process' lifetime
    return subprocess.Popen(argv, env=env, stdout=fh, stderr=subprocess.STDOUT,
                            start_new_session=True)


def _stop(proc: subprocess.Popen, timeout: float = 10.0) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(5)


def run_whatif(reader: BagReader, ns, start_ns, end_ns) -> int:
    """Run a what-if replay; print and write the comparison; return the exit status."""
    inputs = [absolute(t) for t in (ns.inputs or WHATIF_INPUTS)]
    present = [t for t in inputs if t in reader.topics]
    if not present:
        print('sslfr replay --what-if: the bag has none of the input topics '
              + ', '.join(inputs), file=sys.stderr)
        return 1
    rec_exe = find_executable('sslfr_recording', 'recorder')
    if rec_exe is None:
        print('sslfr replay --what-if: sslfr_recording/recorder is not installed (run make setup)',
              file=sys.stderr)
        return 1
    lock = None
    if ns.domain is not None:
        domain = ns.domain
    else:
        try:
            domain, lock = acquire_domain()
        except RuntimeError as exc:
            print(f'sslfr replay --what-if: {exc}: pass --domain', file=sys.stderr)
            return 1
    try:
        return _run(reader, ns, start_ns, end_ns, present, rec_exe, domain)
    finally:
        if lock is not None:
            lock.close()


def _run(reader: BagReader, ns, start_ns, end_ns, present: list[str], rec_exe: Path, domain: int) -> int:
    out = Path(ns.out) if ns.out else Path(tempfile.mkdtemp(prefix='sslfr_whatif_'))
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    config = Path(ns.config) if ns.config else default_config()
    procs = []
    dec_root = out / 'decisions'
    rec_argv = [str(rec_exe), '--ros-args', '-r', f'__node:={RECORDER_NODE}',
                '-p', f'output_dir:={dec_root}', '-p', 'prefix:=whatif',
                '-p', 'per_day:=false', '-p', 'use_sim_time:=true', '-p', 'fsync:=false',
                '-p', 'discovery_period:=0.2',
                '-p', 'topics:=[' + ','.join(f"'{t}'" for t in WHATIF_DECISIONS) + ']']
    procs.append(('recorder', _start(rec_argv, env, out / 'recorder.log')))
    started = []
    listened = []  # decisions of the started nodes: the recorder listens before playing
    for pkg, exe, decisions in DECIDERS:
        path = find_executable(pkg, exe)
        if path is None:
            print(f'what-if: {pkg}/{exe} is not installed: its decisions are not compared',
                  file=sys.stderr)
            continue
        argv = [str(path), '--ros-args', '-p', 'use_sim_time:=true']
        if config is not None:
            argv += ['--params-file', str(config)]
        procs.append((exe, _start(argv, env, out / f'{exe}.log')))
        started.append(exe)
        listened += [absolute(t) for t in decisions]
    try:
        player = run_player(reader, topics=present, rate=ns.rate, start_ns=start_ns, end_ns=end_ns,
                            clock_hz=ns.clock_hz, progress=not ns.no_progress,
                            node_name='sslfr_whatif_player', domain_id=domain,
                            wait_subscribers=15.0, wait_listened=(RECORDER_NODE, listened),
                            wait_clock_subscribers=1 + len(started))
        time.sleep(2.0)  # let the last decisions reach the recorder
    finally:
        for _, proc in reversed(procs):
            _stop(proc)
    if player.error:
        print(f'sslfr replay --what-if: {player.error}', file=sys.stderr)
        return 1
    bags = sorted(dec_root.glob('whatif_*')) if dec_root.exists() else []
    if not bags:
        print('what-if: the fresh nodes published no decision (see logs in ' f'{out})',
              file=sys.stderr)
        return 1
    try:
        result = compare_bags(reader, BagReader(bags[-1]))
    except BagError as exc:
        print(f'sslfr replay --what-if: {exc}', file=sys.stderr)
        return 1
    text = (f'what-if replay of {reader.path} (inputs: {", ".join(present)}; fresh nodes: '
            f'{", ".join(started) or "none"}; domain {domain})\n' + result.text())
    print(text)
    (out / 'whatif.md').write_text('# What-if replay\n\n```\n' + text + '\n```\n', encoding='utf-8')
    print(f'decisions bag and logs: {out}')
    return 0
