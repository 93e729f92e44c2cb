"""Recorded days for the page: list the bags, find one by name, stream it as a zip.

A bag is a rosbag2 directory (``metadata.yaml`` + ``*.mcap``, docs/bags.md) under the
recorder's ``output_dir``. A name from a request is never joined to a path: it must
equal the name of a directory found by :func:`list_bags`, so ``..``, slashes or
symlinks out of the bag directory cannot reach other files. The download is a zip
(stored: the MCAP chunks are already compressed) produced chunk by chunk, so a day's
bag of hundreds of MB is never held in memory.
"""
from __future__ import annotations

import datetime as dt
import os
import re
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path
from sslfr_common.files import user_path
from typing import Iterator

from sslfr_common.timeconv import to_sec


NAME_RE = re.compile(r'^[A-Za-z0-9][A-Za-z0-9_.-]{0,200}$')
CHUNK = 1 << 20


@dataclass
class BagEntry:
    name: str
    start: float | None          # first message [Unix s]
    end: float | None            # last message [Unix s]
    messages: int
    files: int
    size: int                    # bytes on disk (metadata + .mcap)
    date: str                    # UTC date of the first message, else of the name
    problem: str = ''            # why metadata is unusable (recording, crashed: see docs/bags.md)

    def to_json(self) -> dict:
        return asdict(self)


def _bag_files(d: Path) -> list[Path]:
    return sorted(p for p in d.iterdir() if p.is_file() and not p.is_symlink()
                  and (p.suffix == '.mcap' or p.name == 'metadata.yaml'))


def list_bags(root: str | os.PathLike) -> list[BagEntry]:
    """Every bag directory directly under ``root``, newest first."""
    from sslfr_recording.bag.metadata import BagError, read_metadata   # here: the node imports it only when asked (-5 MB)
    root = user_path(root)
    out: list[BagEntry] = []
    try:
        children = list(root.iterdir())
    except OSError:
        return out
    for d in children:
        if not d.is_dir() or d.is_symlink() or not NAME_RE.match(d.name):
            continue
        files = _bag_files(d)
        if not any(f.suffix == '.mcap' for f in files):
            continue
        size = sum(f.stat().st_size for f in files)
        m = re.search(r'(\d{4}-\d{2}-\d{2})', d.name)
        entry = BagEntry(d.name, None, None, 0, sum(f.suffix == '.mcap' for f in files), size,
                         m.group(1) if m else '')
        try:
            meta = read_metadata(d)
            if meta.message_count:
                entry.start, entry.end = to_sec(meta.starting_time_ns), to_sec(meta.end_time_ns)
                entry.date = dt.datetime.fromtimestamp(entry.start, dt.timezone.utc).strftime('%Y-%m-%d')
            entry.messages = meta.message_count
        except (BagError, OSError, ValueError) as exc:
            entry.problem = f'no readable metadata.yaml (being recorded, or run `sslfr bag recover`): {exc}'
        out.append(entry)
    out.sort(key=lambda e: (e.start or 0.0, e.name), reverse=True)
    return out


def find_bag(root: str | os.PathLike, name: str) -> Path | None:
    """The bag directory called ``name`` under ``root``, or None (never a path outside)."""
    if not isinstance(name, str) or not NAME_RE.match(name):
        return None
    for e in list_bags(root):
        if e.name == name:
            return user_path(root) / e.name
    return None


class _Sink:
    """A write-only, unseekable file collecting what zipfile writes."""

    def __init__(self):
        self.parts: list[bytes] = []
        self.pos = 0

    def write(self, b) -> int:
        self.parts.append(bytes(b))
        self.pos += len(b)
        return len(b)

    def tell(self) -> int:
        return self.pos

    def flush(self) -> None:
        pass

    def take(self) -> bytes:
        data, self.parts = b''.join(self.parts), []
        return data


def iter_zip(bag: str | os.PathLike, chunk: int = CHUNK) -> Iterator[bytes]:
    """The bag directory as a zip archive (``<bag>/<file>`` entries), in pieces."""
    bag = Path(bag)
    sink = _Sink()
    with zipfile.ZipFile(sink, 'w', compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for f in _bag_files(bag):
            info = zipfile.ZipInfo.from_file(f, arcname=f'{bag.name}/{f.name}')
            info.compress_type = zipfile.ZIP_STORED
            with open(f, 'rb') as src, zf.open(info, 'w', force_zip64=True) as dst:
                while True:
                    data = src.read(chunk)
                    if not data:
                        break
                    dst.write(data)
                    yield sink.take()
            yield sink.take()
    tail = sink.take()
    if tail:
        yield tail


def report_is_fresh(bag: str | os.PathLike, out: str | os.PathLike) -> bool:
    """True when ``out`` holds a report (report.txt) newer than every file of ``bag``
    (a bag still being recorded today gets a new report when it grew)."""
    rep = Path(out) / 'report.txt'
    try:
        made = rep.stat().st_mtime_ns
        return all(f.stat().st_mtime_ns <= made for f in _bag_files(Path(bag)))
    except OSError:
        return False
