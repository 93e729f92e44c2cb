"""Bring rclpy lifecycle nodes to a state from another process (no ``ros2 lifecycle``).

The ROS CLI is not installed here, so bringup and the tests use this module. It is a
plain rclpy *client* of the standard lifecycle services every lifecycle node offers:
``<node>/get_state`` (lifecycle_msgs/srv/GetState) and ``<node>/change_state``
(lifecycle_msgs/srv/ChangeState).

Library use (from any rclpy node, e.g. a bringup script or a test)::

    from sslfr_drivers.axis.lifecycle_ctl import bring_to
    ok, msg = bring_to(node, 'mirrors_driver', 'active', timeout=10.0)

Command line (the ``lifecycle_ctl`` console script)::

    lifecycle_ctl get mirrors_driver
    lifecycle_ctl set active mirrors_driver mobile_structure_driver secondary_reflector_driver

``set`` walks the standard state machine: unconfigured -configure-> inactive
-activate-> active, and back with deactivate / cleanup. Exit code 0 when every node
reached the state. The axis drivers activate themselves (``autostart``): ``set
active`` then only confirms it, and a transition the node made meanwhile is not an
error (the walk goes on from the state the node is in).

:class:`ActiveWatch` is the non-blocking form for a supervisor that lets the drivers
activate themselves (``sslfr up`` / ``sslfr sim``): it polls ``get_state`` until each
watched node reports ``active`` and never requests a transition.
"""
from __future__ import annotations

import argparse
import sys
import time

from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState

STATE_NAMES = {
    State.PRIMARY_STATE_UNKNOWN: 'unknown',
    State.PRIMARY_STATE_UNCONFIGURED: 'unconfigured',
    State.PRIMARY_STATE_INACTIVE: 'inactive',
    State.PRIMARY_STATE_ACTIVE: 'active',
    State.PRIMARY_STATE_FINALIZED: 'finalized',
}
_RANK = {'unconfigured': 0, 'inactive': 1, 'active': 2}
_UP = {0: Transition.TRANSITION_CONFIGURE, 1: Transition.TRANSITION_ACTIVATE}
_DOWN = {2: Transition.TRANSITION_DEACTIVATE, 1: Transition.TRANSITION_CLEANUP}


def _prefix(target: str) -> str:
    return target.rstrip('/')


def _wait(node, executor, future, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not future.done() and time.monotonic() < deadline:
        if executor is not None:
            executor.spin_once(timeout_sec=0.05)
        else:
            import rclpy
            rclpy.spin_once(node, timeout_sec=0.05)
    return future.done()


def _call(node, srv_type, name: str, request, timeout: float, executor=None):
    client = node.create_client(srv_type, name)
    try:
        deadline = time.monotonic() + timeout
        while not client.service_is_ready():
            if time.monotonic() > deadline:
                return None
            if executor is not None:
                executor.spin_once(timeout_sec=0.05)
            else:
                import rclpy
                rclpy.spin_once(node, timeout_sec=0.05)
        future = client.call_async(request)
        if not _wait(node, executor, future, max(0.1, deadline - time.monotonic())):
            return None
        return future.result()
    finally:
        node.destroy_client(client)


def get_state(node, target: str, timeout: float = 5.0, executor=None) -> str | None:
    """Current primary state label of lifecycle node ``target``, or None (no answer)."""
    res = _call(node, GetState, f'{_prefix(target)}/get_state', GetState.Request(), timeout, executor)
    if res is None:
        return None
    return STATE_NAMES.get(res.current_state.id, res.current_state.label)


def change_state(node, target: str, transition_id: int, timeout: float = 10.0,
                 executor=None) -> bool:
    """Ask ``target`` for one transition (lifecycle_msgs/msg/Transition id); True on success."""
    req = ChangeState.Request()
    req.transition.id = transition_id
    res = _call(node, ChangeState, f'{_prefix(target)}/change_state', req, timeout, executor)
    return bool(res is not None and res.success)


def bring_to(node, target: str, goal: str, timeout: float = 15.0, executor=None) -> tuple[bool, str]:
    """Walk ``target`` to primary state ``goal`` (unconfigured | inactive | active).

    Returns ``(ok, message)``. A failed transition (e.g. configure with no board
    reachable) stops the walk and is reported; the node stays where it was.
    """
    if goal not in _RANK:
        return False, f'unknown goal state {goal!r} (unconfigured | inactive | active)'
    deadline = time.monotonic() + timeout
    for _ in range(6):
        left = deadline - time.monotonic()
        state = get_state(node, target, max(0.1, left), executor)
        if state is None:
            return False, f'{target}: no answer from {target}/get_state'
        if state == goal:
            return True, f'{target}: {state}'
        if state not in _RANK:
            return False, f'{target}: in state {state}, cannot reach {goal}'
        rank = _RANK[state]
        tid = _UP[rank] if _RANK[goal] > rank else _DOWN[rank]
        if not change_state(node, target, tid, max(0.1, deadline - time.monotonic()), executor):
            # refused because the node moved by itself meanwhile (self-activation)? go on from there
            if get_state(node, target, max(0.1, deadline - time.monotonic()), executor) == state:
                return False, f'{target}: transition {tid} from {state} failed (see the node log)'
    return False, f'{target}: did not reach {goal}'


class ActiveWatch:
    """Watch lifecycle nodes until they report ``active`` without blocking (polls
    ``<node>/get_state`` asynchronously; the caller spins ``node``).

    Parameters
    ----------
    node : rclpy node
        The client node (spun by the caller's executor).
    timeout : float
        A node not active this long after :meth:`add` is reported as not active [s].
    period : float
        Poll period per node [s].
    """

    def __init__(self, node, timeout: float = 20.0, period: float = 0.5) -> None:
        self.node, self.timeout, self.period = node, timeout, period
        self._clients: dict = {}
        self._watched: dict[str, dict] = {}

    def add(self, target: str) -> None:
        """Watch ``target`` (again) from now on."""
        if target not in self._clients:
            self._clients[target] = self.node.create_client(GetState, f'{_prefix(target)}/get_state')
        self._watched[target] = {'since': time.monotonic(), 'next': 0.0, 'future': None, 'last': 'no answer'}

    def poll(self) -> list[tuple[str, bool, str]]:
        """Results since the last call: ``(target, True, 'active')`` once a node is
        active, ``(target, False, reason)`` once it was not within ``timeout``; either
        ends the watch of that node."""
        now = time.monotonic()
        out = []
        for target, w in list(self._watched.items()):
            fut = w['future']
            if fut is not None and fut.done():
                w['future'] = None
                res = fut.result()
                if res is not None:
                    w['last'] = STATE_NAMES.get(res.current_state.id, res.current_state.label)
            if w['last'] == 'active':
                out.append((target, True, 'active'))
                del self._watched[target]
            elif now - w['since'] > self.timeout:
                out.append((target, False, f'not active after {self.timeout:.0f} s (state {w["last"]}); '
                            'the driver retries by itself, see its diagnostics'))
                del self._watched[target]
            elif w['future'] is None and now >= w['next']:
                w['next'] = now + self.period
                client = self._clients[target]
                if client.service_is_ready():
                    w['future'] = client.call_async(GetState.Request())
        return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog='lifecycle_ctl', description=__doc__.split('\n\n')[0])
    sub = parser.add_subparsers(dest='cmd', required=True)
    g = sub.add_parser('get', help='print the state of lifecycle nodes')
    g.add_argument('nodes', nargs='+')
    s = sub.add_parser('set', help='bring lifecycle nodes to a primary state')
    s.add_argument('goal', choices=sorted(_RANK))
    s.add_argument('nodes', nargs='+')
    parser.add_argument('--timeout', type=float, default=15.0, help='per node [s]')
    args, ros_args = parser.parse_known_args(sys.argv[1:] if argv is None else argv)

    import rclpy
    rclpy.init(args=['lifecycle_ctl', *ros_args])
    node = rclpy.create_node('lifecycle_ctl')
    ok = True
    try:
        for target in args.nodes:
            if args.cmd == 'get':
                state = get_state(node, target, args.timeout)
                print(f'{target}: {state or "no answer"}')
                ok &= state is not None
            else:
                good, msg = bring_to(node, target, args.goal, args.timeout)
                print(msg)
                ok &= good
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
