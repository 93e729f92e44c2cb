"""What a node that serves a page shares (the operator page's ``web`` node, the
field's ``field_page``): the page's server (:class:`~sslfr_web.app.Server`) on its
own thread, and the backend calls the page makes into the node from that thread
(log lines, ROS time, service calls), and the page's diagnostics.
"""
from __future__ import annotations

import asyncio

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sslfr_common.contract import DIAGNOSTICS, collector_id
from sslfr_common.node import LeanEvents, diagnostics_msg, qos, to_sec

from . import commands
from .app import Server

OK, WARN = 0, 1                                 # DiagnosticStatus levels


class PageHost(LeanEvents, Node):
    """A node with a page: :meth:`serve` starts it, :meth:`on_exit` stops it."""

    def serve(self, op) -> str:
        """Serve ``op`` (an application of :mod:`sslfr_web.app`) on the node's
        ``bind_address``/``port``; the URL. OSError when the address cannot be bound."""
        self.op = op
        self._diag = self.create_publisher(DiagnosticArray, DIAGNOSTICS.name, qos(DIAGNOSTICS))
        self.server = Server(op, self.cfg['bind_address'], int(self.cfg['port']))
        self.url = self.server.start()
        return self.url

    # ------------------------------------------------------------------ backend (web thread)
    def ros_time(self) -> float | None:
        """ROS time [s], None before the clock has a time."""
        t = to_sec(self.get_clock().now())
        return t if t > 0 else None

    def log(self, level: str, text: str) -> None:
        logger = self.get_logger()       # one call site per severity (rclpy refuses to mix them)
        if level == 'error':
            logger.error(text)
        elif level == 'warn':
            logger.warning(text)
        else:
            logger.info(text)

    async def call_service(self, client, request, *, timeout: float, discovery_wait: float,
                           resend_every: float | None = None, missing: str = '') -> dict:
        """Call ``client`` with ``request`` from the page's event loop: wait up to
        ``discovery_wait`` [s] for the server, then ``timeout`` [s] for the answer (sent
        again every ``resend_every`` [s] if given, :func:`commands.first_answer`). The
        response's fields, or ``{'success': False, 'message': why}``."""
        name = client.srv_name
        for _ in range(int(discovery_wait / 0.05)):       # let discovery match the client
            if client.service_is_ready():
                break
            await asyncio.sleep(0.05)
        else:
            return {'success': False, 'message': f'service {name} is not available ({missing})'}
        loop = asyncio.get_running_loop()
        sent: list = []

        def send() -> asyncio.Future:
            done = loop.create_future()
            fut = client.call_async(request)
            fut.add_done_callback(lambda f: loop.call_soon_threadsafe(lambda: done.done() or done.set_result(f)))
            sent.append(fut)
            return done

        f, n = await commands.first_answer(send, timeout, resend_every)
        for fut in sent:
            if not fut.done():
                client.remove_pending_request(fut)
        if f is None:
            return {'success': False, 'message': f'no answer from {name} within {timeout:g} s'
                                                 + (f' ({n} requests)' if n > 1 else '')}
        if n > 1:
            self.get_logger().warning(f'{name}: answered after {n} requests (a response lost or late)')
        resp = f.result()
        return {k: getattr(resp, k) for k in resp.get_fields_and_field_types()}

    # ------------------------------------------------------------------ diagnostics (ROS thread)
    def publish_page_status(self, what: str, ok: bool, message: str, values: dict) -> None:
        """``<node>: <what>`` on ``diagnostics``, OK or WARN with ``message``; ``values``
        after the page's counters, with its sessions and URL."""
        values = {**self.op.counters, **values, 'sessions': len(self.op.sessions), 'url': self.url}
        self._diag.publish(diagnostics_msg(
            f'{self.get_name()}: {what}', OK if ok else WARN, message, collector_id(self.get_namespace()),
            values, self.get_clock().now().to_msg()))

    def on_exit(self) -> None:
        """Stop the HTTP server; called by run_node once spinning ends."""
        self.server.stop()
