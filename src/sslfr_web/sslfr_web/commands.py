"""What the operator page may ask of the graph, validated before any service is called.

Every command goes through an existing service, so the graph's own rules still
decide (the planner refuses forbidden mode changes, a driver refuses a jog outside
maintenance, the safety supervisor refuses a reset while hot). This module refuses
what is malformed or beyond the page's own limits *before* a service is called, so
bad input changes nothing:

====================  ==============================  ===============================
page command          service (relative name)          request
====================  ==============================  ===============================
``stow``              ``planner/set_mode``              mode = ``stow``
``mode``              ``planner/set_mode``              ``{"mode": auto|manual|maintenance|stow}``
``jog``               ``axes/<axis>/jog``               ``{"axis", "delta" [rad], "speed" [rad/s], optional}``
``home``              ``axes/<axis>/home``              ``{"axis"}``
``estop``             ``safety/estop``                  data = true (software stop)
``release``           ``safety/estop``                  data = false
``reset``             ``safety/reset``                  --
``replan``            ``planner/replan``                --
====================  ==============================  ===============================

A command whose request has the effect of one when sent twice (``stow``, ``mode``,
``estop``: the planner accepts the current mode again, the safety node answers an
engaged e-stop "already engaged") is marked ``resend``: the web node sends it again
every :data:`RESEND_S` until the first answer (:func:`first_answer`), because
rmw_fastrtps drops a response when the server has not yet matched the client's
response reader. ``release`` is not (a second release is refused: nothing to
release), nor are ``reset``, ``replan``, ``jog`` and ``home``.

Angles are radians, as everywhere behind the page (degrees only in the page's text).
"""
from __future__ import annotations

import asyncio
import json
import math
from dataclasses import dataclass, field
from typing import Any, Awaitable, Callable, Mapping

from sslfr_common.contract import (AXIS_HOME, AXIS_JOG, JOINTS, MODES, PLANNER_REPLAN, PLANNER_SET_MODE,
                                   SAFETY_ESTOP, SAFETY_RESET)
from sslfr_common.netguard import BadInput, parse_json

#: service key -> (relative service name, service type). ``{axis}`` is filled per axis.
SERVICES: dict[str, tuple[str, str]] = {
    'set_mode': (PLANNER_SET_MODE.name, PLANNER_SET_MODE.type),
    'replan': (PLANNER_REPLAN.name, PLANNER_REPLAN.type),
    'estop': (SAFETY_ESTOP.name, SAFETY_ESTOP.type),
    'reset': (SAFETY_RESET.name, SAFETY_RESET.type),
    'jog': (AXIS_JOG.name, AXIS_JOG.type),
    'home': (AXIS_HOME.name, AXIS_HOME.type),
}
MAX_JOG_SPEED = 2.0     # [rad/s] a speed above this is refused (the driver caps it anyway)
RESEND_S = 1.0          # [s, wall] a ``resend`` command's request is sent again this often until answered
RESENT = frozenset({'stow', 'mode', 'estop'})   # page commands whose request may be sent twice


class CommandError(ValueError):
    """A command refused before any service was called (message for the operator)."""


@dataclass(frozen=True)
class Command:
    """One validated command: which service, with which request fields."""

    name: str                       # page command (table above)
    service: str                    # relative service name, e.g. 'axes/mirrors/jog'
    srv_type: str                   # e.g. 'sslfr_interfaces/srv/Jog'
    request: Mapping[str, Any] = field(default_factory=dict)
    summary: str = ''               # one line for the log and the page

    @property
    def resend(self) -> bool:
        """Sending the request twice acts once (module docstring): sent again until answered."""
        return self.name in RESENT


@dataclass(frozen=True)
class JogLimits:
    """What bounds a jog of one axis: the page's ``max_jog`` [rad] and, when the
    driver has told them, its own ``max_jog`` and soft limits [rad] and the measured
    angle [rad] the jog starts from."""

    page_max: float
    driver_max: float | None = None
    lower: float | None = None
    upper: float | None = None
    measured: float | None = None


def all_service_names(axes: tuple[str, ...] = JOINTS) -> dict[str, tuple[str, str]]:
    """Every service the page may call: name -> (key, type)."""
    out = {}
    for key, (name, typ) in SERVICES.items():
        for axis in (axes if '{axis}' in name else ('',)):
            out[name.format(axis=axis)] = (key, typ)
    return out


MAX_BODY_BYTES = 16384   # [bytes] default bound of a request body (the node's max_request_bytes)
MAX_JSON_DEPTH = 8       # [-] default nesting bound (the node's max_json_depth)


def parse_body(raw: bytes, *, max_bytes: int = MAX_BODY_BYTES, max_depth: int = MAX_JSON_DEPTH) -> dict:
    """Request body -> a JSON object ({} for an empty body), bounded in size and
    nesting depth (:func:`sslfr_common.netguard.parse_json`); CommandError otherwise."""
    if not raw.strip():
        return {}
    try:
        value = parse_json(raw, max_bytes=max_bytes, max_depth=max_depth)
    except BadInput as exc:
        raise CommandError(str(exc)) from None
    if not isinstance(value, dict):
        raise CommandError('the request body must be a JSON object')
    return value


def _only(body: Mapping, allowed: tuple[str, ...], name: str) -> None:
    extra = sorted(set(body) - set(allowed))
    if extra:
        raise CommandError(f'{name}: unknown field(s) {", ".join(map(repr, extra))}'
                           + (f'; expected {", ".join(allowed)}' if allowed else '; expected none'))


def _number(body: Mapping, key: str, name: str) -> float:
    v = body.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise CommandError(f'{name}: {key} must be a number, got {v!r}')
    if not math.isfinite(v):
        raise CommandError(f'{name}: {key} must be finite')
    return float(v)


def _axis(body: Mapping, name: str, axes: tuple[str, ...]) -> str:
    axis = body.get('axis')
    if axis not in axes:
        raise CommandError(f'{name}: unknown axis {axis!r}; expected one of {", ".join(axes)}')
    return axis


def _cmd(name: str, key: str, request: dict, summary: str, axis: str = '') -> Command:
    service, typ = SERVICES[key]
    return Command(name, service.format(axis=axis), typ, request, summary)


async def first_answer(send: Callable[[], Awaitable], timeout: float,
                       resend_every: float | None = None) -> tuple[Any, int]:
    """Send a request with ``send()`` and await its answer for at most ``timeout`` [s].

    With ``resend_every`` [s] the request is sent again that often until the first
    answer to any of them (only for a request that acts once however often it is
    sent: :attr:`Command.resend`). Returns (the answer, or None when none came in
    time; how many requests were sent)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout
    pending = [asyncio.ensure_future(send())]
    try:
        while True:
            left = deadline - loop.time()
            step = left if resend_every is None else min(left, resend_every)
            done, _ = await asyncio.wait(pending, timeout=max(step, 0.0), return_when=asyncio.FIRST_COMPLETED)
            if done:
                return next(iter(done)).result(), len(pending)
            if loop.time() >= deadline:
                return None, len(pending)
            pending.append(asyncio.ensure_future(send()))
    finally:
        for f in pending:
            f.cancel()


def validate(name: str, body: Mapping, jog_limits: Mapping[str, JogLimits] | None = None,
             axes: tuple[str, ...] = JOINTS) -> Command:
    """Turn page command ``name`` with JSON object ``body`` into a :class:`Command`,
    or raise :class:`CommandError` naming what is wrong (nothing is called then)."""
    if name in ('stow', 'estop', 'release', 'reset', 'replan'):
        _only(body, (), name)
        return {'stow': lambda: _cmd(name, 'set_mode', {'mode': 'stow'}, 'set mode stow'),
                'estop': lambda: _cmd(name, 'estop', {'data': True}, 'software e-stop'),
                'release': lambda: _cmd(name, 'estop', {'data': False}, 'release the e-stop'),
                'reset': lambda: _cmd(name, 'reset', {}, 'safety reset'),
                'replan': lambda: _cmd(name, 'replan', {}, 'replan')}[name]()
    if name == 'mode':
        _only(body, ('mode',), name)
        mode = body.get('mode')
        if mode not in MODES:
            raise CommandError(f'mode: unknown mode {mode!r}; expected one of {", ".join(MODES)}')
        return _cmd(name, 'set_mode', {'mode': mode}, f'set mode {mode}')
    if name == 'home':
        _only(body, ('axis',), name)
        axis = _axis(body, name, axes)
        return _cmd(name, 'home', {}, f'home {axis}', axis)
    if name == 'jog':
        _only(body, ('axis', 'delta', 'speed'), name)
        axis = _axis(body, name, axes)
        delta = _number(body, 'delta', name)
        speed = _number(body, 'speed', name) if 'speed' in body else 0.0
        if not 0.0 <= speed <= MAX_JOG_SPEED:
            raise CommandError(f'jog: speed {speed} rad/s outside [0, {MAX_JOG_SPEED}] (0 = the driver\'s default)')
        if delta == 0.0:
            raise CommandError('jog: delta is 0: nothing to move')
        lim = (jog_limits or {}).get(axis) or JogLimits(page_max=0.0)
        bound = lim.page_max if lim.driver_max is None else min(lim.page_max, lim.driver_max)
        if abs(delta) > bound:
            raise CommandError(f'jog: |delta| {abs(delta):.4f} rad ({math.degrees(abs(delta)):.2f} deg) '
                               f'beyond the jog limit {bound:.4f} rad ({math.degrees(bound):.2f} deg)')
        if lim.measured is not None and lim.lower is not None and lim.upper is not None:
            target = lim.measured + delta
            if not lim.lower <= target <= lim.upper:
                raise CommandError(f'jog: target {target:.4f} rad outside {axis} soft limits '
                                   f'[{lim.lower:.4f}, {lim.upper:.4f}] rad')
        return _cmd(name, 'jog', {'delta': delta, 'speed': speed},
                    f'jog {axis} by {delta:+.4f} rad ({math.degrees(delta):+.2f} deg)', axis)
    raise CommandError(f'unknown command {name!r}; expected one of '
                       'stow, mode, jog, home, estop, release, reset, replan')
