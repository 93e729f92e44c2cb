"""The board behind a sensor node's ``port``, and the queue its samples wait in
(pure Python, no rclpy).

:class:`BoardSource` reads the board either through the board protocol (a
:class:`~sslfr_drivers.link.board_link.BoardLink`) or - GPS only, ``framing:
raw_nmea`` - as the bare byte stream of a GPS module. Both run on the one
reconnecting reader (:class:`~sslfr_drivers.link.reader.ReaderThread`, same back-off),
so a lost port is reopened the same way. Callbacks run in the reader thread: nodes put
what they get in a :class:`SampleQueue` that an executor timer drains.
"""
from __future__ import annotations

import collections
from typing import Any, Callable

from sslfr_drivers.link import sensor_messages  # noqa: F401 - registers the sensor message types
from sslfr_drivers.link.board_link import BoardLink, BoardLinkState
from sslfr_drivers.link.keys import KeyFileError, link_key
from sslfr_drivers.link.reader import Protocol, ReaderThread
from sslfr_drivers.link.transport import TransportError, make_transport

#: ``framing`` values: board-protocol frames, or bare NMEA text.
FRAMINGS = ('protocol', 'raw_nmea')


class RawStream(Protocol):
    """Reader protocol of a bare byte stream: every chunk to ``on_bytes(data)``."""

    def __init__(self, on_bytes: Callable[[bytes], None]):
        self.on_bytes = on_bytes

    def data_received(self, data: bytes) -> None:
        self.on_bytes(data)


class BoardSource:
    """The board (or bare NMEA module) behind ``port``.

    Parameters
    ----------
    port : str
        pyserial URL / device path / ``xbee:...`` port; '' = no board configured.
    framing : str
        ``protocol`` (board protocol frames) or ``raw_nmea`` (bare NMEA bytes).
    baudrate : int
        [bit/s].
    on_message : callable(msg)
        Every decoded board message (protocol framing), reader thread.
    on_bytes : callable(bytes)
        Every chunk of raw bytes (raw framing), reader thread.
    heartbeat : float
        PING period keeping the link's silence detection alive [s].
    key_file : str
        Installation key file of the link ('' = none: unprovisioned boards only); a
        file others may read refuses the link (:attr:`last_error` says why).
    on_up : callable(BoardLink) or None
        Called (reader thread) every time the link comes up: after the first
        connection, a reconnection and a board reset (e.g. to set a board input).
    """

    def __init__(self, port: str, framing: str = 'protocol', baudrate: int = 115200,
                 on_message: Callable | None = None, on_bytes: Callable | None = None,
                 heartbeat: float = 0.5, key_file: str = '', on_up: Callable | None = None,
                 owner: str = ''):
        self.on_up = on_up
        self.owner = owner                  # the node it works for (its link's log lines)
        self.port = port
        self.key_file = key_file
        self.framing = framing
        self.baudrate = baudrate
        self.on_message = on_message or (lambda msg: None)
        self.on_bytes = on_bytes or (lambda data: None)
        self.heartbeat = heartbeat
        self.link: BoardLink | None = None
        self.reader: ReaderThread | None = None
        self.last_error = '' if port else 'no port configured (parameter port is empty)'

    def start(self) -> 'BoardSource':
        """Open the port and start reading. A bad port is reported by
        :attr:`state`/:meth:`error`, not raised; returns self."""
        if not self.port:
            return self
        try:
            transport = make_transport(self.port, self.baudrate)
        except (ValueError, TransportError, OSError) as exc:
            self.last_error = f'bad port {self.port!r}: {exc}'
            return self
        if self.framing == 'protocol':
            try:
                key = link_key(self.key_file)
            except KeyFileError as exc:             # never a link with an exposed key
                transport.close()
                self.last_error = f'not starting the board link: {exc}'
                return self
            self.link = BoardLink(transport, name=self.port, heartbeat=self.heartbeat,
                                  silence=max(1.0, 4 * self.heartbeat), key=key, owner=self.owner)
            self.link.add_listener(lambda msg, frame: self.on_message(msg))
            if self.on_up is not None:
                self.link.add_state_listener(
                    lambda state, link: self.on_up(link) if state is BoardLinkState.UP else None)
            self.link.start()
        else:
            self.reader = ReaderThread(transport, RawStream(self.on_bytes), name=self.port,
                                       read_timeout=0.05).start()
        return self

    def stop(self) -> None:
        """Stop reading and close the port (idempotent)."""
        if self.link is not None:
            self.link.stop()
            self.link = None
        if self.reader is not None:
            self.reader.stop()
            self.reader = None

    @property
    def state(self) -> str:
        """'unconfigured', 'down', 'connecting', 'up', 'silent', 'refused'."""
        if not self.port:
            return 'unconfigured'
        if self.link is not None:
            return self.link.state.value
        if self.reader is not None and self.reader.connected:
            return 'up'
        return 'down'

    def counters(self) -> dict:
        """Link counters (protocol framing) or bytes received and reconnects (raw)."""
        if self.link is not None:
            return self.link.counters()
        r = self.reader
        return {'bytes_received': r.bytes_received if r else 0, 'reconnects': r.reconnects if r else 0}

    def error(self) -> str:
        """The last error text of the port or link (empty when none)."""
        if self.link is not None:
            return self.link.last_error
        if self.reader is not None and self.reader.last_error:
            return self.reader.last_error
        return self.last_error


class SampleQueue:
    """Samples handed from the reader thread to the executor, each with its receive
    time; bounded: a full queue drops the oldest sample and counts it (``dropped``).

    Parameters
    ----------
    maxlen : int
        Capacity [samples].
    """

    def __init__(self, maxlen: int):
        self._q: collections.deque = collections.deque(maxlen=maxlen)
        self.dropped = 0

    def put(self, item: Any, received: Any) -> bool:
        """Queue ``item`` received at ``received`` (reader thread); True when the queue
        held only this item afterwards: the consumer must be woken (a consumer that
        drains until empty never misses an item woken this way)."""
        if len(self._q) == self._q.maxlen:
            self.dropped += 1
        self._q.append((item, received))
        return len(self._q) == 1

    def drain(self):
        """Yield ``(item, received)`` in arrival order until the queue is empty."""
        q = self._q
        while q:
            yield q.popleft()

    def __len__(self) -> int:
        return len(self._q)
