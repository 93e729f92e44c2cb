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
