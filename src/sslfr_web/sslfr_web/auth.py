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
- **Login rate limit**: per client address, at most ``max_failures`` failed logins in
  a sliding ``window``; then refused (without even checking the password) until the
  oldest failure leaves the window. A global limit of 10x that bounds a distributed
  guess.

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

from sslfr_common.files import atomic_write

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
    p = Path(path).expanduser()
    p.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(p, line + '\n', mode=0o600)


class PasswordFile:
    """The operator password file, re-read when its mtime or size changes."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path).expanduser()
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


class LoginLimiter:
    """Sliding-window limit of failed logins per client address (and in all)."""

    def __init__(self, max_failures: int = 5, window: float = 300.0,
                 clock: Callable[[], float] = time.monotonic, global_factor: int = 10):
        self.max_failures, self.window, self.clock = int(max_failures), float(window), clock
        self.global_max = int(max_failures) * global_factor
        self._by_addr: dict[str, deque] = {}
        self._all: deque = deque()

    def _prune(self, q: deque, now: float) -> None:
        while q and now - q[0] >= self.window:
            q.popleft()

    def retry_after(self, addr: str) -> float:
        """0 when ``addr`` may try now, else the seconds until it may."""
        now = self.clock()
        self._prune(self._all, now)
        waits = []
        if len(self._all) >= self.global_max:
            waits.append(self.window - (now - self._all[0]))
        q = self._by_addr.get(addr)
        if q is not None:
            self._prune(q, now)
            if not q:
                del self._by_addr[addr]
            elif len(q) >= self.max_failures:
                waits.append(self.window - (now - q[0]))
        return max(waits) if waits else 0.0

    def failure(self, addr: str) -> None:
        now = self.clock()
        self._by_addr.setdefault(addr, deque()).append(now)
        self._all.append(now)
        if len(self._by_addr) > 10000:                       # bounded memory under a flood
            for a in list(self._by_addr)[:5000]:
                del self._by_addr[a]

    def success(self, addr: str) -> None:
        self._by_addr.pop(addr, None)
