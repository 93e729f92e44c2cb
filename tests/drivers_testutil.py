"""Helpers shared by the sslfr_drivers unit tests (imported as a plain module: pytest
puts this directory on sys.path)."""
from __future__ import annotations

import time


def wait_for(pred, timeout: float, step: float = 0.01) -> bool:
    """Poll ``pred()`` every ``step`` [s] until it is true or ``timeout`` [s, monotonic]
    has passed; return its last value."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(step)
    return pred()


class RawHost:
    """A minimal host on a board's pty, for protocol tests of the simulators and the
    firmware: it opens a session (:meth:`hello`), sends frames with chosen sequence
    number / version / payload / tag, and returns what the board sends. No retries, no
    link logic. A frame from the board is *verified* when its tag checks in the session
    or the null session (:attr:`unverified` counts the others; :meth:`answer` only
    returns verified answers).

    Parameters
    ----------
    path : str
        The board's pty.
    key : bytes or None
        The key the host uses (None: the null key of unprovisioned boards).
    auto_session : bool
        Open a session (:meth:`hello`) before the first request sent without one.
    flush : bool
        Discard what the board sent before the port was opened (False: keep its BOOT).
    """

    def __init__(self, path: str, key: bytes | None = None, auto_session: bool = False, flush: bool = True):
        import os
        import termios
        import threading
        import tty
        from sslfr_drivers.link.auth import NULL_KEY, Session
        from sslfr_drivers.link.protocol import Framer, SequenceCounter, SequenceTracker
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        tty.setraw(self.fd)
        termios.tcflush(self.fd, termios.TCIOFLUSH if flush else termios.TCOFLUSH)
        self.key = key if key is not None else NULL_KEY
        self.null = Session(self.key)
        self.session = None
        self.framer = Framer()
        self.tx = SequenceCounter(1)
        self.null_tx = SequenceCounter(1)
        self.rx = SequenceTracker()
        self.seq = 0                 # the last sequence number sent in the session
        self.received = []           # verified frames
        self.unverified = 0
        self.boot_count = None
        self.auto_session = auto_session
        self._lock = threading.Lock()

    # ---------------------------------------------------------------- sending
    def send_raw(self, data: bytes) -> None:
        import os
        os.write(self.fd, data)

    def frame(self, msg=None, seq: int | None = None, version: int | None = None, payload: bytes | None = None,
              mtype: int | None = None, session=None, tag: bytes | None = None):
        """The wire bytes of a request and its sequence number (see :meth:`send`)."""
        from sslfr_drivers.link.auth import HOST_TO_BOARD
        from sslfr_drivers.link.protocol import PROTOCOL_V1, PROTOCOL_VERSION, Frame, encode_frame
        version = PROTOCOL_VERSION if version is None else version
        mtype = msg.TYPE if mtype is None else mtype
        payload = msg.pack() if payload is None else payload
        sess = session or self.session or self.null
        if seq is None:
            full = (self.null_tx if sess.is_null else self.tx).next_full()
        else:
            full = seq
        f = Frame(mtype, full & 0xFFFF, payload, 0, 0, version, None if version != PROTOCOL_V1 else b'')
        if version == PROTOCOL_VERSION:
            f = sess.seal(HOST_TO_BOARD, full, f)
            if tag is not None:
                f = Frame(f.type, f.seq, f.payload, f.ref, f.flags, f.version, tag)
        if not sess.is_null:
            self.seq = full & 0xFFFF
        return encode_frame(f), full & 0xFFFF

    def send(self, msg=None, seq: int | None = None, version: int | None = None, payload: bytes | None = None,
             mtype: int | None = None, session=None, tag: bytes | None = None) -> int:
        """Send ``msg`` (or ``mtype`` + ``payload``) tagged in the session (``session``
        given: in that one; none yet: the null session), sequence number ``seq``
        (default: the next one), ``tag`` replacing the computed tag (a forgery),
        ``version`` 1 for an untagged version-1 frame. Returns the sequence number."""
        from sslfr_drivers.link import messages as m
        if self.auto_session and self.session is None and session is None and mtype is None \
                and not isinstance(msg, (m.Hello, m.Provision)):
            # a host retries: a board just reset may still be starting (a loaded machine
            # slows the simulated one down)
            if all(self.hello() is None for _ in range(3)):
                raise AssertionError('the board does not answer HELLO')
        with self._lock:
            data, seq = self.frame(msg, seq, version, payload, mtype, session, tag)
            self.send_raw(data)
        return seq

    def hello(self, timeout: float = 2.0, nonce: bytes | None = None):
        """Open a session: HELLO in the null session, the HELLO_REPLY verified; returns
        the reply (None: no valid reply in ``timeout`` s; the session is then None)."""
        import os
        import time
        from sslfr_drivers.link import messages as m
        from sslfr_drivers.link.auth import BOARD_TO_HOST, Session
        from sslfr_drivers.link.protocol import SequenceCounter, SequenceTracker
        nonce = nonce or os.urandom(8)
        seq = self.send(m.Hello(nonce), session=self.null)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for f in self._read(0.02):
                if f.is_response and f.ref == seq and f.type == m.HelloReply.TYPE:
                    reply = m.decode(f)
                    cand = Session(self.key, nonce, reply.nonce)
                    if cand.verify(BOARD_TO_HOST, f.seq, f):
                        self.session, self.tx, self.rx = cand, SequenceCounter(), SequenceTracker()
                        self.rx.accept(f.seq)
                        self.boot_count = reply.boot_count
                        return reply
                self._verify(f)
        self.session = None
        return None

    # ---------------------------------------------------------------- receiving
    def _read(self, timeout: float) -> list:
        import os
        import select
        r, _, _ = select.select([self.fd], [], [], max(0.0, timeout))
        if not r:
            return []
        try:
            return self.framer.feed(os.read(self.fd, 4096))
        except BlockingIOError:
            return []

    def _verify(self, f) -> bool:
        from sslfr_drivers.link.auth import BOARD_TO_HOST
        from sslfr_drivers.link.protocol import PROTOCOL_VERSION
        if f.version != PROTOCOL_VERSION:
            self.received.append(f)            # a version-1 frame: nothing to verify
            return True
        if self.session is not None and self.session.verify(BOARD_TO_HOST, self.rx.expand(f.seq), f):
            self.rx.accept(f.seq)
            self.received.append(f)
            return True
        if self.null.verify(BOARD_TO_HOST, f.seq, f):
            self.received.append(f)
            if f.type == 0x84 and self.auto_session:    # BOOT: the board lost the session
                self.session = None
            return True
        self.unverified += 1
        return False

    def poll(self, timeout: float = 0.0) -> list:
        """Verified frames received within ``timeout`` s."""
        import time
        deadline = time.monotonic() + timeout
        out = []
        while True:
            out += [f for f in self._read(deadline - time.monotonic()) if self._verify(f)]
            if time.monotonic() >= deadline:
                break
        return out

    def answer(self, seq: int, timeout: float = 2.0):
        """The decoded verified answer to request ``seq`` (None if none in ``timeout`` s)."""
        import time
        from sslfr_drivers.link import messages as m
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for f in self.poll(0.02):
                if f.is_response and f.ref == seq:
                    return m.decode(f)
        return None

    def request(self, msg, **kw):
        return self.answer(self.send(msg, **kw))

    def heartbeat(self, period: float = 0.25) -> 'RawHost':
        """PING every ``period`` s from a thread (keeps the 1 s board watchdog quiet)."""
        import threading
        from sslfr_drivers.link import messages as m
        self._beat = threading.Event()
        self.beat_paused = threading.Event()

        def run():
            while not self._beat.wait(period):
                if self.beat_paused.is_set() or self.session is None:
                    continue
                try:
                    self.send(m.Ping(0))
                except OSError:
                    return
        threading.Thread(target=run, daemon=True).start()
        return self

    def stop_heartbeat(self) -> None:
        if getattr(self, '_beat', None):
            self._beat.set()

    def close(self) -> None:
        import os
        if getattr(self, '_beat', None):
            self._beat.set()
        os.close(self.fd)


def open_session(board, key: bytes | None = None):
    """Open a session with a simulated board in-process (bytes, no pty): HELLO, its
    HELLO_REPLY, one PING in the new session; returns the host's
    :class:`~sslfr_drivers.link.auth.Session`. Boards send samples only in a session."""
    import os
    from sslfr_drivers.link import messages as m
    from sslfr_drivers.link.auth import BOARD_TO_HOST, HOST_TO_BOARD, NULL_KEY, Session
    from sslfr_drivers.link.protocol import Framer, encode_frame
    key = key if key is not None else NULL_KEY
    nonce = os.urandom(8)
    board.receive(encode_frame(Session(key).seal(HOST_TO_BOARD, 1, m.encode(m.Hello(nonce), 1))))
    for f in Framer().feed(board.take_output()):
        if f.type == m.HelloReply.TYPE:
            s = Session(key, nonce, m.decode(f).nonce)
            assert s.verify(BOARD_TO_HOST, f.seq, f)
            board.receive(encode_frame(s.seal(HOST_TO_BOARD, 0, m.encode(m.Ping(0), 0))))
            board.take_output()
            return s
    raise AssertionError('the board did not answer HELLO')
