"""The installation key file (docs/deploy.md "Board keys"): create, check, read.
Pure Python, no rclpy.

One 128-bit key per installation authenticates every frame between the host and its
boards (link/auth.py). The file is text::

    # SSLFR installation key: keep it secret, back it up offline (docs/deploy.md)
    # key id 1a2b3c4d, created 2026-06-21T10:00:00Z
    5f1c0e...                       <- 32 hex digits

It must belong to the user running the nodes with mode 0600 (``sslfr keys new``
writes it so); :func:`load_key` refuses a file that others may read or that the
group or others may write, a null key and anything that is not exactly one key.
"""
from __future__ import annotations

import datetime as dt
import os
import stat
import tempfile
from pathlib import Path
from sslfr_common.files import user_path

from sslfr_common.params import ParamSpec
from sslfr_drivers.link.auth import NULL_KEY, key_id
from sslfr_drivers.link.siphash import KEY_SIZE

#: environment variable naming the key file of ``sslfr keys`` / ``sslfr flash``
KEY_FILE_ENV = 'SSLFR_KEY_FILE'


#: the node parameter naming the installation key file (every node with a board link)
KEY_FILE_PARAM = ParamSpec(
    'key_file', '', "installation key file of the board links (sslfr keys new; owner-only, mode 0600; "
    "docs/deploy.md 'Board keys'); '' = no key: only unprovisioned boards answer, nothing is "
    "authenticated [-]", read_only=True)


class KeyFileError(ValueError):
    """The key file cannot be used (message says why and what to do)."""


def default_key_path() -> Path:
    """``$SSLFR_KEY_FILE``, else ``$XDG_CONFIG_HOME/sslfr/installation.key`` (default
    ``~/.config/sslfr/installation.key``)."""
    env = os.environ.get(KEY_FILE_ENV)
    if env:
        return user_path(env)
    base = os.environ.get('XDG_CONFIG_HOME') or os.path.join(os.path.expanduser('~'), '.config')
    return Path(base) / 'sslfr' / 'installation.key'


def generate() -> bytes:
    """A fresh random key (os.urandom: the kernel's CSPRNG), never the null key."""
    while True:
        key = os.urandom(KEY_SIZE)
        if key != NULL_KEY:
            return key


def format_key_file(key: bytes, created: dt.datetime | None = None) -> str:
    """The text of a key file holding ``key``."""
    created = created or dt.datetime.now(dt.timezone.utc)
    return ('# SSLFR installation key: keep it secret, back it up offline (docs/deploy.md)\n'
            f'# key id {key_id(key)}, created {created.strftime("%Y-%m-%dT%H:%M:%SZ")}\n'
            f'{key.hex()}\n')


def parse_key_file(text: str, where: str = 'key file') -> bytes:
    """The key in a key file's text: exactly one line of 32 hex digits besides
    comments (#) and blank lines; KeyFileError otherwise."""
    lines = [ln.strip() for ln in text.splitlines()]
    keys = [ln for ln in lines if ln and not ln.startswith('#')]
    if len(keys) != 1:
        raise KeyFileError(f'{where}: expected one line of {2 * KEY_SIZE} hex digits, found {len(keys)} lines')
    try:
        key = bytes.fromhex(keys[0])
    except ValueError:
        key = b''
    if len(key) != KEY_SIZE:
        raise KeyFileError(f'{where}: the key must be {2 * KEY_SIZE} hex digits ({8 * KEY_SIZE} bits)')
    if key == NULL_KEY:
        raise KeyFileError(f'{where}: the null key (all zero) is the key of unprovisioned boards, '
                           'not an installation key: run sslfr keys new')
    return key


def permission_problem(mode: int) -> str | None:
    """Why a key file with ``st_mode`` ``mode`` must not be used, else None: not a
    regular file, readable by others, or writable by group or others."""
    if not stat.S_ISREG(mode):
        return 'is not a regular file'
    if mode & stat.S_IROTH:
        return f'is readable by every user (mode {stat.S_IMODE(mode):04o})'
    if mode & (stat.S_IWOTH | stat.S_IWGRP):
        return f'is writable by other users (mode {stat.S_IMODE(mode):04o})'
    return None


def load_key(path: str | os.PathLike) -> bytes:
    """The key of the key file at ``path``, after checking its permissions.

    Raises
    ------
    KeyFileError
        Missing or unreadable file, permissions open to others (the message gives
        the ``chmod 600``), or not exactly one non-null 128-bit key.
    """
    path = user_path(path)
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        raise KeyFileError(f'key file {path} does not exist (create it once with: sslfr keys new {path})') from None
    except OSError as exc:
        raise KeyFileError(f'key file {path}: {exc.strerror or exc}') from None
    try:
        problem = permission_problem(os.fstat(fd).st_mode)
        if problem:
            raise KeyFileError(f'key file {path} {problem}: refusing to use it '
                               f'(chmod 600 {path}, and make a new key if others may have read it)')
        with os.fdopen(fd, 'r', encoding='ascii', errors='replace') as fh:
            fd = -1
            text = fh.read(4096)
    finally:
        if fd >= 0:
            os.close(fd)
    return parse_key_file(text, f'key file {path}')


def link_key(key_file: str) -> bytes | None:
    """The key a board link uses, from the ``key_file`` parameter: None for '' (no
    key: unprovisioned boards only), else :func:`load_key` (KeyFileError: the link must
    not start)."""
    return load_key(key_file) if key_file else None


def write_key_file(path: str | os.PathLike, key: bytes, force: bool = False) -> Path:
    """Write ``key`` to ``path`` with mode 0600 (parent directories made 0700).
    Refuses to replace an existing file unless ``force`` (KeyFileError): a replaced
    key locks out every board provisioned with it. Returns the path."""
    path = user_path(path)
    if path.exists() and not force:
        raise KeyFileError(f'{path} exists: refusing to overwrite an installation key (boards provisioned '
                           'with it would no longer answer); use --force to replace it')
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix='.sslfr-key-', dir=path.parent)
    try:
        os.fchmod(fd, 0o600)
        with os.fdopen(fd, 'w', encoding='ascii') as fh:
            fh.write(format_key_file(key))
            fh.flush()
            os.fsync(fh.fileno())
        if force:
            os.replace(tmp, path)
        else:
            os.link(tmp, path)          # fails if the file appeared meanwhile: never overwrite
            os.unlink(tmp)
    except FileExistsError:
        os.unlink(tmp)
        raise KeyFileError(f'{path} exists: refusing to overwrite it (use --force)') from None
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
