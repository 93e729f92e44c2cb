"""A field's network for the network-namespace tests and benchmarks (root only).

One network namespace per collector, the station in this (the test's) namespace, each
collector's link shaped like Wi-Fi (linkemu.WIFI: 20 ms +- 5 ms, 1 % loss, each direction):

- ``netem`` (preferred where the kernel has the qdisc): a Linux bridge with the station's
  address, one veth pair per collector, ``tc netem`` on both ends of the pair (the
  collector's egress and the station's towards it); a cut sets the bridge-side end down;
- ``emulator`` (where netem is missing): linkemu's userspace emulator, one TAP device per
  collector moved into its namespace and one for the station carrying the station's
  address; a cut drops every frame of that link in the emulator (the device stays up);
- ``none``: the bridge and veth pairs without shaping (for comparison runs only).

``SSLFR_LINK_SHAPING`` = auto (default: netem, else the emulator) | netem | emulator | none.
"""
from __future__ import annotations

import os
import shutil
import socket
import subprocess

from linkemu import WIFI, LinkEmulator, Shaping, netns_socket

MODES = ('auto', 'netem', 'emulator', 'none')


def _run(*cmd, check=True):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if check and r.returncode != 0:
        raise RuntimeError(f'{" ".join(cmd)}: {r.stderr.strip()}')
    return r


def can_make_netns() -> str:
    """'' where this process can build the network; else why not (a skip message)."""
    if os.geteuid() != 0:
        return 'needs root (ip netns, veth, bridge, TAP)'
    if shutil.which('ip') is None:
        return 'the ip tool (iproute2) is missing'
    probe = f'sslfrprobe{os.getpid()}'
    r = _run('ip', 'netns', 'add', probe, check=False)
    if r.returncode != 0:
        return f'ip netns add refused: {r.stderr.strip()}'
    _run('ip', 'netns', 'del', probe, check=False)
    return ''


def netem_missing() -> str:
    """'' where ``tc netem`` works (tried on a probe namespace's loopback); else tc's answer."""
    if shutil.which('tc') is None:
        return 'the tc tool is missing'
    probe = f'sslfrnetem{os.getpid()}'
    _run('ip', 'netns', 'add', probe)
    try:
        r = _run('ip', 'netns', 'exec', probe, 'tc', 'qdisc', 'add', 'dev', 'lo', 'root', 'netem', 'delay', '1ms',
                 check=False)
        return '' if r.returncode == 0 else (r.stderr.strip() or f'tc exit status {r.returncode}')
    finally:
        _run('ip', 'netns', 'del', probe, check=False)


def choose_shaping(mode: str | None = None) -> tuple[str, str]:
    """(mode, why): ``mode`` (default SSLFR_LINK_SHAPING, else auto) resolved to netem,
    emulator or none; ``why`` says why netem is not used ('' when it is)."""
    mode = mode or os.environ.get('SSLFR_LINK_SHAPING', 'auto')
    if mode not in MODES:
        raise ValueError(f'SSLFR_LINK_SHAPING={mode!r}: one of {", ".join(MODES)}')
    if mode in ('emulator', 'none'):
        return mode, f'{mode} chosen'
    missing = netem_missing()
    if mode == 'netem' and missing:
        raise RuntimeError(f'tc netem asked for but unavailable: {missing}')
    return ('netem', '') if not missing else ('emulator', f'no tc netem: {missing}')


class Net:
    """The station's address in this namespace and one namespace per collector, shaped."""

    def __init__(self, ids: list[str], mode: str | None = None, shaping: Shaping = WIFI, seed: int | None = None):
        pid = os.getpid()
        tag = pid % 100000
        self.subnet = f'10.{200 + pid // 250 % 50}.{pid % 250}'   # apart for concurrent runs (test workers)
        self.bridge = f'sfbr{tag}'
        self.station_if = f'sfs{tag}'              # emulator: the station's TAP device
        self.station_ip = f'{self.subnet}.1'
        self.ns = {cid: f'sf{tag}{cid}' for cid in ids}
        self.host_if = {cid: f'sfh{tag}{cid}' for cid in ids}   # netem/none: the veth's bridge end
        self.coll_if = {cid: f'sfc{cid}' for cid in ids}        # the collector's interface in its namespace
        self.ip = {cid: f'{self.subnet}.{11 + k}' for k, cid in enumerate(ids)}
        self.mode, why = choose_shaping(mode)
        self.shaping = shaping
        self.seed = seed
        self.emu: LinkEmulator | None = None
        how = {'netem': f'tc netem on both ends of each veth: {shaping.describe()}',
               'emulator': f'userspace link emulator (tests/linkemu.py, TAP devices): {shaping.describe()}',
               'none': 'links NOT shaped'}[self.mode]
        #: the shaping in force, for the tests' and benchmarks' output
        self.describe = how + (f' ({why})' if why else '')

    def up(self) -> None:
        if self.mode == 'emulator':
            self._up_emulator()
        else:
            self._up_bridge()
        for ns in self.ns.values():
            _run('ip', 'netns', 'exec', ns, 'ip', 'link', 'set', 'lo', 'up')

    def _netem(self, ns: str | None, dev: str) -> None:
        s = self.shaping
        cmd = ['tc', 'qdisc', 'replace', 'dev', dev, 'root', 'netem', 'delay', f'{s.delay_s * 1e3:g}ms',
               f'{s.jitter_s * 1e3:g}ms', 'loss', f'{s.loss * 100:g}%']
        _run(*((['ip', 'netns', 'exec', ns] if ns else []) + cmd))

    def _up_bridge(self) -> None:
        _run('ip', 'link', 'add', self.bridge, 'type', 'bridge')
        _run('ip', 'addr', 'add', f'{self.station_ip}/24', 'dev', self.bridge)
        _run('ip', 'link', 'set', self.bridge, 'up')
        for cid, ns in self.ns.items():
            _run('ip', 'netns', 'add', ns)
            peer = self.coll_if[cid]
            _run('ip', 'link', 'add', self.host_if[cid], 'type', 'veth', 'peer', 'name', peer, 'netns', ns)
            _run('ip', 'link', 'set', self.host_if[cid], 'master', self.bridge, 'up')
            _run('ip', 'netns', 'exec', ns, 'ip', 'addr', 'add', f'{self.ip[cid]}/24', 'dev', peer)
            _run('ip', 'netns', 'exec', ns, 'ip', 'link', 'set', peer, 'up')
            if self.mode == 'netem':
                self._netem(ns, peer)
                self._netem(None, self.host_if[cid])

    def _up_emulator(self) -> None:
        tag = self.station_if[3:]
        devices = {'station': self.station_if, **{cid: f'sft{tag}{cid}' for cid in self.ns}}
        self.emu = LinkEmulator(devices, self.shaping, wired=('station',), seed=self.seed)
        self.emu.start()
        _run('ip', 'addr', 'add', f'{self.station_ip}/24', 'dev', self.station_if)
        _run('ip', 'link', 'set', self.station_if, 'up')
        for cid, ns in self.ns.items():
            _run('ip', 'netns', 'add', ns)
            _run('ip', 'link', 'set', devices[cid], 'netns', ns)
            _run('ip', 'netns', 'exec', ns, 'ip', 'link', 'set', devices[cid], 'name', self.coll_if[cid])
            _run('ip', 'netns', 'exec', ns, 'ip', 'addr', 'add', f'{self.ip[cid]}/24', 'dev', self.coll_if[cid])
            _run('ip', 'netns', 'exec', ns, 'ip', 'link', 'set', self.coll_if[cid], 'up')

    def link(self, cid: str, up: bool) -> None:
        """Cut (``up=False``) or restore one collector's link."""
        if self.mode == 'emulator':
            self.emu.set_link(cid, up)
        else:
            _run('ip', 'link', 'set', self.host_if[cid], 'up' if up else 'down')

    def packet_socket(self, cid: str) -> socket.socket:
        """An AF_PACKET socket seeing every frame of ``cid``'s link both ways (root)."""
        args = (socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x0003))
        if self.mode == 'emulator':
            s = netns_socket(self.ns[cid], *args)
            s.bind((self.coll_if[cid], 0))
        else:
            s = socket.socket(*args)
            s.bind((self.host_if[cid], 0))
        return s

    def stats(self) -> dict | None:
        """The emulator's per-port counters and its delivery lateness (None without it)."""
        return self.emu.stats() if self.emu else None

    def down(self) -> None:
        if self.emu:                               # first: its devices vanish with it
            self.emu.stop()
            self.emu = None
        for ns in self.ns.values():
            _run('ip', 'netns', 'del', ns, check=False)
        if self.mode != 'emulator':
            _run('ip', 'link', 'del', self.bridge, check=False)
