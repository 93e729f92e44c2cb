"""``sslfr web-password [--file PATH] [--stdin | --unlock]``: set the operator password of the page.

Asks twice (or reads one line from stdin with ``--stdin``, for installers' scripts),
refuses a short or blank password, and writes its scrypt hash (never the password) to
the file the ``web`` node reads (its ``password_file`` parameter, default
``~/.config/sslfr/web_password``), mode 0600. A running node picks the new password
up at the next login; existing sessions stay valid until they expire or log out.
Setting a password also ends every login lockout.

``--unlock`` changes nothing but ends every login lockout of a running page (it
writes ``<password file>.unlock``, which the page watches): the way back in for
the operator at the collector's console or over ssh when someone has locked the
page's logins out.
"""
from __future__ import annotations

import datetime as dt
import getpass
import sys
from pathlib import Path

from sslfr_common.cliargs import CliError, OneLineParser, one_line
from sslfr_common.files import atomic_write, user_path

from .auth import PasswordError, check_new_password, write_password_file
from .params import DEFAULT_PASSWORD_FILE


def unlock(password_file: str) -> Path:
    """Write the unlock file of ``password_file`` (its content: the time, UTC)."""
    p = user_path(password_file)
    target = p.with_name(p.name + '.unlock')
    target.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(target, dt.datetime.now(dt.timezone.utc).isoformat() + '\n', mode=0o600)


def main(argv: list[str]) -> int:
    ap = OneLineParser(prog='sslfr web-password', description=__doc__.split('\n\n')[0])
    ap.add_argument('--file', default=DEFAULT_PASSWORD_FILE,
                    help=f'password file (the web node\'s password_file; default {DEFAULT_PASSWORD_FILE})')
    how = ap.add_mutually_exclusive_group()
    how.add_argument('--stdin', action='store_true', help='read the password from the first line of stdin')
    how.add_argument('--unlock', action='store_true',
                     help='end every login lockout of the running page (the password is unchanged)')
    try:
        args = ap.parse_args(argv)
    except CliError as exc:
        print(f'sslfr web-password: error: {exc}', file=sys.stderr)
        return 2
    if '\0' in args.file or not args.file.strip():
        print('sslfr web-password: --file must be a file path', file=sys.stderr)
        return 2
    if args.unlock:
        try:
            path = unlock(args.file)
        except OSError as exc:
            print(f'sslfr web-password: cannot write the unlock file: {exc.strerror or exc}', file=sys.stderr)
            return 1
        print(f'login lockouts ended (the page reads {path} at the next login)')
        return 0
    try:
        if args.stdin:
            password = sys.stdin.readline().rstrip('\r\n')
        else:
            password = getpass.getpass('new operator password: ')
            check_new_password(password)
            if getpass.getpass('again: ') != password:
                print('sslfr web-password: the two passwords differ; nothing changed', file=sys.stderr)
                return 1
        path = write_password_file(args.file, password)
    except PasswordError as exc:
        print(f'sslfr web-password: {one_line(exc)}; nothing changed', file=sys.stderr)
        return 1
    except (OSError, EOFError) as exc:
        print(f'sslfr web-password: {one_line(exc)}; nothing changed', file=sys.stderr)
        return 1
    print(f'operator password set: scrypt hash in {path} (mode 0600)')
    return 0
