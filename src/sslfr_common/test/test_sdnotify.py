"""The sd_notify protocol against a listener on a real NOTIFY_SOCKET datagram socket
(no systemd needed): the fields arrive with the sender's pid from the kernel, beats are
rate-limited on the steady clock, the environment is read as sd_notify(3) says, and a
missing listener never raises."""
from __future__ import annotations

import os
import socket
import subprocess
import sys
import time

import pytest

from sslfr_common import sdnotify
from sslfr_common.sdnotify import Notifier, NotifyListener, beat_period, parse


def _wait(listener, n=1, timeout=5.0):
    out = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out += listener.receive()
        time.sleep(0.005)
    return out


def test_fields_arrive_with_the_senders_pid(tmp_path):
    with NotifyListener(str(tmp_path / 'n.sock')) as lis:
        n = Notifier(lis.path, watchdog_s=5.0)
        assert n.notify('READY=1', 'STATUS=executor turning: planner')
        got = _wait(lis)
        assert got[0].pid == os.getpid()
        assert got[0].fields == {'READY': '1', 'STATUS': 'executor turning: planner'}


def test_pid_of_another_process_and_abstract_namespace():
    name = f'@sslfr-test-{os.getpid()}-{time.monotonic_ns()}'
    with NotifyListener(name) as lis:
        child = subprocess.Popen([sys.executable, '-c',
                                  'from sslfr_common.sdnotify import Notifier; import os;'
                                  'print(Notifier.from_environ().notify("WATCHDOG=1"), flush=True)'],
                                 env=dict(os.environ, NOTIFY_SOCKET=name), stdout=subprocess.PIPE, text=True)
        out, _ = child.communicate(timeout=30)
        assert out.strip() == 'True'
        got = _wait(lis)
        assert [(g.pid, g.fields) for g in got] == [(child.pid, {'WATCHDOG': '1'})]


def test_beat_is_rate_limited_on_the_steady_clock(tmp_path, monkeypatch):
    clock = [100.0]
    monkeypatch.setattr(sdnotify.time, 'monotonic', lambda: clock[0])
    with NotifyListener(str(tmp_path / 'n.sock')) as lis:
        n = Notifier(lis.path, watchdog_s=5.0)
        assert n.period == 1.0
        sent = []
        for _ in range(50):              # 50 executor turns within 0.49 s: one beat
            n.beat()
            clock[0] += 0.01
        sent.append(n.sent)
        clock[0] = 101.0                 # a period after the first beat: the next one
        n.beat()
        n.beat()
        sent.append(n.sent)
        assert sent == [1, 2]
        assert [g.fields for g in _wait(lis, 2)] == [{'WATCHDOG': '1'}] * 2


def test_beat_period_follows_the_bound():
    assert beat_period(None) is None
    assert beat_period(5.0) == 1.0       # at most every 1 s
    assert beat_period(2.0) == 0.5       # a quarter of the bound
    assert beat_period(0.01) == sdnotify.MIN_BEAT_PERIOD


@pytest.mark.parametrize('env,watchdog', [
    ({'NOTIFY_SOCKET': '/run/x', 'WATCHDOG_USEC': '5000000'}, 5.0),
    ({'NOTIFY_SOCKET': '/run/x', 'WATCHDOG_USEC': '5000000', 'WATCHDOG_PID': '4242'}, 5.0),
    ({'NOTIFY_SOCKET': '/run/x', 'WATCHDOG_USEC': '5000000', 'WATCHDOG_PID': '1'}, None),  # not for us
    ({'NOTIFY_SOCKET': '/run/x', 'WATCHDOG_USEC': 'soon'}, None),
    ({'NOTIFY_SOCKET': '/run/x', 'WATCHDOG_USEC': '0'}, None),
    ({'NOTIFY_SOCKET': '/run/x'}, None),
    ({'WATCHDOG_USEC': '5000000'}, None),                  # nobody to tell
])
def test_environment_as_sd_notify_reads_it(env, watchdog):
    n = Notifier.from_environ(env, pid=4242)
    assert n.watchdog_s == watchdog
    assert n.enabled == ('NOTIFY_SOCKET' in env)
    assert (n.period is None) == (watchdog is None)


def test_no_listener_never_raises(tmp_path):
    n = Notifier(str(tmp_path / 'nobody.sock'), watchdog_s=2.0)
    assert n.notify('READY=1') is False
    n.beat()
    assert (n.sent, n.failed) == (0, 2)
    off = Notifier(None, 2.0)
    assert not off.enabled and off.notify('READY=1') is False
    off.beat()


def test_listener_replaces_a_stale_socket_file_and_removes_it(tmp_path):
    path = tmp_path / 'n.sock'
    stale = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    stale.bind(str(path))
    stale.close()                         # the file stays, as after a SIGKILL
    lis = NotifyListener(str(path))
    assert Notifier(str(path)).notify('WATCHDOG=1')
    assert _wait(lis)[0].fields == {'WATCHDOG': '1'}
    lis.close()
    assert not path.exists()


def test_parse_skips_what_is_not_key_value():
    assert parse(b'READY=1\nnonsense\n=x\nSTATUS=a=b\n\xff') == {'READY': '1', 'STATUS': 'a=b'}
