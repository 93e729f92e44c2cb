"""Shared helpers of the planner's CLI subcommands (argument parsing, one-line errors)."""
from __future__ import annotations

import argparse
import sys

from sslfr_common.cliargs import (CliError, OneLineParser, bounded_int, finite_float,  # noqa: F401 - re-exported
                                  one_line, ranged_float)
from sslfr_common.files import atomic_write


def run(prog: str, body, argv) -> int:
    """Run ``body(argv)``; turn CliError/ValueError into one line on stderr and exit 2."""
    try:
        return int(body(argv) or 0)
    except CliError as exc:
        print(f'sslfr {prog}: error: {exc}', file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f'sslfr {prog}: error: {one_line(exc)}', file=sys.stderr)
        return 2
    except OSError as exc:
        print(one_line(f'sslfr {prog}: error: {exc.strerror or exc}: {exc.filename or ""}'.rstrip(': ')),
              file=sys.stderr)
        return 1


def _path_errors(check):
    """Decorate an argparse path type: a path the OS refuses outright (a name too long,
    a NUL byte, a loop of links) is one clear refusal, not a traceback."""
    import functools

    @functools.wraps(check)
    def parse(text: str):
        try:
            return check(text)
        except (OSError, ValueError) as exc:
            shown = text if len(text) <= 80 else text[:77] + '...'
            raise argparse.ArgumentTypeError(f'{shown!r} is not a usable path '
                                             f'({getattr(exc, "strerror", None) or exc})') from None
    return parse


@_path_errors
def output_dir(text: str):
    """argparse type: a directory that exists and is writable, or can be created.

    Nothing is created here (a refusal leaves nothing behind); the caller creates it
    when the work starts. Returns a :class:`pathlib.Path`.
    """
    import os
    from pathlib import Path
    if not text or not text.strip():
        raise argparse.ArgumentTypeError('must be a directory path, got an empty string')
    if '\0' in text:
        raise argparse.ArgumentTypeError('must be a directory path without NUL bytes')
    import tempfile
    path = Path(os.path.expanduser(text))
    if path.exists():
        if not path.is_dir():
            raise argparse.ArgumentTypeError(f'{text} exists and is not a directory')
        try:  # a real write test (permission bits say nothing to root, /proc, read-only mounts)
            with tempfile.TemporaryFile(dir=path):
                pass
        except OSError as exc:
            raise argparse.ArgumentTypeError(f'{text} is not writable ({exc.strerror or exc})') from None
        return path
    first = path
    while not first.parent.exists() and first.parent != first:
        first = first.parent
    if not first.parent.is_dir():
        raise argparse.ArgumentTypeError(f'{text} cannot be created: {first.parent} is not a directory')
    try:  # create and remove the first missing directory: nothing is left behind
        first.mkdir()
        first.rmdir()
    except OSError as exc:
        raise argparse.ArgumentTypeError(f'{text} cannot be created ({exc.strerror or exc})') from None
    return path


#: Largest text input (configs, metadata.yaml) read [bytes].
MAX_TEXT_BYTES = 16 * 1024 * 1024


def read_text_file(path, what: str = 'file') -> str:
    """UTF-8 text of an input file, or :class:`CliError` naming the file and what is wrong."""
    from pathlib import Path
    p = Path(path)
    try:
        with open(p, 'rb') as fh:
            data = fh.read(MAX_TEXT_BYTES + 1)
    except IsADirectoryError:
        raise CliError(f'{what} {p} is a directory, not a file') from None
    except OSError as exc:
        raise CliError(f'{what} {p}: {exc.strerror or exc}') from None
    except ValueError:                         # a NUL byte in the path
        raise CliError(f'{what} {str(p)!r}: not a usable path (NUL byte)') from None
    if len(data) > MAX_TEXT_BYTES:
        raise CliError(f'{what} {p} is larger than {MAX_TEXT_BYTES >> 20} MiB: not a config or metadata file')
    try:
        text = data.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise CliError(f'{what} {p} is not a text file (byte 0x{data[exc.start]:02x} at offset '
                       f'{exc.start} is not UTF-8)') from None
    if '\0' in text:
        raise CliError(f'{what} {p} is not a text file (it holds NUL bytes)')
    return text


def time_step(span: float, max_samples: int, what: str = 'the run'):
    """argparse type factory: a time step [s] > 0 whose sample count over ``span`` [s] is bounded.

    An upper bound on the work a step implies: ``span / step`` samples at most
    ``max_samples``; the refusal states the smallest step allowed.
    """
    smallest = span / max_samples

    def parse(s: str) -> float:
        value = finite_float(s)
        if value <= 0:
            raise argparse.ArgumentTypeError(f'must be > 0 s, got {s}')
        if value > span:
            raise argparse.ArgumentTypeError(f'must be <= {span:g} s, got {s}')
        if span / value > max_samples:
            raise argparse.ArgumentTypeError(
                f'{s} s would need {span / value:.3g} samples for {what}; at most {max_samples:,} '
                f'(step >= {smallest:g} s)')
        return value
    parse.__name__ = 'step'
    return parse


@_path_errors
def output_file(text: str) -> str:
    """argparse type: a file path that can be created or replaced (checked before any work).

    Refused: an empty path, an existing directory, a parent that is missing, is not a
    directory or is not writable.
    """
    import os

    if not text:
        raise argparse.ArgumentTypeError('empty path')
    if os.path.isdir(text):
        raise argparse.ArgumentTypeError(f'{text} is a directory; expected a file path')
    parent = os.path.dirname(os.path.abspath(text))
    if not os.path.exists(parent):
        raise argparse.ArgumentTypeError(f'directory {parent} does not exist')
    if not os.path.isdir(parent):
        raise argparse.ArgumentTypeError(f'{parent} is not a directory')
    if os.path.exists(text) and not os.access(text, os.W_OK):
        raise argparse.ArgumentTypeError(f'cannot write {text} (permission denied)')
    try:  # the real test (root passes os.access everywhere): create and remove a file there
        import tempfile
        with tempfile.NamedTemporaryFile(dir=parent, prefix='.sslfr-probe-'):
            pass
    except OSError as exc:
        raise argparse.ArgumentTypeError(f'cannot write in {parent} ({exc.strerror or exc})') from None
    return text


def write_atomically(path: str, write) -> None:
    """Write a file through ``write(tmp_path)`` then rename it into place (nothing
    half-written; :func:`sslfr_common.files.atomic_write`)."""
    atomic_write(path, write=write)

def load_yaml_file(path: str, what: str = 'config'):
    """Read a YAML file whose top level must be a mapping; CliError naming the file otherwise.

    Refuses, with one line: a missing or unreadable file, bytes that are not UTF-8
    text (an image, random bytes), invalid YAML, and a document that is not a mapping.
    """
    import yaml

    text = read_text_file(path, what)
    try:
        doc = yaml.safe_load(text)
    except RecursionError:
        raise CliError(f'{what} {path}: YAML nested too deeply') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark is not None else ''
        raise CliError(f'{what} {path}: not valid YAML{where}') from None
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        raise CliError(f'{what} {path}: the top level must be a mapping of node names, got {type(doc).__name__}')
    return doc


# ROS names, checked with the rules rcl/rmw apply (rmw validate_node_name.c,
# rcl validate_topic_name.c, rmw validate_full_topic_name.c) before rcl sees them.
NODE_NAME_MAX = 255
TOPIC_NAME_MAX = 255 - 8


def _alnum(ch: str) -> bool:
    return ch.isascii() and ch.isalnum()


def node_name_error(name: str) -> str:
    """Why rmw_validate_node_name refuses ``name`` ('' when it is valid)."""
    if not name:
        return 'must not be empty'
    for i, ch in enumerate(name):
        if not (_alnum(ch) or ch == '_'):
            return f'character {ch!r} at {i} is not allowed (letters, digits, _)'
    if name[0].isdigit():
        return 'must not start with a digit'
    if len(name) > NODE_NAME_MAX:
        return f'is longer than {NODE_NAME_MAX} characters'
    return ''


def topic_name_error(name: str) -> str:
    """Why rcl would refuse ``name`` as a topic name ('' when valid); relative names allowed."""
    if not name:
        return 'must not be empty'
    if name[0].isdigit():
        return 'must not start with a digit'
    if name.endswith('/'):
        return 'must not end with /'
    depth = 0
    for i, ch in enumerate(name):
        if _alnum(ch) or ch == '_':
            continue
        if ch == '/' and not depth:
            continue
        if ch == '~' and i == 0:
            continue
        if ch == '{' and not depth:
            depth = 1
            continue
        if ch == '}' and depth:
            depth = 0
            continue
        return f'character {ch!r} at {i} is not allowed (letters, digits, _, / and a leading ~)'
    if depth:
        return 'has an unmatched {'
    if '//' in name:
        return 'must not contain //'
    for i, ch in enumerate(name[:-1]):
        if ch == '/' and name[i + 1].isdigit():
            return f'name token at {i + 1} starts with a digit'
    if name.startswith('~') and len(name) > 1 and name[1] != '/':
        return '~ must be followed by /'
    if len(name) + (0 if name.startswith('/') else 1) > TOPIC_NAME_MAX:
        return f'is longer than {TOPIC_NAME_MAX} characters'
    return ''


def ros_topic(text: str) -> str:
    """argparse type: a valid topic name (relative or absolute)."""
    why = topic_name_error(text)
    if why:
        raise argparse.ArgumentTypeError(f'{text!r} is not a valid ROS topic name: {why}')
    return text


def ros_node_name(text: str) -> str:
    """argparse type: a valid ROS node name."""
    why = node_name_error(text)
    if why:
        raise argparse.ArgumentTypeError(f'{text!r} is not a valid ROS node name: {why}')
    return text


def ros_namespace(text: str) -> str:
    """argparse type: '' or an absolute ROS namespace (``/sslfr1``, ``/field/row2``),
    checked with the topic-name rules rcl applies (a trailing / is dropped)."""
    if text == '':
        return text
    why = topic_name_error(text.rstrip('/') or '/') if text.startswith('/') else 'must start with /'
    if not why and '~' in text:
        why = 'must not hold ~'
    if why:
        raise argparse.ArgumentTypeError(f'{text!r} is not a valid ROS namespace: {why}')
    return text.rstrip('/') or '/'


def ros_remap(text: str) -> tuple[str, str]:
    """argparse type: a topic remap ``from:=to`` with both names valid (rcl's rules)."""
    if ':=' not in text:
        raise argparse.ArgumentTypeError(f'{text!r} is not a remap: use from:=to')
    src, dst = text.split(':=', 1)
    for side, name in (('from', src), ('to', dst)):
        why = topic_name_error(name)
        if why:
            raise argparse.ArgumentTypeError(f'remap {text!r}: {side} name {name!r} {why}')
    return src, dst


def file_name(text: str) -> str:
    """argparse type: one path component usable as a file or directory name prefix."""
    if not text or text in ('.', '..'):
        raise argparse.ArgumentTypeError(f'must be a non-empty name, got {text!r}')
    bad = [ch for ch in text if ch in '/\\\0' or not ch.isprintable()]
    if bad:
        raise argparse.ArgumentTypeError(f'{text!r} must not contain {bad[0]!r}')
    if len(text.encode()) > 200:
        raise argparse.ArgumentTypeError('must be at most 200 bytes long')
    return text
