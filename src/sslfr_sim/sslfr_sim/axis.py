"""Simulated stepper axis board (firmware behaviour of seed 000 section 3.5 boards).

Seed facts used: stepper motors with a step of 0.006 deg (seed 000 section 3.4);
mirrors rotate from -45 deg to +90 deg, +90 deg being the sleeping position (seed
000 section 4, Fig. 13); the mobile structure and the secondary reflector tilt 0..90
deg (Fig. 14; the team convention allows either sign, so the sim spans -90..+90 deg
with the rest position at 0); limit switches mark the initial, last and sleeping
positions (section 3.5.3); the Position PCB measures each joint with an ADNS-9800
laser sensor (section 3.5.4), modelled here as the board's position sensor.

Model
-----
* Joint angle ``angle`` [rad] (the truth), step counter ``counter`` [steps, float
  internally, reported rounded]. One step turns the joint by ``step_rad`` (seed 000
  default 0.006 deg). Power-up: counter 0, not HOMED, FaultBits.RESET, joint where
  it was left (``initial_angle``).
* Trapezoidal motion toward the target: speed limited by ``min(MOVE_TO speed,
  max_speed)`` [steps/s], acceleration ``accel`` [steps/s^2], no overshoot.
* Limit switches: LOW closed when ``angle <= lo``, HIGH when ``angle >= hi``, SLEEP
  when ``|angle - sleep| <= switch_width / 2``. Hard stops ``overtravel`` beyond the
  ends: past them the counter keeps counting but the joint does not move (lost
  steps). A move is stopped (fault LIMIT) when a switch in its direction of travel
  closes, except the switch a HOME is looking for.
* Position sensor (inclinometer/encoder): ``angle + N(0, sensor_noise)`` [rad].
* Faults: ``stalled`` (counter advances, joint does not), watchdog (1 s silence ->
  decelerate to stop, fault WATCHDOG), reset (power cycle), a slipping coupling
  (:meth:`AxisSim.slip`: the joint, and so the sensor, turns away from the motor at a
  steady rate until the slip is complete; the counter does not see it).
* Host-loss stow (SET_HOST_LOSS_STOW, kept like the firmware's EEPROM across resets):
  ``delay_ms`` after the watchdog stop, with the host still silent, the board drives by
  itself to the stow steps (only when HOMED) or toward the stow switch until it closes,
  switches and step range respected; fault HOST_LOSS latched (cleared by MOVE_TO /
  HOME), STATUS flag HOST_LOSS_STOWING while it drives; a host request before the
  delay cancels it, a host command (MOVE_TO, HOME, STOP) ends it.
"""
from __future__ import annotations

import dataclasses
import math
import random
from dataclasses import dataclass

from sslfr_common.contract import JOINT_RANGE, MIRRORS, STOW_POSITION
from sslfr_drivers.link import messages as m
from sslfr_sim.base import Refuse, SimBoard

#: [s] a host-silence watchdog stop reaches standstill within this (firmware
#: boards/axis_state.h AXIS_WATCHDOG_STOP_S): 1 s of silence + 0.15 s <= 1.2 s
WATCHDOG_STOP_S = 0.15



@dataclass
class AxisConfig:
    """Physical parameters of one simulated axis (SI units, radians)."""

    axis: str = MIRRORS
    lo: float = JOINT_RANGE[MIRRORS][0]       # [rad] LOW switch
    hi: float = JOINT_RANGE[MIRRORS][1]       # [rad] HIGH switch
    sleep: float = STOW_POSITION[MIRRORS]     # [rad] SLEEP switch centre
    step_rad: float = m.DEFAULT_STEP_RAD    # [rad/step]
    max_speed: float = 3000.0           # [steps/s]
    accel: float = 6000.0               # [steps/s^2]
    sensor_noise: float = math.radians(0.003)  # [rad] 1-sigma
    has_sensor: bool = True
    switch_width: float = math.radians(0.2)    # [rad] SLEEP switch closed band
    overtravel: float = math.radians(1.0)      # [rad] hard stop beyond each end switch
    initial_angle: float | None = None  # [rad] joint angle at first power-up (None: sleep)

    @classmethod
    def for_axis(cls, axis: str, **kw) -> 'AxisConfig':
        """Configuration of the named axis: end-switch angles ``lo``, ``hi`` and the
        sleeping angle [rad] from the contract (JOINT_RANGE, STOW_POSITION); ``kw`` sets the other fields."""
        (lo, hi), sleep = JOINT_RANGE[axis], STOW_POSITION[axis]
        return cls(axis=axis, lo=lo, hi=hi, sleep=sleep, **kw)


class AxisSim(SimBoard):
    """Stepper axis board (see module docstring)."""

    kind = m.BoardKind.AXIS_STEPPER
    name = 'sim-axis'
    firmware = (1, 0, 0)
    REQUESTS = SimBoard.REQUESTS | {m.GetStatus.TYPE, m.MoveTo.TYPE, m.Stop.TYPE, m.Home.TYPE, m.SetZero.TYPE,
                                    m.SetHostLossStow.TYPE}

    def __init__(self, config: AxisConfig | None = None, board_id: int = 1,
                 rng: random.Random | None = None, **kw):
        self.cfg = config or AxisConfig()
        c = self.cfg
        self.angle = c.sleep if c.initial_angle is None else c.initial_angle
        self.stalled = False
        self.slip_left = 0.0         # [rad] of a slipping coupling still to come
        self.slip_rate = 0.0         # [rad/s] its rate (wall time, as the motion)
        super().__init__(board_id=board_id, rng=rng, **kw)
        axis = m.ConfigRecord.AXES.index(c.axis) if c.axis in m.ConfigRecord.AXES else 0
        self.config = dataclasses.replace(self.config, axis=axis, max_speed=c.max_speed, accel=c.accel)

    @classmethod
    def from_options(cls, options: dict, rng: random.Random, board_id: int = 1) -> 'AxisSim':
        """Build from runner options (``axis``, ``max_speed`` [steps/s], ``accel``
        [steps/s^2], ``sensor_noise_deg``, ``initial_angle_deg``, ``no_sensor``)."""
        opts = dict(options)
        kw = {}
        for key in ('max_speed', 'accel'):
            if key in opts:
                kw[key] = float(opts[key])
        if 'sensor_noise_deg' in opts:
            kw['sensor_noise'] = math.radians(float(opts['sensor_noise_deg']))
        if 'initial_angle_deg' in opts:
            kw['initial_angle'] = math.radians(float(opts['initial_angle_deg']))
        if opts.get('no_sensor') in ('1', 'true', True):
            kw['has_sensor'] = False
        cfg = AxisConfig.for_axis(opts.get('axis', MIRRORS), **kw)
        return cls(cfg, board_id=board_id, rng=rng)

    # ------------------------------------------------------------------ state
    def boot_state(self) -> None:
        stored = getattr(self, 'stored_config', None)
        if stored is not None:        # a SET_CONFIG record takes effect at boot
            self.cfg.max_speed, self.cfg.accel = stored.max_speed, stored.accel
        self.counter = 0.0
        self.target = 0.0
        self.speed = 0.0            # [steps/s] signed
        self.cmd_speed = 0.0        # [steps/s] limit of the current move
        self.homed = False
        self.homing: tuple[int, int] | None = None   # (switch, position)
        self.home_angle: float | None = None         # joint angle [rad] where HOME ended
        self.decel = 0.0            # [steps/s^2] of a watchdog stop (0: accel)
        self.faults = m.FaultBits.RESET
        self.seek: int | None = None                 # switch a host-loss stow drives to
        self.hl_stowing = False
        self.hl_armed_at: float | None = None        # watchdog stop time while a stow waits
        if not hasattr(self, 'host_loss'):
            self.host_loss = m.SetHostLossStow()     # the "EEPROM" record (survives resets)

    def limit_bits(self) -> int:
        """Raw limit-switch bits (:class:`messages.LimitBits`) at the joint angle: LOW at
        or below ``lo``, HIGH at or above ``hi``, SLEEP within ``switch_width``/2 of
        ``sleep`` [rad]."""
        c, a = self.cfg, self.angle
        bits = 0
        if a <= c.lo:
            bits |= m.LimitBits.LOW
        if a >= c.hi:
            bits |= m.LimitBits.HIGH
        if abs(a - c.sleep) <= c.switch_width / 2:
            bits |= m.LimitBits.SLEEP
        return bits

    def sensor_angle(self) -> float:
        """Absolute angle sensor reading [rad]: the joint angle plus Gaussian noise of
        standard deviation ``sensor_noise`` [rad]; NaN when the axis has no sensor."""
        if not self.cfg.has_sensor:
            return math.nan
        return self.angle + self.rng.gauss(0.0, self.cfg.sensor_noise)

    def status(self) -> m.Status:
        """The STATUS answer: counter and target [steps], speed [steps/s] (signed),
        flags, limit and fault bits, sensor angle [rad], uptime [ms]."""
        flags = 0
        if self.speed != 0.0 or self.counter != self.target:
            flags |= m.StatusFlags.MOVING
        if self.homed:
            flags |= m.StatusFlags.HOMED
        if self.homing is not None:
            flags |= m.StatusFlags.HOMING
        if self.cfg.has_sensor:
            flags |= m.StatusFlags.HAS_SENSOR
        if self.hl_stowing:
            flags |= m.StatusFlags.HOST_LOSS_STOWING
        pos = int(round(self.counter))
        return m.Status(pos, int(round(self.target)) if self.homing is None else pos,
                        float(self.speed), int(flags), int(self.limit_bits()),
                        int(self.faults), float(self.sensor_angle()), self.uptime_ms)

    # --------------------------------------------------------------- requests
    def handle(self, msg: m.Message, frame) -> m.Message | None:
        if isinstance(msg, m.GetStatus):
            return self.status()
        if isinstance(msg, m.Stop):
            self._stop()
            self.hl_stowing = False
            return m.Ack(msg.TYPE)
        if isinstance(msg, m.SetHostLossStow):
            if not self._host_loss_valid(msg):
                raise Refuse(m.ErrorCode.OUT_OF_RANGE)
            self.host_loss = msg
            return m.Ack(msg.TYPE)
        if isinstance(msg, m.MoveTo):
            if not self.homed:
                raise Refuse(m.ErrorCode.NOT_HOMED)
            if not (0 < msg.speed) or abs(msg.steps) > 2**30:
                raise Refuse(m.ErrorCode.OUT_OF_RANGE)
            if self.homing is not None:
                raise Refuse(m.ErrorCode.BUSY)
            direction = (msg.steps > self.counter) - (msg.steps < self.counter)
            if self._blocking(direction):
                raise Refuse(m.ErrorCode.LIMIT_ACTIVE)
            self.target = float(msg.steps)
            self.decel = 0.0
            self.seek, self.hl_stowing = None, False
            self.cmd_speed = min(msg.speed, self.cfg.max_speed)
            self.faults &= ~(m.FaultBits.WATCHDOG | m.FaultBits.LIMIT | m.FaultBits.HOST_LOSS)
            return m.Ack(msg.TYPE)
        if isinstance(msg, m.Home):
            if msg.switch not in (0, 1, 2) or msg.speed == 0:
                raise Refuse(m.ErrorCode.OUT_OF_RANGE)
            self.homing = (msg.switch, msg.position)
            self.decel = 0.0
            self.cmd_speed = min(abs(msg.speed), self.cfg.max_speed)
            self.target = self.counter + math.copysign(1e9, msg.speed)
            self.seek, self.hl_stowing = None, False
            self.faults &= ~(m.FaultBits.WATCHDOG | m.FaultBits.LIMIT | m.FaultBits.HOST_LOSS)
            if self.limit_bits() & (1 << msg.switch):
                self._home_done()
            return m.Ack(msg.TYPE)
        if isinstance(msg, m.SetZero):
            self.counter = self.target = float(msg.position)
            self.speed = 0.0
            self.homed = True
            self.faults &= ~m.FaultBits.RESET
            return m.Ack(msg.TYPE)
        return super().handle(msg, frame)

    def busy_for_config(self) -> bool:
        return self.busy()

    # ---------------------------------------------------------------- dynamics
    def busy(self) -> bool:
        return self.speed != 0.0 or self.counter != self.target or self.homing is not None

    def watchdog_expired(self) -> None:
        if self.speed != 0.0 or self.counter != self.target or self.homing is not None:
            self.faults |= m.FaultBits.WATCHDOG
        self.homing = None
        # standstill within WATCHDOG_STOP_S, faster than accel when needed (the firmware's rule)
        self._stop(abs(self.speed) / WATCHDOG_STOP_S)
        self.hl_stowing = False
        self.hl_armed_at = self.now if self.host_loss.mode != m.HostLossMode.OFF else None

    def _host_loss_valid(self, h: m.SetHostLossStow) -> bool:
        """The firmware's rule for a host-loss stow record (hl_valid in boards/axis.cpp)."""
        if h.mode == m.HostLossMode.OFF:
            return True
        if h.mode not in (m.HostLossMode.POSITION, m.HostLossMode.SWITCH) or h.speed == 0 \
                or not 0 < h.delay_ms <= m.HOST_LOSS_MAX_DELAY_MS:
            return False
        if h.mode == m.HostLossMode.POSITION:
            return self.config.min_steps <= h.steps <= self.config.max_steps
        return h.switch in (0, 1, 2)

    def _host_loss_poll(self) -> None:
        """Start the host-loss stow once the host stayed silent for its delay."""
        h = self.host_loss
        if self.hl_armed_at is None:
            return
        if not self.watchdog_tripped or h.mode == m.HostLossMode.OFF:
            self.hl_armed_at = None
            return
        if (self.now - self.hl_armed_at) * 1000.0 < h.delay_ms:
            return
        self.hl_armed_at = None
        speed = min(abs(h.speed), self.cfg.max_speed)
        if h.mode == m.HostLossMode.POSITION:
            if not self.homed:
                return                                       # position unknown: stay
            direction = (h.steps > self.counter) - (h.steps < self.counter)
            if self._blocking(direction):
                return
            self.target = float(h.steps)
        else:
            if self.limit_bits() & (1 << h.switch):
                self.faults |= m.FaultBits.HOST_LOSS
                return
            if self._blocking(1 if h.speed > 0 else -1):
                return
            self.seek = h.switch
            self.target = self.counter + math.copysign(1e9, h.speed)
        self.decel, self.cmd_speed = 0.0, speed
        self.faults |= m.FaultBits.HOST_LOSS
        self.hl_stowing = True

    def _stop(self, decel: float = 0.0) -> None:
        """Decelerate to a stop at max(``decel``, accel) [steps/s^2]: the new target is
        the stopping point."""
        if self.homing is not None:
            self.homing = None
        self.seek = None
        self.decel = decel if decel > self.cfg.accel else 0.0
        v = self.speed
        d = v * v / (2 * max(decel, self.cfg.accel))
        self.target = self.counter + math.copysign(d, v) if v else self.counter

    def _blocking(self, direction: int) -> bool:
        """True if a closed switch forbids moving in ``direction`` (+1 increases angle)."""
        bits = self.limit_bits()
        if self.homing is not None:
            bits &= ~(1 << self.homing[0])
        if direction > 0 and bits & m.LimitBits.HIGH:
            return True
        return bool(direction < 0 and bits & m.LimitBits.LOW)

    def _back_to_edge(self, switch: int, direction: int) -> None:
        """Undo the part of the last sub-step beyond the switch's closing edge (the
        firmware samples its switches at every step, so it stops within one step)."""
        c = self.cfg
        if self.stalled or direction == 0:
            return
        edge = {m.Switch.LOW: c.lo, m.Switch.HIGH: c.hi,
                m.Switch.SLEEP: c.sleep - direction * c.switch_width / 2}[switch]
        beyond = (self.angle - edge) * direction
        if beyond > 0:
            steps_back = math.floor(beyond / c.step_rad)
            self.counter -= direction * steps_back
            self.angle -= direction * steps_back * c.step_rad

    def _home_done(self) -> None:
        _, position = self.homing
        self.homing = None
        self.home_angle = self.angle
        self.counter = self.target = float(position)
        self.speed = 0.0
        self.homed = True
        self.faults &= ~m.FaultBits.RESET

    def slip(self, angle: float, duration: float) -> None:
        """Let the coupling slip: the joint turns ``angle`` [rad] relative to the motor,
        at a steady rate over ``duration`` [s of the board's time], and stays there (the
        step counter does not see it; the sensor does). A power cycle does not undo it."""
        if duration <= 0:
            raise ValueError('slip duration must be > 0 s')
        self.slip_left += angle
        self.slip_rate = abs(self.slip_left) / duration

    def update(self, dt: float) -> None:
        if dt <= 0:
            return
        self._host_loss_poll()
        if self.hl_stowing and not self.busy():
            self.hl_stowing = False
        c = self.cfg
        if self.slip_left:
            d = math.copysign(min(abs(self.slip_left), self.slip_rate * dt), self.slip_left)
            self.slip_left -= d
            self.angle = min(max(self.angle + d, c.lo - c.overtravel), c.hi + c.overtravel)
        # integrate in sub-steps of <= 2 ms and of at most half the SLEEP switch's closed
        # band, so no switch is jumped over at any speed (the firmware samples its
        # switches at every step): at 20000 steps/s a 2 ms sub-step is 0.24 deg, more than
        # the 0.2 deg band, and a stow seeking the switch then ran into the end switch
        vmax = max(abs(self.speed), self.cmd_speed or c.max_speed)
        band = c.switch_width / 2 if c.switch_width > 0 else math.inf
        n = max(1, int(math.ceil(dt / 0.002)), int(math.ceil(vmax * dt * c.step_rad / band)))
        h = dt / n
        for _ in range(n):
            err = self.target - self.counter
            if err == 0.0 and self.speed == 0.0:
                self.decel = 0.0
                break
            accel = max(c.accel, self.decel)
            vmax = self.cmd_speed or c.max_speed
            v_brake = math.sqrt(2 * accel * abs(err))
            v_des = math.copysign(min(vmax, v_brake), err)
            dv = max(-accel * h, min(accel * h, v_des - self.speed))
            self.speed += dv
            move = self.speed * h
            if (err > 0 and move >= err) or (err < 0 and move <= err) or \
                    (abs(err) < 0.5 and abs(self.speed) < accel * h * 2):
                move = err
                self.speed = 0.0
            self.counter += move
            if not self.stalled:
                self.angle += move * c.step_rad
                lo_stop, hi_stop = c.lo - c.overtravel, c.hi + c.overtravel
                self.angle = min(max(self.angle, lo_stop), hi_stop)
            direction = (move > 0) - (move < 0)
            if self.seek is not None and self.limit_bits() & (1 << self.seek):
                self._back_to_edge(self.seek, direction)
                self.seek = None
                self.target = self.counter
                self.speed = 0.0
                break
            if self.homing is not None and self.limit_bits() & (1 << self.homing[0]):
                self._back_to_edge(self.homing[0], direction)
                self._home_done()
                break
            if self._blocking(direction):
                self._back_to_edge(m.Switch.HIGH if direction > 0 else m.Switch.LOW, direction)
                self.faults |= m.FaultBits.LIMIT
                self.homing = None
                self.seek = None
                self.target = self.counter
                self.speed = 0.0
                break
