"""The board firmware (``firmware/``) seen from Python: where the build lives, how to
build it, and what is missing when the toolchain is not installed.

Modules: :mod:`.native` (the firmware's protocol code as a host library, ctypes),
:mod:`sslfr_sim.fw_harness` (one simavr harness process, ``firmware/sim/fwsim.c``),
:mod:`sslfr_sim.fw_board` (``fw_board``: firmware boards as a drop-in replacement of
``sim_board``; both are simulators, the product never imports them), :mod:`.flash`
(``sslfr flash``). Pure Python, no rclpy.
"""
from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
from pathlib import Path

#: the firmware images: axis_noswitch is axis.cpp built without switches (seed 003),
#: actuator the linear actuator closed on an inclinometer (seed 004)
BOARDS = ('axis', 'absorber', 'irradiance', 'gps', 'axis_noswitch', 'actuator')
#: board kind name of the simulators (sim.KINDS) -> firmware board
KIND_TO_BOARD = {'axis': 'axis', 'absorber': 'absorber', 'irradiance': 'irradiance', 'gps': 'gps',
                 'axis_noswitch': 'axis_noswitch', 'actuator': 'actuator'}
ARDUINO = Path('/usr/share/arduino/hardware/arduino/avr')
#: the bootloader Debian's arduino-core-avr ships for the Pro Mini 16 MHz ATmega328P
#: (boards.txt pro.menu.cpu.16MHzatmega328.bootloader.file; avrdude -c arduino -b 57600)
BOOTLOADER = ARDUINO / 'bootloaders' / 'atmega' / 'ATmegaBOOT_168_atmega328.hex'
BOOTLOADER_BAUD = 57600
#: Debian packages of the toolchain (scripts/setup.sh installs them as root)
APT_PACKAGES = ('gcc-avr', 'binutils-avr', 'avr-libc', 'arduino-core-avr', 'simavr', 'libsimavr2',
                'libsimavrparts1', 'libsimavr-dev', 'libelf-dev', 'pkg-config', 'avrdude')


#: EEPROM layout (firmware/lib/msgs.h): configuration record + CRC at 0, the installation
#: key + CRC at KEY_EEPROM_ADDR, the u32 boot count at BOOT_EEPROM_ADDR
KEY_EEPROM_ADDR = 64
BOOT_EEPROM_ADDR = 96
EEPROM_IMAGE_SIZE = 100


def key_eeprom_image(key: bytes) -> bytes:
    """The EEPROM block of an installation key: the 16 bytes and their CRC-16."""
    from sslfr_drivers.link.protocol import crc16
    if len(key) != 16:
        raise ValueError('an installation key is 16 bytes')
    return bytes(key) + crc16(bytes(key)).to_bytes(2, 'little')


def eeprom_image(record, key: bytes | None = None, boot_count: int | None = None) -> bytes:
    """A board's EEPROM as written by the configuration, provisioning and the firmware:
    ``record`` (messages.ConfigRecord), the installation ``key`` (None: blank, an
    unprovisioned board), the stored boot count (None: blank). Unused bytes are 0xFF
    (erased)."""
    img = bytearray(b'\xff' * EEPROM_IMAGE_SIZE)
    cfg = record.eeprom_image()
    img[:len(cfg)] = cfg
    if key is not None:
        img[KEY_EEPROM_ADDR:KEY_EEPROM_ADDR + 18] = key_eeprom_image(key)
    if boot_count is not None:
        img[BOOT_EEPROM_ADDR:BOOT_EEPROM_ADDR + 4] = (boot_count & 0xFFFFFFFF).to_bytes(4, 'little')
    return bytes(img)


class FirmwareError(RuntimeError):
    """The firmware or its tools cannot be built or run (message says why)."""


def root() -> Path:
    """The repository checkout holding ``firmware/`` ($SSLFR_ROOT, else found from here)."""
    env = os.environ.get('SSLFR_ROOT')
    if env and (Path(env) / 'firmware' / 'Makefile').is_file():
        return Path(env)
    for parent in Path(__file__).resolve().parents:
        if (parent / 'firmware' / 'Makefile').is_file():
            return parent
    raise FirmwareError('firmware/ not found: set SSLFR_ROOT to the checkout')


def firmware_dir() -> Path:
    return root() / 'firmware'


def build_dir() -> Path:
    return firmware_dir() / 'build'


def elf(board: str) -> Path:
    """The board's firmware ELF (what simavr runs)."""
    return build_dir() / f'{board}.elf'


def hexfile(board: str) -> Path:
    """The board's Intel HEX (what avrdude writes)."""
    return build_dir() / f'{board}.hex'


def harness_path() -> Path:
    return build_dir() / 'fwsim'


def hostlib_path() -> Path:
    return build_dir() / 'host' / 'libsslfr_proto.so'


_NEEDS = {
    'firmware': (('avr-gcc', 'gcc-avr'), ('avr-g++', 'gcc-avr'), ('avr-objcopy', 'binutils-avr'),
                 ('avr-size', 'binutils-avr')),
    'sim': (('gcc', 'gcc'),),
    'host': (('gcc', 'gcc'),),
    'flash': (('avrdude', 'avrdude'),),
}


def toolchain_problem(*what: str) -> str | None:
    """Why the firmware parts ``what`` ('firmware', 'sim', 'host', 'flash') cannot be
    built/run here, with the command that fixes it; None when everything is present."""
    missing: list[str] = []
    for part in what or ('firmware', 'sim', 'host'):
        for tool, pkg in _NEEDS[part]:
            if shutil.which(tool) is None and pkg not in missing:
                missing.append(pkg)
        if part == 'firmware' and not (ARDUINO / 'cores' / 'arduino' / 'Arduino.h').is_file():
            missing.append('arduino-core-avr')
        if part == 'firmware' and not Path('/usr/lib/avr/include/avr/io.h').is_file():
            missing.append('avr-libc')
        if part == 'sim':
            if not Path('/usr/include/simavr/sim_avr.h').is_file():
                missing.append('libsimavr-dev')
            if not Path('/usr/include/libelf.h').is_file():
                missing.append('libelf-dev')
    if not missing:
        return None
    return (f'firmware toolchain missing ({", ".join(dict.fromkeys(missing))}): '
            f'sudo apt-get install --no-install-recommends {" ".join(APT_PACKAGES)} '
            f'(or run make setup as root on Debian/Ubuntu)')


def build(*targets: str) -> None:
    """``make -C firmware TARGETS`` (default: boards, harness, host library), serialised
    between processes by a lock file; FirmwareError with make's output on failure."""
    targets = targets or ('all', 'sim', 'host')
    parts = {'all': 'firmware', 'sim': 'sim', 'host': 'host'}
    problem = toolchain_problem(*(parts.get(t, 'firmware') for t in targets))
    if problem:
        raise FirmwareError(problem)
    fw = firmware_dir()
    (fw / 'build').mkdir(exist_ok=True)
    with open(fw / 'build' / '.lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        proc = subprocess.run(['make', '-s', '-C', str(fw), *targets], capture_output=True, text=True)
    if proc.returncode != 0:
        raise FirmwareError(f'make -C firmware {" ".join(targets)} failed:\n{proc.stdout}{proc.stderr}')


#: ``sslfr sim --boards firmware``: the simulator executable replaced by the firmware one
SIM_EXECUTABLES = {'sim_board': 'fw_board'}


def backend_executable(sim_executable: str | None) -> str | None:
    """The executable that runs a board's firmware in place of its simulator
    ``sim_executable`` (same arguments); None when there is no firmware for it."""
    return SIM_EXECUTABLES.get(sim_executable or '')


def prepare_backend() -> str | None:
    """Build the firmware and the harness for a firmware-in-the-loop run; the reason
    when impossible (missing toolchain, build error), else None."""
    try:
        build('all', 'sim')
    except FirmwareError as exc:
        return str(exc)
    return None
