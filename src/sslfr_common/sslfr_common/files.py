"""Files written so that a crash, a power cut or a failing writer never leaves a
half-written one: the one atomic write of the project (pure, no rclpy).

Used for everything a later reader must trust whole: bag metadata, the planner's
persisted site, password and key files, CLI outputs, the simulators' world file.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Callable


def atomic_write(path: str | os.PathLike, data: str | bytes | None = None, *,
                 write: Callable[[str], None] | None = None, mode: int = 0o644,
                 fsync: bool = True) -> Path:
    """Write ``path`` all-or-nothing and return it.

    Parameters
    ----------
    path : str or path
        The file; its directory must exist.
    data : str or bytes, optional
        The content (text is written as UTF-8).
    write : callable, optional
        Instead of ``data``: ``write(tmp_path)`` writes the content to a temporary
        path beside ``path`` (for writers that take a file name, e.g. CSV or plots).
    mode : int
        Permission bits of the result (``0o600`` for secrets: the content never
        exists with wider permissions, not even in the temporary file).
    fsync : bool
        Flush the file and its directory entry to the disk before returning, so the
        new content survives a power cut (costs a few ms on an SD card).

    The temporary file (``.<name>.<random>.tmp``) is removed when anything fails; the
    previous content of ``path``, if any, stays until the rename.
    """
    if (data is None) == (write is None):
        raise TypeError('atomic_write needs exactly one of data or write')
    path = Path(path)
    directory = path.parent if str(path.parent) else Path('.')
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.tmp', dir=directory)
    try:
        os.fchmod(fd, mode)
        if data is not None:
            with os.fdopen(fd, 'wb') as fh:
                fh.write(data.encode('utf-8') if isinstance(data, str) else data)
                fh.flush()
                if fsync:
                    os.fsync(fh.fileno())
        else:
            os.close(fd)
            write(tmp)
            if fsync:
                with open(tmp, 'rb') as fh:
                    os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    if fsync:
        try:  # make the rename durable
            dfd = os.open(directory, os.O_RDONLY)
            try:
                os.fsync(dfd)
            finally:
                os.close(dfd)
        except OSError:
            pass
    return path


def user_path(text) -> Path:
    """``text`` as a path with a leading ``~`` / ``~user`` expanded; left as written when
    that home cannot be found (``~0``: no such user), so a bad name is refused later as
    a file that does not exist, never with a RuntimeError."""
    p = Path(text)
    try:
        return p.expanduser()
    except RuntimeError:
        return p
