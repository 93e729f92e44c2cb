"""sslfr_common.node: the one main() of every node.

Signals are sent to real processes running :func:`run_node` (the way ``ros2 launch``,
systemd and a terminal's Ctrl-C do): an orderly stop, exit 0, nothing printed as an
error, ``on_exit`` run with the context still valid, whatever further signals arrive.
"""
import signal
import subprocess
import sys
import textwrap
import time

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

from sslfr_common.node import LeanEvents, SpinStats, spin_until_stopped

NODE = textwrap.dedent('''
    import logging, os, sys, time
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import String
    from sslfr_common.node import run_node

    BUILD_S = float(os.environ.get('BUILD_S', '0'))
    EXIT_S = float(os.environ.get('EXIT_S', '0'))
    SLOW_CB_S = float(os.environ.get('SLOW_CB_S', '0'))
    HANG_FILE = os.environ.get('HANG_FILE', '')
    lib = logging.getLogger('sslfr_testlib')

    class Demo(Node):
        def __init__(self):
            super().__init__('plumbing_demo')
            if os.environ.get('BAD'):
                raise ValueError('parameter x = -1 is outside [0, 1]')
            print('building', flush=True)
            time.sleep(BUILD_S)
            self.pub = self.create_publisher(String, 'plumbing_demo_out', 1)
            self.create_timer(0.05, self._tick)
            print('ready', flush=True)

        def _tick(self):
            if not getattr(self, 'said', False):
                self.said = True
                print('executor', type(self.executor).__name__, flush=True)
            if HANG_FILE and os.path.exists(HANG_FILE):   # a callback that never returns
                print('callback hangs', flush=True)
                while True:
                    time.sleep(0.05)
            if SLOW_CB_S:                         # a callback still running at the stop
                print('cb start', flush=True)
                time.sleep(SLOW_CB_S)
                self.pub.publish(String(data='late'))
                print('cb end', flush=True)

        def on_exit(self):
            print('on_exit start', flush=True)
            lib.info('link up -> down')          # a library log during the stop
            time.sleep(EXIT_S)
            self.get_logger().info('stopped cleanly')
            print('on_exit done', flush=True)

    mt = (lambda ctx: MultiThreadedExecutor(num_threads=4, context=ctx)) if os.environ.get('MT') else None
    sys.exit(run_node('plumbing_demo', Demo, log_bridge=('sslfr_testlib',), executor=mt))
''')


def _start(ros_env, **env):
    return subprocess.Popen([sys.executable, '-c', NODE], env={**ros_env, **env}, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def _wait_line(proc, text, timeout=30.0):
    seen = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        seen.append(line)
        if text in line:
            return seen
    raise AssertionError(f'{text!r} not printed: {"".join(seen)}')


def _finish(proc, timeout=20.0):
    out, _ = proc.communicate(timeout=timeout)
    return proc.returncode, out


def _clean(out):
    assert 'Traceback' not in out, out
    assert 'Failed to publish log message to rosout' not in out, out
    assert 'context is invalid' not in out, out
    assert 'on_exit done' in out, out
    assert 'never retrieved' not in out, out


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
def test_one_signal_orderly_stop_exit_0(ros_env, sig):
    proc = _start(ros_env)
    _wait_line(proc, 'ready')
    time.sleep(0.2)
    t0 = time.monotonic()
    proc.send_signal(sig)
    code, out = _finish(proc)
    assert code == 0, out
    _clean(out)
    assert time.monotonic() - t0 < 5.0
    assert 'stopped cleanly' in out      # logged while the context is still valid


@pytest.mark.parametrize('choice, name', [(None, 'LeanExecutor'), ('lean', 'LeanExecutor'),
                                          ('rclpy', 'SingleThreadedExecutor')])
def test_executor_chosen_by_the_environment(ros_env, choice, name):
    env = dict(ros_env)
    env.pop('SSLFR_EXECUTOR', None)
    if choice:
        env['SSLFR_EXECUTOR'] = choice
    proc = _start(env)
    _wait_line(proc, f'executor {name}')
    proc.send_signal(signal.SIGINT)
    code, out = _finish(proc)
    assert code == 0, out
    _clean(out)


def test_unknown_executor_choice_is_one_line_exit_2(ros_env):
    proc = _start(ros_env, SSLFR_EXECUTOR='multi')
    code, out = _finish(proc)
    assert code == 2, out
    assert out.strip() == ("plumbing_demo: not starting: SSLFR_EXECUTOR='multi': "
                           "expected 'lean' (the default) or 'rclpy'"), out


def test_second_sigint_50ms_later_during_the_stop_is_ignored(ros_env):
    proc = _start(ros_env, EXIT_S='1.0')
    _wait_line(proc, 'ready')
    proc.send_signal(signal.SIGINT)
    _wait_line(proc, 'on_exit start')
    time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    proc.send_signal(signal.SIGTERM)
    code, out = _finish(proc)
    assert code == 0, out
    _clean(out)


def test_two_sigints_50ms_apart_right_after_start(ros_env):
    proc = _start(ros_env, EXIT_S='0.5')
    _wait_line(proc, 'ready')
    proc.send_signal(signal.SIGINT)
    time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    code, out = _finish(proc)
    assert code == 0, out
    _clean(out)


def test_callbacks_in_flight_in_a_thread_pool_finish_before_on_exit(ros_env):
    """MultiThreadedExecutor (the axis driver's): a callback still running when the
    stop begins ends before on_exit() and before the node is destroyed; nothing is
    printed about an exception never retrieved (rclpy's Task.__del__)."""
    proc = _start(ros_env, MT='1', SLOW_CB_S='0.4')
    _wait_line(proc, 'cb start')
    proc.send_signal(signal.SIGINT)
    code, out = _finish(proc)
    assert code == 0, out
    _clean(out)
    assert out.rindex('cb end') < out.index('on_exit start'), out


def test_signal_while_the_node_is_being_built(ros_env):
    proc = _start(ros_env, BUILD_S='1.5')
    _wait_line(proc, 'building')
    proc.send_signal(signal.SIGINT)
    code, out = _finish(proc)
    assert code == 0, out
    _clean(out)
    assert 'ready' in out                 # construction finished, then the orderly stop


def test_invalid_configuration_is_one_line_exit_2(ros_env):
    proc = _start(ros_env, BAD='1')
    code, out = _finish(proc)
    assert code == 2, out
    lines = [ln for ln in out.splitlines() if ln.strip()]
    assert lines == ['plumbing_demo: invalid parameters, not starting: parameter x = -1 is outside [0, 1]'], out


class FlakyExecutor(SingleThreadedExecutor):
    """Raises like rclpy's take_message did under load, then shuts the context down."""

    def __init__(self, context, failures):
        super().__init__(context=context)
        self.calls = 0
        self.failures = failures

    def spin_once(self, timeout_sec=None):
        self.calls += 1
        if self.calls <= self.failures:
            raise RuntimeError("Unable to convert call argument '0' to Python object")
        rclpy.try_shutdown(context=self.context)


def test_runtime_errors_are_counted_not_fatal(ros_domain):
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=ros_domain)
    node = rclpy.create_node('spin_test', context=ctx)
    try:
        ex = FlakyExecutor(ctx, failures=3)
        stats = spin_until_stopped(node, ex, stats=SpinStats())
        assert stats.errors == 3 and 'Unable to convert' in stats.last
        assert ex.calls == 4
    finally:
        node.destroy_node()
        rclpy.try_shutdown(context=ctx)
        ex.shutdown()


def test_lean_events_drops_the_default_qos_event_handlers_only(ros_domain):
    from rclpy.event_handler import PublisherEventCallbacks
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from std_msgs.msg import String

    class Lean(LeanEvents, Node):
        pass

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=ros_domain)
    lean = Lean('lean', context=ctx, parameter_overrides=[Parameter('use_sim_time', value=True)])
    plain = Node('plain', context=ctx)
    try:
        assert len(plain.create_publisher(String, 'x', 1).event_handlers) == 2     # rclpy's default
        assert len(plain.create_subscription(String, 'x', lambda m: None, 1).event_handlers) == 2
        assert lean.create_publisher(String, 'x', 1).event_handlers == []
        assert lean.create_subscription(String, 'x', lambda m: None, 1).event_handlers == []
        # the entities rclpy's Node makes itself: /parameter_events, /clock (sim time)
        assert all(p.event_handlers == [] for p in lean.publishers)
        assert all(s.event_handlers == [] for s in lean.subscriptions)
        assert any(s.topic_name == '/clock' for s in lean.subscriptions)
        # callbacks a caller asks for are kept
        own = lean.create_publisher(String, 'y', 1, event_callbacks=PublisherEventCallbacks(
            incompatible_qos=lambda e: None))
        assert len(own.event_handlers) >= 1
    finally:
        lean.destroy_node()
        plain.destroy_node()
        rclpy.try_shutdown(context=ctx)


COMPOSED = textwrap.dedent('''
    import os, sys
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from sslfr_common.node import run_nodes

    class Part(Node):
        def __init__(self, name):
            super().__init__(name)
            if os.environ.get('BAD') == name:
                raise ValueError(f'{name}: bad value')
            self.create_timer(0.05, lambda: None)
            print(f'{name} ready', flush=True)

        def on_exit(self):
            print(f'{self.get_name()} on_exit', flush=True)

    sys.exit(run_nodes([(n, lambda n=n: Part(n)) for n in ('first', 'second', 'third')],
                       executor=lambda ctx: EventsExecutor(context=ctx)))
''')


def test_composed_nodes_stop_in_order_in_one_process(ros_env):
    proc = subprocess.Popen([sys.executable, '-c', COMPOSED], env=ros_env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    _wait_line(proc, 'third ready')
    proc.send_signal(signal.SIGTERM)
    code, out = _finish(proc)
    assert code == 0, out
    assert [ln for ln in out.splitlines() if 'on_exit' in ln] == ['first on_exit', 'second on_exit', 'third on_exit']


def test_a_composed_node_refusing_its_config_stops_the_process(ros_env):
    proc = subprocess.Popen([sys.executable, '-c', COMPOSED], env={**ros_env, 'BAD': 'second'},
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    code, out = _finish(proc)
    assert code == 2, out
    assert 'second: invalid parameters, not starting: second: bad value' in out
    assert 'first on_exit' in out and 'third' not in out


def test_composed_nodes_share_one_clock_subscription(ros_domain):
    """share_time_source: the nodes of one process on sim time take /clock once (the
    first node's subscription), every node's ROS clock follows it, and use_sim_time can
    no longer be changed at run time (refused with the reason)."""
    from rclpy.node import Node
    from rclpy.parameter import Parameter
    from rosgraph_msgs.msg import Clock
    from sslfr_common.executor import LeanExecutor
    from sslfr_common.node import share_time_source

    class Lean(LeanEvents, Node):
        pass

    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=ros_domain)
    sim = [Parameter('use_sim_time', value=True)]
    nodes = [Lean(f'clock_user_{i}', context=ctx, parameter_overrides=sim) for i in range(3)]
    wall = Lean('wall_clock_user', context=ctx)                # system time: left alone
    src = Lean('clock_source', context=ctx)
    ex = LeanExecutor(context=ctx)
    try:
        assert share_time_source([*nodes, wall]) == 2
        clock_subs = [s for n in (*nodes, wall) for s in n.subscriptions if s.topic_name == '/clock']
        assert len(clock_subs) == 1 and clock_subs[0] in nodes[0].subscriptions
        for n in (*nodes, wall, src):
            ex.add_node(n)
        pub = src.create_publisher(Clock, '/clock', 10)
        deadline = time.monotonic() + 5.0
        while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.05)
        for sec in (100, 200):
            msg = Clock()
            msg.clock.sec = sec
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline and any(
                    n.get_clock().now().nanoseconds != sec * 10**9 for n in nodes):
                pub.publish(msg)
                ex.spin_once(timeout_sec=0.05)
            assert [n.get_clock().now().nanoseconds for n in nodes] == [sec * 10**9] * 3
        assert wall.get_clock().now().nanoseconds > 1e18                 # still the system time
        for n in nodes:
            res = n.set_parameters([Parameter('use_sim_time', value=False)])[0]
            assert not res.successful and 'shared by the nodes of this process' in res.reason
            assert n.get_clock().ros_time_is_active
        assert share_time_source(nodes[:1]) == 0                         # alone: nothing to share
    finally:
        ex.shutdown()
        for n in (*nodes, wall, src):
            n.destroy_node()
        rclpy.try_shutdown(context=ctx)


@pytest.mark.parametrize('choice', ['lean', 'rclpy'])
def test_beats_come_from_the_executor_turning(ros_env, tmp_path, choice):
    """READY=1, then WATCHDOG=1 every beat period (a quarter of WATCHDOG_USEC, here
    0.5 s) on a real NOTIFY_SOCKET while the executor turns; a callback that never
    returns stops them although the process runs on (its other threads too); an
    orderly stop says STOPPING=1."""
    from sslfr_common.sdnotify import NotifyListener

    def collect(lis, proc, until, timeout):
        got = []
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not until(got):
            got += [(time.monotonic(), n.fields) for n in lis.receive() if n.pid == proc.pid]
            time.sleep(0.02)
        return got

    hang = tmp_path / 'hang'
    with NotifyListener(str(tmp_path / 'notify.sock')) as lis:
        proc = _start(ros_env, SSLFR_EXECUTOR=choice, NOTIFY_SOCKET=lis.path, WATCHDOG_USEC='2000000',
                      HANG_FILE=str(hang))
        try:
            got = collect(lis, proc, lambda g: sum('WATCHDOG' in f for _, f in g) >= 4, 60.0)
            assert got and got[0][1].get('READY') == '1', got
            assert got[0][1]['STATUS'] == 'executor turning: plumbing_demo'
            beats = [t for t, f in got if f.get('WATCHDOG') == '1']
            assert len(beats) >= 4, got
            gaps = [b - a for a, b in zip(beats, beats[1:])]
            assert all(0.4 <= g <= 1.6 for g in gaps), gaps       # 0.5 s period, loaded machine
            hang.touch()
            _wait_line(proc, 'callback hangs')
            t_hung = time.monotonic()
            late = collect(lis, proc, lambda g: False, 2.5)
            # a beat already on its way when the callback began may still arrive
            assert not [t for t, f in late if 'WATCHDOG' in f and t > t_hung + 0.3], late
            assert proc.poll() is None, 'the process runs on: only its executor stopped'
        finally:
            proc.kill()
            proc.communicate(timeout=20)
        hang.unlink()
        proc = _start(ros_env, SSLFR_EXECUTOR=choice, NOTIFY_SOCKET=lis.path, WATCHDOG_USEC='2000000')
        collect(lis, proc, lambda g: any('WATCHDOG' in f for _, f in g), 60.0)
        proc.send_signal(signal.SIGINT)
        code, out = _finish(proc)
        assert code == 0, out
        assert any(n.fields.get('STOPPING') == '1' for n in lis.receive() if n.pid == proc.pid), out
