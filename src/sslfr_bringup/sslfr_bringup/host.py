"""This machine's side of running the node graph (pure Python, no rclpy): where
``ros2 run`` finds an executable, and a ROS domain id nobody else here is using.

Used by ``sslfr up`` / ``sslfr sim`` / ``sslfr doctor`` / ``sslfr replay --what-if``
and by the test fixtures (conftest.py), so all of them agree.

ROS domains: every process of the project that needs a private domain (a test, a
simulation, a what-if replay) holds an exclusive ``flock`` on
``/tmp/sslfr-ros-domains/<id>.lock`` for as long as it uses the domain (the lock
goes with the process, even if it is killed), so concurrent runs in several
checkouts of one machine never share a domain, nor its ``/clock``.
"""
from __future__ import annotations

import fcntl
import os
import random
from pathlib import Path

#: Lock files of the domains in use, one per id (shared by every checkout).
DOMAIN_LOCK_DIR = Path('/tmp/sslfr-ros-domains')
#: Domains of the test fixtures.
TEST_DOMAINS: tuple[int, ...] = tuple(range(1, 102))
#: Domains of simulations and what-if replays: 215..232 first (valid DDS port
#: ranges outside the tests' 1..101), then downwards from 102.
PRIVATE_DOMAINS: tuple[int, ...] = tuple(range(215, 233)) + tuple(range(102, 0, -1))


def install_prefix(root: str | os.PathLike | None = None) -> Path | None:
    """The colcon overlay ``<root>/ros_ws/install`` of a checkout (default: the
    ``SSLFR_ROOT`` environment variable ``scripts/env.sh`` sets), None when it is not
    built."""
    root = root if root is not None else os.environ.get('SSLFR_ROOT')
    if not root:
        return None
    prefix = Path(root) / 'ros_ws' / 'install'
    return prefix if prefix.is_dir() else None


def executable_path(package: str, exe: str, prefix: str | os.PathLike) -> Path:
    """Where ``ros2 run package exe`` looks in the install ``prefix``:
    ``<prefix>/<package>/lib/<package>/<exe>`` (colcon's isolated layout)."""
    return Path(prefix) / package / 'lib' / package / exe


def find_executable(package: str, exe: str) -> Path | None:
    """The executable ``ros2 run package exe`` would run: in this checkout's overlay
    (:func:`install_prefix`), else in the package's prefix from the ament index (an
    apt-installed package); None when neither holds an executable file."""
    candidates = []
    prefix = install_prefix()
    if prefix is not None:
        candidates.append(executable_path(package, exe, prefix))
    try:
        from ament_index_python.packages import get_package_prefix
        candidates.append(Path(get_package_prefix(package)) / 'lib' / package / exe)
    except Exception:  # noqa: BLE001 - package not installed: no candidate
        pass
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return c
    return None


def acquire_domain(candidates=PRIVATE_DOMAINS, *, shuffle: bool = False):
    """A ROS domain id no other process here holds; returns ``(domain_id, lock
    file)``: keep the file open while the domain is used (closing it, or the end of
    the process, releases the domain).

    Parameters
    ----------
    candidates : sequence of int
        Ids to try, in order (:data:`PRIVATE_DOMAINS`, :data:`TEST_DOMAINS`).
    shuffle : bool
        Try them in random order (fewer collisions between many short-lived holders).

    Raises
    ------
    RuntimeError
        Every candidate is held.
    """
    ids = list(candidates)
    if shuffle:
        random.shuffle(ids)
    DOMAIN_LOCK_DIR.mkdir(exist_ok=True)
    for i in ids:
        fh = open(DOMAIN_LOCK_DIR / f'{i}.lock', 'w')  # noqa: SIM115 - held by the caller
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return i, fh
        except OSError:
            fh.close()
    raise RuntimeError(f'no free ROS domain id among {min(ids)}..{max(ids)} '
                       f'(all held by other runs on this machine)')
