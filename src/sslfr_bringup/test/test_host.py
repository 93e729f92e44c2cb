"""sslfr_bringup.host: executable lookup and ROS-domain locks (shared by the CLI and
the test fixtures)."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from sslfr_bringup import host

ROOT = Path(__file__).resolve().parents[3]


def test_executable_lookup_is_where_ros2_run_looks(monkeypatch, tmp_path):
    assert host.executable_path('pkg', 'exe', '/x/install') == Path('/x/install/pkg/lib/pkg/exe')
    monkeypatch.setenv('SSLFR_ROOT', str(tmp_path))
    assert host.install_prefix() is None                      # not built
    exe = tmp_path / 'ros_ws' / 'install' / 'sslfr_demo' / 'lib' / 'sslfr_demo' / 'node'
    exe.parent.mkdir(parents=True)
    exe.write_text('#!/bin/sh\n')
    assert host.install_prefix() == tmp_path / 'ros_ws' / 'install'
    assert host.find_executable('sslfr_demo', 'node') is None     # not executable
    exe.chmod(0o755)
    assert host.find_executable('sslfr_demo', 'node') == exe
    assert host.find_executable('sslfr_demo', 'other') is None


def test_this_checkout_finds_its_planner():
    if host.install_prefix(ROOT) is None:
        pytest.fail('ros_ws/install missing: run make setup')
    found = host.executable_path('sslfr_planner', 'planner', host.install_prefix(ROOT))
    assert found.is_file() and os.access(found, os.X_OK)


def test_a_held_domain_is_never_given_twice_and_is_freed_with_its_holder(monkeypatch, tmp_path):
    monkeypatch.setattr(host, 'DOMAIN_LOCK_DIR', tmp_path)    # not the machine's real locks
    candidates = (229, 230)
    a, fa = host.acquire_domain(candidates)
    try:
        b, fb = host.acquire_domain(candidates)
        assert {a, b} == set(candidates)
        with pytest.raises(RuntimeError, match='no free ROS domain id'):
            host.acquire_domain(candidates)
        # another process sees the same locks
        probe = textwrap.dedent(f'''
            from pathlib import Path
            from sslfr_bringup import host
            host.DOMAIN_LOCK_DIR = Path({str(tmp_path)!r})
            try:
                host.acquire_domain({candidates!r})
                print('got one')
            except RuntimeError:
                print('none free')
        ''')
        out = subprocess.run([sys.executable, '-c', probe], capture_output=True, text=True, timeout=60)
        assert out.stdout.strip() == 'none free', out.stderr
        fb.close()
        c, fc = host.acquire_domain(candidates)
        assert c == b
        fc.close()
    finally:
        fa.close()
