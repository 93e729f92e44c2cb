"""``fw_board``: the boards' real firmware in simavr (firmware-in-the-loop) as a drop-in
replacement of ``sim_board``: the same command line, the same pty / symlink / path
file, the same control socket and commands, the same fault kinds.

Each board is one ``fwsim`` process (:class:`~.harness.Harness`) running the exact ELF
that would be flashed, paced to the wall clock (the host's timeouts and the firmware's
``millis()`` agree). What the board is wired to comes from two places:

* the harness's C models: stepper + mechanism (joint angle, limit switches at their
  angles, stall, set angle; the switchless stepper of seed 003 runs the
  ``axis_noswitch`` build on the same model), linear actuator + lever + analogue
  inclinometer (seed 004's ``actuator`` board: stall), the MAX6675 / VEML7700 / NEO-6
  chips on their buses. The drives without switches take the simulators' options
  (``description`` = a collector description file, ``axis``, ``initial_angle_deg``,
  ``inclinometer_offset_deg``, ``max_speed``, ``accel``) and the same parsers;
  an actuator whose drive differs from the shipped seed-004 build runs an image built
  for it (:func:`~.fw_harness.actuator_elf`);
* the physical world of the Python simulators (sim.sensors: sun, absorber thermal
  model, GPS receiver, and their fault commands), run as a *shadow* board whose
  samples are not sent to the host but turned into chip inputs: MAX6675 words,
  switch levels (with contact bounce), illuminance, NMEA bytes.

Wirings: plain (the harness owns the pty; byte faults, disconnect and unplug happen in
the harness) and ``--xbee`` (the simulated coordinator of sim/xbee.py on the pty, each
firmware board's UART on a socketpair behind it; faults as in ``sim_board``).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import random
import socket
import sys
import time

from sslfr_common.contract import MIRRORS
from sslfr_drivers.link import messages as m
from sslfr_sim import board_class
from sslfr_sim.axis import AxisConfig
from sslfr_sim.base import FaultInjector, _split_frames
from sslfr_sim.runner import PtyEndpoint, Runner, board_key, build_parser, serve_until_signalled, xbee_host
from sslfr_drivers.firmware import KIND_TO_BOARD, FirmwareError, eeprom_image, elf
from sslfr_sim.fw_harness import Harness, actuator_elf, actuator_mech, mech_of, sensor_zero_for

_KINDS = {'axis': m.BoardKind.AXIS_STEPPER, 'axis_noswitch': m.BoardKind.AXIS_STEPPER,
          'actuator': m.BoardKind.AXIS_ACTUATOR, 'gps': m.BoardKind.GPS, 'absorber': m.BoardKind.ABSORBER,
          'irradiance': m.BoardKind.IRRADIANCE}
#: the kinds whose board drives a joint (FirmwareAxis)
AXIS_KINDS = ('axis', 'axis_noswitch', 'actuator')
#: the name each firmware reports in INFO (core/board.h BoardDef)
_NAMES = {'axis_noswitch': 'sslfr-axis-nosw'}


def axis_config(kind: str, options: dict):
    """The joint a firmware axis board of ``kind`` drives, from the simulators' options
    (the same parser: one meaning per option): ``axis`` a stepper with switches
    (:class:`sslfr_sim.axis.AxisConfig` of the contract's axis), ``axis_noswitch`` the
    switchless stepper and ``actuator`` the linear actuator of the collector
    ``description`` (:func:`sslfr_sim.switchless.config_from_options`,
    :func:`sslfr_sim.actuator.config_from_options`)."""
    if kind == 'axis_noswitch':
        from sslfr_sim.switchless import config_from_options
        return config_from_options(options)
    if kind == 'actuator':
        from sslfr_sim.actuator import config_from_options
        return config_from_options(options)
    init = options.get('initial_angle_deg')
    return AxisConfig.for_axis(options.get('axis', MIRRORS),
                               initial_angle=math.radians(float(init)) if init not in (None, '') else None)


def config_record(kind: str, options: dict, board_id: int, axis=None) -> m.ConfigRecord:
    """The EEPROM configuration a board gets in simulation: the firmware defaults with
    ``board_id`` and, for axes, ``axis`` and, for steppers, ``max_speed`` [steps/s],
    ``accel`` [steps/s^2] (the switchless stepper: its description's axis config,
    ``axis``) and the optional encoder (``sensor=1``, stepper with switches) from the
    options. The record carries no drive geometry: a stepper's step angle is its
    mechanism's (the host converts steps), the actuator's lever, range and deadband are
    its build's (boards/actuator_params.h, :func:`sslfr_sim.fw_harness.actuator_elf`)."""
    rec = m.ConfigRecord.defaults(int(_KINDS[kind]))
    kw = {'board_id': board_id}
    if kind in AXIS_KINDS:
        name = axis.axis if axis is not None else options.get('axis', MIRRORS)
        kw['axis'] = m.ConfigRecord.AXES.index(name)
    if kind == 'axis':
        for key in ('max_speed', 'accel'):
            if key in options:
                kw[key] = float(options[key])
        if str(options.get('sensor', '0')).lower() in ('1', 'true', 'yes'):
            kw['flags'] = m.CFG_HAS_SENSOR
            kw['sensor_zero'] = sensor_zero_for(0.0)
    elif kind == 'axis_noswitch':
        cfg = axis if axis is not None else axis_config(kind, options)
        kw['max_speed'], kw['accel'] = float(cfg.max_speed), float(cfg.accel)
    import dataclasses
    rec = dataclasses.replace(rec, **kw)
    code = rec.check(int(_KINDS[kind]))
    if code:
        raise ValueError(f'board configuration refused by the firmware rules ({m.ErrorCode(code).name}): {rec}')
    return rec


class _Capture:
    """Mixin: a simulator board whose frames are kept, not sent (the shadow world)."""

    def send(self, msg, ref=None):
        self.__dict__.setdefault('captured', []).append(msg)


class FirmwareBoard:
    """One firmware board with the attributes the sim runner, the XBee coordinator sim
    and ``board_state`` use (receive, take_output, tick, busy, reset, control, counters)."""

    def __init__(self, kind: str, options: dict, rng: random.Random, board_id: int = 1, *,
                 uart_fd: int | None = None, link: str | None = None, path_file: str | None = None,
                 pace: float = 1.0, key: bytes | None = None):
        if kind not in KIND_TO_BOARD:
            raise ValueError(f'no firmware for board kind {kind!r} (known: {", ".join(KIND_TO_BOARD)})')
        self.kind = _KINDS[kind]
        self.board = KIND_TO_BOARD[kind]
        self.name = _NAMES.get(kind, f'sslfr-{self.board}')
        self.rng = rng
        self.options = dict(options)
        mech = act = sensor = elf_path = None
        harness_board = self.board
        if kind in AXIS_KINDS:
            self.cfg = axis_config(kind, options)
            record = config_record(kind, options, board_id, self.cfg)
            if kind == 'actuator':
                act = actuator_mech(self.cfg, self.cfg.initial_angle)
                elf_path = str(actuator_elf(self.cfg))
            else:
                mech = mech_of(self.cfg)
                if kind == 'axis_noswitch':      # the stepper's models, the switchless build
                    harness_board, elf_path = 'axis', str(elf('axis_noswitch'))
                if record.flags & m.CFG_HAS_SENSOR:
                    sensor = record.sensor_zero
        else:
            record = config_record(kind, options, board_id)
        self.shadow = None
        if kind not in AXIS_KINDS:
            if kind == 'gps' and options.get('framing', 'protocol') != 'protocol':
                raise ValueError('a bare GPS module (framing raw_nmea) runs no firmware: use sim_board')
            cls = board_class(kind)
            shadow_cls = type(f'Shadow{cls.__name__}', (_Capture, cls), {})
            self.shadow = shadow_cls.from_options(options, random.Random(rng.random()), board_id=board_id)
        self._sock = None
        if uart_fd is None and link is None and path_file is None:
            ours, theirs = socket.socketpair()
            ours.setblocking(False)
            self._sock, uart_fd = ours, theirs.fileno()
            self._theirs = theirs
        self.harness = Harness(harness_board, eeprom=eeprom_image(record, key), link=link, path_file=path_file,
                               uart_fd=uart_fd, pace=pace, mech=mech, act=act, sensor_zero=sensor,
                               seed=rng.randrange(1, 2**31), elf_path=elf_path)
        self._rx = bytearray()
        self._snap: dict = {}
        self._snap_t = -1.0
        self._last_bits: int | None = None
        self.now = 0.0

    def start(self) -> 'FirmwareBoard':
        self.harness.start()
        if self._sock is not None:
            self._theirs.close()             # the harness holds its end now
        return self

    # -------------------------------------------------------------- byte path (XBee)
    def receive(self, data: bytes) -> None:
        """Host bytes for the board's UART (socketpair wiring)."""
        if self._sock is not None and data:
            self._sock.sendall(data)

    def take_output(self) -> bytes:
        """Whole frames the board sent since the last call (socketpair wiring)."""
        if self._sock is None:
            return b''
        try:
            while True:
                chunk = self._sock.recv(65536)
                if not chunk:
                    break
                self._rx += chunk
        except BlockingIOError:
            pass
        # whole frames only (the coordinator sends one frame per RF packet); bytes
        # before a SYNC cannot come from the firmware and are dropped
        out, buf = bytearray(), self._rx
        while True:
            i = buf.find(b'\xa5\x5a')
            if i < 0:
                del buf[:max(0, len(buf) - 1)]
                break
            del buf[:i]
            if len(buf) < 4 or len(buf) < 12 + buf[3]:
                break
            size = 12 + buf[3]
            out += buf[:size]
            del buf[:size]
        return bytes(out)

    # -------------------------------------------------------------- world
    def tick(self, now: float) -> None:
        """Advance the shadow world to ``now`` [s, monotonic] and hand its values to
        the chip models."""
        self.now = now
        if not self.harness.alive():
            raise FirmwareError(f'the {self.board} harness (fwsim) exited with status {self.harness.proc.returncode}')
        sh = self.shadow
        if sh is None:
            return
        sh.tick(now)
        sh.take_output()
        captured, sh.__dict__['captured'] = sh.__dict__.get('captured', []), []
        nmea, bits, temps, lux = bytearray(), [], None, None
        for msg in captured:
            name = type(msg).__name__
            if name == 'NmeaChunk':
                nmea += msg.data
            elif name == 'ThermocoupleSample':
                temps = (msg.inlet, msg.outlet)
            elif name == 'SwitchSample':
                bits.append(msg.bits)
            elif name == 'AlsSample':
                lux = max(0.0, sh.illuminance() * (1.0 + sh.rng.gauss(0.0, sh.noise)))
        if nmea:
            self.harness.cmd('nmea ' + bytes(nmea).hex())
        if temps:
            self.harness.cmd(f'temps {temps[0]} {temps[1]}')
            if hasattr(sh, 'pulse_frequency'):
                # the cup anemometer's square wave on the pin the firmware counts on (the
                # host sets it: SET_PULSE_INPUT), the firmware counts the edges
                hz = 0.0 if sh.anemometer_silent else sh.pulse_frequency()
                self.harness.cmd(f'pulses {hz:.4f}')
        if lux is not None:
            self.harness.cmd(f'lux {lux:.4f}')
        seq = [b for i, b in enumerate(bits) if i == 0 or b != bits[i - 1]]
        if seq and (len(seq) > 1 or seq[0] != self._last_bits):
            self.harness.cmd('switches ' + ' '.join(str(b) for b in seq))
            self._last_bits = seq[-1]

    def busy(self) -> bool:
        return self._sock is not None       # the XBee path needs the 5 ms runner tick

    def reset(self) -> None:
        """Power-cycle (external reset): the firmware restarts, BOOT."""
        self.harness.cmd('reset')

    # -------------------------------------------------------------- state
    def snapshot(self, max_age: float = 0.1) -> dict:
        """The harness's status, at most ``max_age`` s old."""
        t = time.monotonic()
        if t - self._snap_t > max_age:
            self._snap = self.harness.status()
            self._snap_t = t
        return self._snap

    def extra_state(self) -> dict:
        """The harness's whole state under 'firmware' (control socket ``status``)."""
        return {'firmware': dict(self.snapshot(max_age=0.0))}

    def _get(self, key, default=0):
        return self.snapshot().get(key, default)

    resets = property(lambda self: self._get('resets'))
    frames_in = property(lambda self: self._get('frames_in'))
    frames_out = property(lambda self: self._get('frames_out'))
    requests_stale = property(lambda self: self._get('requests_stale'))
    requests_duplicate = property(lambda self: self._get('requests_duplicate'))
    watchdog_trips = property(lambda self: self._get('watchdog_trips'))
    watchdog_tripped = property(lambda self: self._get('watchdog_tripped', False))

    def stop(self) -> None:
        """Quit the harness; its last state goes to stderr (the board's log in sslfr sim)."""
        if self.harness.alive():
            try:
                print(f'fw_board: {self.name} final state {json.dumps(self.harness.status())}',
                      file=sys.stderr, flush=True)
            except RuntimeError:
                pass
        self.harness.stop()
        if self._sock is not None:
            self._sock.close()


class FirmwareSensor(FirmwareBoard):
    """A sensor board (GPS, absorber, irradiance): takes the simulators' model commands."""

    def control(self, cmd: dict) -> dict:
        """A model command (sim.sensors fault kinds) for the shadow world."""
        return self.shadow.control(cmd)

    def set_anchor(self, anchor: float) -> None:
        """Start the shadow world's simulated clock (sim.sensors ``anchor=hold``)."""
        self.shadow.set_anchor(anchor)


class _DriveBoard(FirmwareBoard):
    """An axis board of any drive: the model's stall switch (control socket ``stall``)."""

    @property
    def stalled(self) -> bool:
        return self._get('stalled', False)

    @stalled.setter
    def stalled(self, value: bool) -> None:
        self.harness.cmd(f'stall {1 if value else 0}')
        self._snap_t = -1.0


class FirmwareAxis(_DriveBoard):
    """A stepper axis board (with or without switches): joint state from the mechanism
    model and the firmware's RAM."""

    @property
    def angle(self) -> float:
        """True joint angle [rad] (the mechanism model)."""
        return self._get('angle', float('nan'))

    @angle.setter
    def angle(self, value: float) -> None:
        self.harness.cmd(f'set_angle {float(value):.9f}')
        self._snap_t = -1.0


    counter = property(lambda self: self._get('counter'))
    target = property(lambda self: self._get('target'))
    speed = property(lambda self: self._get('speed', 0.0))
    homed = property(lambda self: self._get('homed', False))
    faults = property(lambda self: self._get('faults'))


class FirmwareActuator(_DriveBoard):
    """The actuator board: line angle and actuator from the drive model, the loop's
    state from the firmware's RAM (the attributes of sim/actuator.py's board)."""

    @property
    def angle(self) -> float:
        """True line angle [rad] (the lever geometry at the model's actuator length);
        read only, as the simulator's (the lines are not moved by hand)."""
        return self._get('angle', float('nan'))


    @property
    def target(self) -> float | None:
        """The move's target line angle [rad], None without a move."""
        return self._get('act_target') if self._get('has_target', False) else None

    measured = property(lambda self: self._get('measured', float('nan')))   # [rad] the firmware's
    duty = property(lambda self: self._get('duty', 0.0))                     # signed PWM duty (model)
    homed = property(lambda self: self._get('homed', False))
    faults = property(lambda self: self._get('faults'))


def board_type(kind: str) -> type:
    """The FirmwareBoard subclass of a board ``kind``."""
    if kind == 'actuator':
        return FirmwareActuator
    return FirmwareAxis if kind in AXIS_KINDS else FirmwareSensor


def make_firmware_board(kind: str, options: dict, rng: random.Random, board_id: int, **kw) -> FirmwareBoard:
    return board_type(kind)(kind, options, rng, board_id, **kw).start()


# ---------------------------------------------------------------- plain wiring
class HarnessEndpoint:
    """The pty of a plain-wired board is the harness's own (no byte passes through
    Python); this stands in for sim.runner.PtyEndpoint so the runner's control socket
    and commands work unchanged."""

    def __init__(self, board: FirmwareBoard):
        self.board = board
        self._r, self._w = os.pipe()      # never readable: the runner selects on it
        self.unplugged_until = 0.0
        self._plugged = True

    master = property(lambda self: self._r)
    plugged = property(lambda self: self._plugged)
    path = property(lambda self: self.board.harness.path)

    def plug(self) -> None:
        self._plugged = True              # the harness re-creates its pty by itself

    def unplug(self, seconds: float, now: float) -> None:
        self.board.harness.cmd(f'unplug {seconds}')
        self.unplugged_until = now + seconds
        self._plugged = False

    def read(self) -> bytes:
        return b''

    def write(self, data: bytes) -> None:
        pass

    def close(self) -> None:
        for fd in (self._r, self._w):
            try:
                os.close(fd)
            except OSError:
                pass


class HarnessFaults:
    """Stand-in of sim.base.FaultInjector whose faults are applied in the harness."""

    def __init__(self, board: FirmwareBoard):
        self.board = board
        self._values = {'drop': 0.0, 'corrupt': 0.0, 'corrupt_frames': 0.0}
        self._silent_until = 0.0

    def __getattr__(self, name):
        if name in ('drop', 'corrupt', 'corrupt_frames'):
            return self.__dict__['_values'][name]
        keys = {'bytes_dropped': 'bytes_dropped', 'bytes_corrupted': 'bytes_corrupted',
                'frames_corrupted': 'frames_corrupted', 'frames_silenced': 'bytes_silenced'}
        if name in keys:
            return self.__dict__['board'].snapshot().get(keys[name], 0)
        raise AttributeError(name)

    def __setattr__(self, name, value):
        if name in ('drop', 'corrupt', 'corrupt_frames'):
            self.board.harness.cmd(f'{name} {float(value):g}')
            self._values[name] = float(value)
        elif name == 'silent_until':
            self.board.harness.cmd(f'disconnect {max(0.0, value - time.monotonic()):.3f}')
            self.__dict__['_silent_until'] = value
        else:
            super().__setattr__(name, value)

    @property
    def silent_until(self) -> float:
        return self._silent_until

    def silent(self, now: float) -> bool:
        return now < self._silent_until


class PlainFirmwareHost:
    """One plain-wired firmware board (the runner's host object)."""

    def __init__(self, board: FirmwareBoard, faults: HarnessFaults):
        self.boards = [(None, board, faults)]

    def from_wire(self, data: bytes, now: float) -> None:
        pass

    def to_wire(self, now: float) -> bytes:
        return b''


# ---------------------------------------------------------------- command line
def parser() -> argparse.ArgumentParser:
    p = build_parser()
    p.prog = 'fw_board'
    p.description = ('The boards\' real firmware in simavr on a real pty: a drop-in replacement of '
                     'sim_board (same options, control socket and commands).')
    p.add_argument('--pace', type=float, default=1.0,
                   help='simulated seconds per wall second of the AVR (default 1: real time; 0: free run)')
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``fw_board``; exit status 0, 2 on bad arguments, 1 if a board
    cannot start."""
    args = parser().parse_args(argv)
    if args.protocol_version is not None:
        print('fw_board: the firmware speaks protocol version 2 only (--protocol-version is for sim_board)',
              file=sys.stderr)
        return 2
    rng = random.Random(args.seed)
    opts = dict(o.split('=', 1) for o in args.opt)
    ok, key = board_key(args, 'fw_board')
    if not ok:
        return 2

    def announce(path):
        print(f'SIM_PTY {path}', flush=True)

    boards: list[FirmwareBoard] = []
    try:
        if args.xbee:
            def make(kind, options, board_id):
                board = make_firmware_board(kind, options, rng, board_id, pace=args.pace, key=key)
                boards.append(board)
                return board

            def injector():
                return FaultInjector(drop=args.drop, corrupt=args.corrupt, corrupt_frames=args.corrupt_frames,
                                     rng=random.Random(rng.random()))
            host = xbee_host(args.board, opts, make, injector, 'fw_board')
            if host is None:
                return 2
            endpoint = PtyEndpoint(args.link, args.path_file, announce)
        else:
            opts.setdefault('axis', args.axis)
            board = board_type(args.kind)(
                args.kind, opts, rng, 1, link=args.link, path_file=args.path_file, pace=args.pace, key=key)
            board.harness.on_pty = announce
            board.start()
            boards.append(board)
            faults = HarnessFaults(board)
            for name in ('drop', 'corrupt', 'corrupt_frames'):
                if getattr(args, name):
                    setattr(faults, name, getattr(args, name))
            host = PlainFirmwareHost(board, faults)
            endpoint = HarnessEndpoint(board)
        return serve_until_signalled(Runner(endpoint, host, control=args.control))
    except (ValueError, FirmwareError) as exc:
        print(f'fw_board: {exc}', file=sys.stderr)
        return 1
    finally:
        for b in boards:
            b.stop()


if __name__ == '__main__':
    sys.exit(main())
