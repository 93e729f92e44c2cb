"""A single-threaded executor whose wake-up and callbacks cost little.

rclpy's ``SingleThreadedExecutor`` rebuilds its wait set in Python at every wake-up and
runs each callback inside a ``Task`` (plus two guard-condition triggers); in a node
process of 60-130 entities that machinery was most of the main thread's CPU
(docs/measurements.md, "The executor"). :class:`LeanExecutor` keeps rclpy's semantics
for one thread and synchronous callbacks, but collects the entities' handles only when
an entity or node is added or removed, waits on the nodes' management services
(:data:`MANAGEMENT_SERVICES`: parameters, type description, lifecycle) at most every
:data:`MANAGEMENT_PERIOD`, and calls each ready callback directly, one per
:meth:`spin_once`. A coroutine callback, a task in flight or a waitable (actions,
QoS-event handlers) goes through rclpy's own implementation.
"""
from __future__ import annotations

import collections
import inspect
import time

from rclpy.exceptions import InvalidHandle
from rclpy.executors import (
    ConditionReachedException, ExternalShutdownException, ShutdownException,
    SingleThreadedExecutor, TimeoutException)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.subscription import Subscription
from rclpy.task import Task
from rclpy.utilities import timeout_sec_to_nsec

__all__ = ['LeanExecutor']

# what a ready entity is
_TIMER, _SUB, _CLIENT, _SERVICE, _GUARD = range(5)
_MESSAGE_ONLY = Subscription.CallbackType.MessageOnly

#: The services rclpy creates for every node (parameters, type description) and every
#: lifecycle node, by their callbacks (a service of the node's own with the same name
#: is not one of them): waited on at most every MANAGEMENT_PERIOD (module docstring).
#: Should a later rclpy rename them, they are simply in every wait again.
MANAGEMENT_SERVICES = frozenset(
    [f'ParameterService._{name}_callback' for name in (
        'describe_parameters', 'get_parameters', 'get_parameter_types', 'list_parameters',
        'set_parameters', 'set_parameters_atomically')]
    + ['TypeDescriptionService._service_callback']
    + [f'LifecycleNodeMixin.__on_{name}' for name in (
        'change_state', 'get_state', 'get_available_states', 'get_available_transitions',
        'get_transition_graph')])
#: [s, steady] longest time between two waits that include the management services
MANAGEMENT_PERIOD = 0.1


def _is_management(service) -> bool:
    """True for one of the :data:`MANAGEMENT_SERVICES` rclpy gives every node."""
    return getattr(service.callback, '__qualname__', '') in MANAGEMENT_SERVICES


def _consume(iterator) -> None:
    """Run ``iterator`` to its end in C (``map`` over a bound builtin method)."""
    collections.deque(iterator, maxlen=0)


class _Entities:
    """The entity lists of a set of nodes, with their handles and pointer maps."""

    __slots__ = ('key', 'waitables', 'subs', 'timers', 'clients', 'services', 'guards',
                 'handles', 'by_sub', 'by_timer', 'by_client', 'by_service', 'by_guard')

    def __init__(self, key: tuple, nodes) -> None:
        self.key = key
        self.waitables = any(_has_waitables(n) for n in nodes)
        self.subs = [(s, n) for n in nodes for s in n._subscriptions]
        self.timers = [(t, n) for n in nodes for t in n._timers]
        self.clients = [(c, n) for n in nodes for c in n._clients]
        self.services = [(s, n) for n in nodes for s in n._services]
        self.guards = [(g, n) for n in nodes for g in n._guards]
        #: (subscriptions, clients, services, timers, guard conditions, management
        #: services) handles
        management = [(s, n) for s, n in self.services if _is_management(s)]
        own = [(s, n) for s, n in self.services if not _is_management(s)]
        self.handles = tuple([e.handle for e, _ in lst] for lst in
                             (self.subs, self.clients, own, self.timers, self.guards, management))
        self.by_sub = {s.handle.pointer: (_SUB, s, n) for s, n in self.subs}
        self.by_timer = {t.handle.pointer: (_TIMER, t, n) for t, n in self.timers}
        self.by_client = {c.handle.pointer: (_CLIENT, c, n) for c, n in self.clients}
        self.by_service = {s.handle.pointer: (_SERVICE, s, n) for s, n in self.services}
        self.by_guard = {g.handle.pointer: g for g, _ in self.guards}


def _key(nodes) -> tuple:
    """Identity of every entity (a node's lists are mutated in place by create/destroy);
    used for an explicit ``nodes`` argument, whose nodes may not call our ``wake``."""
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
    """``SingleThreadedExecutor`` with a cheap wake-up and callback (see the module
    docstring).

    Same API and callback semantics as rclpy's: ``spin_once(timeout_sec)`` runs at most
    one callback, ``spin_until_future_complete``, ``add_node``/``remove_node``,
    ``wake``, ``shutdown``. ``lean_wakeups`` and ``fallback_wakeups`` count the
    wake-ups of each path, ``direct_callbacks`` the callbacks called directly.
    """

    def __init__(self, *, context=None) -> None:
        super().__init__(context=context)
        self._lean: _Entities | None = None
        self._changed = True          # an entity or node was added or removed
        self._ready: collections.deque = collections.deque()
        self._is_async: dict[int, bool] = {}
        self.lean_wakeups = 0
        self.fallback_wakeups = 0
        self.direct_callbacks = 0
        self._management_due = 0.0    # [s, monotonic] next wait that includes them

    # -- what changes the entity set ---------------------------------------------------
    def wake(self) -> None:
        """rclpy's nodes call this on every entity created or destroyed."""
        self._changed = True
        super().wake()

    def add_node(self, node) -> bool:
        self._changed = True
        return super().add_node(node)

    def remove_node(self, node) -> None:
        self._changed = True
        super().remove_node(node)

    def _entities(self, nodes, explicit: bool) -> _Entities:
        ents = self._lean
        if explicit:
            key = _key(nodes)
            if ents is None or ents.key != key:
                ents = self._lean = _Entities(key, nodes)
                self._is_async.clear()
        elif ents is None or self._changed or ents.key is not None:
            self._changed = False
            ents = self._lean = _Entities(None, nodes)
            self._is_async.clear()
        return ents

    # -- the handler of rclpy's path: rclpy's, without the guard-condition triggers ---
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

    def _tasks_in_flight(self) -> bool:
        with self._tasks_lock:
            if self._tasks:
                live = [t for t in self._tasks if not t[0].done()]
                self._tasks = live
                return bool(live)
        return False

    # -- spin_once: the lean path ------------------------------------------------------
    def _spin_once_impl(self, timeout_sec=None, wait_condition=lambda: False) -> None:
        if self._ready:
            self._run(*self._ready.popleft())
            return
        nodes = self.get_nodes()
        if self._tasks_in_flight() or self._entities(nodes, False).waitables:
            super()._spin_once_impl(timeout_sec, wait_condition)
            return
        self._cb_iter = None         # nothing pending from rclpy's generator is lost:
        try:                         # whatever it had not run is still ready
            self._wait(timeout_sec, None, wait_condition)
        except (ShutdownException, TimeoutException, ConditionReachedException):
            return
        if self._ready:
            self._run(*self._ready.popleft())

    def _wait(self, timeout_sec, nodes, condition) -> None:
        """Wait until something is ready and queue it in ``self._ready``."""
        seconds = getattr(timeout_sec, 'timeout', timeout_sec)
        timeout_ns = timeout_sec_to_nsec(seconds)
        deadline = time.monotonic() + timeout_ns * 1e-9 if timeout_ns > 0 else None
        ready = self._ready
        own = (self._guard, self._sigint_gc)
        while not ready and not self._is_shutdown and not condition():
            ents = self._entities(self.get_nodes() if nodes is None else nodes, nodes is not None)
            # a guard triggered but not handled yet (its callback group was busy) is
            # triggered again so that this wait returns for it (as rclpy does)
            for gc, _ in ents.guards:
                if gc._executor_triggered:
                    gc.trigger()
            wait_ns = timeout_ns
            if deadline is not None:
                wait_ns = max(0, int((deadline - time.monotonic()) * 1e9))
            subs, clients, services, timers, guards, management = ents.handles
            now = time.monotonic()
            if now >= self._management_due:
                self._management_due = now + MANAGEMENT_PERIOD
            else:
                management = ()
            ws = _rclpy.WaitSet(len(subs), len(guards) + 2, len(timers), len(clients),
                                len(services) + len(management), 0, self._context.handle)
            ws.clear_entities()
            _consume(map(ws.add_subscription, subs))
            _consume(map(ws.add_client, clients))
            _consume(map(ws.add_service, services))
            _consume(map(ws.add_service, management))
            _consume(map(ws.add_timer, timers))
            _consume(map(ws.add_guard_condition, guards))
            for g in own:
                ws.add_guard_condition(g.handle)
            ws.wait(wait_ns)
            self.lean_wakeups += 1
            if self._is_shutdown:
                raise ShutdownException()
            if not self._context.ok():
                raise ExternalShutdownException()
            timers_ready = ws.get_ready_entities('timer')
            subs_ready = ws.get_ready_entities('subscription')
            clients_ready = ws.get_ready_entities('client')
            services_ready = ws.get_ready_entities('service')
            guards_ready = ws.get_ready_entities('guard_condition')
            del ws
            for p in guards_ready:
                gc = ents.by_guard.get(p)
                if gc is not None:
                    gc._executor_triggered = True
            for pointers, table in ((timers_ready, ents.by_timer), (subs_ready, ents.by_sub),
                                    (clients_ready, ents.by_client), (services_ready, ents.by_service)):
                for p in pointers:
                    item = table.get(p)
                    if item is not None:
                        ready.append(item)
            for gc, n in ents.guards:
                if gc._executor_triggered:
                    ready.append((_GUARD, gc, n))
            if not ready and (timeout_ns == 0 or (deadline is not None and time.monotonic() >= deadline)):
                raise TimeoutException()
        if self._is_shutdown:
            raise ShutdownException()
        if not ready and condition():
            raise ConditionReachedException()

    def _run(self, kind: int, entity, node) -> None:
        """Run one ready entity's callback (rclpy's ``_take_*`` + handler, called directly)."""
        if kind == _TIMER and not _timer_ready(entity):
            return
        is_async = self._is_async.get(id(entity))
        if is_async is None:
            is_async = self._is_async[id(entity)] = (
                kind != _CLIENT and inspect.iscoroutinefunction(entity.callback))
        if is_async:                  # rclpy's path: the callback may suspend
            take = (self._take_timer, self._take_subscription, self._take_client,
                    self._take_service, self._take_guard_condition)[kind]
            handler = self._make_handler(entity, node, take)
            handler()
            if handler.exception() is not None:
                raise handler.exception()
            handler.result()
            return
        group = entity.callback_group
        if not group.beginning_execution(entity):
            if kind == _GUARD:        # kept triggered: the next wait returns for it
                entity.trigger()
            return
        try:
            self.direct_callbacks += 1
            if kind == _SUB:
                try:
                    with entity.handle:
                        msg_info = entity.handle.take_message(entity.msg_type, entity.raw)
                except InvalidHandle:
                    return
                if msg_info is not None:
                    if entity._callback_type is _MESSAGE_ONLY:
                        entity.callback(msg_info[0])
                    else:
                        entity.callback(*msg_info)
            elif kind == _TIMER:
                try:
                    with entity.handle:
                        entity.handle.call_timer()
                except InvalidHandle:
                    return
                entity.callback()
            elif kind == _GUARD:
                entity._executor_triggered = False
                entity.callback()
            elif kind == _SERVICE:
                try:
                    with entity.handle:
                        request, header = entity.handle.service_take_request(entity.srv_type.Request)
                except InvalidHandle:
                    return
                if header is not None:
                    response = entity.callback(request, entity.srv_type.Response())
                    entity.send_response(response, header)
            else:                     # _CLIENT
                try:
                    with entity.handle:
                        header, response = entity.handle.take_response(entity.srv_type.Response)
                except InvalidHandle:
                    return
                if header is not None:
                    try:
                        future = entity.get_pending_request(header.request_id.sequence_number)
                    except KeyError:
                        return        # the request was cancelled
                    future._set_executor(self)
                    future.set_result(response)
        finally:
            group.ending_execution(entity)

    # -- rclpy's generator interface (wait_for_ready_callbacks), for direct callers ------
    def _wait_for_ready_callbacks(self, timeout_sec=None, nodes=None, condition=lambda: False):
        nodes_to_use = self.get_nodes() if nodes is None else nodes
        if self._tasks_in_flight() or any(_has_waitables(n) for n in nodes_to_use):
            self.fallback_wakeups += 1
            yield from super()._wait_for_ready_callbacks(timeout_sec, nodes, condition)
            return
        takes = (self._take_timer, self._take_subscription, self._take_client,
                 self._take_service, self._take_guard_condition)
        self._wait(timeout_sec, nodes, condition)
        while self._ready:
            kind, entity, node = self._ready.popleft()
            if kind == _TIMER and not _timer_ready(entity):
                continue
            if kind == _GUARD and not entity.callback_group.can_execute(entity):
                continue
            yield self._make_handler(entity, node, takes[kind]), entity, node
