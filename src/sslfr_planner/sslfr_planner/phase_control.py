"""The planner's decisions at each tick, without ROS (pure Python + numpy).

The planner node (:mod:`sslfr_planner.planner_node`) feeds a :class:`PhaseControl`
with its inputs (operator mode requests, the safety verdict, replan requests) and
calls :meth:`PhaseControl.tick` every 0.2 s of ROS time and at once on a ROS-time
step of :func:`immediate_step` or more; this module decides

* **the phase in force** (:func:`sslfr_planner.modes.resolve_phase`: safety stow >
  commanded stow > maintenance > manual hold > the automatic day cycle);
* **the override poses**, fixed when an override begins: entering STOW starts a ramp
  from the pose commanded at that instant to the stow target, at ``stow.speeds``
  (seed 000 Step 4.1), anchored at that instant so every republished horizon agrees;
  the target is the sleeping pose, or ``stow.wind_pose`` while safety says the stow
  is for wind only (``wind_stow``); a change of that target during a stow starts a
  new ramp from the pose commanded at that instant;
  entering MANUAL or MAINTENANCE from any other phase holds the pose commanded at
  that instant (switching between the two keeps the hold);
* **when to replan**: a pending request (start-up, parameters, GPS fix, clock jump,
  the replan service), else at 0:00 local solar time (seed 000 Step 5);
* **the publish cadence** on ROS time: ``tracker/phase`` on every phase or reason
  change and every ``phase_period``; ``tracker/sun`` every ``sun_period``;
  ``tracker/trajectory`` on every phase change, after every replan and every
  ``republish_period``, retried at the next tick while it could not be published;
  all three at once when ROS time went backwards;
* **the diagnostics level** (:func:`diagnostic_summary`).

Times are ROS time in float seconds since the Unix epoch; poses radians in
:data:`sslfr_common.contract.JOINTS` order.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sslfr_common.contract import PHASE_NAMES, DayType, Phase

from . import modes
from .trajectory import Horizon, hold, horizon_times, ramp

#: Topics whose publication cadence :class:`PhaseControl` keeps.
PHASE, SUN, TRAJECTORY = 'phase', 'sun', 'trajectory'

#: Override phases that hold the commanded pose.
HOLD_PHASES = frozenset({Phase.MANUAL, Phase.MAINTENANCE})

#: ``SunEvents.day_type`` -> ``TrackerPhase.day_type`` code.
DAY_TYPE_CODES = {'normal': DayType.DAY_NORMAL, 'polar_day': DayType.DAY_POLAR_DAY,
                  'polar_night': DayType.DAY_POLAR_NIGHT}


@dataclass(frozen=True)
class Tick:
    """What one tick decided.

    Attributes
    ----------
    phase_change : tuple or None
        ``(old, new)`` phase codes when the phase changed (``old`` is None at the
        first tick), else None.
    publish_phase, publish_sun, publish_trajectory : bool
        Which topics are due; the node calls :meth:`PhaseControl.published` for
        each one it did publish.
    """

    phase_change: tuple[int | None, int] | None
    publish_phase: bool
    publish_sun: bool
    publish_trajectory: bool


class PhaseControl:
    """Phase, override poses, replan requests and publish cadence of the planner.

    Parameters
    ----------
    mode : str
        Operator mode at start-up, one of :data:`sslfr_common.contract.MODES`.

    The ``cycle`` argument of the methods is the automatic day cycle
    (:class:`sslfr_planner.day_cycle.DayCycle` or anything with ``auto_phase(t)``,
    ``auto_pose(t)``, ``auto_horizon(t)``, ``sleep_pose(t)`` and
    ``needs_new_day(t)``); ``cfg`` holds the validated planner parameters
    (:data:`sslfr_planner.planner_params.PLANNER_PARAMS`): ``phase_period``,
    ``sun_period``, ``republish_period`` [s], ``horizon``, ``step`` [s] and
    ``stow.speeds`` [rad/s].
    """

    def __init__(self, mode: str):
        if mode not in modes.MODES:
            raise ValueError(f'unknown mode {mode!r}')
        self.mode = mode
        self.safety_stow = False
        self.safety_reasons: list[str] = []
        #: the safety stow is for wind only: the stow target is ``stow.wind_pose``
        self.wind_stow = False
        self._stow_for_wind: bool | None = None     # what the current stow ramp targets
        self.phase: int | None = None
        self.reason = ''
        #: pose held in MANUAL / MAINTENANCE [rad] (3,)
        self.hold_pose: np.ndarray | None = None
        #: (start time [s], start pose [rad], target pose [rad]) of the stow ramp
        self.stow_start: tuple[float, np.ndarray, np.ndarray] | None = None
        #: why the next tick replans (None: no replan requested)
        self.pending_replan: str | None = 'start-up'
        self._force_trajectory = True
        self._last = {PHASE: -math.inf, SUN: -math.inf, TRAJECTORY: -math.inf}
        self._last_tick: float | None = None

    # ------------------------------------------------------------------ inputs
    def request_mode(self, requested: str) -> modes.ModeChange:
        """An operator mode request (:func:`sslfr_planner.modes.request_mode`)."""
        res = modes.request_mode(self.mode, requested)
        if res.success:
            self.mode = res.mode
        return res

    def on_safety(self, stow_required: bool, reasons, wind_stow: bool = False) -> bool:
        """The safety verdict; True when it changed what the planner decides (a new
        stow requirement, its end, new reasons or another stow target while it lasts)."""
        stow, reasons, wind = bool(stow_required), list(reasons), bool(wind_stow) and bool(stow_required)
        if stow != self.safety_stow or (stow and (reasons != self.safety_reasons or wind != self.wind_stow)):
            self.safety_stow, self.safety_reasons, self.wind_stow = stow, reasons, wind
            return True
        return False

    def request_replan(self, reason: str) -> None:
        """Replan at the next tick (the latest reason is reported)."""
        self.pending_replan = reason

    def replan_reason(self, now: float, cycle) -> str | None:
        """Why the tick at ``now`` must replan first, or None."""
        if self.pending_replan is not None:
            return self.pending_replan
        if cycle.needs_new_day(now):
            return 'new day'      # seed 000 Step 5: at 0:00 (local solar) start again at Step 1
        return None

    def replanned(self) -> None:
        """A replan succeeded: clear the request; the trajectory is republished."""
        self.pending_replan = None
        self._force_trajectory = True

    # ------------------------------------------------------------------- tick
    def tick(self, now: float, cycle, cfg: dict) -> Tick:
        """Decide the phase at ``now`` [s] and which topics are due."""
        backwards = self._last_tick is not None and now < self._last_tick
        self._last_tick = now
        dec = modes.resolve_phase(self.mode, cycle.auto_phase(now), self.safety_stow,
                                  self.safety_reasons)
        old = self.phase
        changed = dec.phase != old
        retarget = dec.phase == Phase.STOW and not changed and self._stow_for_wind != self._wind_target()
        if changed or retarget:
            self._enter(dec.phase, now, cycle, cfg['stow.speeds'], cfg['stow.wind_pose'])
        if retarget:
            self._force_trajectory = True      # the same phase, a new ramp: publish it now
        publish_phase = (changed or dec.reason != self.reason or backwards
                         or now - self._last[PHASE] >= cfg['phase_period'])
        self.reason = dec.reason
        publish_sun = backwards or now - self._last[SUN] >= cfg['sun_period']
        publish_traj = (changed or self._force_trajectory or backwards
                        or now - self._last[TRAJECTORY] >= cfg['republish_period'])
        return Tick((old, dec.phase) if changed else None, publish_phase, publish_sun, publish_traj)

    def published(self, topic: str, now: float) -> None:
        """``topic`` (:data:`PHASE`, :data:`SUN` or :data:`TRAJECTORY`) went out at ``now``."""
        self._last[topic] = now
        if topic == TRAJECTORY:
            self._force_trajectory = False

    def _wind_target(self) -> bool:
        """True when a stow now goes to the wind pose (a safety stow for wind only)."""
        return self.safety_stow and self.wind_stow

    def _enter(self, phase: int, now: float, cycle, speeds, wind_pose) -> None:
        """Fix the override pose when an override begins (module docstring)."""
        pose = self.commanded_pose(now, cycle, speeds)
        if phase == Phase.STOW:
            self._stow_for_wind = self._wind_target()
            target = np.asarray(wind_pose, dtype=float) if self._stow_for_wind else cycle.sleep_pose(now)
            self.stow_start = (now, pose, target)
        elif phase in HOLD_PHASES and self.phase not in HOLD_PHASES:
            self.hold_pose = pose
        self.phase = phase

    # ----------------------------------------------------------------- setpoints
    def commanded_pose(self, now: float, cycle, speeds) -> np.ndarray:
        """The setpoint in force at ``now`` under the current phase [rad] (3,)."""
        if self.phase is None or self.phase in modes.AUTO_PHASES:
            return cycle.auto_pose(now)
        if self.phase == Phase.STOW and self.stow_start is not None:
            return ramp(np.array([now]), *self.stow_start, speeds).positions[0]
        return self.hold_pose if self.hold_pose is not None else cycle.auto_pose(now)

    def horizon(self, now: float, cycle, cfg: dict) -> Horizon:
        """The setpoints of the coming ``horizon`` at ``step`` spacing under the
        current phase: the day cycle's, the stow ramp or the hold."""
        t = horizon_times(now, cfg['horizon'], cfg['step'])
        if self.phase is None or self.phase in modes.AUTO_PHASES:
            return cycle.auto_horizon(t)
        if self.phase == Phase.STOW:
            return ramp(t, *self.stow_start, cfg['stow.speeds'])
        return hold(t, self.hold_pose)


def immediate_step(cfg: dict, tick_period: float) -> float:
    """Shortest forward step of ROS time [s] that runs a tick at once, not at the
    node's ``tick_period`` timer: the tick period or the shortest publication period
    (``phase_period``, ``sun_period``), whichever is shorter. A simulation faster than
    real time moves ROS time in such steps and must be followed step by step; the
    small steps of /clock at real time (20 Hz) are left to the timer (issue 16: a
    tick per /clock message cost a tick 20 times a second for nothing). Any step back,
    a change of clock source and a jump beyond ``time_jump_threshold`` run it too."""
    return min(tick_period, cfg['phase_period'], cfg['sun_period'])


def diagnostic_summary(phase: int | None, site_source: str, last_error: str,
                       error_age: float, error_shown_for: float) -> tuple[str, str]:
    """Level (``'ok'``, ``'warn'`` or ``'error'``) and message of the planner's
    diagnostics: ERROR while the last error is younger than ``error_shown_for``
    [s, steady]; WARN before the first tick (no ROS time yet) and while the site
    comes from the parameters (no GPS fix, none persisted); OK otherwise."""
    if last_error and error_age < error_shown_for:
        return 'error', last_error
    if phase is None:
        return 'warn', 'waiting for ROS time'
    name = PHASE_NAMES[phase]
    if site_source == 'parameters':
        return 'warn', f'{name}; site from parameters (no GPS fix yet)'
    return 'ok', f'{name}; site from {site_source}'
