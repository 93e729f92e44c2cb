"""Simulated linear-actuator axis board (seed 004 section 2.1), same protocol as the
stepper axis board (docs/protocol.md), board kind AXIS_ACTUATOR.

Seed facts: one linear actuator with a PWM speed controller moves the ten lever arms
through the actuator bar; the inclinometer on line 2 measures the lines' angle. The
sizes come from the collector description's ``actuator`` and ``inclinometer`` blocks
(docs/collectors.md; :mod:`sslfr_common.drives` has the models).

Model
-----
* Truth: actuator length ``length`` [m]; line angle ``angle`` = the lever geometry's
  inverse law of cosines (not linear). Power-up: not HOMED, fault RESET, the lines
  where they were left (``initial_angle``, default the stow angle).
* Every 10 ms the board reads the inclinometer (true angle + mounting offset + noise,
  quantised), removes its calibrated offset and runs :class:`ActuatorLoop` (deadband,
  hysteresis) -> PWM duty -> actuator speed (0 below the start duty).
* Position on the wire: the measured angle in the axis step unit ``step_rad``
  (``messages.DEFAULT_STEP_RAD``), plus the offset SET_ZERO sets (the host references
  the counter to the inclinometer at rest, as with a stepper's position sensor);
  STATUS ``sensor`` is the measured angle [rad]. No limit switches: HOME is not
  implemented (NACK UNKNOWN_TYPE).
* MOVE_TO: target angle = steps x step_rad [rad] (after SET_ZERO's offset), outside
  the mechanical range -> OUT_OF_RANGE; speed [steps/s] x step_rad = the loop's speed
  limit [rad/s]. MOVE_TO clears the WATCHDOG, LIMIT and STALL faults (a new try).
* Stall and time-out (:class:`MotionWatch`): driving with the inclinometer still, or
  a move that does not end -> PWM off, fault STALL. Fault injection ``stalled``: the
  motor is powered but the bar does not move (a jammed mechanism).
* Watchdog (1 s of host silence): PWM off at once (a DC actuator stops within
  milliseconds), fault WATCHDOG when it was driving.
"""
from __future__ import annotations

import dataclasses
import math
import random
from dataclasses import dataclass

from sslfr_common.contract import MIRRORS, DriveKind
from sslfr_common.drives import ActuatorLoop, Inclinometer, LeverGeometry, MotionWatch, speed_for_duty
from sslfr_drivers.link import messages as m
from sslfr_sim.base import Refuse, SimBoard

#: [s] the board's control period (inclinometer read, loop, PWM update)
CONTROL_S = 0.01


@dataclass
class ActuatorConfig:
    """One simulated actuator axis (SI units, radians); :meth:`from_description`."""

    axis: str
    geometry: LeverGeometry
    range: tuple[float, float]        # [rad] mechanical range of the line angle
    stow: float                       # [rad]
    deadband: float                   # [rad]
    max_speed: float                  # [m/s] actuator at full duty
    min_duty: float                   # [-]
    stall_window: float               # [s]
    stall_min: float                  # [rad]
    move_timeout: float               # [s]
    inclinometer: Inclinometer        # the true sensor (offset, noise, resolution)
    offset_cal: float                 # [rad] the offset the board removes (calibration)
    step_rad: float = m.DEFAULT_STEP_RAD
    initial_angle: float | None = None

    @classmethod
    def from_description(cls, desc, axis: str = MIRRORS, **kw) -> 'ActuatorConfig':
        """From a loaded collector description's ``axis`` movement (a
        linear_actuator_inclinometer drive); ``kw`` replaces fields (e.g. a true
        inclinometer offset different from the calibrated one)."""
        from sslfr_planner.description import lever_geometry
        mv = desc.movement(axis)
        if mv is None or mv.drive != DriveKind.LINEAR_ACTUATOR_INCLINOMETER:
            raise ValueError(f'{desc.path}: {axis} is not a linear_actuator_inclinometer movement')
        a, i = mv.actuator, mv.inclinometer
        base = dict(axis=axis, geometry=lever_geometry(mv), range=mv.range, stow=mv.stow, deadband=mv.deadband,
                    max_speed=a['max_speed'], min_duty=a['min_duty'], stall_window=a['stall_window'],
                    stall_min=a['stall_min'], move_timeout=a['move_timeout'],
                    inclinometer=Inclinometer(i['offset'], i['noise'], i['resolution']), offset_cal=i['offset'])
        base.update(kw)
        return cls(**base)


def shipped_description(name: str = 'florianopolis_lepten'):
    """The collector description shipped in sslfr_bringup/config/collectors/."""
    from sslfr_bringup.nodeset import config_dir
    from sslfr_planner.description import load
    return load(config_dir() / 'collectors' / f'{name}.yaml')


def config_from_options(options: dict) -> ActuatorConfig:
    """The actuator axis of runner options (``sim_board`` / ``fw_board --opt``):
    ``description`` (a collector description file; default the shipped seed-004 one),
    ``axis``, ``initial_angle_deg``, ``inclinometer_offset_deg`` (the true mounting
    offset; the board keeps the description's as its calibration), ``max_speed_m_s``
    (the actuator at full duty: ``./sslfr sim`` runs the board on the wall clock, so a
    day at --speed X needs an actuator about X times faster than the description's)."""
    from sslfr_planner.description import load
    opts = dict(options)
    desc = load(opts['description']) if opts.get('description') else shipped_description()
    kw = {}
    if 'initial_angle_deg' in opts:
        kw['initial_angle'] = math.radians(float(opts['initial_angle_deg']))
    if 'max_speed_m_s' in opts:
        kw['max_speed'] = float(opts['max_speed_m_s'])
    cfg = ActuatorConfig.from_description(desc, opts.get('axis', MIRRORS), **kw)
    if 'inclinometer_offset_deg' in opts:
        cfg.inclinometer = dataclasses.replace(cfg.inclinometer,
                                               offset=math.radians(float(opts['inclinometer_offset_deg'])))
    return cfg


class ActuatorSim(SimBoard):
    """Linear actuator axis board (see module docstring)."""

    kind = m.BoardKind.AXIS_ACTUATOR
    name = 'sim-actuator'
    firmware = (1, 0, 0)
    REQUESTS = SimBoard.REQUESTS | {m.GetStatus.TYPE, m.MoveTo.TYPE, m.Stop.TYPE, m.SetZero.TYPE}

    def __init__(self, config: ActuatorConfig, board_id: int = 1, rng: random.Random | None = None, **kw):
        self.cfg = c = config
        start = c.stow if c.initial_angle is None else c.initial_angle
        self.length = c.geometry.length(start)
        self.stalled = False
        super().__init__(board_id=board_id, rng=rng, **kw)
        axis = m.ConfigRecord.AXES.index(c.axis) if c.axis in m.ConfigRecord.AXES else 0
        self.config = dataclasses.replace(self.config, axis=axis)

    @classmethod
    def from_options(cls, options: dict, rng: random.Random, board_id: int = 1) -> 'ActuatorSim':
        """Build from runner options (:func:`config_from_options`)."""
        return cls(config_from_options(options), board_id=board_id, rng=rng)

    @property
    def angle(self) -> float:
        """True line angle [rad] (the lever geometry at the actuator length)."""
        return self.cfg.geometry.angle(self.length)

    # ------------------------------------------------------------------ state
    def boot_state(self) -> None:
        c = self.cfg
        self.loop = ActuatorLoop(c.geometry, c.deadband, c.max_speed, c.min_duty)
        self.watch = MotionWatch(c.stall_window, c.stall_min, c.move_timeout)
        self.zero = 0                 # [steps] counter - measured angle / step_rad
        self.homed = False
        self.target: float | None = None   # [rad] line angle, None: no move
        self.speed_limit = 0.0        # [rad/s]
        self.duty = 0.0
        self.faults = m.FaultBits.RESET
        self._acc = 0.0
        self.last_fault = ''
        self.measured = self._read()

    def _read(self) -> float:
        """One inclinometer reading with the calibrated offset removed [rad]."""
        c = self.cfg
        return c.inclinometer.read(self.angle, self.rng) - c.offset_cal

    def _steps(self, angle: float) -> int:
        return int(round(angle / self.cfg.step_rad)) + self.zero

    def status(self) -> m.Status:
        """STATUS: position and target [steps] from the measured angle, speed [steps/s],
        flags (MOVING while the PWM is on), no limit bits, faults, sensor [rad], uptime."""
        c = self.cfg
        flags = m.StatusFlags.HAS_SENSOR
        if self.duty != 0.0:
            flags |= m.StatusFlags.MOVING
        if self.homed:
            flags |= m.StatusFlags.HOMED
        pos = self._steps(self.measured)
        target = self._steps(self.target) if self.target is not None else pos
        v = speed_for_duty(self.duty, c.max_speed, c.min_duty) if not self.stalled else 0.0
        omega = v / c.geometry.rate(self.angle)
        return m.Status(pos, target, float(omega / c.step_rad), int(flags), 0, int(self.faults),
                        float(self.measured), self.uptime_ms)

    # --------------------------------------------------------------- requests
    def handle(self, msg: m.Message, frame) -> m.Message | None:
        c = self.cfg
        if isinstance(msg, m.GetStatus):
            return self.status()
        if isinstance(msg, m.Stop):
            self._stop()
            return m.Ack(msg.TYPE)
        if isinstance(msg, m.MoveTo):
            if not self.homed:
                raise Refuse(m.ErrorCode.NOT_HOMED)
            target = (msg.steps - self.zero) * c.step_rad
            if not 0 < msg.speed or not c.range[0] <= target <= c.range[1]:
                raise Refuse(m.ErrorCode.OUT_OF_RANGE)
            if self.target is None or self.duty == 0.0:
                self.watch.reset()
            elif target != self.target:
                self.watch.new_target()
            self.target = target
            self.speed_limit = msg.speed * c.step_rad
            self.faults &= ~(m.FaultBits.WATCHDOG | m.FaultBits.LIMIT | m.FaultBits.STALL)
            return m.Ack(msg.TYPE)
        if isinstance(msg, m.SetZero):
            self.zero = int(msg.position) - int(round(self.measured / c.step_rad))
            self.homed = True
            self._stop()              # PWM off: a re-referenced board holds still (as the firmware)
            self.faults &= ~m.FaultBits.RESET
            return m.Ack(msg.TYPE)
        return super().handle(msg, frame)

    def _stop(self) -> None:
        self.target = None
        self.duty = 0.0
        self.loop.driving = False
        self.watch.reset()

    # ---------------------------------------------------------------- dynamics
    def busy(self) -> bool:
        return self.target is not None

    def busy_for_config(self) -> bool:
        return self.duty != 0.0

    def watchdog_expired(self) -> None:
        if self.duty != 0.0 or self.target is not None:
            self.faults |= m.FaultBits.WATCHDOG
        self._stop()

    def update(self, dt: float) -> None:
        if dt <= 0:
            return
        c = self.cfg
        self._acc += dt
        while self._acc >= CONTROL_S:
            self._acc -= CONTROL_S
            self.measured = self._read()
            if self.target is not None:
                self.duty = self.loop.duty(self.target, self.measured, self.speed_limit)
                why = self.watch.update(self.now - self._acc, self.duty != 0.0, self.measured)
                if why is not None:
                    self.last_fault = why
                    self.faults |= m.FaultBits.STALL
                    self._stop()
            v = 0.0 if self.stalled else speed_for_duty(self.duty, c.max_speed, c.min_duty)
            lo, hi = c.geometry.stroke
            self.length = min(max(self.length + v * CONTROL_S, lo), hi)
