"""Benchmark: a field's station and discovery (issue 37 item 6, docs/field.md).

``station`` part (any user): ``./sslfr sim --collectors N`` for each N of
``--collectors`` (default 1 and 4) on this machine. Measures the time from the start to
each collector shown ``ok`` with a phase at the field page (``/api/field``; includes the
collector's own start-up), then, over ``--window`` wall seconds, the CPU time (user +
system, psutil, threads included) of the station's processes: both discovery servers,
``field_page``, ``field_recorder`` and ``modbus_gateway`` (the collectors' node sets and
simulated boards excluded), and their PSS at the end. The per-collector cost is the
slope between the smallest and the largest N.

``discovery`` part (root: network namespaces): ``--ns-collectors`` (default 2) whole
simulated collectors (``sslfr sim --wall-clock --namespace /cK --layout composed``), each
in its own network namespace on a link shaped like Wi-Fi as in the tests
(tests/fieldnet.py: 20 ms +- 5 ms, 1 % loss each way; ``tc netem`` where the kernel has
it, else the userspace link emulator tests/linkemu.py; ``--shaping`` chooses), once as
discovery clients of the station's two Fast DDS discovery servers (the station runs only
the servers: no ROS subscriber of the collectors' topics) and once with Fast DDS's
default simple discovery (multicast on the field's subnet, no station). A packet counter
(an ``AF_PACKET`` socket on each collector's link: the bridge end of its veth, or its
TAP device in its namespace) counts the UDP bytes in both directions over ``--window``
seconds once every collector is up, split by RTPS port: metatraffic (discovery:
SPDP/EDP, the multicast port, the servers' ports) and user traffic (the topics; with
nobody subscribing across, only ``ros_discovery_info`` and the like). It also times a
new participant (a heartbeat publisher started in a collector's namespace; three, one
after the other) until a super client at the station hears it, Python's start-up included.

The shaping in force is printed with the figures (and, with the emulator, how late it
delivered). Load averages at start and end are printed: figures taken while other jobs
load the machine must say so.

    python benchmarks/bench_field.py station [--collectors 1 4] [--window 60]
    sudo python benchmarks/bench_field.py discovery [--ns-collectors 2] [--window 60] [--shaping none]
    python benchmarks/bench_field.py            # both (discovery only as root)
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'tests'))
STATION_MARKS = ('fast-discovery-server', '__node:=field_page', '__node:=field_recorder', '__node:=modbus_gateway')


def _load() -> str:
    return ' '.join(f'{x:.1f}' for x in os.getloadavg())


def _end(minutes: float) -> str:
    return (dt.datetime.now(dt.timezone.utc) + dt.timedelta(minutes=minutes)).strftime('%H:%M')


def _stop(proc: subprocess.Popen, timeout: float = 40.0) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, 2)
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, 9)
            proc.wait(5)


def _station_procs(root_pid: int) -> dict[str, psutil.Process]:
    out = {}
    for p in psutil.Process(root_pid).children(recursive=True):
        try:
            cmd = ' '.join(p.cmdline())
        except psutil.Error:
            continue
        for mark in STATION_MARKS:
            if mark in cmd:
                name = mark.split('=')[-1] + (f' {cmd.split(" -i ")[1].split()[0]}' if ' -i ' in cmd else '')
                out[name] = p
    return out


def _cpu(p: psutil.Process) -> float:
    t = p.cpu_times()
    return t.user + t.system


def bench_station(n: int, window: float, out: Path) -> dict:
    log = open(out / f'sim-{n}.log', 'w')  # noqa: SIM115 - closed below
    t0 = time.monotonic()
    proc = subprocess.Popen([str(ROOT / 'sslfr'), 'sim', '--collectors', str(n), '--end', _end(window / 60 + 15),
                             '--out', str(out / f'field-{n}')], stdout=log, stderr=subprocess.STDOUT,
                            start_new_session=True,      # no ROS_DOMAIN_ID: sim takes a free one
                            env={k: v for k, v in os.environ.items() if k != 'ROS_DOMAIN_ID'})
    try:
        url, seen = None, {}
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and len(seen) < n:
            if proc.poll() is not None:
                raise SystemExit(f'sslfr sim --collectors {n} stopped: {(out / f"sim-{n}.log").read_text()[-2000:]}')
            if url is None:
                import re
                m = re.search(r'FIELD PAGE at (http://\S+/)', (out / f'sim-{n}.log').read_text(errors='replace'))
                url = m.group(1) + 'api/field' if m else None
            else:
                try:
                    with urllib.request.urlopen(url, timeout=5) as r:
                        for c in json.load(r)['collectors']:
                            if c['link'] == 'ok' and c['phase'] and c['id'] not in seen:
                                seen[c['id']] = time.monotonic() - t0
                except OSError:
                    pass
            time.sleep(0.2)
        if len(seen) < n:
            raise SystemExit(f'only {sorted(seen)} of {n} collectors seen within 300 s')
        time.sleep(10.0)                                   # settle: start-up work done
        procs = _station_procs(proc.pid)
        load0 = _load()
        c0 = {k: _cpu(p) for k, p in procs.items()}
        w0 = time.monotonic()
        time.sleep(window)
        wall = time.monotonic() - w0
        cpu = {k: 100.0 * (_cpu(p) - c0[k]) / wall for k, p in procs.items() if p.is_running()}
        pss = {k: p.memory_full_info().pss / 2**20 for k, p in procs.items() if p.is_running()}
        return {'n': n, 'seen_s': seen, 'cpu_pct': cpu, 'pss_mb': pss, 'cpu_total': sum(cpu.values()),
                'pss_total': sum(pss.values()), 'load': f'{load0} -> {_load()}', 'window': wall}
    finally:
        _stop(proc)
        log.close()


# ---------------------------------------------------------------------------------------- discovery
class Counter(threading.Thread):
    """UDP bytes (IP length) on one collector's link, both directions, split by RTPS port."""

    def __init__(self, sock: socket.socket, domain: int, server_ports: set[int]):
        super().__init__(daemon=True)
        self.s = sock                                      # an AF_PACKET socket on the link (fieldnet.Net)
        self.s.settimeout(0.5)
        self.base = 7400 + 250 * domain
        self.server_ports = server_ports
        self.meta = self.user = self.other = 0
        self.counting = False
        self.done = False

    def kind(self, sport: int, dport: int) -> str:
        for port in (dport, sport):
            if port in self.server_ports or port == self.base:
                return 'meta'
        off = dport - self.base
        if off == 1:
            return 'user'                                  # the multicast user-traffic port
        if 10 <= off < 250:
            return 'meta' if off % 2 == 0 else 'user'      # unicast: 10 + 2 id (meta), 11 + 2 id (user)
        return 'other'

    def run(self) -> None:
        while not self.done:
            try:
                frame = self.s.recv(65535)
            except socket.timeout:
                continue
            except OSError:
                return
            if not self.counting or len(frame) < 42 or frame[12:14] != b'\x08\x00' or frame[23] != 17:
                continue
            ihl = (frame[14] & 0x0F) * 4
            length = struct.unpack_from('!H', frame, 16)[0]
            sport, dport = struct.unpack_from('!HH', frame, 14 + ihl)
            k = self.kind(sport, dport)
            setattr(self, k, getattr(self, k) + length)


def bench_discovery(k: int, window: float, out: Path, mode: str, shaping: str, repeats: int = 3) -> dict:
    from fieldnet import Net                       # the tests' namespaces and shaped links
    from test_field_netns import LISTENER, TALKER, _heard  # the tests' probes

    from sslfr_field import field as field_mod
    from sslfr_field import station as station_mod
    from sslfr_bringup.host import acquire_domain
    domain, _lock = acquire_domain()              # held for the run
    ids = [f'c{i + 1}' for i in range(k)]
    net = Net(ids, mode=shaping)
    net.up()
    procs: list[subprocess.Popen] = []
    counters: dict[str, Counter] = {}
    base = {**os.environ, 'ROS_DOMAIN_ID': str(domain)}
    doc = field_mod.simulated(k, ROOT / 'src/sslfr_bringup/config/almeria_sslfr.yaml', address=net.station_ip,
                              discovery_port=11811 + 2 * domain, backup_port=11812 + 2 * domain)  # noqa: E501
    f = field_mod.parse(doc, out / 'field.yaml')

    def start(argv, env, ns=None, name='p'):
        p = subprocess.Popen((['ip', 'netns', 'exec', ns] if ns else []) + argv, env=env,
                             stdout=open(out / f'{mode}-{name}.log', 'w'), stderr=subprocess.STDOUT,  # noqa: SIM115
                             start_new_session=True)
        procs.append(p)
        return p
    try:
        if mode == 'server':
            progs, missing = station_mod.programs(f, role='both', run_dir=out, out_dir=None,
                                                  finder=lambda pkg, exe: None)
            for p in progs:
                start(p.argv, station_mod.station_environment(f, base), name=p.name)
            cenv = station_mod.collector_environment(f, base)
            senv = station_mod.station_environment(f, base)
            server_ports = {f.station.discovery_port, f.station.backup_port}
        else:
            cenv = {**base, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'}
            cenv.pop('ROS_DISCOVERY_SERVER', None)
            senv, server_ports = cenv, set()
        counters.update({cid: Counter(net.packet_socket(cid), domain, server_ports) for cid in ids})
        for c in counters.values():
            c.start()
        for cid in ids:
            start([str(ROOT / 'sslfr'), 'sim', '--wall-clock', '--namespace', f'/{cid}', '--layout', 'composed',
                   '--end', _end(window / 60 + 10), '--no-report', '--out', str(out / f'{mode}-{cid}')],
                  cenv, ns=net.ns[cid], name=cid)
        # the station's probe (a super client with the servers, else a plain participant): hears /new/heartbeat
        probe = out / f'{mode}-probe.log'
        news = [f'new{j + 1}' for j in range(repeats)]
        start([sys.executable, '-c', LISTENER, *news], senv, name='probe')
        # counting starts once every collector's safety supervisor went to OK (its nodes up, axes homed)
        deadline = time.monotonic() + 240

        def up(cid):
            try:
                return '-> OK' in (out / f'{mode}-{cid}' / 'logs' / 'safety.log').read_text(errors='replace')
            except OSError:
                return False
        while not all(up(c) for c in ids):
            if time.monotonic() > deadline:
                raise SystemExit(f'{mode}: not every collector up within 240 s (logs in {out})')
            time.sleep(0.5)
        load0 = _load()
        for c in counters.values():
            c.counting = True
        time.sleep(window)
        for c in counters.values():
            c.counting = False
        per = {cid: {'meta_Bps': c.meta / window, 'user_Bps': c.user / window, 'other_Bps': c.other / window}
               for cid, c in counters.items()}
        # new participants, one after the other in the collectors' namespaces: until the station's probe hears each
        seen = []
        for j, name in enumerate(news):
            t0 = time.monotonic()
            p = start([sys.executable, '-c', TALKER, f'/{name}'], cenv, ns=net.ns[ids[j % k]], name=name)
            heard = None
            while time.monotonic() - t0 < 60 and heard is None:
                if name in _heard(probe):
                    heard = time.monotonic() - t0
                time.sleep(0.1)
            seen.append(heard)
            _stop(p, 10)
        return {'mode': mode, 'collectors': k, 'per_collector': per, 'new_participant_s': seen,
                'load': f'{load0} -> {_load()}', 'links': net.describe, 'emulator': net.stats()}
    finally:
        for c in counters.values():
            c.done = True
        for p in reversed(procs):
            _stop(p, 30)
        net.down()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('part', nargs='?', choices=('station', 'discovery', 'all'), default='all',
                    help='all (default): station, then discovery where root')
    ap.add_argument('--collectors', type=int, nargs='+', default=[1, 4])
    ap.add_argument('--ns-collectors', type=int, default=2)
    ap.add_argument('--window', type=float, default=60.0)
    ap.add_argument('--shaping', choices=('auto', 'netem', 'emulator', 'none'), default=None,
                    help='discovery: the links (tests/fieldnet.py; default SSLFR_LINK_SHAPING, else auto: '
                         'netem where the kernel has it, else the userspace emulator)')
    ap.add_argument('--json', default=None)
    args = ap.parse_args()
    out = Path(tempfile.mkdtemp(prefix='bench-field-'))
    print(f'load average at start: {_load()}; logs in {out}')
    results = []
    if args.part in ('station', 'all'):
        for n in args.collectors:
            r = bench_station(n, args.window, out)
            results.append(r)
            seen = ', '.join(f'{c} {s:.1f} s' for c, s in sorted(r['seen_s'].items()))
            print(f'N={n}: station CPU {r["cpu_total"]:.1f} % of one core, PSS {r["pss_total"]:.0f} MB '
                  f'(load {r["load"]}); seen at the field page after start: {seen}')
            for name in sorted(r['cpu_pct']):
                print(f'    {name:24s} {r["cpu_pct"][name]:5.1f} %  {r["pss_mb"][name]:6.1f} MB')
        if len(results) >= 2:
            a, b = results[0], results[-1]
            dn = b['n'] - a['n']
            print(f'per collector (N={a["n"]} -> N={b["n"]}): CPU {(b["cpu_total"] - a["cpu_total"]) / dn:+.2f} % of '
                  f'one core, PSS {(b["pss_total"] - a["pss_total"]) / dn:+.1f} MB')
    if args.part in ('discovery', 'all') and os.geteuid() != 0:
        print('discovery: SKIPPED, needs root (network namespaces, packet counter)', file=sys.stderr)
        if args.part == 'discovery':
            return 1
    elif args.part in ('discovery', 'all'):
        for mode in ('server', 'simple'):
            r = bench_discovery(args.ns_collectors, args.window, out, mode, args.shaping)
            results.append(r)
            per = r['per_collector']
            meta = sum(v['meta_Bps'] for v in per.values()) / len(per)
            user = sum(v['user_Bps'] for v in per.values()) / len(per)
            new = ', '.join(f'{x:.1f} s' if x is not None else 'not within 60 s' for x in r['new_participant_s'])
            print(f'{mode:6s} discovery, {r["collectors"]} collectors: per collector {meta / 1000:.2f} kB/s discovery '
                  f'(metatraffic), {user / 1000:.2f} kB/s user traffic; new participants heard at the station in '
                  f'{new} (load {r["load"]}; links: {r["links"]})')
            if r['emulator']:
                late = r['emulator']['late']
                print(f'    link emulator: deliveries late by {late["mean_s"] * 1e6:.0f} us on average, at most '
                      f'{late["max_s"] * 1e3:.1f} ms; frames lost ' + ', '.join(
                          f'{p} {v["lost"]} of {v["rx_frames"] + v["tx_frames"]}'
                          for p, v in r['emulator']['ports'].items() if p != 'station'))
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))
    print(f'load average at end: {_load()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
