"""One firmware-in-the-loop board: the simavr harness process ``firmware/build/fwsim``
running a board's exact ELF, driven through its stdin/stdout command channel.

>>> h = Harness('axis', link='/tmp/ax').start()      # doctest: +SKIP
>>> h.path                                           # the pty the host opens
>>> h.status()['counter'], h.cmd('set_angle 0.5')

Commands and the status fields are documented in ``firmware/sim/fwsim.c``. Pure Python.
"""
from __future__ import annotations

import json
import math
import os
import queue
import subprocess
import tempfile
import threading
import time
from pathlib import Path

from sslfr_drivers.firmware import FirmwareError, build, elf, harness_path


class Harness:
    """The ``fwsim`` process of one board.

    Parameters
    ----------
    board : str
        'axis', 'absorber', 'irradiance', 'gps' or 'actuator' (selects the ELF and the
        models; the switchless stepper runs as 'axis' with ``elf_path`` its ELF).
    eeprom : bytes, optional
        EEPROM image loaded at power-up (the configuration record, messages.ConfigRecord).
    link, path_file : str, optional
        Symlink / file kept pointing at the UART's pty.
    uart_fd : int, optional
        Put the UART on this inherited descriptor instead of a pty (XBee wiring).
    pace : float
        Simulated seconds per wall second (1: the firmware's millis() runs with the
        host's steady clock; 0: free run).
    mech : tuple, optional
        Axis mechanism (lo, hi, sleep, step_rad, switch_width, overtravel, angle) [rad].
    act : tuple, optional
        Actuator board's drive (:func:`actuator_mech`).
    sensor_zero : int, optional
        Fit the optional AS5048A encoder (count at joint angle 0).
    bootloader : str, optional
        Put this bootloader (.hex) in flash and start there (BOOTRST, as the Pro Mini's
        fuses); ``app=False`` leaves the application flash empty (flash tests).
    """

    def __init__(self, board: str, *, eeprom: bytes | None = None, link: str | None = None,
                 path_file: str | None = None, uart_fd: int | None = None, pace: float = 1.0,
                 mech: tuple | None = None, act: tuple | None = None, sensor_zero: int | None = None, seed: int = 1,
                 bootloader: str | None = None, app: bool = True, elf_path: str | None = None, log=None):
        self.board = board
        self.eeprom = eeprom
        self.link, self.path_file, self.uart_fd = link, path_file, uart_fd
        self.act = act
        self.pace, self.mech, self.sensor_zero, self.seed = pace, mech, sensor_zero, seed
        self.bootloader = bootloader
        self.app = app
        self.elf_path = elf_path
        self.log = log
        self.path = ''
        self.resets = 0
        self.proc: subprocess.Popen | None = None
        self._replies: queue.Queue = queue.Queue()
        self._lock = threading.Lock()
        self._pty_event = threading.Event()
        self._ready = threading.Event()
        self.on_pty = None          # callback(path) after every (re)created pty
        self._tmp = None

    def argv(self) -> list[str]:
        argv = [str(harness_path()), '--board', self.board, '--pace', f'{self.pace:g}', '--seed', str(self.seed)]
        if self.bootloader:
            argv += ['--bootloader', str(self.bootloader)]
        # without the application in flash (it comes later, through the bootloader) only
        # its symbols are read (status: the firmware's variables)
        argv += ['--elf' if self.app else '--symbols', str(self.elf_path or elf(self.board))]
        if self.eeprom is not None:
            fd, self._tmp = tempfile.mkstemp(prefix='fwsim-ee', suffix='.bin')
            with os.fdopen(fd, 'wb') as fh:
                fh.write(self.eeprom)
            argv += ['--eeprom', self._tmp]
        if self.uart_fd is not None:
            argv += ['--uart-fd', str(self.uart_fd)]
        else:
            if self.link:
                argv += ['--link', self.link]
            if self.path_file:
                argv += ['--path-file', self.path_file]
        if self.mech is not None:
            argv += ['--mech', ','.join(f'{v:.12g}' for v in self.mech)]
        if self.act is not None:
            argv += ['--act', ','.join(f'{v:.12g}' for v in self.act)]
        if self.sensor_zero is not None:
            argv += ['--sensor', str(int(self.sensor_zero))]
        return argv

    def start(self, timeout: float = 20.0) -> 'Harness':
        """Start the process (building the firmware if needed); wait for its pty."""
        if not harness_path().exists() or not Path(self.elf_path or elf(self.board)).exists():
            build()
        pass_fds = (self.uart_fd,) if self.uart_fd is not None else ()
        # its own session: a signal to the caller's process group (Ctrl-C, the supervisor's
        # stop) reaches the caller, which quits the harness; it also quits when its stdin
        # closes (the caller died)
        self.proc = subprocess.Popen(self.argv(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=self.log or subprocess.DEVNULL, text=True, bufsize=1,
                                     pass_fds=pass_fds, start_new_session=True)
        threading.Thread(target=self._read, name=f'fwsim-{self.board}', daemon=True).start()
        if not self._ready.wait(timeout) or (self.uart_fd is None and not self._pty_event.wait(timeout)):
            self.stop()
            raise FirmwareError(f'fwsim {self.board} did not start: {" ".join(self.argv())}')
        return self

    def _read(self) -> None:
        for line in self.proc.stdout:
            if not line.startswith('FWSIM '):
                continue                      # libsimavr's own messages
            word, _, rest = line[6:].rstrip('\n').partition(' ')
            if word == 'pty':
                self.path = rest
                self._pty_event.set()
                if self.on_pty:
                    self.on_pty(rest)
            elif word == 'ready':
                self._ready.set()
            elif word == 'reset':
                self.resets = int(rest)
            elif word == 'status':
                self._replies.put(json.loads(rest))
            elif word in ('ok', 'error'):
                self._replies.put({'ok': word == 'ok', 'error': rest} if word == 'error' else {'ok': True})
        self._replies.put({'ok': False, 'error': 'fwsim exited'})

    def cmd(self, line: str, timeout: float = 5.0) -> dict:
        """Send one command line; its reply (status: the JSON state). RuntimeError on an
        error reply or no reply."""
        with self._lock:
            if self.proc is None or self.proc.poll() is not None:
                raise RuntimeError(f'fwsim {self.board} is not running')
            self.proc.stdin.write(line.strip() + '\n')
            self.proc.stdin.flush()
            try:
                reply = self._replies.get(timeout=timeout)
            except queue.Empty:
                raise RuntimeError(f'fwsim {self.board}: no reply to {line!r}') from None
        if reply.get('ok') is False:
            raise RuntimeError(f'fwsim {self.board}: {line!r}: {reply.get("error")}')
        return reply

    def status(self) -> dict:
        """The harness's JSON state (see fwsim.c)."""
        return self.cmd('status')

    def wait(self, predicate, timeout: float, period: float = 0.05) -> dict:
        """Poll :meth:`status` until ``predicate(status)``; return the last status
        (TimeoutError when it never held)."""
        deadline = time.monotonic() + timeout
        while True:
            st = self.status()
            if predicate(st):
                return st
            if time.monotonic() > deadline:
                raise TimeoutError(f'fwsim {self.board}: condition not met in {timeout} s: {st}')
            time.sleep(period)

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def stop(self) -> None:
        """Quit the process (kill after 3 s) and remove temporary files."""
        if self.proc is not None and self.proc.poll() is None:
            try:
                self.proc.stdin.write('quit\n')
                self.proc.stdin.flush()
                self.proc.wait(3)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait(3)
        if self._tmp:
            try:
                os.unlink(self._tmp)
            except OSError:
                pass
            self._tmp = None

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()


def axis_mech(axis: str, initial_angle: float | None = None) -> tuple:
    """The mechanism of ``axis`` as the simulator models it (sim/axis.py AxisConfig):
    (lo, hi, sleep, step_rad, switch_width, overtravel, initial angle) [rad]."""
    from sslfr_sim.axis import AxisConfig
    return mech_of(AxisConfig.for_axis(axis), initial_angle)


def mech_of(c, initial_angle: float | None = None) -> tuple:
    """``fwsim --mech`` of a :class:`sslfr_sim.axis.AxisConfig` (a stepper axis: switch
    angles or, switchless, the range ends the hard stops are ``overtravel`` beyond; the
    step [rad/step]) with the joint at ``initial_angle`` [rad] (default the config's,
    else its sleep angle)."""
    angle = initial_angle if initial_angle is not None else c.initial_angle
    angle = c.sleep if angle is None else angle
    return (c.lo, c.hi, c.sleep, c.step_rad, c.switch_width, c.overtravel, angle)


def sensor_zero_for(offset: float = 0.0) -> int:
    """AS5048A count [0, 16384) at joint angle 0 for an encoder mounted ``offset`` [rad]."""
    return int(round(offset / (2 * math.pi) * 16384)) % 16384


def actuator_mech(config, initial_angle: float | None = None, noise_mv: float = 3.0) -> tuple:
    """The actuator board's drive for ``fwsim --act`` from a :class:`sslfr_sim.actuator.ActuatorConfig`
    (lever geometry, stroke, speed at full duty, start duty, the TRUE inclinometer mounting
    offset) with ``noise_mv`` [mV rms] of electrical noise on every ADC conversion and the
    line at ``initial_angle`` [rad] (default the stow angle)."""
    g = config.geometry
    angle = config.stow if initial_angle is None else initial_angle
    return (g.lever, g.mount_distance, g.mount_angle, g.stroke[0], g.stroke[1], config.max_speed,
            config.min_duty, config.inclinometer.offset, noise_mv, angle)


# ----------------------------------------------------------------- actuator builds
#: the actuator firmware's compile-time drive parameters (boards/actuator_params.h):
#: name -> (unit in the header: 'm', 'm/s', '1', 'deg' (radians here), 'ms' (s here))
ACTUATOR_PARAMS = {
    'ACT_LEVER_M': 'm', 'ACT_MOUNT_M': 'm', 'ACT_MOUNT_ANGLE': 'deg', 'ACT_STROKE_MIN': 'm',
    'ACT_STROKE_MAX': 'm', 'ACT_RANGE_LO': 'deg', 'ACT_RANGE_HI': 'deg', 'ACT_DEADBAND': 'deg',
    'ACT_MAX_SPEED': 'm/s', 'ACT_MIN_DUTY': '1', 'ACT_STALL_WINDOW_MS': 'ms', 'ACT_STALL_MIN': 'deg',
    'ACT_TIMEOUT_MS': 'ms', 'ACT_OFFSET_CAL': 'deg',
}
#: [s] the motion watch's block (actuator.cpp BLOCK_MS); the stall window holds 4..50 of
#: them (the block means are kept in RAM: 4 bytes each)
_BLOCK_S = 0.1
_BLOCKS = (4, 50)


def actuator_params(config) -> dict[str, float]:
    """The actuator firmware's drive parameters for a :class:`sslfr_sim.actuator.ActuatorConfig`
    (SI units, radians, seconds; names of boards/actuator_params.h). The firmware removes
    the description's calibrated offset (``offset_cal``); the model's true offset is
    :func:`actuator_mech`'s. ValueError when the firmware cannot take the drive (a
    stall window that is not 4..50 blocks of 100 ms)."""
    g = config.geometry
    blocks = config.stall_window / _BLOCK_S
    if abs(blocks - round(blocks)) > 1e-6 or not _BLOCKS[0] <= round(blocks) <= _BLOCKS[1]:
        raise ValueError(f'actuator firmware: stall_window_s {config.stall_window:g} s is not '
                         f'{_BLOCKS[0]}..{_BLOCKS[1]} blocks of {_BLOCK_S:g} s')
    return {'ACT_LEVER_M': g.lever, 'ACT_MOUNT_M': g.mount_distance, 'ACT_MOUNT_ANGLE': g.mount_angle,
            'ACT_STROKE_MIN': g.stroke[0], 'ACT_STROKE_MAX': g.stroke[1], 'ACT_RANGE_LO': config.range[0],
            'ACT_RANGE_HI': config.range[1], 'ACT_DEADBAND': config.deadband, 'ACT_MAX_SPEED': config.max_speed,
            'ACT_MIN_DUTY': config.min_duty, 'ACT_STALL_WINDOW_MS': config.stall_window,
            'ACT_STALL_MIN': config.stall_min, 'ACT_TIMEOUT_MS': config.move_timeout,
            'ACT_OFFSET_CAL': config.offset_cal}


def compiled_actuator_params(text: str | None = None) -> dict[str, float]:
    """The defaults of boards/actuator_params.h (``text``: its contents) in the units of
    :func:`actuator_params`."""
    import re
    from sslfr_drivers.firmware import firmware_dir
    if text is None:
        text = (firmware_dir() / 'boards' / 'actuator_params.h').read_text()
    out = {}
    for name, unit in ACTUATOR_PARAMS.items():
        mo = re.search(rf'#define {name} \(?(-?[0-9.]+(?:e[-+]?[0-9]+)?)(f|u|ul)?( \* DEG\))?', text)
        if mo is None:
            raise FirmwareError(f'boards/actuator_params.h: no {name}')
        v = float(mo.group(1))
        # as C reads it: `* DEG` converts degrees, the generated headers give radians
        out[name] = math.radians(v) if mo.group(3) else v / 1000.0 if unit == 'ms' else v
    return out


def actuator_params_header(params: dict[str, float]) -> str:
    """A header that overrides boards/actuator_params.h's defaults (``-include``): the
    C definitions of :func:`actuator_params`."""
    lines = ['/* generated by sslfr_sim.fw_harness.actuator_elf: one collector\'s actuator drive */']
    for name, unit in ACTUATOR_PARAMS.items():
        v = params[name]
        lines.append(f'#define {name} {round(v * 1000)}ul' if unit == 'ms' else f'#define {name} ({float(v)!r}f)')
    return '\n'.join(lines) + '\n'


def actuator_elf(config) -> Path:
    """The actuator firmware for ``config``'s drive: build/actuator.elf when its
    parameters are boards/actuator_params.h's (the shipped seed-004 description), else
    an image built for them (build/variants/actuator-HASH.elf, made by ``make`` on use,
    as an installer would build the board for another collector; the parameters are
    constants: its flash is the shipped build's, its RAM grows by 4 B per 100 ms of
    stall window, at most 5 s). FirmwareError when it cannot be built."""
    import hashlib
    from sslfr_drivers.firmware import build, build_dir
    want = actuator_params(config)
    have = compiled_actuator_params()
    if all(math.isclose(want[k], have[k], rel_tol=1e-6, abs_tol=1e-9) for k in ACTUATOR_PARAMS):
        return elf('actuator')
    text = actuator_params_header(want)
    tag = hashlib.sha1(text.encode()).hexdigest()[:12]
    out = build_dir() / 'variants' / f'actuator-{tag}.elf'
    out.parent.mkdir(parents=True, exist_ok=True)
    header = out.with_suffix('.h')
    if not header.exists() or header.read_text() != text:
        tmp = header.with_suffix(f'.h.{os.getpid()}')
        tmp.write_text(text)
        os.replace(tmp, header)
    build(f'build/variants/{out.name}')      # make: rebuilt when the sources changed
    return out
