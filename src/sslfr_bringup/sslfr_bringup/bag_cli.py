"""``sslfr bag info|recover DIR``: inspect a bag, or rebuild one after a crash.

``info`` prints what ``ros2 bag info`` prints (files, duration, start/end, topics with
types, counts and QoS). ``recover`` makes every ``.mcap`` of the directory readable
(keeps every complete chunk whose CRC matches, drops the unfinished tail) and
rewrites ``metadata.yaml``. Exit status: 0 ok, 1 bag error (message on stderr).
"""
from __future__ import annotations

import argparse
import sys

from .bag.metadata import BagError


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog='sslfr bag', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest='verb', required=True)
    pi = sub.add_parser('info', help='summary of a bag (directory or .mcap file)')
    pi.add_argument('bag')
    pr = sub.add_parser('recover', help='rebuild a bag cut by a crash or power loss')
    pr.add_argument('bag')
    pr.add_argument('--no-verify', action='store_true',
                    help='trust files that have a summary (skip the CRC check of every chunk)')
    pr.add_argument('--dry-run', action='store_true', help='report only, change nothing')
    ns = p.parse_args(argv)
    try:
        if ns.verb == 'info':
            from .bag.reader import BagReader
            print(BagReader(ns.bag).info_text())
        else:
            from .bag.recover import recover_bag
            report = recover_bag(ns.bag, verify=not ns.no_verify, write=not ns.dry_run)
            print(report.text())
    except BagError as exc:
        print(f'sslfr bag {ns.verb}: {exc}', file=sys.stderr)
        return 1
    return 0
