"""Run-time accuracy alarm of one axis (pure Python, no rclpy).

While the axis tracks the sun, its measured position (encoder, inclinometer or step
count: ``AxisStatus.measured``) is compared with the setpoint; the RMS of the error
over the last ``accuracy.window`` seconds of ROS time is judged against two
thresholds: seed 000's 0.06 deg (WARN: about 0.2 % of the power lost,
:mod:`sslfr_common.tracking_loss`) and 0.36 deg (ERROR: 2.5-3.4 % lost, growing to
10-17 % at 0.6 deg). Each alarm quotes the estimated optical loss from the collector's
loss table (``accuracy.loss_table``, :mod:`sslfr_common.tracking_loss`). A level is left when the filtered error falls below :data:`CLEAR` times
its threshold (no chatter around a threshold).

"Tracking" (:func:`tracking`) is the planner's phase TRACKING with the driver following
a trajectory (:data:`TRACKING_STATES`: ``following``, or ``waiting`` for the first
point of the newest one, holding that point): not the night's sleeping pose, a stow, a
manual hold. It also excludes the deliberate moves the day report leaves out: no
sample is judged from a setpoint jump (faster
than :data:`MOVE_RATE`: the pre-dawn slew, a stow ramp, a law's repositioning, or the
first sample after any other state) until the axis is within :data:`SETTLE` of its
setpoint, or :data:`MOVE_CAP` seconds later (an axis that never arrives is then judged,
so a fault is never hidden). The window restarts at each move.

The same class runs in the driver (``diagnostics``, logs) and in the day report
(``sslfr report``, on the recorded ``axes/<axis>/status``), so both count the same
time above each threshold.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from sslfr_common.contract import Phase
from sslfr_common.params import ParamSpec
from sslfr_common import tracking_loss
from sslfr_common.tracking_loss import loss_text

#: a setpoint moving faster than this is a deliberate move, not sun tracking [rad/s]: the
#: longitudinal laws' jump bound (0.05 deg in 1 s, docs/optics.md), ten times the fastest
#: sun-following axis rate (~0.004 deg/s)
MOVE_RATE = math.radians(0.05)
#: a move ends when the axis is back within this of its setpoint [rad] (~10 motor steps)
SETTLE = 1e-3
#: a move not settled after this long ends anyway: what follows counts as tracking error [s]
MOVE_CAP = 300.0
#: a level is left when the filtered error falls below CLEAR x its threshold [-]
CLEAR = 0.8
OK, WARN, ERROR = 0, 1, 2
#: the driver's states (AxisStatus.state) in which the axis tracks the sun: following the
#: trajectory, or waiting for the first point of the newest one (that point held; the
#: planner sends a trajectory every 5 s whose first point lies ahead)
TRACKING_STATES = ('following', 'waiting')


def tracking(state: str, phase: int | None) -> bool:
    """Whether a sample is one of sun tracking: the driver's ``state`` (AxisStatus.state)
    in :data:`TRACKING_STATES` during the planner's ``phase`` TRACKING (TrackerPhase.phase;
    None: not known yet)."""
    return state in TRACKING_STATES and phase == Phase.TRACKING
LEVEL_TEXT = {OK: 'OK', WARN: 'WARN', ERROR: 'ERROR'}


def _table_problem(values) -> str | None:
    """Why a flat ``accuracy.loss_table`` is not a loss table (None: it is one)."""
    if len(values) % 3:
        return f'{len(values)} numbers: rows of three expected'
    problems = tracking_loss.table_problems([values[i:i + 3] for i in range(0, len(values), 3)])
    return '; '.join(problems) or None


#: The driver's parameters of the alarm (sslfr_drivers.axis.params adds them to its table).
PARAM_SPECS = (
    ParamSpec('accuracy.warn_threshold', math.radians(0.06), 'tracking error (RMS over accuracy.window, '
              'measured - setpoint while tracking) that raises a WARN [rad]; default 0.06 deg, seed 000 '
              'Figs. 21-24 (~0.2 % optical loss)', 'rad', 1e-5, 0.2),
    ParamSpec('accuracy.error_threshold', math.radians(0.36), 'tracking error that raises the strong '
              'warning (diagnostics ERROR, log ERROR) [rad]; default 0.36 deg, seed 000 Figs. 22-24 '
              '(~2.5-3.4 % optical loss); must exceed accuracy.warn_threshold', 'rad', 1e-5, 0.5),
    ParamSpec('accuracy.window', 60.0, 'window of the RMS filter [s] (ROS time); 0 = the latest '
              'sample alone', 's', 0.0, 3600.0),
    ParamSpec('accuracy.loss_table', [0.0, 0.0, 0.0], 'the collector\'s loss table, rows of (mirror tilt '
              'error [rad], smallest and largest optical loss [%]) flattened, errors from 0 increasing '
              '(seed 000 section 5.2 on the 3-D ray trace for the collector\'s optics at its site: the node '
              'set sets it for the mirror movement, sslfr_planner.analysis.ideal.loss_table); one row: the '
              'loss is not estimated', 'rad, %', 0.0, 100.0,
              validator=_table_problem),
)


def cross_check(p: dict) -> list[str]:
    """The warning threshold must be below the strong one."""
    if not p['accuracy.warn_threshold'] < p['accuracy.error_threshold']:
        return [f"accuracy.warn_threshold {p['accuracy.warn_threshold']!r} rad must be below "
                f"accuracy.error_threshold {p['accuracy.error_threshold']!r} rad"]
    return []


@dataclass(frozen=True)
class AccuracyConfig:
    """Thresholds [rad], filter window [s, ROS time] and the loss table the alarms quote
    (:data:`sslfr_common.tracking_loss.LossTable`; empty: no estimate)."""

    warn: float = math.radians(0.06)
    error: float = math.radians(0.36)
    window: float = 60.0
    loss_table: tracking_loss.LossTable = ()

    @classmethod
    def from_params(cls, p: dict) -> 'AccuracyConfig':
        return cls(p['accuracy.warn_threshold'], p['accuracy.error_threshold'], p['accuracy.window'],
                   tracking_loss.from_flat(p.get('accuracy.loss_table', ())))


class AccuracyAlarm:
    """The alarm of one axis, fed one sample at a time in ROS-time order.

    Attributes
    ----------
    level : int
        OK / WARN / ERROR in force.
    filtered : float
        RMS error over the window [rad] (NaN when not judged).
    time_above : dict
        ROS time [s] spent at WARN or above (key WARN) and at ERROR (key ERROR); an
        interval between two judged samples counts at the level held during it.
    """

    def __init__(self, axis: str, cfg: AccuracyConfig | None = None):
        self.axis = axis
        self.cfg = cfg or AccuracyConfig()
        self.level = OK
        self.filtered = math.nan
        self.peak = 0.0                         # largest filtered error judged [rad]
        self.time_above = {WARN: 0.0, ERROR: 0.0}
        self.judged_time = 0.0                  # ROS time [s] judged (tracking)
        self.tracking = False
        self._samples: deque = deque()          # (t, error^2) in the window
        self._sum = 0.0                         # of error^2 over _samples [rad^2]: a running sum
        self._last_t: float | None = None
        self._last_sp = math.nan
        self._move_since: float | None = None   # ROS time the current move began
        self._following = False                 # the previous sample was following
        self.phase: int | None = None           # the planner's phase (the driver sets it)

    def configure(self, cfg: AccuracyConfig) -> None:
        """New thresholds / window (a run-time parameter change); judged from the next sample."""
        self.cfg = cfg

    def sample(self, t: float, following: bool, setpoint: float, measured: float):
        """One sample at ROS time ``t`` [s]: ``following`` (:func:`tracking` of the
        driver's state and the phase), ``setpoint`` and ``measured`` [rad]. Returns None, or
        ``(level, line)`` when the level changed (the line for the log)."""
        if self._last_t is not None and t <= self._last_t:
            if t == self._last_t:
                return None                      # the same snapshot again
            self._last_t, self._following = None, False   # ROS time went back: start afresh
        prev_t, prev_sp, self._last_t, self._last_sp = self._last_t, self._last_sp, t, setpoint
        err = measured - setpoint
        was_tracking, was_following = self.tracking, self._following
        self._following = following and math.isfinite(err)
        if not self._following:
            self._move_since = None
            return self._stop_judging()
        jump = not was_following or not math.isfinite(prev_sp) or \
            abs(setpoint - prev_sp) > MOVE_RATE * (t - prev_t) + 1e-9
        if jump and self._move_since is None:
            self._move_since = t
        if self._move_since is not None:
            if (jump or abs(err) > SETTLE) and t - self._move_since <= MOVE_CAP:
                return self._stop_judging()
            self._move_since = None
        # judged: the interval since the previous judged sample counts at the level held
        if was_tracking and prev_t is not None:
            dt = t - prev_t
            self.judged_time += dt
            for lvl in (WARN, ERROR):
                if self.level >= lvl:
                    self.time_above[lvl] += dt
        self.tracking = True
        self._samples.append((t, err * err))
        self._sum += err * err
        while self._samples[0][0] < t - self.cfg.window:      # the new sample always stays
            self._sum -= self._samples.popleft()[1]
        if len(self._samples) == 1:
            self._sum = self._samples[0][1]      # exact again: no rounding carried over a day
        self.filtered = math.sqrt(max(self._sum, 0.0) / len(self._samples))
        self.peak = max(self.peak, self.filtered)
        return self._judge()

    def sample_snapshot(self, snap, lifecycle: str, log) -> None:
        """Feed the driver's status numbers (a ``core.Snapshot``, lifecycle state label)
        during :attr:`phase`; a level change is logged with ``log`` (info / warning /
        error by the new level)."""
        change = self.sample(snap.stamp, lifecycle == 'active' and tracking(snap.state, self.phase),
                             snap.setpoint, snap.measured)
        if not change:
            return
        # one call site per severity: rclpy refuses a call site whose severity changes
        if change[0] == ERROR:
            log.error(change[1])
        elif change[0] == WARN:
            log.warning(change[1])
        else:
            log.info(change[1])

    def _stop_judging(self):
        self.tracking = False
        self._samples.clear()
        self._sum = 0.0
        self.filtered = math.nan
        if self.level != OK:
            self.level = OK
            return OK, f'{self.axis}: accuracy alarm cleared: not tracking'
        return None

    def _judge(self):
        f, c = self.filtered, self.cfg
        new = ERROR if f > c.error else WARN if f > c.warn else OK
        if new < self.level:                     # leave a level only clearly below it
            held = c.error if self.level == ERROR else c.warn
            if f >= CLEAR * held:
                new = self.level
        if new == self.level:
            return None
        self.level = new
        return new, self.text()

    def text(self) -> str:
        """The state in one line (the log line of a change and the diagnostics message)."""
        if not self.tracking:
            return f'{self.axis}: not tracking (accuracy not judged)'
        deg, c = math.degrees(self.filtered), self.cfg
        if self.level == OK:
            return f'{self.axis}: tracking error {deg:.3f} deg RMS over {c.window:g} s, within ' \
                   f'{math.degrees(c.warn):.3f} deg'
        thr = c.error if self.level == ERROR else c.warn
        return (f'{self.axis}: tracking error {deg:.3f} deg RMS over {c.window:g} s > '
                f'{math.degrees(thr):.3f} deg: {loss_text(self.filtered, c.loss_table)}')

    def values(self) -> dict:
        """Diagnostics key/values (degrees for people, seconds of ROS time)."""
        c = self.cfg
        return {'level': LEVEL_TEXT[self.level], 'tracking': self.tracking,
                'error_rms_deg': f'{math.degrees(self.filtered):.4f}' if self.tracking else 'nan',
                'peak_deg': f'{math.degrees(self.peak):.4f}',
                'estimated_loss': loss_text(self.filtered, c.loss_table) if self.tracking else '',
                'warn_threshold_deg': f'{math.degrees(c.warn):.4f}',
                'error_threshold_deg': f'{math.degrees(c.error):.4f}', 'window_s': c.window,
                'time_above_warn_s': f'{self.time_above[WARN]:.1f}',
                'time_above_error_s': f'{self.time_above[ERROR]:.1f}',
                'time_judged_s': f'{self.judged_time:.1f}'}
