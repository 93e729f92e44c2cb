"""Requests waiting for a board's answer (no I/O): matched to answers by sequence
number, retried unanswered with the SAME number (the board answers a duplicate from
its cache and does not execute it twice), ended by the answer or an error."""
from __future__ import annotations

import math
import threading
from concurrent.futures import Future
from dataclasses import dataclass

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.link_errors import AuthError, LinkTimeout, NackError

#: NACKs saying a frame with our number was refused (possibly a forged copy of our
#: request): the request stays pending, ours may still be answered (else it times out)
_REFUSALS = (m.ErrorCode.AUTH, m.ErrorCode.REPLAY, m.ErrorCode.NO_SESSION)


@dataclass
class Pending:
    key: object          # seq (session requests) or ('n', seq) (HELLO, version-1 GET_INFO)
    msg: m.Message
    data: bytes
    future: Future
    timeout: float
    retries_left: int
    deadline: float
    nonce: bytes = b''   # HELLO: the host nonce Nh
    adopt: bool = True   # HELLO: start using the new session when it is answered
    refused: str = ''    # HELLO: why the board refused it (the error if no reply comes)


class RequestTable:
    """The requests of one link waiting for an answer, by key (see :class:`Pending`).

    ``lock`` (re-entrant) guards the table; the link also holds it while it numbers a
    request or changes its session, so that a request and its number go together.
    """

    def __init__(self, name: str):
        self.name = name
        self.lock = threading.RLock()
        self._pending: dict[object, Pending] = {}
        self.timeouts = 0
        self.retries_sent = 0
        self.nacks = 0
        self.auth_refusals = 0

    def add(self, p: Pending) -> None:
        with self.lock:
            self._pending[p.key] = p

    def get(self, key) -> Pending | None:
        with self.lock:
            return self._pending.get(key)

    def resolve(self, key, result=None, exc: BaseException | None = None) -> None:
        """End the request ``key`` with ``result`` or ``exc`` (nothing if gone or done)."""
        with self.lock:
            p = self._pending.pop(key, None)
        if p is None or p.future.done():
            return
        if exc is not None:
            p.future.set_exception(exc)
        else:
            p.future.set_result(result)

    def fail_all(self, exc: BaseException, session_only: bool = False) -> None:
        """End every request (``session_only``: not HELLO / version-1 GET_INFO) with ``exc``."""
        with self.lock:
            keys = [k for k in self._pending if not (session_only and isinstance(k, tuple))]
        for k in keys:
            self.resolve(k, exc=exc)

    def take_session(self) -> list[Pending]:
        """Remove and return the requests of the session (a new session renumbers them)."""
        with self.lock:
            old = [p for k, p in self._pending.items() if not isinstance(k, tuple)]
            for p in old:
                del self._pending[p.key]
        return old

    def answer(self, p: Pending | None, msg: m.Message) -> None:
        """The board's authenticated new frame ``msg`` answering ``p`` (None: answers
        nothing): ``p`` ends with it, or with :class:`NackError` for a NACK (counted),
        except a refusal (``_REFUSALS``, counted in ``auth_refusals`` like an AUTH or
        REPLAY NACK answering nothing)."""
        if p is not None:
            if isinstance(msg, m.Nack):
                self.nacks += 1
                if msg.code in _REFUSALS:
                    self.auth_refusals += 1
                else:
                    self.resolve(p.key, exc=NackError(msg.request_type, msg.code))
            else:
                self.resolve(p.key, result=msg)
        elif isinstance(msg, m.Nack) and msg.code in (m.ErrorCode.AUTH, m.ErrorCode.REPLAY):
            self.auth_refusals += 1

    def due(self, now: float) -> tuple[list[Pending], list[Pending]]:
        """``(resend, expired)`` at steady ``now`` [s]: past their deadline, those with a
        try left get a new deadline (and a count in ``retries_sent``), the others expire."""
        expired: list[Pending] = []
        resend: list[Pending] = []
        with self.lock:
            for p in self._pending.values():
                if now >= p.deadline:
                    if p.retries_left > 0:
                        p.retries_left -= 1
                        p.deadline = now + p.timeout
                        resend.append(p)
                    else:
                        expired.append(p)
        self.retries_sent += len(resend)
        return resend, expired

    def expire(self, p: Pending) -> None:
        """End an expired request: :class:`AuthError` for a HELLO the board refused,
        else :class:`LinkTimeout` (counted in ``timeouts``)."""
        if p.refused:
            self.resolve(p.key, exc=AuthError(p.refused))
            return
        self.timeouts += 1
        self.resolve(p.key, exc=LinkTimeout(
            f'{self.name}: no answer to {type(p.msg).__name__} (seq {p.data[5] | p.data[6] << 8})'))

    def next_deadline(self) -> float:
        """The first deadline [s, steady], inf when nothing waits."""
        with self.lock:
            return min((p.deadline for p in self._pending.values()), default=math.inf)
