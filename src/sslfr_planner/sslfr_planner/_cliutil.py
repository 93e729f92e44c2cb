"""Shared helpers of the planner's CLI subcommands (argument parsing, one-line errors)."""
from __future__ import annotations

import argparse
import math
import sys


class CliError(Exception):
    """A user input error: printed as one line, exit status 2."""


class OneLineParser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one clear line on stderr (exit status 2)."""

    def error(self, message):  # noqa: D401 - argparse API
        raise CliError(message)


def finite_float(text: str) -> float:
    """argparse type: a finite float."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'not a finite number: {text!r}')
    return value


def run(prog: str, body, argv) -> int:
    """Run ``body(argv)``; turn CliError/ValueError into one line on stderr and exit 2."""
    try:
        return int(body(argv) or 0)
    except CliError as exc:
        print(f'sslfr {prog}: error: {exc}', file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f'sslfr {prog}: error: {exc}', file=sys.stderr)
        return 2
    except OSError as exc:
        print(f'sslfr {prog}: error: {exc.strerror or exc}: {exc.filename or ""}'.rstrip(': '), file=sys.stderr)
        return 1


def float_in(lo: float, hi: float, unit: str = '', lo_open: bool = False, hi_open: bool = False):
    """argparse type factory: a finite float within [lo, hi] (``lo_open``/``hi_open``: exclusive).

    The refusal names the allowed range, e.g. ``must be within (0, 86400] s, got 1e+09``.
    """
    text = f'{"(" if lo_open else "["}{lo:g}, {hi:g}{")" if hi_open else "]"}{" " + unit if unit else ""}'

    def parse(s: str) -> float:
        value = finite_float(s)
        if value < lo or value > hi or (lo_open and value == lo) or (hi_open and value == hi):
            raise argparse.ArgumentTypeError(f'must be within {text}, got {s}')
        return value
    parse.__name__ = 'number'
    return parse


def int_in(lo: int, hi: int):
    """argparse type factory: an integer within [lo, hi]."""
    def parse(s: str) -> int:
        try:
            value = int(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f'not an integer: {s!r}') from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f'must be within {lo}..{hi}, got {value}')
        return value
    parse.__name__ = 'integer'
    return parse


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
    """Write a file through ``write(tmp_path)`` then rename it into place (nothing half-written).

    The temporary file sits beside ``path`` and is removed if ``write`` fails.
    """
    import os
    import tempfile

    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix='.' + os.path.basename(path) + '.', suffix='.tmp', dir=directory)
    os.close(fd)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def load_yaml_file(path: str, what: str = 'config'):
    """Read a YAML file whose top level must be a mapping; CliError naming the file otherwise.

    Refuses, with one line: a missing or unreadable file, bytes that are not UTF-8
    text (an image, random bytes), invalid YAML, and a document that is not a mapping.
    """
    import yaml

    try:
        with open(path, 'rb') as fh:
            raw = fh.read(16 * 1024 * 1024 + 1)
    except OSError as exc:
        raise CliError(f'{what} {path}: cannot read it ({exc.strerror or exc})') from None
    if len(raw) > 16 * 1024 * 1024:
        raise CliError(f'{what} {path}: larger than 16 MiB; not a config file')
    try:
        text = raw.decode('utf-8')
    except UnicodeDecodeError as exc:
        raise CliError(f'{what} {path}: not a UTF-8 text file (byte {exc.start}); expected a YAML params file') \
            from None
    if '\x00' in text:
        raise CliError(f'{what} {path}: contains NUL bytes; expected a YAML params file')
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' at line {mark.line + 1}' if mark is not None else ''
        raise CliError(f'{what} {path}: not valid YAML{where}') from None
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        raise CliError(f'{what} {path}: the top level must be a mapping of node names, got {type(doc).__name__}')
    return doc
