"""``sslfr bag info|check|recover BAG``: inspect a bag, check it against rosbag2, rebuild it.

``info`` prints what ``ros2 bag info`` prints (files, size, duration, start/end,
topics with type, count and serialization format) plus each topic's offered QoS; a
bag that ``ros2 bag info``/``play`` (rosbag2 Jazzy) would refuse is refused with
the file, line and key, exit status 2. ``check`` lists every finding of the
conformance check (:mod:`sslfr_recording.bag.conformance`; ``--rules`` prints the
rules and their rosbag2 sources), exit status 1 when there is any. ``recover``
rescues every intact chunk of every file, keeps damaged originals as
``<file>.damaged``, rebuilds damaged schema texts from the installed message
definitions and ``metadata.yaml`` (docs/bags.md); when ``info`` would still refuse
the bag it says so (what and why) and exits 1: recover and info always agree.

Exit status: 0 ok, 1 check findings, a bag recover cannot repair, or a failure while writing, 2 bad input.
"""
from __future__ import annotations

import sys
from pathlib import Path
from sslfr_common.files import user_path

from sslfr_planner.cli_input import CliError, OneLineParser, run

from .bag.metadata import BagError


def _existing(text: str) -> Path:
    path = user_path(text)
    if not path.exists():
        raise CliError(f'bag {text}: no such file or directory')
    if not (path.is_dir() or path.is_file()):
        raise CliError(f'bag {text}: not a directory or a file')
    return path


def parser() -> OneLineParser:
    p = OneLineParser(prog='sslfr bag', description=__doc__)
    sub = p.add_subparsers(dest='verb', required=True, parser_class=OneLineParser)
    pi = sub.add_parser('info', help='ros2 bag info of a bag (directory or .mcap file)')
    pi.add_argument('bag')
    pc = sub.add_parser('check', help='check a bag against rosbag2 Jazzy\'s reading rules')
    pc.add_argument('bag', nargs='?')
    pc.add_argument('--rules', action='store_true', help='list the rules and their sources')
    pr = sub.add_parser('recover', help='rebuild a bag cut by a crash, a power loss or damage')
    pr.add_argument('bag')
    pr.add_argument('--no-verify', action='store_true',
                    help='trust files whose summary can be read (skip scanning every chunk)')
    pr.add_argument('--dry-run', action='store_true', help='report only, change nothing')
    return p


def _info(path: Path) -> int:
    from .bag.conformance import check_bag
    from .bag.reader import BagReader
    report = check_bag(path)
    blocking = report.blocking
    if blocking:
        more = f' (and {len(blocking) - 1} more: sslfr bag check {path})' if len(blocking) > 1 else ''
        hint = '' if blocking[0].rule.startswith('M') else f'; try sslfr bag recover {path}'
        if blocking[0].rule in ('F09', 'F10') and path.is_dir():   # a schema: can recover rebuild it here?
            from .bag.recover import recover_bag
            cannot = [c for f in recover_bag(path, write=False).files for c in f.cannot]
            if cannot:
                hint = f'; sslfr bag recover cannot repair it: {cannot[0]}'
        raise CliError(f'{path}: {blocking[0].text()}{more}{hint}')
    print(BagReader(path).info_text())
    if report.findings:
        print(f'note: {len(report.findings)} place(s) where the bag differs from what rosbag2 '
              f'writes (sslfr bag check {path})', file=sys.stderr)
    return 0


def _check(ns) -> int:
    from .bag.conformance import check_bag
    from .bag.rules import RULES, SOURCES, describe
    if ns.rules:
        print(describe())
        print('\nsources:\n' + '\n'.join(f'  {k}: {v}' for k, v in SOURCES.items()))
        return 0
    if not ns.bag:
        raise CliError('check needs a BAG (or --rules)')
    report = check_bag(_existing(ns.bag))
    print(report.text())
    if report.findings:
        print(f'{len(report.findings)} finding(s) against {len(RULES)} rules', file=sys.stderr)
    return 1 if report.findings else 0


def _still_refused(path: Path) -> int:
    """After a recovery: 0 when ``bag info`` (rosbag2's rules) accepts the bag, else one
    line saying plainly what recovery could not repair, exit status 1."""
    from .bag.conformance import check_bag
    blocking = check_bag(path).blocking
    if not blocking:
        return 0
    more = f' (and {len(blocking) - 1} more: sslfr bag check {path})' if len(blocking) > 1 else ''
    print(f'sslfr bag recover: recovery cannot repair everything: rosbag2 would still refuse {path}: '
          f'{blocking[0].text()}{more}', file=sys.stderr)
    return 1


def _body(argv: list[str]) -> int:
    ns = parser().parse_args(argv)
    try:
        if ns.verb == 'info':
            return _info(_existing(ns.bag))
        if ns.verb == 'check':
            return _check(ns)
        path = _existing(ns.bag)
        if not path.is_dir():
            raise CliError(f'bag {ns.bag}: recover needs a bag directory, not a file')
        from .bag.recover import recover_bag
        report = recover_bag(path, verify=not ns.no_verify, write=not ns.dry_run)
        print(report.text())
        return _still_refused(path) if not ns.dry_run else 0
    except BagError as exc:
        raise CliError(str(exc)) from None


def main(argv: list[str]) -> int:
    return run('bag', _body, argv)
