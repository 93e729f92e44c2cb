"""The test harness of the topic-level tests and the benchmarks: node executables as
processes and an rclpy node in a test's own ROS domain (a plain module: conftest.py's
fixtures and benchmarks/ import it; product code never does).

- :func:`executable`: the path ``ros2 run package exe`` would run in this checkout;
- :func:`acquire_test_domain`: a ROS domain id no other test here holds;
- :class:`NodeProcess`: a node executable as its own process, output to a file;
- :class:`RosHarness`: an rclpy context and node in a domain, with ``spin_until``,
  ``collect`` and ``call``.
"""
from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from sslfr_bringup.host import TEST_DOMAINS, acquire_domain, executable_path

ROOT = Path(__file__).resolve().parents[1]
INSTALL = ROOT / 'ros_ws' / 'install'


def executable(package: str, exe: str) -> Path:
    """Path ``ros2 run package exe`` would run in this checkout's overlay."""
    return executable_path(package, exe, INSTALL)


def acquire_test_domain() -> tuple[int, object]:
    """A test domain id held for the caller: ``(id, lock file)`` (sslfr_bringup.host)."""
    return acquire_domain(TEST_DOMAINS, shuffle=True)


class NodeProcess:
    """A node executable running as its own process, output captured to a file."""

    def __init__(self, argv: list[str], env: dict, log_path: Path):
        self.argv = argv
        self.log_path = log_path
        self._log = open(log_path, 'wb')  # noqa: SIM115 - closed in stop()
        self.proc = subprocess.Popen(argv, env=env, stdout=self._log, stderr=subprocess.STDOUT,
                                     start_new_session=True)

    @property
    def pid(self) -> int:
        return self.proc.pid

    def running(self) -> bool:
        return self.proc.poll() is None

    def output(self) -> str:
        """Everything the process printed so far (also after :meth:`stop`)."""
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors='replace')

    def wait_for_output(self, text: str, timeout: float = 15.0) -> bool:
        """Wait until ``text`` appears in the output (or the process exits)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.output():
                return True
            if not self.running():
                return text in self.output()
            time.sleep(0.05)
        return False

    def signal(self, sig: int) -> None:
        if self.running():
            os.killpg(self.proc.pid, sig)

    def stop(self, timeout: float = 5.0) -> int | None:
        """SIGINT, then SIGKILL after ``timeout``; return the exit code."""
        if self.running():
            try:
                os.killpg(self.proc.pid, signal.SIGINT)
            except ProcessLookupError:
                pass
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait(5)
        self._log.close()
        return self.proc.returncode


class RosHarness:
    """An rclpy context and node living in the test's ROS domain."""

    def __init__(self, domain: int):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = rclpy.create_node(f'test_harness_{os.getpid()}', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=min(0.05, max(0.0, deadline - time.monotonic())))

    def spin_until(self, predicate, timeout: float = 10.0) -> bool:
        """Spin until ``predicate()`` is true; return whether it became true."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.05)
        # what had arrived by the deadline still counts: a test process that did not
        # run for a while (a long garbage collection late in a run) takes it in first
        for _ in range(200):
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.0)
        return bool(predicate())

    def collect(self, msg_type, topic: str, qos=10) -> list:
        """Subscribe and append every message to the returned list."""
        box: list = []
        self.node.create_subscription(msg_type, topic, box.append, qos)
        return box

    #: Services whose request may be sent twice with the same effect as once.
    IDEMPOTENT = frozenset({'GetParameters', 'ListParameters', 'DescribeParameters', 'GetParameterTypes',
                            'SetParameters', 'GetState', 'GetAvailableStates', 'GetAvailableTransitions'})
    RESEND_S = 2.0

    def call(self, srv_type, name: str, request, timeout: float = 10.0):
        """Call a service and return its response (fails the test on time-out).

        ``service_is_ready`` is the client's view of discovery: the server may not yet
        have matched the client's response reader, and rmw_fastrtps then drops the
        response after a short wait (seen once in a fresh-clone run on a loaded machine:
        `recorder/get_parameters` ready, no answer in 20 s). An idempotent request
        (``IDEMPOTENT``) is therefore sent again every ``RESEND_S`` s until one answer
        arrives; any other is sent once (sending it again could act twice)."""
        client = self.node.create_client(srv_type, name)
        if not self.spin_until(client.service_is_ready, timeout):
            pytest.fail(f'service {name} not available within {timeout} s')
        resend = srv_type.__name__ in self.IDEMPOTENT
        deadline = time.monotonic() + timeout
        futures = [client.call_async(request)]
        while True:
            step = min(self.RESEND_S if resend else timeout, deadline - time.monotonic())
            if self.spin_until(lambda: any(f.done() for f in futures), max(step, 0.0)):
                return next(f for f in futures if f.done()).result()
            if time.monotonic() >= deadline:
                pytest.fail(f'service {name} did not answer within {timeout} s'
                            + (f' ({len(futures)} requests)' if resend else ''))
            futures.append(client.call_async(request))

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.context)
