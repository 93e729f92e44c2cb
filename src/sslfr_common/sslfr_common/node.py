"""Node plumbing shared by every node of the tracker: the Jazzy main pattern, written once.

:func:`run_node` is the whole ``main()`` of a node (as in ros2/demos ``lifecycle_py``
and ``demo_nodes_py``), with what a tracker on a Pi needs on top of it:

- **Signals.** SIGINT and SIGTERM (Ctrl-C in a terminal, ``ros2 launch``, systemd) ask
  for an orderly stop: the executor is woken at once, the spin loop ends, the node's
  ``on_exit()`` hook runs (motors stopped, links and bags closed) while the ROS
  context is still valid (so its last logs still reach ``/rosout`` and a lifecycle
  node can still publish its transitions), then the node is destroyed and rclpy shut
  down. Every further SIGINT/SIGTERM during that stop is ignored (``ros2 launch``
  without a terminal sends SIGINT twice): the process exits 0 with nothing printed
  as an error. A signal that arrives while the node is being built stops it the same
  way once it exists. Only SIGKILL can cut ``on_exit()`` short.
- **A message rclpy cannot take never ends the process.** Under heavy load rclpy's
  ``take_message`` was seen raising ``RuntimeError`` for one received message
  (compare ros2/rclpy#848); ``rclpy.spin`` would let that end the node. The loop
  logs it (throttled), counts it in :attr:`SpinStats` and goes on.
- **Invalid start-up configuration** (the exceptions in ``config_errors``, by default
  ``ValueError`` and rclpy's parameter exceptions) prints one line
  (``<node>: invalid parameters, not starting: <reason>``) and exits 2, so a supervisor can tell it from a crash.
- **Liveness.** With ``NOTIFY_SOCKET`` in the environment (given by ``sslfr up`` /
  ``sslfr sim``, the launch file's watchdog, or systemd) the process sends ``READY=1``
  when its executor starts, ``WATCHDOG=1`` from the spin loop after executor turns
  (rate-limited: at most one per beat period, a quarter of ``WATCHDOG_USEC``, <= 1 s)
  and ``STOPPING=1`` when it begins to stop (:mod:`sslfr_common.sdnotify`). The beat
  comes from the thread that runs the callbacks, so a deadlock, a callback that never
  returns or a stopped process silences it; the watcher kills and restarts the process.
- **The log bridge.** The pure modules log with Python ``logging``; :class:`LogBridge`
  forwards their records to the node's rclpy logger (once per distinct text) and is
  detached before the node is destroyed: nothing is forwarded to ``/rosout`` after
  shutdown.
"""
from __future__ import annotations

import faulthandler
import logging
import os
import signal
import sys
import threading
import time
from typing import Callable

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.event_handler import PublisherEventCallbacks, SubscriptionEventCallbacks
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException, \
    ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.duration import Duration
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions

from .contract import Qos, Topic
from .executor import LeanExecutor
from .log_route import NODE_ATTR
from .sdnotify import STACK_DUMP_SIGNAL, Notifier
from .timeconv import duration, stamp, stamp_from_ns, steady_now, to_ns, to_sec  # noqa: F401 - re-exported

#: Exceptions from a node's constructor that mean "invalid configuration" (exit 2).
CONFIG_ERRORS: tuple[type[BaseException], ...] = (
    ValueError, TypeError, ParameterException, InvalidParameterTypeException,
    InvalidParameterValueException)

#: The rclpy profile of each QoS of the contract (docs/architecture.md), built once.
QOS_PROFILES: dict[Qos, QoSProfile] = {
    Qos.R10: QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE),
    Qos.BE: QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT),
    Qos.TL1: QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL),
    Qos.LOG: QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL, lifespan=Duration(seconds=10)),
}


def qos(what: Topic | Qos) -> QoSProfile:
    """The rclpy QoS profile of a topic of the contract (or of a profile)."""
    return QOS_PROFILES[what.qos if isinstance(what, Topic) else what]


#: Longest wait of one spin_once [s]; the signal wake-up makes stops immediate anyway.
SPIN_TIMEOUT_S = 0.5


class LeanEvents:
    """Node mixin: publishers and subscriptions without rclpy's default QoS-event handlers.

    rclpy gives every publisher and subscription two event handlers by default (they
    only log "incompatible QoS" / "incompatible type" warnings), and the executor adds
    each one to its wait set in Python at every wake-up: in the recorder (16
    subscriptions) they were most of its CPU at real time (issue 16). Callers that pass
    their own ``event_callbacks`` keep them. Put it first in the bases:
    ``class Recorder(LeanEvents, Node)``. It also covers the entities rclpy's ``Node``
    makes itself through these methods (``/parameter_events``, ``/clock``). What is
    lost: the two warnings above; a QoS mismatch on a topic of the graph shows as a
    silent topic, which every consumer of the tracker already treats as a fault
    (watchdogs).
    """

    def create_publisher(self, *args, event_callbacks=None, **kwargs):
        return super().create_publisher(
            *args, event_callbacks=event_callbacks or PublisherEventCallbacks(use_default_callbacks=False),
            **kwargs)

    def create_subscription(self, *args, event_callbacks=None, **kwargs):
        return super().create_subscription(
            *args, event_callbacks=event_callbacks or SubscriptionEventCallbacks(use_default_callbacks=False),
            **kwargs)


class SpinStats:
    """What :func:`run_node` dropped: ``errors`` [-] and the ``last`` error text."""

    def __init__(self) -> None:
        self.errors = 0
        self.last = ''


class LogBridge(logging.Handler):
    """Forward Python ``logging`` records of ``loggers`` to a node's rclpy logger: the
    node the record names (:mod:`sslfr_common.log_route`; a composed process's
    board links and control loops name their own driver), else the first node.

    Repeated identical texts are forwarded once (a link that retries every 0.1 s does
    not flood the log). :meth:`detach` removes the bridge; records after that are
    dropped below WARNING and printed to stderr from WARNING up (Python's last
    resort), never sent to a destroyed node.
    """

    def __init__(self, node, loggers: tuple[str, ...], others=()) -> None:
        super().__init__(logging.INFO)
        self.node = node
        self.by_name = {n.get_name(): n for n in (node, *others)}
        self.last = ''
        self._loggers = [logging.getLogger(name) for name in loggers]
        for lg in self._loggers:
            lg.addHandler(self)
            lg.setLevel(logging.INFO)
            lg.propagate = False

    def emit(self, record: logging.LogRecord) -> None:
        node = self.node
        if node is None:
            return
        node = self.by_name.get(getattr(record, NODE_ATTR, ''), node)
        text = record.getMessage()
        if text == self.last:
            return
        self.last = text
        try:
            log = node.get_logger()
            if record.levelno >= logging.ERROR:
                log.error(text)
            elif record.levelno >= logging.WARNING:
                log.warning(text)
            else:
                log.info(text)
        except Exception:  # noqa: BLE001 - a log line must never break its caller
            pass

    def detach(self) -> None:
        """Stop forwarding (idempotent)."""
        self.node = None
        self.by_name = {}
        for lg in self._loggers:
            lg.removeHandler(self)
            lg.propagate = True


class StopRequest:
    """SIGINT/SIGTERM -> a flag and an executor wake-up, immediately.

    The Python-level handler runs only when the main thread returns to the
    interpreter, which it does not while it waits in ``rcl_wait``. A wake-up fd
    (written by CPython's C-level handler, async-signal-safe) is read by a small
    thread that triggers the executor's guard condition, so ``spin_once`` returns
    at once and the handler runs.
    """

    def __init__(self) -> None:
        self.requested = threading.Event()
        self.signal_name = ''
        self.executor = None
        self._old: dict[int, object] = {}
        self._rfd, self._wfd = os.pipe()
        os.set_blocking(self._wfd, False)
        self._old_wakeup = signal.set_wakeup_fd(self._wfd, warn_on_full_buffer=False)
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old[sig] = signal.signal(sig, self._handler)
        threading.Thread(target=self._waker, name='signal-waker', daemon=True).start()

    def _handler(self, signum, frame) -> None:  # noqa: ARG002 - signal API
        if not self.requested.is_set():
            self.signal_name = signal.Signals(signum).name
            self.requested.set()
        self._wake()

    def _waker(self) -> None:
        while True:
            try:
                data = os.read(self._rfd, 64)
            except OSError:
                return
            if not data:
                return
            self._wake()

    def _wake(self) -> None:
        ex = self.executor
        if ex is not None:
            try:
                ex.wake()
            except Exception:  # noqa: BLE001 - executor already shut down
                pass

    def ignore_further(self) -> None:
        """From now on SIGINT/SIGTERM are ignored (the stop is under way). A handler
        that does nothing, not SIG_IGN: a signal that arrived just before (pending in
        the interpreter, its handler not run yet) would otherwise be reported on stderr
        as "OSError: Signal 2 ignored due to race condition" with a traceback."""
        for sig in self._old:
            signal.signal(sig, _ignore_signal)

    def close(self) -> None:
        # the stop is done: from here to the end of the process signals are ignored at
        # the C level (Python's finalisation resets handlers written in Python to the
        # default, so a late SIGINT would otherwise kill the process with -2)
        for sig in self._old:
            signal.signal(sig, signal.SIG_IGN)
        signal.set_wakeup_fd(self._old_wakeup if self._old_wakeup is not None else -1)
        for fd in (self._wfd, self._rfd):
            try:
                os.close(fd)
            except OSError:
                pass


def _ignore_signal(signum, frame) -> None:
    """A signal during the stop: nothing more to do."""


def _no_beat() -> None:
    """No watcher: nothing to prove."""


def spin_until_stopped(node, executor, stop: StopRequest | None = None,
                       stats: SpinStats | None = None, beat: Callable[[], None] | None = None) -> SpinStats:
    """Spin ``node`` in ``executor`` until ``stop`` is requested or the context ends.

    A ``RuntimeError`` from the executor (a message rclpy could not take, a callback
    failing with it) is logged (throttled) and counted in ``stats``; the loop goes on.
    ``beat()`` is called after every turn of the executor (every ``spin_once``, which
    returns at least every :data:`SPIN_TIMEOUT_S`), by the thread that runs the
    callbacks: a callback that never returns, a wait that never wakes or a stopped
    process stops the beats (:meth:`sslfr_common.sdnotify.Notifier.beat`, which sends
    at most one ``WATCHDOG=1`` per beat period).
    """
    stats = stats or SpinStats()
    beat = beat or _no_beat
    if node not in executor.get_nodes():
        executor.add_node(node)
    while node.context.ok() and not (stop is not None and stop.requested.is_set()):
        try:
            executor.spin_once(timeout_sec=SPIN_TIMEOUT_S)
            beat()
        except RuntimeError as exc:
            stats.errors += 1
            stats.last = str(exc)
            node.get_logger().error(
                f'a message or callback failed and was dropped ({stats.errors} so far): {exc}',
                throttle_duration_sec=5.0)
    return stats


def drain_callbacks(executor, stats: SpinStats | None = None, timeout_s: float = 2.0) -> int:
    """Wait (at most ``timeout_s`` [s], steady clock) for the callbacks a
    MultiThreadedExecutor's pool is still running when spinning ends, and fetch their
    outcome: a failure is counted in ``stats`` instead of being printed by rclpy's
    ``Task.__del__`` ("The following exception was never retrieved") after the node is
    gone. A SingleThreadedExecutor has nothing in flight. Returns the callbacks still
    running at the deadline."""
    pending = list(getattr(executor, '_futures', ()))     # rclpy Jazzy: handlers submitted to the pool
    deadline = time.monotonic() + timeout_s
    left = 0
    for task in pending:
        while not task.done() and time.monotonic() < deadline:
            time.sleep(0.005)
        if not task.done():
            left += 1
            continue
        exc = task.exception()                             # marks it retrieved
        if exc is not None and stats is not None:
            stats.errors += 1
            stats.last = str(exc)
    if pending and hasattr(executor, '_futures'):
        executor._futures[:] = [t for t in executor._futures if not t.done()]
    return left


def run_node(name: str, make_node: Callable[[], object], *, args: list[str] | None = None,
             executor: Callable[[object], object] | None = None,
             config_errors: tuple[type[BaseException], ...] = CONFIG_ERRORS,
             log_bridge: tuple[str, ...] = ()) -> int:
    """The whole ``main()`` of a node; returns the exit status (0, or 2 for an invalid
    start-up configuration).

    Parameters
    ----------
    name : str
        Name used in the one-line refusal (``<name>: invalid parameters, not
        starting: <reason>``).
    make_node : callable
        Builds the node (rclpy is initialised). May raise one of ``config_errors``.
    executor : callable, optional
        ``executor(context) -> Executor``; default :func:`default_executor`.
    log_bridge : tuple of str
        Python logger names whose records are forwarded to the node's logger
        (:class:`LogBridge`) until the node is destroyed.

    The node may define ``on_exit()``: called once after spinning ends, with the
    context still valid (stop motors, close links and files).
    """
    return run_nodes([(name, make_node)], args=args, executor=executor, config_errors=config_errors,
                     log_bridge=log_bridge)


def share_time_source(nodes: list) -> int:
    """One ``/clock`` subscription for the nodes of one process (composition).

    Each rclpy node with ``use_sim_time`` subscribes to ``/clock`` itself, so a process
    of six nodes took and deserialized every clock message six times (at 20 Hz in the
    simulation, ``ros2 bag play --clock`` on a Pi: about a fifth of the composed
    ``hardware`` process's CPU, issue 16). Here the first node's time source drives
    the ROS clocks of all the nodes that use sim time and the others' subscriptions
    are removed. ``use_sim_time`` is then fixed for the life of the process: a change
    at run time is refused with the reason (it would stop or double the shared
    updates). Returns the number of ``/clock`` subscriptions removed.
    """
    users = [n for n in nodes if n._time_source.ros_time_is_active]
    if len(users) < 2:
        return 0
    owner = users[0]._time_source
    names = ', '.join(n.get_name() for n in users)

    def refuse_use_sim_time(params):
        from rcl_interfaces.msg import SetParametersResult
        for p in params:
            if p.name == 'use_sim_time':
                return SetParametersResult(
                    successful=False,
                    reason=f'use_sim_time is shared by the nodes of this process ({names}) and '
                           'fixed at start-up; restart the process to change it')
        return SetParametersResult(successful=True)

    for node in users:
        node.add_on_set_parameters_callback(refuse_use_sim_time)
    for node in users[1:]:
        ts = node._time_source
        if ts._clock_sub is not None:
            node.destroy_subscription(ts._clock_sub)
            ts._clock_sub = None
        owner.attach_clock(node.get_clock())
    return len(users) - 1


def default_executor():
    """The executor factory of every node process, ``context -> Executor``:
    :class:`~sslfr_common.executor.LeanExecutor` (rclpy's single-threaded semantics,
    cheap wake-ups), or rclpy's own ``SingleThreadedExecutor`` when the environment has
    ``SSLFR_EXECUTOR=rclpy`` (a fallback for the field, and the peer that
    benchmarks/bench_nodeset_cpu.py measures against). ValueError for another value."""
    choice = os.environ.get('SSLFR_EXECUTOR', 'lean')
    if choice == 'rclpy':
        return lambda context: SingleThreadedExecutor(context=context)
    if choice != 'lean':
        raise ValueError(f"SSLFR_EXECUTOR={choice!r}: expected 'lean' (the default) or 'rclpy'")
    return lambda context: LeanExecutor(context=context)


def run_nodes(nodes: list[tuple[str, Callable[[], object]]], *, args: list[str] | None = None,
              executor: Callable[[object], object] | None = None,
              config_errors: tuple[type[BaseException], ...] = CONFIG_ERRORS,
              log_bridge: tuple[str, ...] = ()) -> int:
    """Several nodes in one process, one executor, one DDS participant (ROS 2
    composition in Python): the same life as :func:`run_node` for each. ``nodes`` is
    ``[(name, make_node), ...]`` in start order; on a stop each node's ``on_exit()`` is
    called in that order (put the axis drivers first: they stop their motors first).
    A node that refuses its configuration stops the whole process (exit 2, one line
    naming it), after the nodes already built have run their ``on_exit()``."""
    try:
        make_executor = executor or default_executor()
    except ValueError as exc:
        print(f'{nodes[0][0]}: not starting: {exc}', file=sys.stderr, flush=True)
        return 2
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    # a hung process's every thread's stack to its log, asked for before it is killed
    # (works with the GIL held by a stuck thread; sslfr_bringup.supervisor)
    faulthandler.register(STACK_DUMP_SIGNAL, all_threads=True)
    stop = StopRequest()
    built: list = []
    ex = bridge = stats = notifier = None
    code = 0
    try:
        for name, make_node in nodes:
            try:
                built.append(make_node())
            except config_errors as exc:
                print(f'{name}: invalid parameters, not starting: {exc}', file=sys.stderr, flush=True)
                code = 2
                return code
            if stop.requested.is_set():
                return code
        if log_bridge:
            bridge = LogBridge(built[0], log_bridge, built[1:])
        share_time_source(built)
        ex = make_executor(built[0].context)
        stop.executor = ex
        for node in built:
            ex.add_node(node)
        notifier = Notifier.from_environ()
        notifier.notify('READY=1', 'STATUS=executor turning: ' + ', '.join(n.get_name() for n in built))
        stats = spin_until_stopped(built[0], ex, stop, beat=notifier.beat if notifier.period else None)
        for node in built:
            node.spin_stats = stats
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        stop.ignore_further()
        if notifier is not None:
            notifier.notify('STOPPING=1')     # from here no beats: the watcher lets it go
            notifier.close()
        if ex is not None:
            drain_callbacks(ex, stats)      # nothing runs in the pool while on_exit() does
        for node in built:
            on_exit = getattr(node, 'on_exit', None)
            if on_exit is not None:
                try:
                    on_exit()
                except Exception as exc:  # noqa: BLE001 - best effort on the way out
                    try:
                        node.get_logger().error(f'while stopping: {exc}')
                    except Exception:  # noqa: BLE001
                        pass
        if bridge is not None:
            bridge.detach()
        if ex is not None:
            stop.executor = None
            ex.shutdown(timeout_sec=2.0)
        for node in built:
            try:
                node.destroy_node()
            except Exception:  # noqa: BLE001 - context already gone
                pass
        rclpy.try_shutdown()
        stop.close()
    return code


# ---------------------------------------------------------------- parameters
def declare_parameters(node, table) -> dict:
    """Declare every parameter of ``table`` (a :class:`sslfr_common.params.ParamTable`)
    on ``node`` with its description, unit and range, and return the values in force
    (defaults overridden by the command line or params files; integers made floats
    where the table takes them, :meth:`ParamTable.coerce`).

    Raises
    ------
    ValueError
        One line listing every invalid value (``run_node`` turns it into exit 2):
        the ones rclpy refuses when declaring (type, range) and the table's checks.
    """
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    problems = []
    for spec in table:
        d = ParameterDescriptor(description=spec.description, read_only=spec.read_only,
                                additional_constraints=spec.constraints)
        default = spec.default
        floating = isinstance(default, float) or (isinstance(default, list) and bool(default)
                                                  and isinstance(default[0], float))
        if floating and table.integers_for_floats:
            d.dynamic_typing = True           # 22 for 22.0; the table judges the value
        if spec.lo is not None and spec.hi is not None:
            if floating:
                d.floating_point_range = [FloatingPointRange(from_value=float(spec.lo), to_value=float(spec.hi))]
            elif isinstance(default, int) and not isinstance(default, bool):
                d.integer_range = [IntegerRange(from_value=int(spec.lo), to_value=int(spec.hi), step=1)]
        try:
            node.declare_parameter(spec.name, default, d)
        except CONFIG_ERRORS as exc:
            problems.append(f'{spec.name}: {exc}')
    if problems:
        raise ValueError('; '.join(problems))
    values = table.coerce({spec.name: node.get_parameter(spec.name).value for spec in table})
    errors = table.validate(values)
    if errors:
        raise ValueError('; '.join(errors))
    return values


class ParameterGuard:
    """Run-time parameter changes checked against the table, all or nothing.

    ``apply(proposed)`` is called with the complete proposed set (integers made
    floats where the table takes them) once the table's checks pass; it may raise
    ``ValueError`` (a node-specific rule) to refuse the change. On a refusal the
    reason is returned to the caller of ``set_parameters``, logged as an error and
    counted (:attr:`refused`), and the last good configuration (:attr:`values`)
    stays in force.
    """

    def __init__(self, node, table, values: dict, apply: Callable[[dict], None]):
        self.node = node
        self.table = table
        self.values = dict(values)
        self.apply = apply
        self.refused = 0
        self.last_refusal = ''
        node.add_on_set_parameters_callback(self._on_set)

    def _on_set(self, params):
        from rcl_interfaces.msg import SetParametersResult
        from rclpy.parameter import Parameter

        proposed = dict(self.values)
        for prm in params:
            spec = self.table.by_name.get(prm.name)
            if spec is None:
                continue
            if prm.type_ == Parameter.Type.NOT_SET:
                return self._refuse(f'{prm.name}: cannot be unset')
            value = self.table.coerce({prm.name: prm.value})[prm.name]
            if spec.read_only and value != self.values[prm.name]:
                return self._refuse(f'{prm.name} is fixed at start-up')
            proposed[prm.name] = value
        errors = self.table.validate(proposed)
        if not errors:
            try:
                self.apply(proposed)
            except ValueError as exc:
                errors = [str(exc)]
        if errors:
            return self._refuse('; '.join(errors))
        self.values = proposed
        return SetParametersResult(successful=True)

    def _refuse(self, reason: str):
        from rcl_interfaces.msg import SetParametersResult

        self.refused += 1
        self.last_refusal = reason
        self.node.get_logger().error(
            f'parameter change refused, keeping the last good configuration: {reason}')
        return SetParametersResult(successful=False, reason=reason)


def diagnostics_msg(name: str, level: int | bytes, message: str, hardware_id: str, values: dict,
                    now) -> DiagnosticArray:
    """One DiagnosticStatus (``level`` 0 OK, 1 WARN, 2 ERROR; every value as text) in an
    array stamped ``now`` (a builtin Time)."""
    st = DiagnosticStatus(level=level if isinstance(level, bytes) else bytes([level]), name=name,
                          message=message, hardware_id=hardware_id,
                          values=[KeyValue(key=k, value=str(v)) for k, v in values.items()])
    arr = DiagnosticArray(status=[st])
    arr.header.stamp = now
    return arr


def message_class(type_name: str):
    """The generated Python class of ``pkg/msg/Type`` (or ``pkg/Type``); ImportError,
    AttributeError or ValueError when there is none."""
    import importlib
    parts = type_name.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or not all(parts):
        raise ValueError(f'not a message type name: {type_name!r}')
    pkg, kind, typ = parts
    return getattr(importlib.import_module(f'{pkg}.{kind}'), typ)
