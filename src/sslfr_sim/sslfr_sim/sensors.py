"""Simulated sensor boards: GPS, absorber (thermocouples + limit switches), irradiance.

Each class is a :class:`~sslfr_sim.base.SimBoard` speaking the board
protocol like the Arduino firmware of seed 000 section 3.5 (streams samples
unsolicited, answers PING / GET_INFO / RESET, NACKs GET_STATUS), driven by the models
of :mod:`sslfr_sim.world`:

* :class:`GpsSim` - a NEO-6M behind an Arduino: one NMEA epoch (RMC, GGA, GSA, GSV)
  per second, forwarded as :class:`NmeaChunk` frames, or - option
  ``framing: raw_nmea`` - as the bare NMEA byte stream of a GPS module plugged on its
  own USB port (no board protocol at all).
* :class:`AbsorberSim` - two MAX6675 words at 4 Hz (the converter's 220 ms
  conversion time) from :class:`~sslfr_sim.world.AbsorberThermal`, and the
  five raw limit switch bits at 20 Hz and on every change.
* :class:`IrradianceSim` - a VEML7700 with the firmware's auto gain / integration
  time (:func:`sslfr_drivers.sensors.veml7700.next_setting`) measuring the clear-sky beam
  illuminance DNI * 104 lm/W (1 % noise).

Time. The boards run on the runner's steady clock ``now`` [s] (CLOCK_MONOTONIC, shared
by every process). The simulated UTC is ``start_utc + speed * (now - anchor)``
(options ``start_utc`` [s since epoch or ISO 8601 string], ``speed`` [-] and
``anchor`` [s of CLOCK_MONOTONIC], default: the board's first tick), the mapping
``sslfr sim`` uses for ``/clock``; without ``start_utc`` it is the wall clock. With
``anchor=hold`` the simulated UTC stays at ``start_utc`` until the runner's ``anchor T``
command: ``sslfr sim`` anchors its sensor boards and ``/clock`` at the same instant,
once the node set is up, however long the start-up took.

World state (how the absorber sees the mirrors). The option ``world`` names a small
JSON file (default: environment variable ``SSLFR_SIM_WORLD``; none = no file) that
simulated boards share::

    {"axes": {"mirrors": {"angle": 0.12}, "mobile_structure": {"angle": 0.3}, ...}}

angles in rad (the joint angle the axis board's position sensor reports). The
absorber reads the ``mirrors`` angle for the focus (mirror error = theta_t / 2 -
angle, seed 000 eq. 17) and all three for its limit switches; without a file or an
entry it assumes ideal tracking (beta_0 = theta_t / 2 while the sun is up, the
sleeping position +pi/2 at night). The writer is the ``sim_board`` runner: when
``SSLFR_SIM_WORLD`` is set, :class:`WorldPublisher` records every simulated axis
board's true joint angle there at 5 Hz (``sslfr sim`` sets it for all simulators).

Fault injection (:meth:`control` of each class, the runner's control channel):
``{"cmd": "fault", "kind": KIND, "active": bool, ...}`` with the kinds of
``./sslfr sim --fault`` (sslfr_sim.faults): ``overtemp`` (outlet forced to
``value`` degC, default 200), ``thermocouple-open`` (``target`` inlet/outlet),
``gps-loss``; plus ``gps-clock`` (``offset`` s added to the receiver's UTC),
``switch`` (``name``, ``closed`` true/false/null to release), ``switch-bounce``
(``name``: next change bounces), ``lux`` (``value`` lx override, null to release),
``cloud`` (``value`` 0..1), ``flow`` (``value`` W/K, 0 = pump stopped), ``wind``
(``value`` mean wind [m/s] of a gusty wind at the anemometer; inactive: back to the
``wind`` option), ``anemometer-silent`` (the pulse samples stop).
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import fcntl
import json
import math
import os
import random
import time

from sslfr_common.contract import (JOINT_RANGE, MIRRORS, MOBILE_STRUCTURE, STOW_POSITION, SWITCH_AXIS, SWITCH_POSITION,
                                   SWITCHES, WIND)
from sslfr_common.files import atomic_write
from sslfr_planner import raytrace

from sslfr_drivers.sensors import anemometer, max6675, thermal
from sslfr_drivers.sensors import veml7700
from sslfr_drivers.link import messages as m
from sslfr_drivers.link.protocol import MAX_PAYLOAD
from sslfr_drivers.link.sensor_messages import (PULSE_PIN_OFF, AlsSample, NmeaChunk, PulseSample, SetPulseInput,
                                                SwitchSample, ThermocoupleSample)
from sslfr_sim.world import AbsorberThermal, GpsReceiver, GustyWind, Sky, ThermalParameters
from sslfr_sim.base import Refuse, SimBoard

#: Defaults: the seed 000 prototype at the University of Almeria (36.83 N, 2.40 W).
DEFAULT_SITE = {'latitude_deg': 36.8381, 'longitude_deg': -2.4597, 'elevation': 60.0}


def _utc_option(value) -> float | None:
    if value in (None, '', 'now'):
        return None
    try:
        return float(value)
    except (TypeError, ValueError):
        t = _dt.datetime.fromisoformat(str(value).replace('Z', '+00:00'))
        if t.tzinfo is None:
            t = t.replace(tzinfo=_dt.timezone.utc)
        return t.timestamp()


def write_axis_angles(path: str, angles: dict[str, float]) -> None:
    """Record joint angles [rad] (axis -> angle) in the shared world file: one
    read-modify-write under an exclusive ``flock`` of ``<path>.lock`` (several runner
    processes share the file: without the lock one could write back another's older
    angle), then an atomic replace (readers take no lock and never see a torn file)."""
    with open(f'{path}.lock', 'a') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            with open(path) as fh:
                world = json.load(fh)
        except (OSError, ValueError):
            world = {}
        if not isinstance(world.get('axes'), dict):
            world['axes'] = {}
        for axis, angle in angles.items():
            world['axes'][axis] = {'angle': float(angle)}
        atomic_write(path, json.dumps(world), fsync=False)


def write_axis_angle(path: str, axis: str, angle: float) -> None:
    """Record ``axis``' joint angle [rad] in the shared world file (:func:`write_axis_angles`)."""
    write_axis_angles(path, {axis: angle})


class WorldPublisher:
    """Writes the joint angle of the simulated axis boards of one runner process to the
    world file every ``period`` seconds (the runner calls :meth:`update` after each
    tick). Several processes share the file: each rewrites only its own axes, in one
    locked read-modify-write (:func:`write_axis_angles`)."""

    def __init__(self, path: str, period: float = 0.2):
        self.path = path
        self.period = period
        self._next = 0.0

    def update(self, boards, now: float) -> None:
        """Write the axis boards' joint angles [rad] to the world file, at most every
        ``period`` [s] (``now`` [s, monotonic])."""
        if now < self._next:
            return
        self._next = now + self.period
        angles = {}
        for board in boards:
            axis = getattr(getattr(board, 'cfg', None), 'axis', None)
            angle = getattr(board, 'angle', None)
            if axis and isinstance(angle, (int, float)):
                angles[axis] = angle
        if angles:
            try:
                write_axis_angles(self.path, angles)
            except OSError:
                pass


def read_axis_angles(path: str | None) -> dict[str, float]:
    """Axis angles [rad] from the world file ({} if absent or unreadable)."""
    if not path:
        return {}
    try:
        with open(path) as fh:
            axes = json.load(fh).get('axes', {})
        return {k: float(v['angle']) for k, v in axes.items()
                if isinstance(v, dict) and isinstance(v.get('angle'), (int, float))}
    except (OSError, ValueError, AttributeError, TypeError):
        return {}


class _SensorSim(SimBoard):
    """Shared plumbing: simulated UTC, site, world file, GET_STATUS refusal."""

    def __init__(self, options: dict | None = None, rng: random.Random | None = None,
                 board_id: int = 1):
        o = dict(options or {})
        self.options = o
        self.start_utc = _utc_option(o.get('start_utc'))
        self.speed = float(o.get('speed', 1.0))
        anchor = o.get('anchor')
        #: held: frozen at start_utc until :meth:`set_anchor`
        self.held = anchor == 'hold'
        self.anchor = float(anchor) if anchor not in (None, '', 'hold') else None
        self.world = o.get('world', os.environ.get('SSLFR_SIM_WORLD'))
        self.site = {k: float(o.get(k, v)) for k, v in DEFAULT_SITE.items()}
        self._t0: float | None = None
        super().__init__(board_id=board_id, rng=rng or random.Random(int(o.get('seed', 1))))

    @classmethod
    def from_options(cls, options: dict, rng: random.Random | None = None, board_id: int = 1):
        """Build from ``sim_board --opt KEY=VALUE`` options (values may be strings)."""
        return cls(options, rng, board_id=board_id)

    def utc(self) -> float:
        """Simulated UTC [s since epoch] at the board's current steady time."""
        if self.start_utc is None:
            return time.time()
        if self.held:
            return self.start_utc
        if self._t0 is None:
            self._t0 = self.anchor if self.anchor is not None else self.now
        return self.start_utc + self.speed * max(0.0, self.now - self._t0)

    def set_anchor(self, anchor: float) -> None:
        """Start the simulated clock: UTC = start_utc at ``anchor`` [s of CLOCK_MONOTONIC]."""
        if not math.isfinite(anchor):
            raise ValueError(f'anchor must be a finite CLOCK_MONOTONIC time, not {anchor!r}')
        self.anchor = self._t0 = float(anchor)
        self.held = False

    def busy(self) -> bool:
        """Sensor boards sample at <= 20 Hz: the runner's 20 ms idle tick is enough."""
        return False

    def handle(self, msg, frame):
        if isinstance(msg, m.GetStatus):
            raise Refuse(m.ErrorCode.UNKNOWN_TYPE)
        return super().handle(msg, frame)

    def control(self, cmd: dict) -> dict:
        """Runner control channel (see module docstring); returns a reply dict."""
        return {'ok': False, 'error': f'unknown command {cmd!r}'}

    @property
    def board_ms(self) -> int:
        return self.uptime_ms


# ------------------------------------------------------------------------ GPS
class GpsSim(_SensorSim):
    """Simulated GPS board (see module docstring). Options: site keys, ``altitude``
    [m MSL, default elevation - geoid], ``geoid_separation`` [m], ``noise`` [m],
    ``satellites``, ``hdop``, ``ttff`` [s], ``clock_offset`` [s],
    ``framing`` (``protocol`` | ``raw_nmea``), ``chunk`` [bytes per NmeaChunk]."""

    kind = m.BoardKind.GPS
    name = 'sim-gps'

    def __init__(self, options: dict | None = None, rng: random.Random | None = None,
                 board_id: int = 1):
        self.framing = str((options or {}).get('framing', 'protocol'))
        if self.framing not in ('protocol', 'raw_nmea'):
            raise ValueError(f"framing must be 'protocol' or 'raw_nmea', not {self.framing!r}")
        super().__init__(options, rng, board_id)
        o = self.options
        sep = float(o.get('geoid_separation', 50.0))
        self.receiver = GpsReceiver(self.site['latitude_deg'], self.site['longitude_deg'],
                                    altitude=float(o.get('altitude', self.site['elevation'] - sep)),
                                    geoid_separation=sep, noise=float(o.get('noise', 2.0)),
                                    satellites=int(o.get('satellites', 8)),
                                    hdop=float(o.get('hdop', 1.1)), ttff=float(o.get('ttff', 1.0)),
                                    seed=int(o.get('seed', 1)))
        self.receiver.clock_offset = float(o.get('clock_offset', 0.0))
        self.chunk = max(1, min(MAX_PAYLOAD, int(o.get('chunk', 64))))
        self._next_epoch = 0.0
        self.epochs = 0

    def boot_state(self):
        self._next_epoch = self.now + 0.2

    def update(self, dt):
        if self.now < self._next_epoch:
            return
        self._next_epoch += 1.0
        if self._next_epoch < self.now:
            self._next_epoch = self.now + 1.0
        # epoch time to the 10 ms the NMEA time fields carry
        data = self.receiver.epoch(math.floor(self.utc() * 100.0) / 100.0)
        self.epochs += 1
        if self.framing == 'raw_nmea':
            self._out += data
            return
        for i in range(0, len(data), self.chunk):
            self.send(NmeaChunk(data[i:i + self.chunk]))

    def _queue(self, frame):
        if self.framing == 'raw_nmea':
            return  # a bare GPS module: no BOOT, no answers, only NMEA text
        super()._queue(frame)

    def receive(self, data: bytes) -> None:
        if self.framing == 'raw_nmea':
            return  # a bare module ignores what the host sends (no UBX config here)
        super().receive(data)

    def control(self, cmd):
        kind = cmd.get('kind')
        if cmd.get('cmd') == 'fault' and kind == 'gps-loss':
            self.receiver.blocked = bool(cmd.get('active', True))
        elif cmd.get('cmd') == 'fault' and kind == 'gps-clock':
            self.receiver.clock_offset = float(cmd.get('offset', 0.0)) if cmd.get('active', True) else 0.0
        else:
            return super().control(cmd)
        return {'ok': True}


# ------------------------------------------------------------------- absorber
#: Switch geometry used when axis angles are known [rad]: (axis, test). The switch ->
#: axis table and the nominal angles are the contract's; the closed bands are the
#: simulated mechanism's (the initial switch is an end stop, the others narrow cams).
_SWITCH_BAND = {name: math.radians(0.5) if name == 'last' else 1e-3 for name in SWITCHES}


def _switch_rule(name: str):
    pos, band = SWITCH_POSITION[name], _SWITCH_BAND[name]
    lo, hi = JOINT_RANGE[SWITCH_AXIS[name]]
    if pos <= lo + 1e-9:                 # an end stop at the low end: closed at or below
        return lambda a: a <= pos + band
    if pos >= hi - 1e-9:                 # at the high end
        return lambda a: a >= pos - band
    if name.startswith('longitudinal'):  # rest position: closed at or below 0
        return lambda a: a <= pos + band
    return lambda a: abs(a - pos) <= band


SWITCH_RULES = {name: (SWITCH_AXIS[name], _switch_rule(name)) for name in SWITCHES}


class AbsorberSim(_SensorSim):
    """Simulated temperature + limit switch board (see module docstring).

    Options: site keys, ``ambient`` [degC], ``flow`` [W/K], ``heat_capacity`` [J/K],
    ``loss`` [W/K], ``temperature`` (initial outlet) [degC], ``cloud`` [0..1],
    ``thermo_period`` [s] (0.25), ``switch_period`` [s] (0.05), ``noise`` [degC] (0.2),
    ``wind`` [m/s] (2: mean of the gusty wind at the cup anemometer, whose pulses are
    counted on the pin the host sets with SetPulseInput; the anemometer follows the
    typical calibration of :mod:`sslfr_drivers.sensors.anemometer`), ``flow_lph`` [L/h]
    (a pulse flow meter on the pulse input instead of the anemometer, the fluid pumped
    at this constant flow: the heat balance's m_dot c_p follows it, and ``flow`` with
    it), ``flow_k_factor`` [pulses/L] (its calibration, default
    :data:`sslfr_drivers.sensors.thermal.K_FACTOR`), ``description`` (a collector
    description's path: its field and receiver focus the sun on the tube, instead of
    seed 000's prototype).
    """

    kind = m.BoardKind.ABSORBER
    name = 'sim-absorber'
    REQUESTS = _SensorSim.REQUESTS | {SetPulseInput.TYPE}

    def __init__(self, options: dict | None = None, rng: random.Random | None = None,
                 board_id: int = 1):
        super().__init__(options, rng, board_id)
        o = self.options
        p = ThermalParameters(heat_capacity=float(o.get('heat_capacity', 6000.0)),
                              loss_coefficient=float(o.get('loss', 8.0)),
                              flow_capacity=float(o.get('flow', 20.0)),
                              ambient=float(o.get('ambient', 25.0)))
        optics = None
        if o.get('description'):
            from sslfr_planner import description as desc_mod
            from sslfr_planner.analysis.ideal import optical_parameters
            desc = desc_mod.load(o['description'])
            optics = optical_parameters(desc)
            p = dataclasses.replace(p, cavity_half_aperture=desc.optics.receiver_width / 2.0)
        self.thermal = AbsorberThermal(p, optics)
        flow = o.get('flow_lph')
        self.flow_lph = None if flow in (None, '') else float(flow)
        self.flow_k_factor = float(o.get('flow_k_factor', thermal.K_FACTOR))
        if self.flow_lph is not None:
            if not (math.isfinite(self.flow_lph) and 0.0 <= self.flow_lph <= 1.0e5):
                raise ValueError(f'flow_lph {self.flow_lph!r}: 0..100000 L/h')
            thermal.check_k_factor(self.flow_k_factor)
            p.flow_capacity = self._flow_capacity(self.flow_lph)
        if 'temperature' in o:
            self.thermal.temperature = float(o['temperature'])
        self.sky = Sky(self.site['latitude_deg'], self.site['longitude_deg'], self.site['elevation'])
        self.sky.cloud_factor = float(o.get('cloud', 1.0))
        self.sky.prepare(self.start_utc if self.start_utc is not None else time.time())
        self.thermo_period = float(o.get('thermo_period', 0.25))
        self.switch_period = float(o.get('switch_period', 0.05))
        self.noise = float(o.get('noise', 0.2))
        self.calm_wind = float(o.get(WIND.name, 2.0))
        self.wind = GustyWind(self.calm_wind, random.Random(self.rng.random()))
        self.pulse_pin = PULSE_PIN_OFF
        self.pulses = 0.0                  # falling edges since SetPulseInput (fractional: phase)
        self.anemometer_silent = False
        self.overtemp: float | None = None
        self.open = {'inlet': False, 'outlet': False}
        self.switch_override: dict[str, bool] = {}
        self.bounce_next: set[str] = set()
        self._last_bits: int | None = None
        self._world_cache: tuple[float, dict] = (-1e9, {})
        self._next_thermo = 0.0
        self._next_switch = 0.0
        self._model_utc: float | None = None

    def boot_state(self):
        self._next_thermo = self.now + 0.25
        self._next_switch = self.now + 0.05
        self._last_bits = None
        self.pulse_pin = PULSE_PIN_OFF

    def handle(self, msg, frame):
        if isinstance(msg, SetPulseInput):
            if msg.pin != PULSE_PIN_OFF and msg.pin not in anemometer.FREE_PINS:
                raise Refuse(m.ErrorCode.OUT_OF_RANGE)
            self.pulse_pin, self.pulses = msg.pin, 0.0
            return m.Ack(msg.TYPE)
        return super().handle(msg, frame)

    def pulse_frequency(self) -> float:
        """Pulse frequency [Hz] on the pulse input: the flow meter's at the pumped flow
        (``flow_lph``), else the anemometer's in the wind now."""
        if self.flow_lph is not None:
            return thermal.pulse_rate(self.flow_lph / 3.6e6, self.flow_k_factor)
        return anemometer.frequency(self.wind.speed)

    def _flow_capacity(self, lph: float) -> float:
        """m_dot c_p [W/K] of ``lph`` [L/h] of water at the inlet (ambient) temperature."""
        t = self.thermal.p.ambient
        return lph / 3.6e6 * thermal.water_density(t) * thermal.water_cp(t)

    def axis_angles(self) -> dict[str, float]:
        """Axis joint angles [rad] from the world file, re-read at most every 0.1 s
        of board time."""
        t, cache = self._world_cache
        if self.now - t >= 0.1:
            cache = read_axis_angles(self.world)
            self._world_cache = (self.now, cache)
        return cache

    def _ideal(self, utc: float) -> dict[str, float]:
        sun = self.sky.sun(utc)
        if not sun.above_horizon:
            return {MIRRORS: STOW_POSITION[MIRRORS]}
        return {MIRRORS: max(SWITCH_POSITION['initial'], min(SWITCH_POSITION['last'], sun.transversal / 2))}

    def update(self, dt):
        utc = self.utc()
        if self._model_utc is None:
            self._model_utc = utc
        sim_dt = utc - self._model_utc
        self._model_utc = utc
        angles = {**self._ideal(utc), **self.axis_angles()}
        self.wind.step(dt)
        self.pulses += self.pulse_frequency() * max(0.0, dt)
        if sim_dt > 0:
            sun = self.sky.sun(utc)
            dni = self.sky.dni(utc) if sun.above_horizon else 0.0
            # the mirrors turn about the tilted rows: theta_t in their frame (planner's command)
            tt = float(raytrace.transversal_angle(raytrace.sun_vector(sun.zenith, sun.azimuth),
                                                  angles.get(MOBILE_STRUCTURE, 0.0)))
            power = self.thermal.focused_power(dni, tt, angles.get(MIRRORS))
            self.thermal.step(sim_dt, power)
        if self.now >= self._next_thermo:
            self._next_thermo = max(self._next_thermo + self.thermo_period, self.now)
            out_t = self.thermal.outlet if self.overtemp is None else self.overtemp
            words = []
            for name, t in (('inlet', self.thermal.inlet), ('outlet', out_t)):
                words.append(max6675.encode(t + self.rng.gauss(0.0, self.noise), self.open[name]))
            self.send(ThermocoupleSample(self.board_ms, *words))
            if self.pulse_pin != PULSE_PIN_OFF and not self.anemometer_silent:
                self.send(PulseSample(self.board_ms, int(self.pulses) & 0xFFFFFFFF, self.pulse_pin))
        bits = self._switch_bits(angles)
        if self._last_bits is not None and bits != self._last_bits:
            changed = bits ^ self._last_bits
            names = {SWITCHES[i] for i in range(5) if changed >> i & 1}
            if names & self.bounce_next:
                # contact bounce: the new state chattered over the last 8 ms
                self.bounce_next -= names
                ms = self.board_ms
                for k, b in enumerate((bits, self._last_bits, bits, self._last_bits)):
                    self.send(SwitchSample((ms - 8 + 2 * k) & 0xFFFFFFFF, b))
            self._last_bits = bits
            self.send(SwitchSample(self.board_ms, bits))
            self._next_switch = self.now + self.switch_period
        elif self.now >= self._next_switch:
            self._last_bits = bits
            self._next_switch = max(self._next_switch + self.switch_period, self.now)
            self.send(SwitchSample(self.board_ms, bits))

    def _switch_bits(self, angles: dict[str, float]) -> int:
        bits = 0
        for i, name in enumerate(SWITCHES):
            if name in self.switch_override:
                closed = self.switch_override[name]
            else:
                axis, test = SWITCH_RULES[name]
                a = angles.get(axis)
                closed = a is not None and test(a)
            bits |= int(closed) << i
        return bits

    def control(self, cmd):
        if cmd.get('cmd') != 'fault':
            return super().control(cmd)
        kind, active = cmd.get('kind'), bool(cmd.get('active', True))
        if kind == 'overtemp':
            self.overtemp = float(cmd.get('value', 200.0)) if active else None
        elif kind == 'thermocouple-open':
            target = cmd.get('target') or 'outlet'
            if target not in self.open:
                return {'ok': False, 'error': f'thermocouple {target!r}: inlet or outlet'}
            self.open[target] = active
        elif kind == 'switch':
            name = cmd.get('name')
            if name not in SWITCHES:
                return {'ok': False, 'error': f'switch {name!r}: one of {SWITCHES}'}
            if cmd.get('closed') is None or not active:
                self.switch_override.pop(name, None)
            else:
                self.switch_override[name] = bool(cmd['closed'])
        elif kind == 'switch-bounce':
            self.bounce_next.add(cmd.get('name'))
        elif kind == 'cloud':
            self.sky.cloud_factor = float(cmd.get('value', 1.0))
        elif kind == 'flow':
            self.thermal.p.flow_capacity = float(cmd.get('value', 20.0))
            if self.flow_lph is not None:     # the meter sees the same flow
                self.flow_lph = self.thermal.p.flow_capacity / self._flow_capacity(1.0)
        elif kind == WIND.name:       # the control kind is the sslfr sim fault's (faults.WIND_FAULT)
            value = float(cmd.get('value', self.calm_wind)) if active else self.calm_wind
            if not (math.isfinite(value) and 0.0 <= value <= 100.0):
                return {'ok': False, 'error': f'wind mean {value!r}: 0..100 m/s'}
            self.wind.mean = value
        elif kind == 'anemometer-silent':
            self.anemometer_silent = active
        else:
            return super().control(cmd)
        return {'ok': True}


# ----------------------------------------------------------------- irradiance
class IrradianceSim(_SensorSim):
    """Simulated VEML7700 board (see module docstring). Options: site keys,
    ``efficacy`` [lm/W] (104), ``cloud`` [0..1], ``lux`` (fixed illuminance
    override [lx]), ``period`` [s] between samples (1.0), ``noise`` (relative, 0.01)."""

    kind = m.BoardKind.IRRADIANCE
    name = 'sim-irradiance'

    def __init__(self, options: dict | None = None, rng: random.Random | None = None,
                 board_id: int = 1):
        super().__init__(options, rng, board_id)
        o = self.options
        self.sky = Sky(self.site['latitude_deg'], self.site['longitude_deg'], self.site['elevation'])
        self.sky.cloud_factor = float(o.get('cloud', 1.0))
        self.sky.prepare(self.start_utc if self.start_utc is not None else time.time())
        self.efficacy = float(o.get('efficacy', veml7700.LUMINOUS_EFFICACY))
        self.lux_override = float(o['lux']) if o.get('lux') not in (None, '') else None
        self.period = float(o.get('period', 1.0))
        self.noise = float(o.get('noise', 0.01))
        self.setting = veml7700.LADDER[2]
        self._next = 0.0

    def boot_state(self):
        self.setting = veml7700.LADDER[2]   # the application note's start: x1/8, 100 ms
        self._next = self.now + 0.1

    def illuminance(self) -> float:
        """True illuminance on the sensor [lx]."""
        if self.lux_override is not None:
            return self.lux_override
        utc = self.utc()
        sun = self.sky.sun(utc)
        return self.sky.dni(utc) * self.efficacy if sun.above_horizon else 0.0

    def update(self, dt):
        if self.now < self._next:
            return
        self._next = max(self._next + self.period, self.now)
        lux = self.illuminance() * (1.0 + self.rng.gauss(0.0, self.noise))
        g, it = self.setting
        count = veml7700.encode(lux, g, it)
        self.send(AlsSample(self.board_ms, count, g, it))
        self.setting = veml7700.next_setting(count, g, it)

    def control(self, cmd):
        if cmd.get('cmd') != 'fault':
            return super().control(cmd)
        kind, active = cmd.get('kind'), bool(cmd.get('active', True))
        if kind == 'lux':
            self.lux_override = float(cmd['value']) if active and cmd.get('value') is not None else None
        elif kind == 'cloud':
            self.sky.cloud_factor = float(cmd.get('value', 1.0)) if active else 1.0
        else:
            return super().control(cmd)
        return {'ok': True}
