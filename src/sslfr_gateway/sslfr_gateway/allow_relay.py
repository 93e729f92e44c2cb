"""The Foxglove server's front door: client allow-list, connection caps and WebSocket
frame limits (asyncio, own thread; no rclpy).

The foxglove-sdk WebSocket server has no admission control and accepts client
messages of 16 MiB, so it listens on a free loopback port and this relay listens on
the public ``bind_address:port``. For each client:

- an IP address not in ``allow`` (IPv4-mapped IPv6 compared as IPv4) is closed at once;
- :class:`sslfr_common.netguard.ConnectionGuard` caps connections per address and in
  all (the heaviest address's oldest one makes room for a newcomer) and closes a
  connection whose upgrade request is not complete within ``header_timeout``;
- the upgrade request head is at most ``MAX_HEAD_BYTES`` (else HTTP 431);
- every client frame is parsed as it passes (:class:`ClientFrames`): a message larger
  than ``max_message_bytes`` (close code 1009), more than ``max_messages_per_s``
  sustained (token bucket of two seconds' worth; 1008), or a frame that breaks
  RFC 6455 (1002) ends the connection with a close frame and a reason;
- a client ``advertise`` or binary message (client publishing: the server offers no
  ``clientPublish`` capability, the SDK answers it with an error status) is counted.

Everything else is piped byte for byte; the SDK answers protocol errors (bad JSON,
unknown channels) with a status message. The server -> client direction is bounded
by the writer's flow control (a client that does not read stalls only its own pipe;
the SDK drops its oldest data messages). Each refusal is counted in ``counters`` and
reported as one rate-limited line.
"""
from __future__ import annotations

import asyncio
import ipaddress
import json
import struct
import threading
import time

from sslfr_common.netguard import ConnectionGuard, Limits, OneLineLog

MAX_HEAD_BYTES = 8192          # [bytes] the client's HTTP upgrade request head
CLOSE_WAIT_S = 2.0             # [s] the server's remaining bytes before the close frame


def client_ip(peer) -> str:
    """The peer's address as a plain string (``::ffff:a.b.c.d`` -> ``a.b.c.d``)."""
    if not peer:
        return ''
    ip = ipaddress.ip_address(peer[0].split('%')[0])
    mapped = getattr(ip, 'ipv4_mapped', None)
    return str(mapped or ip)


class FrameError(Exception):
    """A client frame the server refuses: ``code`` is the WebSocket close code."""

    def __init__(self, code: int, reason: str):
        super().__init__(reason)
        self.code, self.reason = code, reason


def _unmask(data: bytes, mask: bytes, offset: int) -> bytes:
    """``data`` XOR the 4-byte ``mask`` starting at mask byte ``offset % 4``."""
    n = len(data)
    k = offset % 4
    key = (mask[k:] + mask[:k]) * (n // 4 + 1)
    return (int.from_bytes(data, 'little') ^ int.from_bytes(key[:n], 'little')).to_bytes(n, 'little')


class ClientFrames:
    """Client -> server WebSocket frames (RFC 6455 section 5), parsed incrementally.

    :meth:`feed` takes the bytes as they arrive and returns the messages completed in
    them as ``(opcode, payload)``: the unmasked payload for text (1) and control frames
    (8 close, 9 ping, 10 pong), ``b''`` for binary (2: not kept). :class:`FrameError`
    for an unmasked frame, reserved bits or opcodes (no extension is negotiated), a
    fragmented or long control frame, a continuation out of place, or a message larger
    than ``max_message_bytes`` (refused from its header, before its payload arrives).
    """

    def __init__(self, max_message_bytes: int):
        self.max = int(max_message_bytes)
        self._buf = b''              # bytes of a frame header not complete yet
        self._op: int | None = None  # opcode of the frame whose payload is passing (None: between frames)
        self._fin = True
        self._left = 0               # payload bytes of that frame still to come
        self._pos = 0                # payload bytes of that frame seen
        self._mask = b''
        self._ctl = b''
        self._msg_op = 0             # opcode of the message in progress (0: none)
        self._msg_len = 0
        self._text: list[bytes] = []

    def feed(self, data: bytes) -> list[tuple[int, bytes]]:
        out: list[tuple[int, bytes]] = []
        buf = self._buf + data if self._buf else data
        i = 0
        while i < len(buf):
            if self._op is None:
                used = self._header(buf, i)
                if not used:
                    break
                i += used
            else:
                take = min(self._left, len(buf) - i)
                self._payload(buf[i:i + take])
                i += take
                self._left -= take
            if self._op is not None and self._left == 0:
                self._end_frame(out)
        self._buf = buf[i:]
        return out

    def _header(self, buf: bytes, i: int) -> int:
        """Parse the frame header at ``buf[i:]``; its length, 0 when incomplete."""
        if len(buf) - i < 2:
            return 0
        b0, b1 = buf[i], buf[i + 1]
        if not b1 & 0x80:
            raise FrameError(1002, 'client frame not masked')
        if b0 & 0x70:
            raise FrameError(1002, 'reserved bits set (no extension was negotiated)')
        n = b1 & 0x7F
        need = 2 + (2 if n == 126 else 8 if n == 127 else 0) + 4
        if len(buf) - i < need:
            return 0
        op, fin = b0 & 0x0F, bool(b0 & 0x80)
        if n == 126:
            n = struct.unpack_from('!H', buf, i + 2)[0]
        elif n == 127:
            n = struct.unpack_from('!Q', buf, i + 2)[0]
        if op >= 8:
            if op not in (8, 9, 10):
                raise FrameError(1002, f'reserved opcode {op}')
            if not fin or n > 125:
                raise FrameError(1002, 'control frame fragmented or longer than 125 bytes')
        elif op in (1, 2):
            if self._msg_op:
                raise FrameError(1002, 'new message inside a fragmented one')
            self._msg_op, self._msg_len, self._text = op, 0, []
        elif op == 0:
            if not self._msg_op:
                raise FrameError(1002, 'continuation frame without a message')
        else:
            raise FrameError(1002, f'reserved opcode {op}')
        if op < 8:
            self._msg_len += n
            if self._msg_len > self.max:
                raise FrameError(1009, f'message larger than {self.max} bytes')
        self._mask = bytes(buf[i + need - 4:i + need])
        self._op, self._fin, self._left, self._pos, self._ctl = op, fin, n, 0, b''
        return need

    def _payload(self, chunk: bytes) -> None:
        if self._op >= 8:
            self._ctl += _unmask(chunk, self._mask, self._pos)
        elif self._msg_op == 1:
            self._text.append(_unmask(chunk, self._mask, self._pos))
        self._pos += len(chunk)

    def _end_frame(self, out) -> None:
        op, self._op = self._op, None
        if op >= 8:
            out.append((op, self._ctl))
        elif self._fin:
            out.append((self._msg_op, b''.join(self._text) if self._msg_op == 1 else b''))
            self._msg_op, self._msg_len, self._text = 0, 0, []


def publish_attempt(opcode: int, payload: bytes) -> bool:
    """True for a client message of the Foxglove protocol that publishes (a binary
    message, or a JSON ``advertise``)."""
    if opcode == 2:
        return True
    if opcode != 1 or b'advertise' not in payload:
        return False
    try:
        return json.loads(payload).get('op') == 'advertise'
    except (ValueError, AttributeError, RecursionError):
        return False


def close_frame(code: int, reason: str) -> bytes:
    """A server close frame (unmasked) with ``code`` and at most 123 bytes of reason."""
    body = struct.pack('!H', code) + reason.encode()[:123]
    return bytes([0x88, len(body)]) + body


class AllowRelay:
    """Relay ``bind_address:port`` -> ``127.0.0.1:target_port`` (module docstring)."""

    def __init__(self, bind_address: str, port: int, target_port: int, allow: tuple[str, ...],
                 limits: Limits, log: OneLineLog, max_message_bytes: int = 65536,
                 max_messages_per_s: float = 50.0):
        self.bind_address, self.port, self.target_port = bind_address, port, target_port
        self.allow = frozenset(allow)
        self.log = log
        self.guard = ConnectionGuard(limits, log)
        self.max_message_bytes, self.max_messages_per_s = max_message_bytes, float(max_messages_per_s)
        self.counters = {'admitted': 0, 'refused_address': 0, 'bad_requests': 0, 'oversized': 0,
                         'flooding': 0, 'bad_frames': 0, 'publish_refused': 0}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: asyncio.base_events.Server | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None

    @property
    def active(self) -> int:
        """Open client connections [-]."""
        return len(self.guard)

    def all_counters(self) -> dict[str, int]:
        """The relay's and the connection guard's counters (for diagnostics)."""
        return {**self.counters, **self.guard.counters}

    def start(self, timeout: float = 10.0) -> int:
        """Start; return the bound port. Raises OSError when it cannot bind."""
        self._thread = threading.Thread(target=self._run, name='allow-relay', daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout) or self._error is not None:
            raise OSError(f'cannot listen on {self.bind_address}:{self.port}: {self._error}')
        return self.port

    def _run(self) -> None:
        self._loop = loop = asyncio.new_event_loop()
        loop.set_exception_handler(lambda _loop, ctx: self.log.report(
            'relay error', f"foxglove relay: {ctx.get('exception') or ctx.get('message')!r}", 'error'))

        def streams():
            reader = asyncio.StreamReader(limit=MAX_HEAD_BYTES, loop=loop)
            return asyncio.StreamReaderProtocol(reader, self._client, loop=loop)
        try:
            self._server = loop.run_until_complete(
                loop.create_server(self.guard.wrap(streams), self.bind_address, self.port))
            self.port = self._server.sockets[0].getsockname()[1]
        except BaseException as exc:  # noqa: BLE001 - reported through start()
            self._error = exc
            self._ready.set()
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            loop.close()

    def _refuse(self, key: str, ip: str, why: str) -> None:
        self.counters[key] += 1
        self.log.report(key, f'foxglove client {ip} refused: {why} ({self.counters[key]} so far)')

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        ip = client_ip(writer.get_extra_info('peername'))
        if ip not in self.allow:
            self._refuse('refused_address', ip, 'address not in allow')
            writer.transport.abort()
            return
        try:
            head = await reader.readuntil(b'\r\n\r\n')
        except asyncio.LimitOverrunError:
            self._refuse('bad_requests', ip, f'request head longer than {MAX_HEAD_BYTES} bytes')
            writer.write(b'HTTP/1.1 431 Request Header Fields Too Large\r\nConnection: close\r\n'
                         b'Content-Length: 0\r\n\r\n')
            writer.close()
            return
        except (asyncio.IncompleteReadError, ConnectionError):
            writer.close()
            return
        self.guard.busy(writer.transport)          # a WebSocket session: no idle time-out
        self.counters['admitted'] += 1
        try:
            up_r, up_w = await asyncio.open_connection('127.0.0.1', self.target_port)
        except OSError:
            writer.close()
            return
        up_w.write(head)
        down = asyncio.ensure_future(_pipe(up_r, writer))
        up = asyncio.ensure_future(self._pipe_up(reader, up_w, ip))
        try:
            await asyncio.wait((up, down), return_when=asyncio.FIRST_COMPLETED)
            refusal = up.result() if up.done() else None
            if refusal is not None:                 # the server's remaining frames, then ours
                up_w.write_eof()
                try:
                    await asyncio.wait_for(asyncio.shield(down), CLOSE_WAIT_S)
                    writer.write(close_frame(*refusal))
                    await asyncio.wait_for(writer.drain(), CLOSE_WAIT_S)
                except (asyncio.TimeoutError, ConnectionError, OSError):
                    pass
        except asyncio.CancelledError:
            pass                                    # stop(): close both ends below
        finally:
            for task in (up, down):
                task.cancel()
            writer.close()
            # the server's side at once, unflushed: a graceful close would wait for its
            # buffered bytes, and once the loop stops the server would hold a connection
            # nobody reads (its stop() waits for it)
            up_w.transport.abort()

    async def _pipe_up(self, src: asyncio.StreamReader, dst: asyncio.StreamWriter,
                       ip: str) -> tuple[int, str] | None:
        """Client -> server through :class:`ClientFrames`; the close code and reason when
        the client is refused, None when either side closed."""
        frames = ClientFrames(self.max_message_bytes)
        capacity = 2.0 * self.max_messages_per_s
        tokens, last = capacity, time.monotonic()
        try:
            while data := await src.read(65536):
                try:
                    msgs = frames.feed(data)
                except FrameError as exc:
                    self._refuse('oversized' if exc.code == 1009 else 'bad_frames', ip, exc.reason)
                    return exc.code, exc.reason
                now = time.monotonic()
                tokens = min(capacity, tokens + (now - last) * self.max_messages_per_s)
                last = now
                for op, payload in msgs:
                    tokens -= 1.0
                    if publish_attempt(op, payload):
                        self._refuse('publish_refused', ip, 'client publishing is not offered')
                if tokens < 0:
                    why = f'more than {self.max_messages_per_s:g} messages per second'
                    self._refuse('flooding', ip, why)
                    return 1008, why
                dst.write(data)
                await dst.drain()
        except (ConnectionError, OSError):
            pass
        return None

    def stop(self) -> None:
        if self._loop is None or not self._loop.is_running():
            return

        async def _close():
            self._server.close()
            self.guard.close_all()
            tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
            for t in tasks:
                t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
            self._loop.stop()
        asyncio.run_coroutine_threadsafe(_close(), self._loop)
        if self._thread is not None:
            self._thread.join(5)


async def _pipe(src: asyncio.StreamReader, dst: asyncio.StreamWriter) -> None:
    """Server -> client, byte for byte; waits while the client does not read."""
    try:
        while data := await src.read(65536):
            dst.write(data)
            await dst.drain()
    except (ConnectionError, OSError):
        pass
