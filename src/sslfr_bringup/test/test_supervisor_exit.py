"""`sslfr up` / `sslfr sim` end even when their ROS side does not: RosSide.shutdown is
bounded and exit_if_stuck leaves with the command's exit code (a quiet soak round once
saw a `sslfr sim` that had printed its stop and never exited)."""
from __future__ import annotations

import subprocess
import sys
import textwrap
import time

from sslfr_bringup import supervisor

STUCK = textwrap.dedent('''
    import sys, threading, time
    from sslfr_bringup import cli, supervisor

    class Stuck(supervisor.RosSide):
        SHUTDOWN_BOUNDS = (0.1, 0.1, 0.2)
        def run(self):                     # ignores its halt, like a thread blocked in rclpy
            self.ready.set()
            threading.Event().wait()

    class Cmd:
        @staticmethod
        def main(argv):
            ros = Stuck(0)
            ros.start()
            ros.ready.wait()
            t0 = time.monotonic()
            ended = ros.shutdown()
            print(f'ended={ended} took={time.monotonic() - t0:.2f}', flush=True)
            return 3

    sys.modules['fake_cmd'] = Cmd
    cli._available = lambda: {'fake': ('fake_cmd', 'a command whose ROS side sticks')}
    sys.exit(cli.main(['fake']))
''')


def test_a_stuck_ros_side_is_bounded_and_the_command_exits_with_its_code():
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, '-c', STUCK], capture_output=True, text=True, timeout=60)
    assert r.returncode == 3, (r.stdout, r.stderr)
    assert 'ended=False' in r.stdout, r.stdout
    took = float(r.stdout.split('took=')[1].split()[0])
    assert took < 2.0, took                       # the bounds above, not a hang
    assert 'the ROS side did not end' in r.stderr and '(exit 3)' in r.stderr, r.stderr
    assert time.monotonic() - t0 < 30


def test_a_ros_side_that_ends_is_joined_and_nothing_is_forced():
    class Quick(supervisor.RosSide):
        def run(self):
            self.ready.set()
            self._halt.wait()

    ros = Quick(0)
    ros.start()
    ros.ready.wait(5)
    assert ros.shutdown() is True and not ros.is_alive()
    assert ros not in supervisor._STUCK
    supervisor.exit_if_stuck(0, 'test')          # returns: nothing stuck


def test_a_ros_side_that_fails_while_setting_up_releases_its_waiters_with_the_error():
    """Its waiters (sslfr up / sim start-up) must not wait forever for ``ready``."""
    class Broken(supervisor.RosSide):
        def _run(self):
            raise RuntimeError('publisher refused')

    ros = Broken(0)
    ros.start()
    failed = ros.wait_ready(supervisor.StopSignals())
    assert failed == 'publisher refused' and isinstance(ros.error, RuntimeError)
    assert ros.shutdown() is True
