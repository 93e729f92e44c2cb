"""The field tests' link shaping (tests/linkemu.py, tests/fieldnet.py).

The emulator's core (learning switch, per-link delay, jitter and loss, order, cut) on
frames and numbers; then, as root, the shaping in force (netem where the kernel has it,
else the emulator) measured with UDP between the station's namespace and a collector's:
the one-way delays of each direction and their spread, the loss of each direction, and
a cut link carrying nothing. Unshaped links fail every one of these checks.
"""
from __future__ import annotations

import os
import random
import select
import socket
import statistics
import struct
import subprocess
import sys
import time

import pytest

from fieldnet import Net, can_make_netns, choose_shaping
from linkemu import WIFI, Shaping, Switch

A, B, C, S = (bytes([2, 0, 0, 0, 0, k]) for k in (1, 2, 3, 9))     # unicast MACs
BCAST = b'\xff' * 6


def frame(dst: bytes, src: bytes, n: int = 0) -> bytes:
    return dst + src + b'\x08\x00' + n.to_bytes(4, 'big')


def switch(shaped=('a', 'b', 'c'), shaping=WIFI, seed=1) -> Switch:
    ports = ['s', 'a', 'b', 'c']
    return Switch(ports, {p: (shaping if p in shaped else None) for p in ports}, random.Random(seed))


def test_learning_switch_floods_unknown_and_broadcast_then_forwards_to_the_learnt_port():
    sw = switch(shaped=())
    sw.ingress('a', frame(S, A), 0.0)                  # S not learnt yet: every other port
    assert sorted(p for p, _, _ in sw.due(0.0)) == ['b', 'c', 's']
    sw.ingress('s', frame(A, S), 0.0)                  # A learnt on port a
    assert [p for p, _, _ in sw.due(0.0)] == ['a']
    sw.ingress('b', frame(BCAST, B), 0.0)
    assert sorted(p for p, _, _ in sw.due(0.0)) == ['a', 'c', 's']
    sw.ingress('a', frame(A, A), 0.0)                  # to its own port: nowhere
    assert sw.due(0.0) == [] and sw.next_due() is None


def test_a_shaped_link_delays_each_direction_within_its_jitter_in_order_and_loses_its_share():
    sw = switch(shaped=('a',))
    sw.ingress('s', frame(S, S), 0.0)
    sw.due(0.0)                                        # the station learnt; a not yet: learn it
    sw.ingress('a', frame(S, A), 0.0)
    sw.due(1.0)
    n, period = 20000, 0.010                           # frames 10 ms apart: jitter never reorders them
    up, down = [], []
    for k in range(n):
        t = 1.0 + k * period
        sw.ingress('a', frame(S, A, k), t)             # uplink
        sw.ingress('s', frame(A, S, k), t)             # downlink
        for port, f, due in sw.due(t):
            (up if port == 's' else down).append((int.from_bytes(f[14:18], 'big'), due - (1.0 + int.from_bytes(f[14:18], 'big') * period)))
    for port, f, due in sw.due(1e9):
        (up if port == 's' else down).append((int.from_bytes(f[14:18], 'big'), due - (1.0 + int.from_bytes(f[14:18], 'big') * period)))
    for got in (up, down):
        seqs = [k for k, _ in got]
        assert seqs == sorted(seqs)                    # in order
        d = [x for _, x in got]
        assert min(d) >= WIFI.delay_s - WIFI.jitter_s - 1e-12 and max(d) <= WIFI.delay_s + WIFI.jitter_s + 1e-12
        assert statistics.mean(d) == pytest.approx(WIFI.delay_s, abs=2e-4)
        assert statistics.pstdev(d) == pytest.approx(WIFI.jitter_s / 3 ** 0.5, rel=0.05)   # uniform
        assert 1 - len(got) / n == pytest.approx(WIFI.loss, abs=0.003)
    assert sw.stats['a'].lost == 2 * n - len(up) - len(down)


def test_frames_closer_than_the_jitter_leave_in_order_never_earlier_than_drawn():
    sw = switch(shaped=('a',), shaping=Shaping(0.020, 0.005, 0.0))
    sw.ingress('s', frame(A, S), 0.0)                  # flooded: a learns nothing, s is learnt
    sw.due(1.0)
    for k in range(200):                               # a burst: 200 frames in 2 ms
        sw.ingress('a', frame(S, A, k), 1.0 + k * 1e-5)
    got = sw.due(2.0)
    assert [int.from_bytes(f[14:18], 'big') for _, f, _ in got] == list(range(200))
    dues = [t for _, _, t in got]
    assert dues == sorted(dues) and dues[0] >= 1.015 and dues[-1] <= 1.025 + 2e-3


def test_between_two_shaped_links_a_frame_crosses_both():
    sw = switch(shaped=('a', 'b'), shaping=Shaping(0.020, 0.0, 0.0))
    sw.ingress('b', frame(BCAST, B), 0.0)
    sw.due(1.0)
    sw.ingress('a', frame(B, A), 1.0)
    assert sw.due(1.039) == []
    (port, _, due), = sw.due(1.041)
    assert port == 'b' and due == pytest.approx(1.040)


def test_a_cut_link_drops_both_ways_and_what_is_in_flight_then_carries_again():
    sw = switch(shaped=('a',), shaping=Shaping(0.020, 0.0, 0.0))
    sw.ingress('s', frame(BCAST, S), 0.0)
    sw.ingress('a', frame(BCAST, A), 0.0)
    sw.due(1.0)
    sw.ingress('s', frame(A, S), 1.0)                  # in flight to a when it is cut
    sw.set_up('a', False)
    sw.ingress('a', frame(S, A), 1.001)
    sw.ingress('s', frame(A, S), 1.002)
    assert sw.due(2.0) == []
    assert sw.stats['a'].cut == 3
    sw.set_up('a', True)
    sw.ingress('s', frame(A, S), 2.0)
    sw.ingress('a', frame(S, A), 2.0)
    assert sorted(p for p, _, _ in sw.due(3.0)) == ['a', 's']
    with pytest.raises(KeyError):
        sw.set_up('nope', False)


def test_shaping_out_of_range_is_refused():
    for bad in ((0.01, 0.02, 0.0), (0.02, 0.005, 1.0), (0.02, -0.001, 0.0)):
        with pytest.raises(ValueError):
            Shaping(*bad)


# ------------------------------------------------------------------------------ measured, root only
ECHO = r'''
import signal, socket, struct, sys, time
s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
s.setsockopt(socket.SOL_SOCKET, getattr(socket, 'SO_TIMESTAMPNS', 35), 1)
s.bind((sys.argv[1], int(sys.argv[2])))
count = {}
def bye(*_):
    print(count.get('probe', 0), count.get('cut', 0), flush=True)
    sys.exit(0)
signal.signal(signal.SIGTERM, bye)
print('ready', flush=True)
while True:
    data, anc, _, addr = s.recvmsg(64, 64)
    rx = next(a for a in anc if a[0] == socket.SOL_SOCKET)[2]
    sec, nsec = struct.unpack('qq', rx[:16])
    seq = struct.unpack_from('!i', data)[0]
    kind = 'probe' if seq >= 0 else 'cut' if seq == -2 else 'warm'
    count[kind] = count.get(kind, 0) + 1
    s.sendto(data + struct.pack('!qq', sec * 10**9 + nsec, time.time_ns()), addr)
'''
N_PROBES = 1000          # per direction: ~10 lost of 1 %; below 2 or above 25 is off by > 2.5 sigma
PERIOD = 0.010           # [s] >= the jitter's spread (2 x 5 ms): the delays come out undistorted by order


def _rx_time(sock):
    data, anc, _, _ = sock.recvmsg(64, 64)
    sec, nsec = struct.unpack('qq', next(a for a in anc if a[0] == socket.SOL_SOCKET)[2][:16])
    return data, sec * 10**9 + nsec


def _pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))]


@pytest.fixture
def net1():
    why = can_make_netns()
    if why:
        pytest.skip(f'link shaping measured over network namespaces: {why}')
    n = Net(['c1'])
    try:
        n.up()
        yield n
    finally:
        n.down()


def test_link_shaping_in_force_measured_with_udp_between_namespaces(net1):
    """Station -> collector and back, each probe timed by the kernel at its receiver:
    each direction's one-way delays lie in delay +- jitter (none earlier; their median near
    the delay, their 10-90 % spread near the uniform's 0.8 x 2 x jitter) and each direction
    loses about its share; a cut link carries nothing and carries again once joined."""
    print(f'shaping in force: {net1.describe}')
    s = WIFI
    port = 47000 + os.getpid() % 1000
    echo = subprocess.Popen(['ip', 'netns', 'exec', net1.ns['c1'], sys.executable, '-c', ECHO, net1.ip['c1'], str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, getattr(socket, 'SO_TIMESTAMPNS', 35), 1)
    sock.bind((net1.station_ip, 0))
    dest = (net1.ip['c1'], port)
    replies = {}

    def send(seq):
        sock.sendto(struct.pack('!iq', seq, time.time_ns()), dest)

    def drain(until):
        while True:
            r, _, _ = select.select([sock], [], [], max(0.0, until - time.monotonic()))
            if not r:
                return
            data, rx = _rx_time(sock)
            seq, tx, rx_echo, tx_echo = struct.unpack('!iqqq', data)
            replies.setdefault(seq, []).append((rx_echo - tx, rx - tx_echo))
    try:
        assert echo.stdout.readline().strip() == 'ready', echo.stderr.read()
        for _ in range(100):                            # warm-up (ARP both ways) until a probe comes back
            send(-1)
            drain(time.monotonic() + 0.2)
            if -1 in replies:
                break
        assert -1 in replies, 'no answer through the link at all'
        t_next = time.monotonic()
        for k in range(N_PROBES):
            send(k)
            t_next = max(t_next + PERIOD, time.monotonic())
            drain(t_next)
        drain(time.monotonic() + 0.5)
        net1.link('c1', False)                          # cut: nothing either way
        for _ in range(20):
            send(-2)
            drain(time.monotonic() + 0.02)
        drain(time.monotonic() + 0.3)
        net1.link('c1', True)
        for _ in range(100):
            send(-3)
            drain(time.monotonic() + 0.1)
            if -3 in replies:
                break
        emu = net1.stats()
    finally:
        echo.terminate()
        out, err = echo.communicate(10)
    got_probe, got_cut = map(int, out.split())
    down = [1e-9 * d for k in range(N_PROBES) for d, _ in replies.get(k, [])]
    up = [1e-9 * u for k in range(N_PROBES) for _, u in replies.get(k, [])]
    loss_down = 1 - got_probe / N_PROBES
    loss_up = 1 - len(up) / got_probe
    lines = []
    for name, d in (('station -> collector', down), ('collector -> station', up)):
        lines.append(f'{name}: one-way delay min {min(d) * 1e3:.2f} ms, p10 {_pct(d, .1) * 1e3:.2f}, median '
                     f'{statistics.median(d) * 1e3:.2f}, p90 {_pct(d, .9) * 1e3:.2f}, max {max(d) * 1e3:.2f} ms')
    lines.append(f'loss station -> collector {loss_down:.2%}, collector -> station {loss_up:.2%} of {N_PROBES}')
    if emu:
        lines.append(f'emulator: deliveries late by {emu["late"]["mean_s"] * 1e6:.0f} us on average, at most '
                     f'{emu["late"]["max_s"] * 1e3:.2f} ms, {emu["late"]["over_1ms"]} of {emu["late"]["n"]} by over 1 ms')
    print('\n'.join(lines))
    assert got_cut == 0 and not replies.get(-2), 'a cut link carried probes'
    assert -3 in replies, 'the link did not carry again once joined'
    for d in (down, up):
        assert min(d) >= s.delay_s - s.jitter_s - 1e-4, lines
        assert s.delay_s - 1e-3 <= statistics.median(d) <= s.delay_s + 3e-3, lines
        assert 0.6 * 1.6 * s.jitter_s <= _pct(d, .9) - _pct(d, .1) <= 1.6 * s.jitter_s + 4e-3, lines
    for loss in (loss_down, loss_up):
        assert 2 / N_PROBES <= loss <= 25 / N_PROBES, lines


def test_the_shaping_choice_is_netem_else_the_emulator():
    if can_make_netns():
        pytest.skip('needs root (a probe network namespace for tc)')
    mode, why = choose_shaping('auto')
    assert mode in ('netem', 'emulator') and (mode == 'netem') == (why == '')
    with pytest.raises(ValueError):
        choose_shaping('wifi')
