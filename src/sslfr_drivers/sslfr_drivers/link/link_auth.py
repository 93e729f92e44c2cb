"""The board link's authenticated session (protocol version 2, docs/protocol.md
"Authentication"): HELLO / HELLO_REPLY opens a session (link/auth.py), requests are
sealed in it, and a board frame is used only when its tag verifies in the session and
its sequence number is new. Everything else is dropped and counted on the link
(``auth_failures``: forged, damaged, another key, another session; ``stale``: replayed
or late; ``out_of_session``: the board's own frames of no session, BOOT / NO_SESSION,
which only make the link check for a board reboot)."""
from __future__ import annotations

import logging
import os
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.auth import BOARD_TO_HOST, HOST_TO_BOARD, NONCE_SIZE, NULL_KEY, NULL_NONCE, Session, key_id
from sslfr_drivers.link.link_errors import LinkDown, LinkTimeout, NoSession
from sslfr_drivers.link.link_state import BoardLinkState
from sslfr_drivers.link.protocol import (PROTOCOL_V1, PROTOCOL_VERSION, Frame, PayloadError, ProtocolVersionError,
                                         SequenceCounter, SequenceTracker, encode_frame)
from sslfr_drivers.link.requests import Pending

_log = logging.getLogger('sslfr_drivers.link.board_link')


class LinkAuth:
    """Keys, the session in use and its sequence numbers for ``link`` (the
    :class:`~.board_link.BoardLink` it is part of); seals the host's frames and sorts
    the board's (:meth:`on_frame`).

    key : bytes or None
        The installation key (16 bytes); None: the null key of unprovisioned boards.
    """

    def __init__(self, link, key: bytes | None):
        self.link = link
        self.key = bytes(key) if key is not None else NULL_KEY
        if len(self.key) != 16:
            raise ValueError(f'{link.name}: the key must be 16 bytes')
        self.null = Session(self.key)                 # HELLO, the board's BOOT / NO_SESSION
        self.unprovisioned = Session(NULL_KEY) if self.key != NULL_KEY else None
        self.session: Session | None = None
        self.null_seq = SequenceCounter()
        self.seq = SequenceCounter()
        self.tracker = SequenceTracker()

    def seal(self, msg: m.Message) -> tuple[int, bytes]:
        """``(full sequence number, wire bytes)`` of ``msg`` in the session (the caller
        holds the link's locks and checked that a session exists)."""
        full = self.seq.next_full()
        return full, encode_frame(self.session.seal(HOST_TO_BOARD, full, m.encode(msg, 0)))

    # ------------------------------------------------ handshake (refresh thread)
    def null_request(self, msg: m.Message, version: int = PROTOCOL_VERSION, adopt: bool = True):
        """Send ``msg`` outside any session (HELLO in the null session, or a version-1
        GET_INFO) and wait for its answer (the usual time-out and retries)."""
        link = self.link
        fut: Future = Future()
        if not link.connected:
            raise LinkDown(f'{link.name}: port not open ({link.last_error})')
        seq = self.null_seq.next()
        if version == PROTOCOL_VERSION:
            frame = self.null.seal(HOST_TO_BOARD, seq, m.encode(msg, seq))
        else:
            frame = Frame(msg.TYPE, seq, msg.pack(), version=version)
        data = encode_frame(frame)
        p = Pending(('n', seq), msg, data, fut, link.timeout, link.retries, link.clock() + link.timeout,
                    nonce=getattr(msg, 'nonce', b''), adopt=adopt)
        link.requests.add(p)
        link.write(data, p)
        try:
            return fut.result(timeout=link.timeout * (link.retries + 1) + 1.0)
        except FutureTimeout:
            raise LinkTimeout(f'{link.name}: no answer to {type(msg).__name__}') from None

    def handshake(self, adopt: bool = True) -> m.HelloReply:
        """HELLO with a fresh host nonce; the board's HELLO_REPLY (adopted if ``adopt``)."""
        nonce = NULL_NONCE
        while nonce == NULL_NONCE:
            nonce = os.urandom(NONCE_SIZE)
        return self.null_request(m.Hello(nonce), adopt=adopt)

    # ------------------------------------------------------- frames (reader thread)
    def on_frame(self, frame: Frame, now: float) -> None:
        """Sort one board frame: of the session (handed to the link), the reply to our
        HELLO, the board's own of no session, another protocol version, or forged."""
        link = self.link
        if frame.version != PROTOCOL_VERSION:
            self._foreign_frame(frame)
            return
        session = self.session
        if session is not None:
            full = self.tracker.expand(frame.seq)
            if session.verify(BOARD_TO_HOST, full, frame):
                link.session_frame(frame, full, now)
                return
        hello = link.requests.get(('n', frame.ref)) if frame.is_response else None
        if hello is not None and isinstance(hello.msg, m.Hello) and frame.type == m.HelloReply.TYPE:
            if self._hello_reply(hello, frame):
                return
        if self.null.verify(BOARD_TO_HOST, frame.seq, frame):
            link.out_of_session += 1
            link.states.heard_no_session(now)
            return
        link.auth_failures += 1
        if hello is not None and isinstance(hello.msg, m.Hello) and frame.type == m.Nack.TYPE:
            hello.refused = self._refusal(frame)

    def _refusal(self, frame: Frame) -> str:
        """Why the board answered our HELLO with a frame we cannot verify."""
        name = self.link.name
        if self.unprovisioned is not None and self.unprovisioned.verify(BOARD_TO_HOST, frame.seq, frame):
            return (f'{name}: the board is not provisioned (it has no installation key): '
                    'provision it over its USB port: sslfr keys provision BOARD --port PORT')
        if self.key == NULL_KEY:
            return (f'{name}: the board is provisioned with an installation key and this '
                    'host has none: set the key_file parameter to the installation key file')
        return (f'{name}: the board does not accept this host\'s key (key id '
                f'{key_id(self.key)}): it was provisioned with another key; use the '
                'installation\'s key file or provision the board again over USB')

    def _foreign_frame(self, frame: Frame) -> None:
        """A frame of another protocol version: a version-1 INFO answering our version-1
        GET_INFO is read (it names the board); anything else refuses the board."""
        link = self.link
        p = link.requests.get(('n', frame.ref)) if frame.is_response else None
        if p is not None and frame.version == PROTOCOL_V1 and frame.type == m.Info.TYPE:
            try:
                info = m.decode(frame)
            except PayloadError as exc:
                link.requests.resolve(p.key, exc=exc)
                return
            link.info = info
            link.requests.resolve(p.key, result=info)
            return
        link.version_errors += 1
        link.version_error = ProtocolVersionError(frame.version)
        link.last_error = str(link.version_error)
        self.session = None
        if link.states.state != BoardLinkState.REFUSED:
            _log.error('%s: %s', link.name, link.version_error, extra=link.log_extra)
        link.requests.fail_all(link.version_error)
        link.states.set(BoardLinkState.REFUSED, str(link.version_error))

    def _hello_reply(self, hello: Pending, frame: Frame) -> bool:
        """A HELLO_REPLY to our HELLO: True when it verifies in the session it opens
        (then adopted if the HELLO says so, and the HELLO answered)."""
        try:
            reply = m.decode(frame)
        except PayloadError:
            return False
        candidate = Session(self.key, hello.nonce, reply.nonce)
        if not candidate.verify(BOARD_TO_HOST, frame.seq, frame):
            return False
        if hello.adopt:
            self._adopt(candidate, reply, frame)
        self.link.requests.resolve(hello.key, result=reply)
        return True

    def _adopt(self, session: Session, reply: m.HelloReply, frame: Frame) -> None:
        """Use ``session`` from now on (reader thread). Requests still waiting for an
        answer in the previous session are sent again in the new one (new sequence
        numbers: the board cannot answer them otherwise), except RESET (never twice) and
        except after a board reset (a changed boot count: the board lost its position,
        its owner must re-reference it before moving: they end with NoSession)."""
        link = self.link
        rebooted = link.boot_count is not None and reply.boot_count != link.boot_count
        with link.tx_lock:
            with link.requests.lock:
                self.session = session
                self.seq = SequenceCounter()
                self.tracker.restart()
                self.tracker.accept(frame.seq)
                old = link.requests.take_session()
                moved = []
                for p in old:
                    if isinstance(p.msg, m.Reset) or rebooted:
                        continue
                    full, p.data = self.seal(p.msg)
                    p.key = full & 0xFFFF
                    p.deadline = link.clock() + p.timeout
                    link.requests.add(p)
                    moved.append(p)
            for p in moved:
                link.write(p.data, p)
        kept = {id(p) for p in moved}
        for p in old:
            if id(p) not in kept and not p.future.done():
                p.future.set_exception(NoSession(f'{link.name}: new session with the board'
                                                 + (' (it was reset)' if rebooted else '')))
        link.sessions += 1
        link.auth_error = ''
        link.version_error = None
        link.beat.last_rx = link.clock()
        link.states.boot_count(reply.boot_count, in_session=True)
