"""A field's discovery over real network namespaces (root only; skipped otherwise).

Each collector is a process in its own network namespace, its link to the station's
namespace shaped like Wi-Fi (tests/fieldnet.py: 20 ms +- 5 ms and 1 % loss each way, with
``tc netem`` on veth pairs where the kernel has it, else with the userspace link emulator
tests/linkemu.py on TAP devices; the tests print which). The station runs the field's
two Fast DDS discovery servers (primary and backup, as ``sslfr station`` starts them:
sslfr_field.station.programs) on the station's address and a super client that notes
when it hears each collector. The collectors are plain discovery clients
(sslfr_field.station.collector_environment) publishing a heartbeat in their namespace at
10 Hz.

Checked: every collector is heard within a bound; with the primary server killed the
running links keep carrying messages and a restarted collector is found through the
backup; a collector cut off (its link cut) is silent at the station and is heard again
when its link is back. This tests the discovery set-up and the network, not the node
set (the whole-collector test below runs ``sslfr sim`` collectors and ``sslfr station``).
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fieldnet import Net, can_make_netns
from sslfr_field import field as field_mod
from sslfr_field import station as station_mod

def _kill_process_of(root_pid: int, node: str) -> float:
    """SIGKILL the node process running ``node`` under ``root_pid``; the time [s, wall]."""
    import signal

    import psutil
    for p in psutil.Process(root_pid).children(recursive=True):
        try:
            if f'__node:={node}' in p.cmdline():
                p.send_signal(signal.SIGKILL)
                return time.time()
        except psutil.Error:
            continue
    raise AssertionError(f'no process of {node} under {root_pid}')


#: [s] bound for the station to hear a (re)started collector over the shaped link
SEEN_BOUND = 30.0

TALKER = r'''
import sys, time, rclpy
from std_msgs.msg import String
rclpy.init()
n = rclpy.create_node('heartbeat', namespace=sys.argv[1])
pub = n.create_publisher(String, 'heartbeat', 10)
n.create_timer(0.1, lambda: pub.publish(String(data=sys.argv[1])))
rclpy.spin(n)
'''

#: the nodes a participant with this environment names once it names every node of argv (the
#: discovery through the servers done), 1.5 s later
GRAPH = r'''
import sys, time, rclpy
rclpy.init()
n = rclpy.create_node('graph_probe', namespace='/graph_probe')
names = lambda: {f"{ns.rstrip('/')}/{nm}" for nm, ns in n.get_node_names_and_namespaces()}
deadline = time.monotonic() + 30
while time.monotonic() < deadline and not set(sys.argv[1:]) <= names():
    rclpy.spin_once(n, timeout_sec=0.1)
end = time.monotonic() + 1.5
while time.monotonic() < end:
    rclpy.spin_once(n, timeout_sec=0.1)
print(' '.join(sorted(names())))
'''

LISTENER = r'''
import sys, time, rclpy
from std_msgs.msg import String
rclpy.init()
n = rclpy.create_node('station_probe')
last = {}
def heard(m, cid):
    now = time.monotonic()
    if now - last.get(cid, 0.0) >= 0.2:
        last[cid] = now
        print(cid, f'{now:.3f}', flush=True)
for cid in sys.argv[1:]:
    n.create_subscription(String, f'/{cid}/heartbeat', lambda m, c=cid: heard(m, c), 10)
rclpy.spin(n)
'''


def _net(ids):
    why = can_make_netns()
    if why:
        pytest.skip(f'network-namespace field test: {why}')
    n = Net(ids)
    print(f'links: {n.describe}')
    try:
        n.up()
        yield n
        if n.emu:                                  # what the links did (the emulator's counters)
            st = n.stats()
            late = st['late']
            print('emulated links: ' + ', '.join(f'{p} {v["rx_frames"]} frames in, {v["tx_frames"]} out, {v["lost"]} lost'
                                                  for p, v in st['ports'].items() if p != 'station')
                  + f'; deliveries late by {late["mean_s"] * 1e6:.0f} us on average, at most {late["max_s"] * 1e3:.1f} ms'
                  + f'; emulator CPU {st["cpu_s"]:.1f} s')
    finally:
        n.down()


@pytest.fixture
def net():
    yield from _net(['c1', 'c2', 'c3', 'c4'])


def _heard(log: Path) -> dict[str, float]:
    out = {}
    for line in log.read_text().splitlines():
        parts = line.split()
        if len(parts) == 2:
            out[parts[0]] = float(parts[1])
    return out


def _wait(pred, timeout, what, show=lambda: ''):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return time.monotonic()
        time.sleep(0.1)
    pytest.fail(f'{what} not within {timeout} s {show()}')


def test_field_discovery_over_network_namespaces(net, ros_env, tmp_path):
    from sslfr_field.field import DISCOVERY_PORT
    doc = field_mod.simulated(len(net.ns), Path(__file__).resolve().parents[1] / 'src' / 'sslfr_bringup' /
                              'config' / 'almeria_sslfr.yaml', address=net.station_ip,
                              discovery_port=DISCOVERY_PORT + os.getpid() % 1000 * 2,
                              backup_port=DISCOVERY_PORT + os.getpid() % 1000 * 2 + 1)
    f = field_mod.parse(doc, tmp_path / 'field.yaml')
    progs, missing = station_mod.programs(f, role='both', run_dir=tmp_path, out_dir=None,
                                          finder=lambda pkg, exe: None)
    servers = [p for p in progs if p.name.startswith('discovery_server_')]
    if len(servers) != 2:
        pytest.skip(f'no discovery server: {missing}')
    procs: dict[str, subprocess.Popen] = {}
    logs = {}

    def start(name, argv, env, ns=None):
        logs[name] = tmp_path / f'{name}.log'
        cmd = (['ip', 'netns', 'exec', ns] if ns else []) + argv
        procs[name] = subprocess.Popen(cmd, env=env, stdout=open(logs[name], 'w'),  # noqa: SIM115
                                       stderr=subprocess.STDOUT, start_new_session=True)

    def stop(name):
        p = procs.pop(name)
        p.terminate()
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait(5)

    station_env = station_mod.station_environment(f, ros_env)
    collector_env = station_mod.collector_environment(f, ros_env)
    try:
        for s in servers:
            start(s.name, s.argv, station_env)
        probe_log = tmp_path / 'probe.log'
        start('probe', [sys.executable, '-c', LISTENER, *f.ids], station_env)
        t0 = time.monotonic()
        for c in f.collectors:
            start(c.id, [sys.executable, '-c', TALKER, c.namespace], collector_env, ns=net.ns[c.id])
        heard = lambda: _heard(probe_log)  # noqa: E731
        t_all = _wait(lambda: set(heard()) == set(f.ids), SEEN_BOUND * 2, 'every collector heard',
                      lambda: f'(heard {sorted(heard())}; links: {net.describe})')
        print(f'{len(f.ids)} collectors in their own network namespaces heard {t_all - t0:.1f} s after they '
              f'started (links: {net.describe})')

        # the primary discovery server killed: running links keep working ...
        stop('discovery_server_0')
        t_kill = time.monotonic()
        _wait(lambda: all(heard().get(c, 0) > t_kill + 2.0 for c in f.ids), 10,
              'every running link still carrying messages 2 s after the primary server died')
        # ... and a restarted collector is found through the backup
        stop('c2')
        t_stop = time.monotonic()
        _wait(lambda: time.monotonic() - heard()['c2'] > 2.0, 10, 'c2 silent after its stop')
        start('c2', [sys.executable, '-c', TALKER, '/c2'], collector_env, ns=net.ns['c2'])
        t_back = _wait(lambda: heard()['c2'] > t_stop + 0.5, SEEN_BOUND, 'the restarted c2 through the backup server')
        print(f'restarted collector found through the backup in {t_back - t_stop:.1f} s')

        # a collector cut off: silent at the station, heard again when its link is back
        net.link('c3', False)
        t_cut = time.monotonic()
        _wait(lambda: time.monotonic() - heard()['c3'] > 3.0, 10, 'c3 silent while cut off')
        assert heard()['c1'] > t_cut, 'the other collectors keep talking'
        net.link('c3', True)
        t_up = time.monotonic()
        t_again = _wait(lambda: heard()['c3'] > t_up, SEEN_BOUND, 'c3 heard again after its link is back')
        print(f'cut-off collector heard again {t_again - t_up:.1f} s after its link came back')
    finally:
        for name in list(procs):
            stop(name)


#: [s] how long one collector is cut off in the whole-collector test (the issue's 5 min: 300; the
#: run then takes ~6 min: pass ``-o faulthandler_timeout=900``, pytest.ini's 330 s ends the process)
CUT_S = float(os.environ.get('SSLFR_FIELD_CUT_S', '30'))
#: whole simulated collectors in the whole-collector test (SSLFR_FIELD_COLLECTORS; the issue's
#: field: 4, ~85 s wall and ~90 s CPU on a loaded 2-core machine; 2: ~70 s, ~45 s CPU)
N_WHOLE = int(os.environ.get('SSLFR_FIELD_COLLECTORS', '4'))
#: [s] shortest cut the whole-collector test can check (the planner's restart lies within it)
MIN_CUT_S = 20.0
#: c1's safety log line that clears the killed planner's silence: the new planner heard
RESTART_HEARD = re.compile(r'-> (OK|WARN) \| cleared: [^\n]*planner silent')
#: [s] of the cut kept after that, to see c1 tracking again without the station
RESTART_SEEN_S = 10.0
#: [s] longest the cut is held beyond CUT_S waiting for it
CUT_EXTRA_S = 90.0


def _daylit_config(tmp_path) -> Path:
    """Seed 000's site config moved to where the sun is near its noon now: the collectors
    run on the system clock (``--wall-clock``) and must track whatever the hour of the
    test (at Almeria the sun sets at 17-20 UTC). Latitude 20 N, the longitude of local
    solar noon at this UTC hour; the collector description by its absolute path."""
    import yaml

    from conftest import ROOT
    src = ROOT / 'src/sslfr_bringup/config/almeria_sslfr.yaml'
    doc = yaml.safe_load(src.read_text())
    now = time.gmtime()
    hours = now.tm_hour + now.tm_min / 60.0
    lon = (12.0 - hours) * 15.0
    lon = (lon + 180.0) % 360.0 - 180.0
    doc['/**']['ros__parameters'].update({'site.latitude_deg': 20.0, 'site.longitude_deg': round(lon, 4)})
    planner = doc['planner']['ros__parameters']
    planner['collector.description'] = str((src.parent / planner['collector.description']).resolve())
    out = tmp_path / 'daylit_site.yaml'
    out.write_text(yaml.safe_dump(doc))
    return out


@pytest.fixture
def netw():
    yield from _net([f'c{k + 1}' for k in range(N_WHOLE)])


@pytest.mark.slow
@pytest.mark.timeout(CUT_S + CUT_EXTRA_S + 300)
def test_whole_collectors_in_network_namespaces_with_the_station(netw, ros_env, tmp_path):
    """SSLFR_FIELD_COLLECTORS (default 4) whole simulated collectors (``sslfr sim
    --wall-clock --namespace``), each in its own network namespace on a shaped link,
    and ``sslfr station`` at the station's address: the field page hears every one; one
    collector cut off for SSLFR_FIELD_CUT_S (30 s; the issue's 5 minutes: 300), and until
    its restarted planner (below) is heard by its own safety, is shown lost while it keeps tracking on its own (its bag: the mirrors following through the
    cut, no safety stow), the others staying heard, and is heard again when its link is
    back. Cut off, its process of the planner and the recorder is killed: restarted, it
    finds the collector's other processes through the collector's own discovery server
    (safety OK again, the drivers recorded again, before the link is back), and the
    station hears the new planner after the rejoin (the page's phase and safety ages, not
    only its last values). Then the station's primary discovery server is killed (and
    kept dead): every collector stays heard, and c2's process of the planner, killed, is
    heard again after its restart, through the backup server. The cut starts once every collector is past its
    start-up (tracking with safety OK or WARN for 3 s at the page): the start-up's own
    safety STOW is not a stow of the cut."""
    if CUT_S < MIN_CUT_S:
        pytest.fail(f'SSLFR_FIELD_CUT_S={CUT_S:g}: at least {MIN_CUT_S:g} s, so that c1\'s planner killed at the '
                    f'cut\'s start is restarted (8.5 s restart wait + start-up) and checked within the cut')
    import datetime as dt
    import json
    import urllib.request

    import psutil
    import yaml

    from conftest import ROOT, NodeProcess
    base = os.getpid() % 1000 * 2 + 20000
    web_port = base + 7
    config = _daylit_config(tmp_path)
    doc = {'field': {'id': 'netns_field',
                     'station': {'address': netw.station_ip, 'discovery_port': base, 'backup_address': netw.station_ip,
                                 'backup_port': base + 1, 'web_port': web_port},
                     'collectors': [{'id': cid, 'address': netw.ip[cid], 'config': str(config)}
                                    for cid in netw.ns]}}
    fpath = tmp_path / 'field.yaml'
    fpath.write_text(yaml.safe_dump(doc))
    f = field_mod.load(fpath)
    end = (dt.datetime.now(dt.timezone.utc) + dt.timedelta(seconds=CUT_S + 600)).strftime('%H:%M')
    procs = {'station': NodeProcess([str(ROOT / 'sslfr'), 'station', '--field', str(fpath), '--out',
                                     str(tmp_path / 'station')], ros_env, tmp_path / 'station.out')}
    env = station_mod.collector_environment(f, ros_env)
    try:
        for c in f.collectors:
            procs[c.id] = NodeProcess(['ip', 'netns', 'exec', netw.ns[c.id], str(ROOT / 'sslfr'), 'sim',
                                       '--wall-clock', '--config', str(config), '--namespace', c.namespace,
                                       '--layout', 'composed',
                                       '--end', end, '--no-report', '--out', str(tmp_path / c.id)],
                                      env, tmp_path / f'{c.id}.out')
        url = f'http://{netw.station_ip}:{web_port}/api/field'

        def page():
            try:
                with urllib.request.urlopen(url, timeout=5) as r:
                    return {c['id']: c for c in json.load(r)['collectors']}
            except OSError:
                return {}
        show = lambda: f'page: {page()}; outputs: ' + ' | '.join(  # noqa: E731
            f'{k}: {p.output()[-600:]}' for k, p in procs.items())
        t0 = time.monotonic()
        _wait(lambda: (s := page()) and all(s[c]['link'] == 'ok' and s[c]['phase'] for c in f.ids), 240,
              f'all {len(f.ids)} collectors heard at the field page', show)
        print(f'field page heard all {len(f.ids)} collectors (own network namespaces; links: {netw.describe}) '
              f'{time.monotonic() - t0:.1f} s after start')
        # collectors find the station, not each other: c1's processes name its own nodes and the
        # station's, never c2's; the station names every collector's (ROS's graph topic in a
        # partition per collector, sslfr_bringup.dds_profile)
        def graph_probe(root_pid, node, wanted, netns=None):     # started now, read below: both at once
            proc = next(p for p in psutil.Process(root_pid).children(recursive=True)
                        if f'__node:={node}' in ' '.join(p.cmdline()))
            penv = {k: v for k, v in proc.environ().items() if k.startswith(('ROS_', 'FASTRTPS_', 'RMW_'))}
            return subprocess.Popen((['ip', 'netns', 'exec', netns] if netns else []) + [sys.executable, '-c', GRAPH,
                                    *wanted], env={**os.environ, **penv}, stdout=subprocess.PIPE, text=True)
        safeties = [f'{c.namespace}/safety' for c in f.collectors]
        probes = [graph_probe(procs['c1'].pid, 'safety', ['/c1/safety', '/field_page'], netw.ns['c1']),
                  graph_probe(procs['station'].pid, 'field_page', ['/field_page', *safeties])]
        seen_c1, seen_station = (set(p.communicate(timeout=60)[0].split()) for p in probes)
        assert '/c1/safety' in seen_c1 and '/field_page' in seen_c1, sorted(seen_c1)
        assert not any(n.startswith(tuple(f'{c.namespace}/' for c in f.collectors[1:])) for n in seen_c1), sorted(seen_c1)
        assert set(safeties) <= seen_station, sorted(seen_station)
        # both past their start-up before the cut: tracking AND their safety OK or WARN at once. The
        # planner's first phase is TRACKING, sent before its safety supervisor has heard every node;
        # the start-up's STOW ('... not heard yet (start-up)') follows it for a few seconds, so a
        # TRACKING phase alone may be that first message (a cut then falls into the start-up).
        def settled(c):
            return c['link'] == 'ok' and c['phase'] == 'TRACKING' and c['safety_level'] in ('OK', 'WARN')
        since = {}

        def steady(ids, hold=3.0):                   # settled for `hold` s in a row (the start-up's changes done)
            s, now = page(), time.monotonic()
            for c in ids:
                since[c] = (since.get(c) or now) if s and settled(s[c]) else None
            return all(since[c] is not None and now - since[c] >= hold for c in ids)
        _wait(lambda: steady(f.ids), 120, 'every collector tracking with safety OK for 3 s', show)
        netw.link('c1', False)
        t_cut = time.time()
        # and, cut off, c1's process of the planner and the recorder dies: its restart must find
        # the collector's other processes without the station (the collector's own discovery
        # server, sslfr_bringup.local_discovery; without it the new planner went unheard and
        # safety kept c1 stowed for the rest of a 300 s cut)
        c1_safety = tmp_path / 'c1' / 'logs' / 'safety.log'
        mark = c1_safety.stat().st_size if c1_safety.exists() else 0
        killed = _kill_process_of(procs['c1'].pid, 'planner')
        t0 = time.monotonic()
        _wait(lambda: page()['c1']['link'] == 'lost', 30, 'c1 shown lost', show)
        # the cut lasts CUT_S, and longer while c1's new planner is not yet heard by its own
        # safety (+ RESTART_SEEN_S of tracking after it) so that the restart is judged within the
        # cut however slow the start-up on this loaded machine (seen: 27 s); c1 stays lost all
        # along, the others ok
        heard_again = None
        while True:
            now = time.monotonic()
            if heard_again is None and RESTART_HEARD.search(c1_safety.read_bytes()[mark:].decode(errors='replace')):
                heard_again = now
            if now - t0 >= CUT_S and (heard_again is not None and now - heard_again >= RESTART_SEEN_S
                                      or now - t0 >= CUT_S + CUT_EXTRA_S):
                break
            s = page()
            assert s['c1']['link'] == 'lost', s['c1']
            assert all(s[c]['link'] == 'ok' for c in f.ids[1:]), {c: s[c]['link'] for c in f.ids}
            time.sleep(1.0)
        cut_s = time.monotonic() - t0
        netw.link('c1', True)
        t_up = time.monotonic()
        t_again = _wait(lambda: page()['c1']['link'] == 'ok', 120, 'c1 heard again', show)
        t_cut_end = time.time()
        print(f'c1 cut off for {cut_s:.0f} s, heard again {t_again - t_up:.1f} s after its link came back')
        # the page's values of c1 are those from before the cut until each topic is heard again (its
        # phase is republished every second): tracking with safety OK/WARN once they are (the bag
        # below says it was so all along the cut)
        _wait(lambda: settled(page()['c1']), 30, 'c1 shown tracking with safety OK or WARN after the rejoin', show)
        # the page hears c1's processes again, not only its last values: the restarted planner's
        # phase and safety's state, each within a second and a half
        fresh = lambda c: all((a := c.get(k)) is not None and a < 1.5 for k in ('phase_age_s', 'safety_age_s'))  # noqa: E731
        _wait(lambda: fresh(page()['c1']), 30, 'c1\'s planner (restarted) and safety heard at the station', show)
        # the primary discovery server killed (the station's supervisor paused meanwhile, so that
        # it stays dead): the running links keep working ...
        station_sup = psutil.Process(procs['station'].pid)
        servers = [p for p in station_sup.children(recursive=True) if 'fast-discovery-server' in ' '.join(p.cmdline())]
        primary = [p for p in servers if p.cmdline()[p.cmdline().index('-i') + 1] == '0']
        assert len(servers) == 2 and len(primary) == 1, [p.cmdline() for p in servers]
        station_sup.suspend()
        primary[0].kill()
        t_prim = time.monotonic()
        _wait(lambda: time.monotonic() - t_prim > 3.0 and all(fresh(page()[c]) for c in f.ids), 20,
              'every collector heard 3 s after the primary server died', show)
        # ... and a collector's process restarted meanwhile is found through the backup (c2's
        # process of the planner killed: the page sees its planner silent, then hears the new one)
        _kill_process_of(procs['c2'].pid, 'planner')
        t_kill2 = time.monotonic()
        _wait(lambda: (page()['c2'].get('phase_age_s') or 0) > 3.0, 30, 'the station sees c2\'s planner silent', show)
        t_new = _wait(lambda: fresh(page()['c2']), 60, 'c2\'s restarted planner heard at the station', show)
        s = page()
        assert all(s[c]['link'] == 'ok' for c in f.ids), {c: s[c]['link'] for c in f.ids}
        print(f'the primary discovery server killed; then c2\'s process of the planner killed: restarted and '
              f'heard at the station through the backup {t_new - t_kill2:.1f} s later')
        station_sup.resume()
    finally:
        try:
            psutil.Process(procs['station'].pid).resume()
        except Exception:  # noqa: BLE001 - gone or never paused
            pass
        for p in procs.values():
            p.stop(timeout=30)
    # c1 kept tracking on its own while cut off: its own bag says so, as c2's (never cut) does
    from sslfr_recording.bag import BagReader

    def during_cut(cid):
        # one bag per UTC day: a run across midnight has two
        bags = sorted(b for b in (tmp_path / cid / 'bags').iterdir() if (b / 'metadata.yaml').exists())
        assert bags and all(b.name.startswith(f'{cid}_') for b in bags), bags
        states, levels, why, missed = [], [], {}, []
        times[cid] = {'status': [], 'safety': []}
        for bag in bags:
            reader = BagReader(bag)
            for raw in reader.messages([f'/{cid}/axes/mirrors/status', f'/{cid}/safety/state']):
                if not t_cut + 1 <= raw.log_time * 1e-9 <= t_cut_end - 1:
                    continue
                m = reader.decoder(raw.type)(raw.data)
                times[cid]['status' if raw.topic.endswith('status') else 'safety'].append(
                    (raw.log_time * 1e-9, m.state if raw.topic.endswith('status') else m.level))
                if raw.topic.endswith('status'):
                    states.append(m.state)
                    if m.state == 'link_down':
                        missed.append(raw.log_time * 1e-9)
                else:
                    levels.append(m.level)
                    if m.level > 1:              # the rule that stowed: its reasons, first time seen
                        why.setdefault('; '.join(m.reasons), f'{raw.log_time * 1e-9 - t_cut:.1f} s after the cut')
        return states, levels, why, missed

    def safety_log(cid):
        log = tmp_path / cid / 'logs' / 'safety.log'
        return '\n'.join(ln for ln in log.read_text(errors='replace').splitlines() if 'transition' in ln)[-3000:]
    times: dict = {}
    # c1's restart during the cut: the new recorder records the drivers' statuses again and the
    # safety supervisor hears the new planner (STOW while it was silent, then OK): both before the
    # link is back, so through the collector's own discovery server
    states, levels, why, _ = during_cut('c1')
    t_back = next((t for t, lvl in times['c1']['safety'] if t > killed + 1 and lvl <= 1), None)
    resumed = [t for t, _ in times['c1']['status'] if t > killed + 3]
    print(f'c1 process of the planner and recorder killed {killed - t_cut:.1f} s into the cut: statuses '
          f'recorded again {resumed[0] - killed if resumed else float("nan"):.1f} s later, safety OK again '
          f'{t_back - killed if t_back else float("nan"):.1f} s later, both before the link came back')
    assert resumed and t_back is not None, (times['c1']['safety'][-5:], why, safety_log('c1'))
    assert all('planner' in r for r in why), (why, safety_log('c1'))      # STOW: the planner's silence only
    for cid in f.ids:
        states, levels, why, missed = during_cut(cid)
        if cid == 'c1':                              # before the kill and after safety was OK again
            states = [st for t, st in times[cid]['status'] if t < killed or t > t_back + 5]
            levels = [lvl for t, lvl in times[cid]['safety'] if t < killed or t >= t_back]
        # 'waiting': a new horizon whose first point is still ahead (each republication). 'link_down'
        # for one status: the driver got no fresh board STATUS within its poll's 2-3 control periods
        # (the collector's own pty board, not the network: seen once 84 s into a 300 s cut on a loaded
        # machine, the link itself up); allowed alone only, the next status following again
        lone = all(i + 1 < len(states) and states[i + 1] != 'link_down' and states[i - 1] != 'link_down'
                   for i, st in enumerate(states) if st == 'link_down')
        assert states and set(states) <= {'following', 'waiting', 'link_down'} and lone, \
            (cid, set(states), missed, safety_log(cid))
        assert states.count('link_down') <= 2, (cid, 'board answers missed', missed)
        # OK or WARN: no stow (else: the reasons of each stow, and the safety log's transitions)
        assert levels and max(levels) <= 1, (cid, sorted(set(levels)), why, safety_log(cid))
        print(f'{cid} during the cut: mirrors following {states.count("following") / len(states):.0%} of '
              f'{len(states)} status messages, else waiting for the next horizon'
              + (f' ({len(missed)} lone board answer(s) missed)' if missed else '')
              + f'; safety levels {sorted(set(levels))}')
