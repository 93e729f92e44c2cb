"""Operator authentication for the page (pure Python, standard library only).

- **Password**: stored as a scrypt hash (``hashlib.scrypt``, RFC 7914; N = 2^14,
  r = 8, p = 1, 16-byte random salt, 32-byte key: ~16 MiB and ~50 ms per try on a
  PC, a few hundred ms on a Raspberry Pi, which is what makes guessing slow) in one
  line ``scrypt$N$r$p$salt$key`` (base64), file mode 0600. Compared in constant time.
- **Sessions**: a random 256-bit token in a cookie (HttpOnly, SameSite=Strict, set by
  the app), kept server-side with its own random CSRF token, the client address and
  the last use; it ends after ``timeout`` s without a request or at logout.
- **CSRF**: every command must carry the session's CSRF token (header
  ``X-CSRF-Token``); a cross-site page can neither read it nor (SameSite=Strict) send
  the cookie.
- **Login rate limit** (:class:`LoginLimiter`): every attempt is counted before its
  password is checked; an address with ``max_failures`` in a sliding ``window`` is
  locked out (refused without checking the password) for a lockout that doubles at
  each repetition. A global limit of 10x bounds a distributed guess from outside the
  trusted networks (loopback and the collector's own segment), which it never locks
  out; ``./sslfr web-password --unlock`` ends every lockout.

Times are ``time.monotonic()`` seconds unless a clock is given (tests).
"""
from __future__ import annotations

import base64
import hashlib
import hmac
import os
import secrets
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from sslfr_common.files import atomic_write, user_path

SCRYPT_N, SCRYPT_R, SCRYPT_P, KEY_LEN, SALT_LEN = 2 ** 14, 8, 1, 32, 16
MIN_PASSWORD_LEN = 8


class PasswordError(ValueError):
    """A password or a password file that cannot be used (message says why)."""


def _b64(b: bytes) -> str:
    return base64.b64encode(b).decode('ascii')


def _scrypt(password: str, salt: bytes, n: int, r: int, p: int, dklen: int) -> bytes:
    return hashlib.scrypt(password.encode('utf-8'), salt=salt, n=n, r=r, p=p, dklen=dklen,
                          maxmem=256 * 1024 * 1024)


def hash_password(password: str, *, n: int = SCRYPT_N, r: int = SCRYPT_R, p: int = SCRYPT_P,
                  salt: bytes | None = None) -> str:
    """The stored form ``scrypt$N$r$p$salt$key`` of ``password`` (a new salt each call)."""
    check_new_password(password)
    salt = os.urandom(SALT_LEN) if salt is None else salt
    key = _scrypt(password, salt, n, r, p, KEY_LEN)
    return f'scrypt${n}${r}${p}${_b64(salt)}${_b64(key)}'


def check_new_password(password: str) -> None:
    """Refuse passwords an installer should not set (too short, blank, control chars)."""
    if not isinstance(password, str) or len(password) < MIN_PASSWORD_LEN:
        raise PasswordError(f'the password must have at least {MIN_PASSWORD_LEN} characters')
    if not password.strip():
        raise PasswordError('the password cannot be blank')
    if any(ord(c) < 32 for c in password):
        raise PasswordError('the password cannot contain control characters')


def parse_hash(stored: str) -> tuple[int, int, int, bytes, bytes]:
    """``scrypt$N$r$p$salt$key`` -> (N, r, p, salt, key); PasswordError if malformed."""
    parts = stored.strip().split('$')
    if len(parts) != 6 or parts[0] != 'scrypt':
        raise PasswordError('not an scrypt password line (expected scrypt$N$r$p$salt$key)')
    try:
        n, r, p = int(parts[1]), int(parts[2]), int(parts[3])
        salt, key = base64.b64decode(parts[4], validate=True), base64.b64decode(parts[5], validate=True)
    except ValueError as exc:
        raise PasswordError(f'malformed scrypt password line: {exc}') from exc
    if n < 2 or n & (n - 1) or not 1 <= r <= 64 or not 1 <= p <= 16 or len(salt) < 8 or len(key) < 16:
        raise PasswordError('scrypt parameters out of range in the password line')
    return n, r, p, salt, key


def verify_password(password: str, stored: str) -> bool:
    """True when ``password`` matches the stored line (constant-time comparison)."""
    n, r, p, salt, key = parse_hash(stored)
    if not isinstance(password, str) or len(password) > 1024:
        return False
    return hmac.compare_digest(_scrypt(password, salt, n, r, p, len(key)), key)


def write_password_file(path: str | os.PathLike, password: str) -> Path:
    """Hash ``password`` and write it to ``path`` atomically with mode 0600."""
    line = hash_password(password)
    p = user_path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(p, line + '\n', mode=0o600)


class PasswordFile:
    """The operator password file, re-read when its mtime or size changes."""

    def __init__(self, path: str | os.PathLike):
        self.path = user_path(path)
        self._stamp: tuple | None = None
        self._line: str | None = None
        self.problem = ''

    def line(self) -> str | None:
        """The stored hash line, or None (``problem`` says why: missing, malformed)."""
        try:
            st = self.path.stat()
        except OSError:
            self._stamp, self._line = None, None
            self.problem = f'no operator password set ({self.path} missing): run ./sslfr web-password'
            return None
        stamp = (st.st_mtime_ns, st.st_size)
        if stamp != self._stamp:
            self._stamp = stamp
            try:
                text = self.path.read_text(encoding='utf-8').strip()
                parse_hash(text)
                self._line, self.problem = text, ''
            except (OSError, UnicodeDecodeError, PasswordError) as exc:
                self._line = None
                self.problem = f'password file {self.path} unusable ({exc}): run ./sslfr web-password'
        return self._line


@dataclass
class Session:
    token: str
    csrf: str
    origin: str
    created: float
    last_seen: float


@dataclass
class SessionStore:
    """Server-side sessions: token -> :class:`Session`, with idle expiry."""

    timeout: float = 3600.0
    clock: Callable[[], float] = time.monotonic
    max_sessions: int = 64
    _sessions: dict = field(default_factory=dict)

    def create(self, origin: str) -> Session:
        self.expire()
        while len(self._sessions) >= self.max_sessions:      # drop the least recently used
            oldest = min(self._sessions.values(), key=lambda s: s.last_seen)
            del self._sessions[oldest.token]
        now = self.clock()
        s = Session(secrets.token_urlsafe(32), secrets.token_urlsafe(32), origin, now, now)
        self._sessions[s.token] = s
        return s

    def get(self, token: str | None) -> Session | None:
        """The live session of ``token`` (its idle timer restarts), else None."""
        if not token or not isinstance(token, str):
            return None
        s = self._sessions.get(token)
        if s is None:
            return None
        now = self.clock()
        if now - s.last_seen > self.timeout:
            del self._sessions[token]
            return None
        s.last_seen = now
        return s

    def check_csrf(self, session: Session | None, token: str | None) -> bool:
        return bool(session and token and hmac.compare_digest(session.csrf.encode(), str(token).encode()))

    def end(self, token: str | None) -> None:
        self._sessions.pop(token or '', None)

    def expire(self) -> None:
        now = self.clock()
        for tok in [t for t, s in self._sessions.items() if now - s.last_seen > self.timeout]:
            del self._sessions[tok]

    def __len__(self) -> int:
        return len(self._sessions)


@dataclass
class _AddrState:
    failures: deque = field(default_factory=deque)   # times of counted attempts in the window
    locked_until: float = 0.0
    strikes: int = 0                                # lockouts so far (the back-off doubles each)
    last: float = 0.0                               # last counted attempt


class LoginLimiter:
    """Failed-login limits: per client address with a growing lockout, and in all
    for addresses outside the trusted networks.

    An attempt is counted *before* its password is checked (:meth:`attempt`), so
    attempts sent at once cannot pass the check together; a right password takes
    its own count back (:meth:`success`). When an address reaches ``max_failures``
    in ``window`` s it is locked out for ``lockout`` s, doubled at each further
    lockout up to ``lockout_max`` (forgotten after a success, or ``lockout_max`` +
    ``window`` s without an attempt). The global limit (``global_factor`` x
    ``max_failures`` in ``window``) counts and refuses only addresses outside
    ``trusted(addr)``: a flood from elsewhere never locks out the collector's own
    network segment or its console (loopback). :meth:`clear` (``./sslfr
    web-password --unlock``) ends every lockout.
    """

    def __init__(self, max_failures: int = 5, window: float = 300.0,
                 clock: Callable[[], float] = time.monotonic, global_factor: int = 10,
                 lockout: float | None = None, lockout_max: float | None = None,
                 trusted: Callable[[str], bool] = lambda addr: False, max_addresses: int = 10000):
        self.max_failures, self.window, self.clock = int(max_failures), float(window), clock
        self.lockout = float(window if lockout is None else lockout)
        self.lockout_max = max(self.lockout, float(self.lockout * 64 if lockout_max is None else lockout_max))
        self.global_max = int(max_failures) * global_factor
        self.trusted, self.max_addresses = trusted, int(max_addresses)
        self._by_addr: dict[str, _AddrState] = {}
        self._all: deque = deque()

    def _prune(self, q: deque, now: float) -> None:
        while q and now - q[0] >= self.window:
            q.popleft()

    def _state(self, addr: str, now: float, create: bool = False) -> _AddrState | None:
        st = self._by_addr.get(addr)
        if st is not None:
            self._prune(st.failures, now)
            if st.strikes and now - max(st.last, st.locked_until) > self.lockout_max + self.window:
                st.strikes = 0
            if not st.failures and not st.strikes and now >= st.locked_until:
                del self._by_addr[addr]
                st = None
        if st is None and create:
            if len(self._by_addr) >= self.max_addresses:          # bounded memory under a flood
                free = [a for a, s in self._by_addr.items() if s.locked_until <= now]
                for a in (free or list(self._by_addr))[:max(1, self.max_addresses // 2)]:
                    del self._by_addr[a]
            st = self._by_addr[addr] = _AddrState()
        return st

    def retry_after(self, addr: str) -> float:
        """0 when ``addr`` may try now, else the seconds until it may."""
        now = self.clock()
        waits = [0.0]
        if not self.trusted(addr):
            self._prune(self._all, now)
            if len(self._all) >= self.global_max:
                waits.append(self.window - (now - self._all[0]))
        st = self._state(addr, now)
        if st is not None and st.locked_until > now:
            waits.append(st.locked_until - now)
        return max(waits)

    def attempt(self, addr: str) -> tuple[float, float | None]:
        """Check and count one login attempt of ``addr`` at once (no await between):
        (0, ticket) when it may go on, its ticket for :meth:`success`; (wait, None)
        when it is refused for ``wait`` s."""
        wait = self.retry_after(addr)
        if wait > 0:
            return wait, None
        now = self.clock()
        st = self._state(addr, now, create=True)
        st.failures.append(now)
        st.last = now
        if not self.trusted(addr):
            self._all.append(now)
        if len(st.failures) >= self.max_failures:
            st.locked_until = now + min(self.lockout * 2 ** min(st.strikes, 30), self.lockout_max)
            st.strikes += 1
            st.failures.clear()
        return 0.0, now

    def failure(self, addr: str) -> None:
        """Count a failed attempt that was not counted by :meth:`attempt`."""
        self.attempt(addr)

    def success(self, addr: str, ticket: float | None = None) -> None:
        """A right password from ``addr``: its failures, lockout and strikes are gone,
        and its own attempt leaves the global count."""
        self._by_addr.pop(addr, None)
        if ticket is not None and not self.trusted(addr):
            try:
                self._all.remove(ticket)
            except ValueError:
                pass

    def clear(self) -> None:
        """End every lockout and forget every count (a local unlock)."""
        self._by_addr.clear()
        self._all.clear()

    def locked(self) -> dict[str, float]:
        """Address -> seconds left, of every address locked out now."""
        now = self.clock()
        return {a: s.locked_until - now for a, s in list(self._by_addr.items()) if s.locked_until > now}
