"""``sslfr flash BOARD --port PORT``: build the board's firmware if needed, write it with
avrdude through the Arduino Pro Mini's bootloader, then read INFO back and print the
version; optionally write the EEPROM configuration record (``--set KEY=VALUE``, the
documented procedure of docs/firmware.md "EEPROM configuration").

    sslfr flash axis --port /dev/ttyUSB0 --set axis=mirrors --set board_id=11
    sslfr flash axis --port /dev/ttyUSB0 --config-only --set max_speed=2500
"""
from __future__ import annotations

import argparse
import dataclasses
import shutil
import subprocess
import sys
import time

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.keys import KeyFileError, link_key
from sslfr_drivers.firmware import BOARDS, BOOTLOADER_BAUD, FirmwareError, build, hexfile
from sslfr_drivers.link.keys_cli import BAUD_RANGE
from sslfr_common.cliargs import OneLineParser, bounded_int, one_line, ranged_float

#: --set keys: name -> (ConfigRecord field, parser)
CONFIG_KEYS = {
    'board_id': ('board_id', lambda v: int(v, 0)),
    'baud': ('baud', int),
    'axis': ('axis', lambda v: m.ConfigRecord.AXES.index(v) if v in m.ConfigRecord.AXES else int(v)),
    'max_speed': ('max_speed', float),
    'accel': ('accel', float),
    'min_steps': ('min_steps', int),
    'max_steps': ('max_steps', int),
    'flags': ('flags', lambda v: int(v, 0)),
    'sensor_zero': ('sensor_zero', int),
}
KINDS = {'axis': m.BoardKind.AXIS_STEPPER, 'absorber': m.BoardKind.ABSORBER,
         'irradiance': m.BoardKind.IRRADIANCE, 'gps': m.BoardKind.GPS,
         'axis_noswitch': m.BoardKind.AXIS_STEPPER, 'actuator': m.BoardKind.AXIS_ACTUATOR}


def parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog='sslfr flash', description=__doc__.split('\n\n')[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog='configuration keys (--set): ' + ', '.join(CONFIG_KEYS))
    p.add_argument('board', choices=BOARDS, help='which firmware')
    p.add_argument('--port', required=True, help='serial port of the board (USB-serial adapter)')
    p.add_argument('--baud', type=bounded_int(*BAUD_RANGE), default=BOOTLOADER_BAUD,
                   help=f'bootloader baud rate (default {BOOTLOADER_BAUD}: the Pro Mini 16 MHz '
                        'bootloader of arduino-core-avr; optiboot: 115200)')
    p.add_argument('--fw-baud', type=bounded_int(*BAUD_RANGE), default=None,
                   help='firmware UART baud rate (default: from --set baud, else 115200)')
    p.add_argument('--no-build', action='store_true', help='flash the existing build/BOARD.hex as it is')
    p.add_argument('--config-only', action='store_true', help='do not flash: only read INFO and write --set keys')
    p.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                   help='write this configuration field to the EEPROM (repeatable); takes effect after a RESET, '
                        'which this command sends')
    p.add_argument('--timeout', type=ranged_float(0.1, 600.0, unit='s'), default=8.0,
                   help='seconds to wait for the board after flashing, 0.1..600')
    p.add_argument('--avrdude', default='avrdude', help='avrdude executable')
    p.add_argument('--key-file', default=None,
                   help='installation key file of a board already provisioned (re-flashing keeps its key); '
                        'default: a fresh, unprovisioned board')
    return p


def parse_sets(items: list[str]) -> dict:
    """``KEY=VALUE`` strings -> {record field: value}; ValueError with the reason."""
    out = {}
    for item in items:
        key, eq, value = item.partition('=')
        if not eq or key not in CONFIG_KEYS:
            raise ValueError(f'--set {item!r}: expected KEY=VALUE with KEY one of {", ".join(CONFIG_KEYS)}')
        field, conv = CONFIG_KEYS[key]
        try:
            out[field] = conv(value)
        except ValueError as exc:
            raise ValueError(f'--set {item!r}: {exc}') from None
    return out


def run_avrdude(avrdude: str, port: str, baud: int, hex_path, out=None) -> None:
    """Write ``hex_path`` through the bootloader (STK500v1, ``-c arduino``); the board is
    reset into its bootloader by avrdude's DTR pulse. FirmwareError on failure."""
    out = out or sys.stdout
    if shutil.which(avrdude) is None:
        raise FirmwareError(f'{avrdude} not found: sudo apt-get install avrdude')
    argv = [avrdude, '-p', 'atmega328p', '-c', 'arduino', '-P', port, '-b', str(baud), '-D',
            '-U', f'flash:w:{hex_path}:i']
    print('flash: ' + ' '.join(argv), file=out, flush=True)
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=180)
    text = proc.stderr + proc.stdout
    if proc.returncode != 0:
        raise FirmwareError(f'avrdude failed (exit {proc.returncode}):\n{text[-2000:]}')
    verified = [ln.strip() for ln in text.splitlines() if 'verified' in ln]
    print('flash: ' + (verified[-1] if verified else 'written'), file=out, flush=True)


def read_board(port: str, baud: int, timeout: float, key: bytes | None = None):
    """Open the board's port and return (BoardLink, Info) once it answers (``key``: the
    installation key of a provisioned board; re-flashing keeps the EEPROM and its key)."""
    from sslfr_drivers.link.board_link import BoardLink
    from sslfr_drivers.link.transport import SerialTransport
    link = BoardLink(SerialTransport(port, baud), timeout=0.3, retries=3, key=key).start()
    if not link.wait_up(timeout):
        link.stop()
        raise FirmwareError(f'no answer from the board on {port} within {timeout:.0f} s '
                            f'({link.last_error or "silent"})')
    return link, link.request(m.GetInfo())


def main(argv: list[str] | None = None, out=None) -> int:
    out = out or sys.stdout           # the stream of the call, not of the import
    args = parser().parse_or_report(argv)
    if args is None:
        return 2
    try:
        sets = parse_sets(args.set)
    except ValueError as exc:
        print(f'sslfr flash: {one_line(exc)}', file=sys.stderr)
        return 2
    fw_baud = args.fw_baud or 115200
    try:
        if not args.config_only:
            if not args.no_build:
                build('all')
            if not hexfile(args.board).exists():
                raise FirmwareError(f'{hexfile(args.board)} does not exist: run make firmware')
            run_avrdude(args.avrdude, args.port, args.baud, hexfile(args.board), out)
        key = link_key(args.key_file or '')
        link, info = read_board(args.port, fw_baud, args.timeout, key)
        try:
            if info.board_kind != KINDS[args.board]:
                raise FirmwareError(f'the board answers as {m.BoardKind(info.board_kind).name}, not {args.board}')
            print(f'board: {info.name_str} firmware {info.firmware} protocol {info.protocol} '
                  f'id {info.board_id}', file=out, flush=True)
            if sets:
                rec = dataclasses.replace(link.request(m.GetConfig()).value, **sets)
                code = rec.check(info.board_kind)
                if code:
                    raise FirmwareError(f'configuration refused ({m.ErrorCode(code).name}): {rec}')
                link.request(m.SetConfig(rec.pack()))
                link.request(m.Reset())
                new_baud = rec.baud
                link.stop()
                time.sleep(0.3)
                link, info = read_board(args.port, new_baud, args.timeout, key)
                got = link.request(m.GetConfig()).value
                if got != rec:
                    raise FirmwareError(f'the board kept {got}, not {rec}')
                print(f'config: {got}', file=out, flush=True)
        finally:
            link.stop()
    except KeyFileError as exc:
        print(f'sslfr flash: {one_line(exc)}', file=sys.stderr)
        return 2
    except (FirmwareError, subprocess.TimeoutExpired) as exc:
        print(f'sslfr flash: {one_line(exc)}', file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: BLE001 - a NACK or link error: say it, no traceback
        print(f'sslfr flash: {type(exc).__name__}: {one_line(exc)}', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
