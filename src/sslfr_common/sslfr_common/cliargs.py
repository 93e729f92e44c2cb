"""Command-line argument helpers every package's CLI shares (pure, stdlib only).

One-line refusals: :class:`OneLineParser` turns every argparse error into a
:class:`CliError` (printed as one line, exit status 2), :func:`one_line` shows the
control characters a user's argument may carry escaped (a refusal stays one line and
cannot forge log lines), and the argparse types :func:`finite_float`,
:func:`ranged_float` and :func:`bounded_int` refuse NaN, infinities and values outside
the documented range, naming the range.
"""
from __future__ import annotations

import argparse
import math


def one_line(text, *, keep_newlines: bool = False) -> str:
    """``text`` as one line: control characters a user's argument may carry (newline,
    carriage return, escape, U+0085, ...) shown escaped, so a refusal stays one line and
    cannot forge log lines. ``keep_newlines``: a message that lists several problems
    on purpose keeps its own line breaks ('\\n'), everything else is escaped."""
    def esc(part: str) -> str:
        return ''.join(c if c.isprintable() or c == ' ' else repr(c)[1:-1] for c in part)
    text = str(text)
    return '\n'.join(esc(p) for p in text.split('\n')) if keep_newlines else esc(text)


class CliError(Exception):
    """A user input error: printed as one line, exit status 2."""

    def __str__(self) -> str:
        return one_line(super().__str__())


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


def ranged_float(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False,
                 zero: bool = False, unit: str = ''):
    """argparse type: a finite float in [lo, hi] ((lo, hi] with ``lo_open``); ``zero`` also allows 0.

    The refusal names the allowed range, e.g. ``must be in (0.05, 60] s, got 'nan'``.
    """
    def fmt(x: float) -> str:
        return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f'{x:g}'

    def describe() -> str:
        left = '(' if lo_open else '['
        rng = f'{left}{fmt(lo)}, {fmt(hi)}]' if lo is not None and hi is not None else \
            (f'>= {fmt(lo)}' if lo is not None else f'<= {fmt(hi)}')
        if lo_open and hi is None:
            rng = f'> {fmt(lo)}'
        return ('0 or ' if zero else '') + rng + (f' {unit}' if unit else '')

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'must be a finite number {describe()}, got {text!r}') from None
        ok = math.isfinite(value)
        if ok and not (zero and value == 0.0):
            if lo is not None:
                ok = value > lo if lo_open else value >= lo
            if ok and hi is not None:
                ok = value <= hi
        if not ok:
            raise argparse.ArgumentTypeError(f'must be a finite number {describe()}, got {text!r}')
        return value
    parse.__name__ = 'number'
    return parse


def bounded_int(lo: int, hi: int):
    """argparse type: an integer in [lo, hi]."""
    def parse(text: str) -> int:
        try:
            value = int(text, 10)
        except ValueError:
            raise argparse.ArgumentTypeError(f'must be an integer in [{lo}, {hi}], got {text!r}') from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f'must be an integer in [{lo}, {hi}], got {text!r}')
        return value
    parse.__name__ = 'integer'
    return parse
