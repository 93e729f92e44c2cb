"""``sslfr web-password [--file PATH] [--stdin]``: set the operator password of the page.

Asks twice (or reads one line from stdin with ``--stdin``, for installers' scripts),
refuses a short or blank password, and writes its scrypt hash (never the password) to
the file the ``web`` node reads (its ``password_file`` parameter, default
``~/.config/sslfr/web_password``), mode 0600. A running node picks the new password
up at the next login; existing sessions stay valid until they expire or log out.
"""
from __future__ import annotations

import argparse
import getpass
import sys

from .auth import PasswordError, check_new_password, write_password_file
from .params import DEFAULT_PASSWORD_FILE


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog='sslfr web-password', description=__doc__.split('\n\n')[0])
    ap.add_argument('--file', default=DEFAULT_PASSWORD_FILE,
                    help=f'password file (the web node\'s password_file; default {DEFAULT_PASSWORD_FILE})')
    ap.add_argument('--stdin', action='store_true', help='read the password from the first line of stdin')
    args = ap.parse_args(argv)
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
        print(f'sslfr web-password: {exc}; nothing changed', file=sys.stderr)
        return 1
    except (OSError, EOFError) as exc:
        print(f'sslfr web-password: {exc}; nothing changed', file=sys.stderr)
        return 1
    print(f'operator password set: scrypt hash in {path} (mode 0600)')
    return 0
