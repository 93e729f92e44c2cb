"""The Foxglove face under hostile clients, over real sockets: the foxglove-sdk server
behind its relay exactly as ``foxglove_bridge`` serves it (FoxgloveFront, the node's
default parameters), WebSocket clients (aiohttp) from several loopback addresses.

Each bad input (not JSON, not the protocol, nested, unknown channels, ids out of
range, client publishing, oversized and malformed frames, a message flood, a connect
flood, unfinished upgrade requests, a client that never reads) gets a clear refusal
(an error status from the server, or a close frame with a code and reason) and a
count; the operator's client at 127.0.0.1 keeps receiving its channel throughout;
nothing reaches the graph (the listener is never asked to take a client's message);
the log gets single lines, never a traceback."""
from __future__ import annotations

import asyncio
import contextlib
import json
import os
import struct
import threading
import time

import aiohttp
import foxglove
import psutil
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gateway_fixtures import extra_loopbacks  # noqa: F401 - a fixture
from sslfr_common.netguard import OneLineLog
from sslfr_gateway import params as gp
from sslfr_gateway.allow_relay import ClientFrames, FrameError, close_frame, publish_attempt
from sslfr_gateway.foxglove_front import FoxgloveFront

PROTOCOLS = ('foxglove.sdk.v1', 'foxglove.websocket.v1')
OPERATOR = '127.0.0.1'


class Listener(foxglove.ServerListener):
    """Records what the server asks of the graph."""

    def __init__(self):
        self.subscribed, self.client_calls = [], []

    def on_subscribe(self, client, channel):
        self.subscribed.append(channel.topic)

    def on_client_advertise(self, client, channel):
        self.client_calls.append(('advertise', channel.topic))

    def on_message_data(self, client, client_channel_id, data):
        self.client_calls.append(('data', client_channel_id))


@contextlib.contextmanager
def serving(extra_allow=(), payload_bytes=2000, **cfg):
    """The front with the node's defaults (+ ``cfg``), a channel ``/fast`` logged at
    ~200 Hz with ``payload_bytes`` messages while it runs (their number in
    ``front.logged``); yields (url, front, listener, lines)."""
    conf = {**gp.FOXGLOVE_PARAMS.defaults(), 'port': 0,
            'allow': ['127.0.0.1', *extra_allow], **cfg}
    assert gp.FOXGLOVE_PARAMS.validate(conf) == []
    lines: list[tuple[str, str]] = []
    listener = Listener()
    front = FoxgloveFront(conf, listener, OneLineLog(lambda level, text: lines.append((level, text))))
    port = front.start()
    schema = foxglove.Schema(name='std_msgs/msg/String', encoding='ros2msg', data=b'string data')
    channel = foxglove.Channel('/fast', schema=schema, message_encoding='cdr')
    stop = threading.Event()
    front.logged = 0

    def produce():
        payload = b'\x00\x01\x00\x00' + b'x' * payload_bytes
        while not stop.wait(0.005):
            channel.log(payload)
            front.logged += 1
    producer = threading.Thread(target=produce, daemon=True)
    producer.start()
    try:
        yield f'ws://127.0.0.1:{port}', front, listener, lines
    finally:
        stop.set()
        producer.join(2)
        channel.close()
        front.stop()
    assert listener.client_calls == []
    assert all('\n' not in t and 'Traceback' not in t for _, t in lines), lines


def session(addr: str) -> aiohttp.ClientSession:
    return aiohttp.ClientSession(connector=aiohttp.TCPConnector(local_addr=(addr, 0), force_close=True),
                                 timeout=aiohttp.ClientTimeout(total=30))


async def connect(s: aiohttp.ClientSession, url: str):
    return await s.ws_connect(url, protocols=PROTOCOLS, autoping=True, max_msg_size=0)


async def channels(ws) -> dict[str, int]:
    """Topic -> channel id from the server's first advertise."""
    while True:
        msg = await asyncio.wait_for(ws.receive(), 10)
        assert msg.type == aiohttp.WSMsgType.TEXT, msg
        body = json.loads(msg.data)
        if body.get('op') == 'advertise':
            return {c['topic']: c['id'] for c in body['channels']}


async def status_after(ws, raw) -> str:
    """Send ``raw`` (text or bytes) and return the server's next status message."""
    await (ws.send_bytes(raw) if isinstance(raw, bytes) else ws.send_str(raw))
    while True:
        msg = await asyncio.wait_for(ws.receive(), 10)
        if msg.type == aiohttp.WSMsgType.TEXT:
            body = json.loads(msg.data)
            if body.get('op') == 'status':
                assert body['level'] == 2, body
                return body['message']
        elif msg.type != aiohttp.WSMsgType.BINARY:
            raise AssertionError(f'connection ended instead of a status: {msg}')


class Operator:
    """The legitimate client: subscribed to /fast, counting the messages it receives."""

    def __init__(self, url: str):
        self.url, self.received, self.task = url, 0, None

    async def __aenter__(self):
        self.session = session(OPERATOR)
        self.ws = await connect(self.session, self.url)
        self.fast = (await channels(self.ws))['/fast']
        await self.ws.send_str(json.dumps({'op': 'subscribe', 'subscriptions': [{'id': 1, 'channelId': self.fast}]}))
        self.task = asyncio.ensure_future(self._read())
        await self.receives()
        return self

    async def _read(self):
        async for msg in self.ws:
            if msg.type == aiohttp.WSMsgType.BINARY and msg.data[0] == 1:
                self.received += 1

    async def receives(self, n: int = 20, within: float = 10.0) -> bool:
        """True when ``n`` more messages arrive within ``within`` seconds."""
        goal, deadline = self.received + n, time.monotonic() + within
        while self.received < goal and time.monotonic() < deadline and not self.task.done():
            await asyncio.sleep(0.05)
        return self.received >= goal

    async def __aexit__(self, *exc):
        self.task.cancel()
        await self.ws.close()
        await self.session.close()


def masked_frame(opcode: int, payload: bytes, *, fin: bool = True, mask: bool = True, length: int | None = None) -> bytes:
    n = len(payload) if length is None else length
    head = bytes([(0x80 if fin else 0) | opcode])
    bit = 0x80 if mask else 0
    if n < 126:
        head += bytes([bit | n])
    elif n < 65536:
        head += bytes([bit | 126]) + struct.pack('!H', n)
    else:
        head += bytes([bit | 127]) + struct.pack('!Q', n)
    if not mask:
        return head + payload
    key = os.urandom(4)
    return head + key + bytes(b ^ key[i % 4] for i, b in enumerate(payload))


async def raw_session(port: int, source: str = OPERATOR):
    """A WebSocket opened by hand (for frames aiohttp would not send); after the 101."""
    r, w = await asyncio.open_connection('127.0.0.1', port, local_addr=(source, 0))
    w.write(b'GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n'
            b'Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n'
            b'Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n')
    head = await asyncio.wait_for(r.readuntil(b'\r\n\r\n'), 10)
    assert head.startswith(b'HTTP/1.1 101'), head
    return r, w


async def close_code(r: asyncio.StreamReader) -> int | None:
    """Read server frames until a close frame (its code) or the end (None)."""
    with contextlib.suppress(asyncio.IncompleteReadError, ConnectionError):
        while True:
            b0, b1 = await asyncio.wait_for(r.readexactly(2), 10)
            n = b1 & 0x7F
            if n == 126:
                n = struct.unpack('!H', await r.readexactly(2))[0]
            elif n == 127:
                n = struct.unpack('!Q', await r.readexactly(8))[0]
            body = await r.readexactly(n)
            if b0 & 0x0F == 8:
                return struct.unpack('!H', body[:2])[0]
    return None


def test_bad_messages_get_an_error_status_and_a_count_and_reach_nothing(extra_loopbacks):
    attacker = extra_loopbacks[0] if extra_loopbacks else OPERATOR
    with serving(extra_allow=extra_loopbacks) as (url, front, listener, lines):
        async def main():
            async with Operator(url) as op, session(attacker) as s:
                ws = await connect(s, url)
                ids = await channels(ws)
                said = [await status_after(ws, raw) for raw in (
                    'not json', '{"op": "nope"}', '[1, 2]', '[' * 5000 + ']' * 5000, '{"op": "subscribe"}',
                    '{"op":"subscribe","subscriptions":[{"id":1,"channelId":999999}]}',
                    '{"op":"subscribe","subscriptions":[{"id":18446744073709551616,"channelId":%d}]}' % ids['/fast'],
                    '{"op":"subscribe","subscriptions":[{"id":-1,"channelId":%d}]}' % ids['/fast'],
                    '{"op":"advertise","channels":[{"id":1,"topic":"/planner/set_mode","encoding":"cdr",'
                    '"schemaName":"sslfr_interfaces/srv/SetMode"}]}',
                    b'\x01\x01\x00\x00\x00{"mode": "manual"}',
                    b'\xff' * 40)]
                assert all(said), said
                assert 'clientPublish' in said[8] and 'nknown channel' in said[5]
                assert await op.receives()
                await ws.close()
        asyncio.run(main())
        c = front.counters()
        assert c['bad_messages'] >= 6 and c['unknown_channel'] >= 1, c
        assert c['publish_refused'] == 3 and c['client_data_refused'] >= 1, c
        assert listener.subscribed == ['/fast']


def test_oversized_malformed_and_flooding_clients_are_closed_with_a_reason(extra_loopbacks):
    attacker = extra_loopbacks[0] if extra_loopbacks else OPERATOR
    with serving(extra_allow=extra_loopbacks, max_message_bytes=65536, max_messages_per_s=20.0) as (
            url, front, listener, lines):
        port = int(url.rsplit(':', 1)[1])

        async def main():
            async with Operator(url) as op:
                # a 1 MB message through a real client: close 1009 before the server sees it
                async with session(attacker) as s:
                    ws = await connect(s, url)
                    await channels(ws)
                    await ws.send_str('{"op":"subscribe","subscriptions":[' + ' ' * 1_000_000 + ']}')
                    msg = await asyncio.wait_for(ws.receive(), 10)
                    while msg.type in (aiohttp.WSMsgType.TEXT, aiohttp.WSMsgType.BINARY):
                        msg = await asyncio.wait_for(ws.receive(), 10)
                    assert msg.type == aiohttp.WSMsgType.CLOSE and msg.data == 1009, msg
                    assert 'larger than 65536' in msg.extra
                # frames no client may send: announced 2**40 bytes, unmasked, reserved bits,
                # a fragmented control frame, a continuation out of place
                for frame, code in ((masked_frame(1, b'', length=1 << 40), 1009),
                                    (masked_frame(1, b'{}', mask=False), 1002),
                                    (bytes([0xC1, 0x80]) + b'\0' * 4, 1002),
                                    (masked_frame(9, b'', fin=False), 1002),
                                    (masked_frame(0, b'{}'), 1002)):
                    r, w = await raw_session(port, attacker)
                    w.write(frame)
                    assert await close_code(r) == code, frame[:4]
                    w.close()
                # a subscribe flood: more than 20 messages/s sustained -> close 1008
                async with session(attacker) as s:
                    ws = await connect(s, url)
                    ids = await channels(ws)
                    sub = json.dumps({'op': 'subscribe', 'subscriptions': [{'id': 5, 'channelId': ids['/fast']}]})
                    unsub = json.dumps({'op': 'unsubscribe', 'subscriptionIds': [5]})
                    code = None
                    for _ in range(400):
                        try:
                            await ws.send_str(sub)
                            await ws.send_str(unsub)
                        except ConnectionError:
                            break
                        await asyncio.sleep(0.002)
                        if ws.closed:
                            break
                    while not ws.closed:
                        msg = await asyncio.wait_for(ws.receive(), 10)
                        if msg.type == aiohttp.WSMsgType.CLOSE:
                            code = msg.data
                    code = code or ws.close_code
                    assert code == 1008, code
                assert await op.receives()
        asyncio.run(main())
        c = front.counters()
        assert c['oversized'] == 2 and c['bad_frames'] == 4 and c['flooding'] == 1, c
        assert listener.client_calls == []


def test_a_connect_flood_and_unfinished_requests_leave_the_operator_served(extra_loopbacks):
    if len(extra_loopbacks) < 2:
        pytest.skip('needs 127.0.0.2 and 127.0.0.3')
    with serving(extra_allow=extra_loopbacks, max_connections=12, max_connections_per_address=4,
                 header_timeout=1.0) as (url, front, listener, lines):
        port = int(url.rsplit(':', 1)[1])

        async def main():
            held = []
            for addr in extra_loopbacks:            # unfinished upgrade requests, 10 per address
                for _ in range(10):
                    r, w = await asyncio.open_connection('127.0.0.1', port, local_addr=(addr, 0))
                    w.write(b'GET / HTTP/1.1\r\nHost: x\r\nUpgrade: web')
                    held.append((r, w))
            sessions = []                           # and full WebSocket sessions, 6 per address
            for addr in extra_loopbacks:
                for _ in range(6):
                    s = session(addr)
                    sessions.append(s)
                    with contextlib.suppress(aiohttp.ClientError, asyncio.TimeoutError):
                        await connect(s, url)
            async with Operator(url) as op:
                assert front.relay.guard.connections_of('127.0.0.2') <= 4
                assert await op.receives()
                # the unfinished requests are closed by the header time-out
                for r, w in held:
                    with contextlib.suppress(ConnectionError, asyncio.TimeoutError):
                        assert await asyncio.wait_for(r.read(), 5) == b''
                    w.close()
                assert await op.receives()
            for s in sessions:
                await s.close()
        asyncio.run(main())
        c = front.counters()
        assert c['connections_refused'] >= 10 and c['header_timeouts'] >= 1, c


def test_a_client_that_never_reads_neither_grows_memory_nor_stalls_the_others():
    """/fast carries ~200 x 20 kB messages/s; a client subscribed to it reads nothing for
    10 s (tens of MB sent its way): the process grows by the bounded queues only (the
    SDK's backlog of 64 messages, the relay's and the kernel's buffers: a few MB), and
    the operator keeps receiving."""
    size, bound = 20000, 12 * 2**20
    with serving(message_backlog=64, payload_bytes=size) as (url, front, listener, lines):
        port = int(url.rsplit(':', 1)[1])

        async def main():
            r, w = await raw_session(port)
            w.transport.pause_reading()             # the kernel's receive buffer fills, then nothing
            async with Operator(url) as op:
                sub = {'op': 'subscribe', 'subscriptions': [{'id': 9, 'channelId': op.fast}]}
                w.write(masked_frame(1, json.dumps(sub).encode()))
                deadline = time.monotonic() + 5
                while listener.subscribed.count('/fast') < 2 and time.monotonic() < deadline:
                    await asyncio.sleep(0.05)
                assert listener.subscribed.count('/fast') == 2       # the reader that never reads
                proc = psutil.Process()
                await asyncio.sleep(0.5)
                rss0, logged0, t0, n0 = proc.memory_info().rss, front.logged, time.monotonic(), op.received
                while time.monotonic() - t0 < 10.0:
                    await asyncio.sleep(0.5)
                    assert proc.memory_info().rss - rss0 < bound, proc.memory_info().rss - rss0
                sent = (front.logged - logged0) * size
                assert sent > 2 * bound, f'only {sent} bytes logged: the test proves nothing'
                assert (op.received - n0) > 0.5 * (front.logged - logged0), (op.received - n0, front.logged - logged0)
                assert await op.receives()
            w.close()
        asyncio.run(main())


# ------------------------------------------------------------------ the frame parser alone
def test_frames_are_parsed_across_any_split_and_text_is_unmasked():
    msgs = (masked_frame(1, b'{"op":"subscribe"}') + masked_frame(2, b'\x01abc')
            + masked_frame(1, b'{"op":', fin=False) + masked_frame(9, b'hi') + masked_frame(0, b'"advertise"}')
            + masked_frame(1, b'x' * 300))
    whole = ClientFrames(1000).feed(msgs)
    assert whole == [(1, b'{"op":"subscribe"}'), (2, b''), (9, b'hi'), (1, b'{"op":"advertise"}'), (1, b'x' * 300)]
    for step in (1, 2, 3, 7):
        p = ClientFrames(1000)
        got = [m for i in range(0, len(msgs), step) for m in p.feed(msgs[i:i + step])]
        assert got == whole
    assert [publish_attempt(op, b) for op, b in whole] == [False, True, False, True, False]
    with pytest.raises(FrameError) as e:
        ClientFrames(100).feed(masked_frame(1, b'a' * 60, fin=False) + masked_frame(0, b'a' * 60)[:6])
    assert e.value.code == 1009
    assert close_frame(1009, 'too big')[:4] == b'\x88\x09\x03\xf1'


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400), st.integers(1, 64))
def test_any_bytes_are_messages_or_a_frame_error(data, step):
    p = ClientFrames(256)
    try:
        for i in range(0, len(data), step):
            for op, payload in p.feed(data[i:i + step]):
                assert op in (1, 2, 8, 9, 10) and len(payload) <= 256
                publish_attempt(op, payload)
    except FrameError as exc:
        assert exc.code in (1002, 1009) and exc.reason
