"""A single-threaded executor whose wake-up costs little per entity (issue 16).

rclpy's ``SingleThreadedExecutor`` rebuilds its wait set in Python at every wake-up:
for each subscription, timer, service, client and guard condition of every node it
calls ``can_execute``, enters the handle's context manager through an ``ExitStack``,
adds the handle, and after the wait scans every entity again for readiness. A node
process of this project holds 60-100 entities (each node has 7 parameter and type
services, each lifecycle driver 5 more), so that is several hundred Python calls per
wake-up. Its callback handler also triggers the executor's own guard condition twice
per callback (a wake-up meant for other threads of a multi-threaded executor), so
every callback costs one or two further empty rebuilds.

:class:`LeanExecutor` keeps rclpy's semantics for this process's case (one thread,
synchronous callbacks) and does per wake-up only:

- the entity lists are collected once and reused while no entity was created or
  destroyed (compared by identity; the cache holds the entities, so an identity is
  never reused while cached);
- no ``can_execute`` filter and no handle context managers: with one thread and no
  task in flight nothing executes during the wait, and entities are destroyed only by
  this thread between waits;
- readiness is looked up from the ready pointers (a dict), not by scanning entities;
- the handler does not trigger the executor's guard condition.

Anything outside that case falls back to rclpy's own implementation for that wake-up:
a task still in flight (an ``async`` callback awaiting, a future's done-callback
scheduled with ``create_task``) or a node with waitables (actions, QoS-event handlers).
It is the executor of :func:`sslfr_common.node.run_nodes` and ``run_node`` (the one
``main()`` of every node process); measured in benchmarks/bench_nodeset_cpu.py.
"""
from __future__ import annotations

import time

from rclpy.exceptions import InvalidHandle
from rclpy.executors import (
    ConditionReachedException, ExternalShutdownException, ShutdownException,
    SingleThreadedExecutor, TimeoutException)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.task import Task
from rclpy.utilities import timeout_sec_to_nsec

__all__ = ['LeanExecutor']


class _Entities:
    """The entity lists of a set of nodes, with their handles and pointer maps."""

    __slots__ = ('key', 'subs', 'timers', 'clients', 'services', 'guards',
                 'by_sub', 'by_timer', 'by_client', 'by_service', 'by_guard')

    def __init__(self, key: tuple, nodes) -> None:
        self.key = key
        self.subs = [(s, n) for n in nodes for s in n._subscriptions]
        self.timers = [(t, n) for n in nodes for t in n._timers]
        self.clients = [(c, n) for n in nodes for c in n._clients]
        self.services = [(s, n) for n in nodes for s in n._services]
        self.guards = [(g, n) for n in nodes for g in n._guards]
        self.by_sub = {s.handle.pointer: (s, n) for s, n in self.subs}
        self.by_timer = {t.handle.pointer: (t, n) for t, n in self.timers}
        self.by_client = {c.handle.pointer: (c, n) for c, n in self.clients}
        self.by_service = {s.handle.pointer: (s, n) for s, n in self.services}
        self.by_guard = {g.handle.pointer: g for g, _ in self.guards}


def _key(nodes) -> tuple:
    """Identity of every entity (a node's lists are mutated in place by create/destroy)."""
    ids = []
    for n in nodes:
        ids.append(id(n))
        ids.append(-1)
        ids.extend(map(id, n._subscriptions))
        ids.append(-2)
        ids.extend(map(id, n._timers))
        ids.append(-3)
        ids.extend(map(id, n._clients))
        ids.append(-4)
        ids.extend(map(id, n._services))
        ids.append(-5)
        ids.extend(map(id, n._guards))
    return tuple(ids)


def _timer_ready(tmr) -> bool:
    """rclpy's check for a cancelled timer; False for one destroyed by an earlier
    callback of the same wake-up."""
    try:
        return tmr.handle.is_timer_ready()
    except InvalidHandle:
        return False


def _has_waitables(node) -> bool:
    for _ in node.waitables:
        return True
    return False


class LeanExecutor(SingleThreadedExecutor):
    """``SingleThreadedExecutor`` with a cheap wake-up (see the module docstring).

    Same API and callback semantics as rclpy's: ``spin_once(timeout_sec)``,
    ``spin_until_future_complete``, ``add_node``/``remove_node``, ``shutdown``.
    ``lean_wakeups`` and ``fallback_wakeups`` count the wake-ups of each path.
    """

    def __init__(self, *, context=None) -> None:
        super().__init__(context=context)
        self._lean: _Entities | None = None
        self.lean_wakeups = 0
        self.fallback_wakeups = 0

    # -- the handler: rclpy's, without the guard-condition triggers ------------------
    def _make_handler(self, entity, node, take_from_wait_list):
        entity._executor_event = True
        is_shutdown = self._is_shutdown
        work_tracker = self._work_tracker
        guard = self._guard

        async def handler(entity):
            if is_shutdown or not entity.callback_group.beginning_execution(entity):
                entity._executor_event = False
                guard.trigger()          # not taken: let the wait see it again
                return
            with work_tracker:
                call_coroutine = take_from_wait_list(entity)
                entity._executor_event = False
                try:
                    if call_coroutine is not None:
                        await call_coroutine()
                finally:
                    entity.callback_group.ending_execution(entity)

        task = Task(handler, (entity,), executor=self)
        with self._tasks_lock:
            self._tasks.append((task, entity, node))
        return task

    # -- the wait ---------------------------------------------------------------------
    def _lean_ok(self, nodes) -> bool:
        """True when nothing is in flight and no node has waitables."""
        with self._tasks_lock:
            if self._tasks:
                live = [t for t in self._tasks if not t[0].done()]
                self._tasks = live
                if live:
                    return False
        return not any(_has_waitables(n) for n in nodes)

    def _wait_for_ready_callbacks(self, timeout_sec=None, nodes=None, condition=lambda: False):
        nodes_to_use = self.get_nodes() if nodes is None else nodes
        if not self._lean_ok(nodes_to_use):
            self.fallback_wakeups += 1
            yield from super()._wait_for_ready_callbacks(timeout_sec, nodes, condition)
            return
        seconds = getattr(timeout_sec, 'timeout', timeout_sec)
        timeout_ns = timeout_sec_to_nsec(seconds)
        deadline = time.monotonic() + timeout_ns * 1e-9 if timeout_ns > 0 else None
        yielded = False
        while not yielded and not self._is_shutdown and not condition():
            if nodes is None:
                nodes_to_use = self.get_nodes()
            own = (self._guard, self._sigint_gc)
            key = _key(nodes_to_use)
            ents = self._lean
            if ents is None or ents.key != key:
                ents = self._lean = _Entities(key, nodes_to_use)
            # a guard triggered but not handled yet (its callback group was busy) is
            # triggered again so that this wait returns for it (as rclpy does)
            for gc, _ in ents.guards:
                if gc._executor_triggered:
                    gc.trigger()
            wait_ns = timeout_ns
            if deadline is not None:
                wait_ns = max(0, int((deadline - time.monotonic()) * 1e9))
            ws = _rclpy.WaitSet(len(ents.subs), len(ents.guards) + 2, len(ents.timers),
                                len(ents.clients), len(ents.services), 0, self._context.handle)
            ws.clear_entities()
            for s, _ in ents.subs:
                ws.add_subscription(s.handle)
            for c, _ in ents.clients:
                ws.add_client(c.handle)
            for s, _ in ents.services:
                ws.add_service(s.handle)
            for t, _ in ents.timers:
                ws.add_timer(t.handle)
            for g, _ in ents.guards:
                ws.add_guard_condition(g.handle)
            for g in own:
                ws.add_guard_condition(g.handle)
            ws.wait(wait_ns)
            self.lean_wakeups += 1
            if self._is_shutdown:
                raise ShutdownException()
            if not self._context.ok():
                raise ExternalShutdownException()
            subs_ready = ws.get_ready_entities('subscription')
            guards_ready = ws.get_ready_entities('guard_condition')
            timers_ready = ws.get_ready_entities('timer')
            clients_ready = ws.get_ready_entities('client')
            services_ready = ws.get_ready_entities('service')
            del ws
            for p in guards_ready:
                gc = ents.by_guard.get(p)
                if gc is not None:
                    gc._executor_triggered = True
            batches = ((timers_ready, ents.by_timer, self._take_timer, True),
                       (subs_ready, ents.by_sub, self._take_subscription, False),
                       (clients_ready, ents.by_client, self._take_client, False),
                       (services_ready, ents.by_service, self._take_service, False))
            for ready, table, take, is_timer in batches:
                for p in ready:
                    entity_node = table.get(p)
                    if entity_node is None or (is_timer and not _timer_ready(entity_node[0])):
                        continue
                    yielded = True
                    yield self._make_handler(*entity_node, take), *entity_node
            for gc, n in ents.guards:
                if gc._executor_triggered and gc.callback_group.can_execute(gc):
                    yielded = True
                    yield self._make_handler(gc, n, self._take_guard_condition), gc, n
            if not yielded and (timeout_ns == 0 or (deadline is not None and time.monotonic() >= deadline)):
                raise TimeoutException()
        if self._is_shutdown:
            raise ShutdownException()
        if condition():
            raise ConditionReachedException()
