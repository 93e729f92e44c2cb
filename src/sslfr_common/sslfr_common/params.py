"""Parameter tables: every node declares its parameters once, as data (pure Python).

A :class:`ParamTable` is a tuple of :class:`ParamSpec` (name, default, description,
unit, range or choices) plus an optional cross-parameter check. The same table is

- declared by the node (``sslfr_common.node.declare_parameters``: descriptors with
  the description, unit and range, so ``ros2 param describe`` shows them),
- checked at start-up (an invalid value refuses to start, exit 2, one line),
- checked on every run-time change (refused with the reason, the last good
  configuration stays: ``sslfr_common.node.ParameterGuard``),
- and used by ``sslfr up`` / ``sslfr sim`` / ``sslfr doctor`` to validate a site
  config before anything starts (unknown keys included).

No rclpy here: tables are importable by the CLI and by tests without ROS.
"""
from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping


@dataclass(frozen=True)
class ParamSpec:
    """One parameter.

    Attributes
    ----------
    name : str
        Parameter name (dots for groups).
    default : bool, int, float, str or list
        Default value; its type is the parameter's type.
    description : str
        Meaning, with the unit in brackets.
    unit : str
        Unit ('-' for none).
    lo, hi : float or None
        Inclusive range for numbers (each element of a number array).
    choices : tuple of str
        Allowed values of a string parameter (empty: any).
    length : int or None
        Required length of an array parameter.
    read_only : bool
        Fixed at start-up (a run-time change is refused).
    validator : callable or None
        A rule no range or choice expresses (e.g. "a literal IP address"):
        ``validator(value) -> None`` when valid, else the reason (without the
        name); run after the type, range and choice checks pass.
    """

    name: str
    default: Any
    description: str
    unit: str = '-'
    lo: float | None = None
    hi: float | None = None
    choices: tuple[str, ...] = ()
    length: int | None = None
    read_only: bool = False
    validator: Callable[[Any], str | None] | None = None

    @property
    def constraints(self) -> str:
        """Human-readable constraint, for the descriptor and error messages."""
        parts = [f'unit: {self.unit}']
        if self.lo is not None or self.hi is not None:
            parts.append(f'range [{self.lo}, {self.hi}]')
        if self.choices:
            parts.append('one of ' + ', '.join(self.choices))
        if self.length is not None:
            parts.append(f'{self.length} values')
        return '; '.join(parts)

    def check(self, value: Any) -> str | None:
        """None when ``value`` is valid for this parameter, else a one-line reason
        naming the parameter, the value and what is allowed."""
        why = self._check_type_and_range(value)
        if why is None and self.validator is not None:
            rule = self.validator(value)
            why = None if rule is None else f'{self.name}: {rule}'
        return why

    def _check_type_and_range(self, value: Any) -> str | None:
        d = self.default
        if isinstance(d, bool):
            return None if isinstance(value, bool) else f'{self.name}: expected a bool (true or false), got {value!r}'
        if isinstance(d, list):
            if not isinstance(value, (list, tuple)) or isinstance(value, str):
                return f'{self.name}: expected a list, got {value!r}'
            if self.length is not None and len(value) != self.length:
                return f'{self.name}: expected {self.length} values, got {len(value)}'
            if d and isinstance(d[0], str):
                bad = [v for v in value if not isinstance(v, str)]
                return f'{self.name}: expected strings, got {bad[0]!r}' if bad else None
            for v in value:
                why = self._check_number(v)
                if why:
                    return why
            return None
        if isinstance(d, str):
            if not isinstance(value, str):
                return f'{self.name}: expected a string, got {value!r}'
            if self.choices and value not in self.choices:
                return f'{self.name}: {value!r} is not one of {", ".join(self.choices)}'
            return None
        if isinstance(d, int) and (not isinstance(value, int) or isinstance(value, bool)):
            return f'{self.name}: expected an integer, got {value!r}'
        return self._check_number(value)

    def _check_number(self, v: Any) -> str | None:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            return f'{self.name}: expected a number, got {v!r}'
        if not math.isfinite(v):
            return f'{self.name}: {v} is not a finite number'
        if (self.lo is not None and v < self.lo) or (self.hi is not None and v > self.hi):
            unit = '' if self.unit == '-' else f' {self.unit}'
            return f'{self.name}: {v}{unit} is outside [{self.lo}, {self.hi}]'
        return None


class ParamTable:
    """The parameters of one node: specs in declaration order + a cross check.

    Parameters
    ----------
    specs : iterable of ParamSpec
    cross_check : callable, optional
        ``cross_check(values) -> list[str]``: rules between parameters, run only
        when every single value is valid.
    integers_for_floats : bool
        True: a floating-point parameter (or array) also takes integers (a params
        file's ``22`` for 22.0, ``ros2 param set ... horizon 60``), converted to float
        (:meth:`coerce`; the node declares these parameters with dynamic typing).
        False: rclpy's strict typing, which refuses them.
    """

    def __init__(self, specs: Iterable[ParamSpec],
                 cross_check: Callable[[dict[str, Any]], list[str]] | None = None, *,
                 integers_for_floats: bool = False):
        self.specs: tuple[ParamSpec, ...] = tuple(specs)
        self.by_name: dict[str, ParamSpec] = {s.name: s for s in self.specs}
        if len(self.by_name) != len(self.specs):
            raise ValueError('duplicate parameter names in a table')
        self.cross_check = cross_check
        self.integers_for_floats = integers_for_floats

    def __iter__(self):
        return iter(self.specs)

    def __contains__(self, name: str) -> bool:
        return name in self.by_name

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.by_name)

    def defaults(self) -> dict[str, Any]:
        """Name -> default value (copies of lists)."""
        return {s.name: (list(s.default) if isinstance(s.default, list) else s.default) for s in self.specs}

    def with_defaults(self, **defaults: Any) -> 'ParamTable':
        """The same table with other defaults (e.g. per-axis limits); names with
        dots are given with ``__`` (``stow__speeds=...``)."""
        new = {k.replace('__', '.'): v for k, v in defaults.items()}
        unknown = set(new) - set(self.by_name)
        if unknown:
            raise KeyError(f'unknown parameters: {", ".join(sorted(unknown))}')
        return ParamTable((replace(s, default=new[s.name]) if s.name in new else s for s in self.specs),
                          self.cross_check, integers_for_floats=self.integers_for_floats)

    def coerce(self, values: dict[str, Any]) -> dict[str, Any]:
        """A copy of ``values`` with integers given for floating-point parameters (and
        elements of floating-point arrays) converted to float; other values unchanged
        (:meth:`validate` judges them)."""
        out = dict(values)
        for name, value in values.items():
            spec = self.by_name.get(name)
            if spec is not None:
                out[name] = _as_float(spec, value)
        return out

    def validate(self, values: dict[str, Any]) -> list[str]:
        """Problems of a complete set of values (empty list: valid)."""
        errors = []
        for spec in self.specs:
            if spec.name not in values:
                errors.append(f'{spec.name}: missing')
                continue
            why = spec.check(values[spec.name])
            if why:
                errors.append(why)
        if not errors and self.cross_check is not None:
            errors.extend(self.cross_check(values))
        return errors

    def check_overrides(self, values: dict[str, Any]) -> list[str]:
        """Problems of a partial set (a site config's node section): unknown names
        (a misspelt key is refused, with the closest known names) and bad values;
        the cross check runs on the defaults overlaid with ``values``."""
        import difflib
        errors = []
        for name, value in values.items():
            spec = self.by_name.get(name)
            if spec is None:
                close = difflib.get_close_matches(name, self.names, n=2)
                hint = f' (did you mean {" or ".join(close)}?)' if close else ''
                errors.append(f'{name}: not a parameter of this node{hint}')
                continue
            why = (None if self.integers_for_floats else _strict_type(spec, value)) or spec.check(value)
            if why:
                errors.append(why)
        if not errors and self.cross_check is not None:
            errors.extend(self.cross_check({**self.defaults(), **values}))
        return errors


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _as_float(spec: ParamSpec, value: Any) -> Any:
    """``value`` with integers made floats where ``spec`` is floating-point."""
    d = spec.default
    if isinstance(d, float) and _is_int(value):
        return float(value)
    if isinstance(d, list) and d and isinstance(d[0], float) and isinstance(value, (list, tuple)):
        return [float(v) if _is_int(v) else v for v in value]
    return value


def _strict_type(spec: ParamSpec, value: Any) -> str | None:
    """rclpy refuses a params-file value whose YAML type is not the declared one: an
    integer (``5``) for a double parameter (write ``5.0``), a double for an integer."""
    d = spec.default
    if isinstance(d, float) and isinstance(value, int) and not isinstance(value, bool):
        return f'{spec.name}: {value} is an integer, the parameter is a floating-point number (write {value}.0)'
    if isinstance(d, list) and d and isinstance(d[0], float) and isinstance(value, (list, tuple)):
        if any(isinstance(v, int) and not isinstance(v, bool) for v in value):
            return f'{spec.name}: write every element as a floating-point number (e.g. 1.0, not 1)'
    return None


def writable_directory(value: str, *, empty_ok: bool = True) -> str | None:
    """A :class:`ParamSpec` validator for a directory the node writes into (``~``
    expanded): None when it is a directory this process can create a file in, or
    does not exist yet and can be created (its nearest existing ancestor accepts a new
    directory); else the reason. The check is a real attempt (a temporary file or
    directory, removed at once), so pseudo file systems (``/proc/x``), read-only
    mounts and permissions are judged as the node would meet them; nothing is left
    behind. ``''`` means "disabled" when ``empty_ok``."""
    if value == '':
        return None if empty_ok else 'an empty path is not a directory'
    path = Path(os.path.expanduser(value))
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        return f'{value!r}: {probe} is not a directory'
    try:
        if probe == path:
            with tempfile.TemporaryFile(dir=path):
                pass
        else:
            os.rmdir(tempfile.mkdtemp(dir=probe))
    except OSError as exc:
        what = 'cannot write in' if probe == path else 'cannot write there: cannot create directories in'
        return f'{value!r}: {what} {probe} ({exc.strerror or exc})'
    return None


def flatten(d: Mapping[str, Any], prefix: str = '') -> dict:
    """A nested parameter mapping (a params file's ``ros__parameters``) -> one level
    with dotted names, as ROS 2 names grouped parameters (``{'a': {'b': 1}}`` ->
    ``{'a.b': 1}``)."""
    out = {}
    for k, v in d.items():
        key = f'{prefix}{k}'
        if isinstance(v, Mapping):
            out.update(flatten(v, key + '.'))
        else:
            out[key] = v
    return out
