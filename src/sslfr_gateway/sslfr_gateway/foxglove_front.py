"""What the ``foxglove_bridge`` node serves, without rclpy: the foxglove-sdk WebSocket
server on a free loopback port, behind its :class:`~.allow_relay.AllowRelay` on
``bind_address:port``, with the SDK's log taken over by :class:`~.sdk_log.SdkLog`.
Built from the node's parameters (``params.FOXGLOVE_PARAMS``)."""
from __future__ import annotations

import foxglove

from sslfr_common.netguard import OneLineLog, limits_from

from . import params as gp
from .allow_relay import AllowRelay
from .sdk_log import SdkLog


class FoxgloveFront:
    """The server and its front door; :meth:`start` binds, :meth:`stop` closes both."""

    def __init__(self, cfg: dict, listener, log: OneLineLog, name: str = 'sslfr'):
        self.cfg, self.listener, self.log, self.name = cfg, listener, log, name
        self.sdk_log = SdkLog(log)
        self.server = None
        self.relay: AllowRelay | None = None

    def start(self) -> int:
        """Start the server and the relay; the relay's port. OSError when it cannot bind."""
        cfg = self.cfg
        self.sdk_log.attach()
        self.server = foxglove.start_server(name=self.name, host='127.0.0.1', port=0,
                                            server_listener=self.listener,
                                            message_backlog_size=int(cfg['message_backlog']))
        self.relay = AllowRelay(cfg['bind_address'], cfg['port'], self.server.port, gp.allowed(cfg['allow']),
                                limits_from(cfg), self.log, int(cfg['max_message_bytes']), float(cfg['max_messages_per_s']))
        try:
            return self.relay.start()
        except OSError:
            self.stop()
            raise

    def counters(self) -> dict[str, int]:
        """Open clients and every refusal (relay, connection guard, SDK) [-]."""
        relay = self.relay.all_counters() if self.relay is not None else {}
        return {'clients': self.relay.active if self.relay is not None else 0, **relay, **self.sdk_log.counters}

    #: [s] longest wait for the SDK server's stop (it waits for its clients' connections)
    STOP_TIMEOUT = 5.0

    def stop(self) -> None:
        """Close the relay, then the server; bounded: a server stop that does not return
        within STOP_TIMEOUT is left to its daemon thread (one line logged)."""
        if self.relay is not None:
            self.relay.stop()
        if self.server is not None:
            import threading
            t = threading.Thread(target=self.server.stop, daemon=True, name='foxglove-stop')
            t.start()
            t.join(self.STOP_TIMEOUT)
            if t.is_alive():
                self.log.report('stop', f'foxglove server: stop not done within {self.STOP_TIMEOUT:g} s, left behind')
        self.sdk_log.detach()
