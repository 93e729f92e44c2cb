"""``sslfr keys``: the installation key (docs/deploy.md "Board keys").

    sslfr keys new [PATH] [--force]        write a fresh key file (mode 0600), print its id
    sslfr keys id [PATH]                   print the key id of a key file
    sslfr keys provision --port PORT [--key-file PATH]
                                           give the key to one board over its USB serial port

PATH defaults to ``$SSLFR_KEY_FILE`` or ``~/.config/sslfr/installation.key``.
Provisioning works only over the board's USB serial adapter: opening the port pulses
DTR, which resets the Pro Mini (an *external* reset); the firmware accepts PROVISION
only in the 10 s after such a reset and refuses it otherwise (NACK LOCKED), so nobody
within radio range can set a board's key. The board then answers under the new key
and is checked with a session (INFO).
"""
from __future__ import annotations

import argparse
import sys
import time

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.auth import BOARD_TO_HOST, HOST_TO_BOARD, NULL_KEY, Session, key_id
from sslfr_drivers.link.keys import KeyFileError, default_key_path, generate, load_key, write_key_file
from sslfr_drivers.link.protocol import Framer, encode_frame
from sslfr_common.cliargs import CliError, OneLineParser, bounded_int, one_line, ranged_float


class ProvisionError(RuntimeError):
    """The board did not take the key (message says why and what to do)."""


def provision_frame(key: bytes, seq: int) -> bytes:
    """The PROVISION request carrying ``key``, tagged in the null session of the null key
    (its protection is the provisioning window, not a key the board may not have)."""
    return encode_frame(Session(NULL_KEY).seal(HOST_TO_BOARD, seq, m.encode(m.Provision(key), 0)))


def provision(port, key: bytes, timeout: float = 15.0, period: float = 0.5) -> None:
    """Send PROVISION(``key``) on the open serial ``port`` (pyserial-like: write, read
    with a time-out) every ``period`` s until the board answers (the bootloader runs
    first after the reset), at most ``timeout`` s. Returns when the board ACKs under the
    new key; ProvisionError for LOCKED, another refusal or silence."""
    framer, new = Framer(), Session(key)
    deadline = time.monotonic() + timeout
    seq, next_send = 0, 0.0
    while time.monotonic() < deadline:
        if time.monotonic() >= next_send:
            seq += 1
            port.write(provision_frame(key, seq))
            next_send = time.monotonic() + period
        for f in framer.feed(port.read(256)):
            if not (f.is_response and f.type in (m.Ack.TYPE, m.Nack.TYPE)):
                continue
            try:
                ans = m.decode(f)
            except m.PayloadError:
                continue
            if ans.request_type != m.Provision.TYPE:
                continue
            if isinstance(ans, m.Ack) and new.verify(BOARD_TO_HOST, f.seq, f):
                return
            if isinstance(ans, m.Nack) and ans.code == m.ErrorCode.LOCKED:
                raise ProvisionError(
                    'the board refused the key: its provisioning window is closed (it opens for 10 s '
                    'after an external reset). Connect the board through its USB serial adapter (DTR '
                    'wired to RESET) or press its reset button, and run this again at once')
            if isinstance(ans, m.Nack):
                raise ProvisionError(f'the board refused the key: {m.ErrorCode(ans.code).name}')
    raise ProvisionError(f'no answer to PROVISION within {timeout:.0f} s (is this the board\'s USB serial '
                         'port, at the board\'s baud rate, with firmware 1.0.0 or later?)')


def _open_serial(port: str, baud: int):
    """The port opened with a DTR pulse (resets a Pro Mini through its USB adapter)."""
    import serial
    s = serial.serial_for_url(port, baudrate=baud, timeout=0.05, do_not_open=True)
    s.dtr = False
    s.open()
    try:
        s.dtr = False
        time.sleep(0.1)
        s.dtr = True                      # the falling edge on the adapter's DTR pin resets the board
    except (OSError, serial.SerialException):
        pass                              # a pty or socket has no modem lines
    s.reset_input_buffer()
    return s


BAUD_RANGE = (300, 2_000_000)     # [bit/s] UART speeds a board may be asked for


def parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog='sslfr keys', description=__doc__.split('\n')[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter,
                                epilog='\n'.join(__doc__.split('\n')[2:]))
    sub = p.add_subparsers(dest='cmd', required=True, parser_class=OneLineParser)
    n = sub.add_parser('new', help='write a fresh installation key file (mode 0600)')
    n.add_argument('path', nargs='?', help=f'key file (default {default_key_path()})')
    n.add_argument('--force', action='store_true',
                   help='replace an existing key file (boards provisioned with it stop answering)')
    i = sub.add_parser('id', help='print the id of a key file')
    i.add_argument('path', nargs='?')
    pr = sub.add_parser('provision', help='give the key to a board over its USB serial port')
    pr.add_argument('--port', required=True, help='the board\'s USB serial port (e.g. /dev/ttyUSB0)')
    pr.add_argument('--key-file', help=f'key file (default {default_key_path()})')
    pr.add_argument('--baud', type=bounded_int(*BAUD_RANGE), default=115200,
                    help=f'the board\'s UART speed [bit/s], {BAUD_RANGE[0]}..{BAUD_RANGE[1]}')
    pr.add_argument('--timeout', type=ranged_float(0.1, 600.0, unit='s'), default=15.0,
                    help='[s] to wait for the board, 0.1..600')
    return p


def main(argv: list[str] | None = None, out=None) -> int:
    out = out or sys.stdout           # the stream of the call, not of the import
    try:
        args = parser().parse_args(argv)
    except CliError as exc:
        print(f'sslfr keys: error: {exc}', file=sys.stderr)
        return 2
    try:
        if args.cmd == 'new':
            path = write_key_file(args.path or default_key_path(), generate(), force=args.force)
            print(f'{path}: new installation key, key id {key_id(load_key(path))} (mode 0600; back it up '
                  'offline, docs/deploy.md)', file=out)
            return 0
        if args.cmd == 'id':
            path = args.path or default_key_path()
            print(f'{path}: key id {key_id(load_key(path))}', file=out)
            return 0
        key = load_key(args.key_file or default_key_path())
        port = _open_serial(args.port, args.baud)
        try:
            provision(port, key, args.timeout)
        finally:
            port.close()
        info = _check(args.port, args.baud, key)
        print(f'{args.port}: board {info.name_str} id {info.board_id} provisioned with key id {key_id(key)}',
              file=out)
        return 0
    except KeyFileError as exc:
        print(f'sslfr keys: {one_line(exc)}', file=sys.stderr)
        return 2
    except (ProvisionError, OSError) as exc:
        where = f'{args.port}: ' if args.cmd == 'provision' else ''
        print(f'sslfr keys: {one_line(where)}{one_line(exc)}', file=sys.stderr)
        return 1


def _check(port: str, baud: int, key: bytes) -> m.Info:
    """A session with the new key and the board's INFO (ProvisionError if none)."""
    from sslfr_drivers.link.board_link import BoardLink
    from sslfr_drivers.link.transport import SerialTransport
    link = BoardLink(SerialTransport(port, baud), key=key, timeout=0.3, retries=3).start()
    try:
        if not link.wait_up(10.0):
            raise ProvisionError(f'the board took the key but no session opened ({link.last_error})')
        return link.info
    finally:
        link.stop()


if __name__ == '__main__':
    sys.exit(main())
