"""sslfr_common.executor.LeanExecutor: rclpy's single-threaded semantics, cheaper wake-ups.

Every kind of entity is served (timers, subscriptions, services, clients, guard
conditions triggered from another thread), entities created and destroyed by callbacks
are picked up, ``async`` callbacks and futures go through rclpy's own path, timeouts
are kept, and a callback costs one wake-up (rclpy's handler triggers its guard
condition twice per callback: :func:`test_one_wakeup_per_callback` fails with it).
"""
import threading
import time

import pytest
import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger

from sslfr_common.executor import LeanExecutor
from sslfr_common.node import LeanEvents


class Lean(LeanEvents, Node):
    """The product's node classes all have LeanEvents (no waitables)."""


@pytest.fixture
def ctx(ros_domain):
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=ros_domain)
    yield context
    rclpy.try_shutdown(context=context)


@pytest.fixture
def lean(ctx):
    """``lean(name, cls=Lean) -> (node, executor)``, both shut down at the end."""
    made = []

    def make(name, cls=None):
        node = (cls or Lean)(name, context=ctx)
        ex = LeanExecutor(context=ctx)
        ex.add_node(node)
        made.append((node, ex))
        return node, ex
    yield make
    for node, ex in made:
        ex.shutdown()
        node.destroy_node()


def _spin(ex, until, timeout=5.0):
    deadline = time.monotonic() + timeout
    while not until() and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.1)
    return until()


def test_every_entity_kind_is_served(lean):
    node, ex = lean('lean_all')
    got = {'timer': 0, 'msg': [], 'guard': 0, 'served': 0}
    node.create_timer(0.02, lambda: got.__setitem__('timer', got['timer'] + 1))
    pub = node.create_publisher(String, 'lean_topic', 10)
    node.create_subscription(String, 'lean_topic', lambda m: got['msg'].append(m.data), 10)

    def serve(req, resp):
        got['served'] += 1
        resp.success, resp.message = True, 'pong'
        return resp
    node.create_service(Trigger, 'lean_srv', serve)
    cli = node.create_client(Trigger, 'lean_srv')
    gc = node.create_guard_condition(lambda: got.__setitem__('guard', got['guard'] + 1))

    assert _spin(ex, lambda: got['timer'] >= 5)
    assert _spin(ex, lambda: pub.get_subscription_count() >= 1)
    for i in range(3):
        pub.publish(String(data=f'm{i}'))
    assert _spin(ex, lambda: len(got['msg']) == 3), got
    assert got['msg'] == ['m0', 'm1', 'm2']

    threading.Thread(target=gc.trigger).start()        # from another thread, as the
    assert _spin(ex, lambda: got['guard'] == 1)         # sensor nodes' readers do

    assert cli.wait_for_service(timeout_sec=5.0)
    fut = cli.call_async(Trigger.Request())
    ex.spin_until_future_complete(fut, timeout_sec=5.0)
    assert fut.done() and fut.result().message == 'pong' and got['served'] == 1
    assert ex.lean_wakeups > 0


def test_entities_created_and_destroyed_by_callbacks(lean):
    node, ex = lean('lean_change')
    got = {'a': 0, 'b': 0, 'late': 0}
    b = node.create_timer(0.01, lambda: got.__setitem__('b', got['b'] + 1))

    def a():
        got['a'] += 1
        if got['a'] == 3:                # b may be ready in this very wake-up
            node.destroy_timer(b)
            node.create_timer(0.01, lambda: got.__setitem__('late', got['late'] + 1))
    node.create_timer(0.01, a)
    assert _spin(ex, lambda: got['late'] >= 5)
    frozen = got['b']
    assert _spin(ex, lambda: got['late'] >= 15)
    assert got['b'] == frozen, 'a destroyed timer never fires again'


def test_async_callbacks_take_rclpys_path_and_complete(lean):
    node, ex = lean('lean_async')
    done = []
    node.create_service(Trigger, 'lean_async_srv',
                        lambda req, resp: setattr(resp, 'message', 'ok') or resp)
    # the awaiting timer in its own group: the default group's service answers meanwhile
    cli = node.create_client(Trigger, 'lean_async_srv', callback_group=ReentrantCallbackGroup())
    assert cli.wait_for_service(timeout_sec=5.0)

    async def once():
        if done:
            return
        done.append('asked')
        resp = await cli.call_async(Trigger.Request())      # suspends the callback
        done.append(resp.message)
    node.create_timer(0.05, once, callback_group=MutuallyExclusiveCallbackGroup())
    assert _spin(ex, lambda: done == ['asked', 'ok']), done
    assert ex.fallback_wakeups > 0, 'the suspended task went through rclpy'
    w = ex.lean_wakeups
    assert _spin(ex, lambda: ex.lean_wakeups > w + 3), 'back on the lean path'


def test_timeout_is_kept_when_nothing_is_ready(lean):
    node, ex = lean('lean_idle')
    ex.spin_once(timeout_sec=0.0)       # discovery, parameter events: let them settle
    t0 = time.monotonic()
    for _ in range(3):
        ex.spin_once(timeout_sec=0.2)
    took = time.monotonic() - t0
    assert 0.15 <= took < 3.0, took


def test_one_wakeup_per_callback(lean):
    """20 timer callbacks in a second cost about 20 wake-ups, not 40-60."""
    node, ex = lean('lean_count')
    n = [0]
    node.create_timer(0.05, lambda: n.__setitem__(0, n[0] + 1))
    assert _spin(ex, lambda: n[0] >= 2)
    w0, c0 = ex.lean_wakeups, n[0]
    assert _spin(ex, lambda: n[0] >= c0 + 20)
    wakeups = ex.lean_wakeups - w0
    assert wakeups <= 1.5 * (n[0] - c0) + 3, (wakeups, n[0] - c0)


def test_a_node_with_waitables_is_served_by_rclpys_path(lean):
    """A plain rclpy Node has QoS-event waitables: every wake-up takes rclpy's path."""
    node, ex = lean('lean_plain', Node)
    n = [0]
    node.create_timer(0.02, lambda: n.__setitem__(0, n[0] + 1))
    assert _spin(ex, lambda: n[0] >= 5)
    assert ex.lean_wakeups == 0 and ex.fallback_wakeups >= 5


def test_sync_callbacks_are_called_directly(lean):
    """A plain (not async) callback runs without rclpy's Task/coroutine machinery."""
    node, ex = lean('lean_direct')
    n = [0]
    node.create_timer(0.02, lambda: n.__setitem__(0, n[0] + 1))
    assert _spin(ex, lambda: n[0] >= 5)
    assert ex.direct_callbacks >= 5 and not ex._tasks


def test_management_services_are_served_but_not_in_every_wait(lean, ctx):
    """Parameter and type-description services (and a lifecycle node's) are waited on
    at most every MANAGEMENT_PERIOD: a get_parameters request is answered within about
    that period, while a busy timer wakes the executor far more often; the node's own
    services are in every wait."""
    from rcl_interfaces.srv import GetParameters
    from rclpy.lifecycle import LifecycleNode
    from sslfr_common.executor import MANAGEMENT_PERIOD, _is_management

    node, ex = lean('lean_mgmt')
    node.declare_parameter('answer', 42)
    own = node.create_service(Trigger, 'lean_mgmt/get_state', lambda q, r: r)   # not rclpy's
    assert not _is_management(own)
    assert {s.srv_name.rpartition('/')[2] for s in node._services if _is_management(s)} == {
        'describe_parameters', 'get_parameters', 'get_parameter_types', 'list_parameters',
        'set_parameters', 'set_parameters_atomically', 'get_type_description'}
    life = LifecycleNode('lean_mgmt_life', context=ctx)
    try:
        assert sum(_is_management(s) for s in life._services) == 12
    finally:
        life.destroy_node()

    ticks = [0]
    node.create_timer(0.005, lambda: ticks.__setitem__(0, ticks[0] + 1))      # a busy process
    asker = Lean('lean_mgmt_asker', context=ctx)
    try:
        cli = asker.create_client(GetParameters, 'lean_mgmt/get_parameters')
        ex.add_node(asker)
        assert _spin(ex, lambda: cli.service_is_ready())
        for _ in range(5):
            t0 = time.monotonic()
            fut = cli.call_async(GetParameters.Request(names=['answer']))
            ex.spin_until_future_complete(fut, timeout_sec=5.0)
            took = time.monotonic() - t0
            assert fut.done() and fut.result().values[0].integer_value == 42
            assert took < MANAGEMENT_PERIOD + 0.4, took        # a period + a loaded machine
    finally:
        ex.remove_node(asker)
        asker.destroy_node()
