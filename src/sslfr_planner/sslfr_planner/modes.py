"""Operator modes and the phase the tracker is in (pure Python, no rclpy).

The automatic day cycle of seed 000 section 4 (Steps 1-5: NIGHT -> PRE_DAWN ->
TRACKING -> STOWING -> NIGHT) is computed by the ephemeris core
(:func:`sslfr_planner.tracking_table.evaluate`). This module decides what overrides it:

* the operator's **mode** (``planner/set_mode``): ``auto`` follows the day cycle,
  ``stow`` sends the mirrors to the sleeping position, ``manual`` holds the axes where
  they were commanded last (operator hold), ``maintenance`` switches automatic motion
  off so the axes can be jogged;
* the **safety supervisor** (``safety/state.stow_required``): while it requires a stow
  the phase is STOW whatever the mode, including maintenance (a defocus request for an
  over-temperature must never be ignored because somebody forgot the mode).

Phase codes are those of ``sslfr_interfaces/TrackerPhase`` (NIGHT=0 ... MAINTENANCE=6).
"""
from __future__ import annotations

from dataclasses import dataclass

from sslfr_common.contract import MODES, PHASE_NAMES, Phase  # noqa: F401 - re-exported for the planner


#: The automatic (day-cycle) phases the core computes.
AUTO_PHASES = frozenset({Phase.NIGHT, Phase.PRE_DAWN, Phase.TRACKING, Phase.STOWING})


#: Allowed operator transitions ``from -> {to}``. Re-requesting the current mode is
#: always accepted (idempotent). Refused, with the reason in :data:`FORBIDDEN_REASONS`:
#: ``stow -> manual`` (holding in the sleeping position is a stow; leave through
#: ``auto``) and ``maintenance -> manual`` (leave maintenance through ``auto`` or
#: ``stow`` so the axes get a defined target first).
TRANSITIONS: dict[str, frozenset[str]] = {
    'auto': frozenset({'stow', 'manual', 'maintenance'}),
    'stow': frozenset({'auto', 'maintenance'}),
    'manual': frozenset({'auto', 'stow', 'maintenance'}),
    'maintenance': frozenset({'auto', 'stow'}),
}

FORBIDDEN_REASONS: dict[tuple[str, str], str] = {
    ('stow', 'manual'): 'a hold in the sleeping position is a stow; switch to auto first',
    ('maintenance', 'manual'): 'leave maintenance through auto or stow first',
}


@dataclass(frozen=True)
class ModeChange:
    """Result of a mode request.

    Attributes
    ----------
    success : bool
        Whether the mode is now the requested one.
    message : str
        One line for the operator (why it was refused, or what happened).
    mode : str
        The mode in force after the request.
    """

    success: bool
    message: str
    mode: str


def request_mode(current: str, requested: str) -> ModeChange:
    """Apply an operator mode request.

    Parameters
    ----------
    current : str
        Mode in force, one of :data:`MODES`.
    requested : str
        Requested mode; surrounding blanks and case are ignored (``' Stow'`` is
        ``'stow'``). ``'hold'`` and ``'manual_hold'`` are accepted aliases of
        ``'manual'`` (the issue calls it "manual hold").

    Returns
    -------
    ModeChange
        ``success=False`` with a reason for an unknown mode or a forbidden
        transition (see :data:`TRANSITIONS`); the mode is then unchanged.
    """
    want = (requested or '').strip().lower()
    want = {'hold': 'manual', 'manual_hold': 'manual'}.get(want, want)
    if want not in MODES:
        return ModeChange(False, f'unknown mode {requested!r}; expected one of {", ".join(MODES)}',
                          current)
    if want == current:
        return ModeChange(True, f'already in {current}', current)
    if want not in TRANSITIONS[current]:
        why = FORBIDDEN_REASONS.get((current, want), 'transition not allowed')
        return ModeChange(False, f'{current} -> {want} refused: {why}', current)
    return ModeChange(True, f'{current} -> {want}', want)


@dataclass(frozen=True)
class PhaseDecision:
    """The phase in force and why.

    Attributes
    ----------
    phase : int
        TrackerPhase code.
    reason : str
        Human-readable reason (published in ``TrackerPhase.reason``).
    """

    phase: int
    reason: str


def resolve_phase(mode: str, auto_phase: int, safety_stow: bool,
                  safety_reasons: tuple[str, ...] | list[str] = ()) -> PhaseDecision:
    """Combine the day cycle, the operator mode and the safety verdict.

    Priority (highest first): safety stow, commanded stow, maintenance, manual hold,
    the automatic day-cycle phase (seed 000 section 4, Steps 1-5).

    Parameters
    ----------
    mode : str
        Operator mode, one of :data:`MODES`.
    auto_phase : int
        Phase of the day cycle at this instant (NIGHT, PRE_DAWN, TRACKING or STOWING),
        as computed by the core's day table.
    safety_stow : bool
        ``SafetyState.stow_required`` from the safety supervisor.
    safety_reasons : sequence of str
        ``SafetyState.reasons``, quoted in the reason.

    Returns
    -------
    PhaseDecision
    """
    if mode not in MODES:
        raise ValueError(f'unknown mode {mode!r}')
    if auto_phase not in AUTO_PHASES:
        raise ValueError(f'auto_phase {auto_phase} is not a day-cycle phase')
    if safety_stow:
        why = '; '.join(safety_reasons) if safety_reasons else 'stow required'
        return PhaseDecision(Phase.STOW, f'safety: {why}')
    if mode == 'stow':
        return PhaseDecision(Phase.STOW, 'operator: stow commanded')
    if mode == 'maintenance':
        return PhaseDecision(Phase.MAINTENANCE, 'operator: maintenance, automatic motion off')
    if mode == 'manual':
        return PhaseDecision(Phase.MANUAL, 'operator: manual hold')
    return PhaseDecision(auto_phase, f'day cycle: {PHASE_NAMES[auto_phase]}')
