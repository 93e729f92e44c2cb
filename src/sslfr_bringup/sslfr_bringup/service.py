"""``sslfr install-service``: a systemd unit that runs the node set at boot.

The unit runs ``<repo>/sslfr up --config CONFIG`` (which sources the ROS underlay
and the workspace itself) as a ``Type=notify`` service with a watchdog
(``WatchdogSec=``: ``sslfr up`` sends READY=1 and WATCHDOG=1, sd_notify(3)),
restarts it on failure or on a missed beat, logs to the journal
(``journalctl -u sslfr-tracker``) and stops it with SIGTERM to the supervisor only
(``KillMode=mixed``), so the supervisor can stop the axes first; systemd kills any
leftover after ``TimeoutStopSec``. Step by step: docs/deploy.md.

``--dry-run`` prints the unit instead of writing it (no root needed).
"""
from __future__ import annotations

import argparse
import getpass
import ipaddress
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from sslfr_bringup import nodeset as nodeset_mod
from sslfr_planner.cli_input import (CliError, OneLineParser, bounded_int, output_dir, ros_namespace, run,
                                    write_atomically)

UNIT_NAME = 'sslfr-tracker.service'
#: [s] WatchdogSec= of the unit: `sslfr up` beats at least every 1 s from its loop
#: (sslfr_common.sdnotify.MAX_BEAT_PERIOD), whose longest step is a reap after SIGKILL
#: (<= 5 s); 15 s leaves room for a loaded Pi
SUPERVISOR_WATCHDOG_S = 15
#: [s] TimeoutStartSec=: from the start to READY=1 (every node process's executor
#: turning; a process silent past defaults.watchdog_startup, 60 s, is restarted first)
START_TIMEOUT_S = 180


def repo_root() -> Path:
    """The checkout holding the ``sslfr`` wrapper (``$SSLFR_ROOT`` when set)."""
    root = os.environ.get('SSLFR_ROOT')
    if root:
        return Path(root)
    return Path(__file__).resolve().parents[3]


def systemd_word(value: str) -> str:
    """``value`` as one word of a unit file line (systemd.syntax(7), systemd.service(5)
    "Command lines"): control characters refused (ValueError: a newline would start a
    new directive), ``%`` and ``$`` escaped, double-quoted with ``\\`` and ``"``
    escaped when it holds a space or a quote."""
    bad = [ch for ch in value if ord(ch) < 0x20 or ord(ch) == 0x7f]
    if bad:
        raise ValueError(f'{value!r} holds a control character ({bad[0]!r}): it cannot go into a unit file')
    out = value.replace('%', '%%').replace('$', '$$')
    if any(ch in out for ch in ' \t"\'\\;') or out == '':
        out = '"' + out.replace('\\', '\\\\').replace('"', '\\"') + '"'
    return out


def render_unit(*, root: Path, config: str, user: str, domain_id: int, discovery_range: str,
                namespace: str = '', peers: str = '', layout: str = '') -> str:
    """Text of the systemd unit (pure; tested). Every value that reaches the file is
    checked and quoted (:func:`systemd_word`); ValueError when one cannot be written."""
    up = ' '.join(systemd_word(w) for w in (f'{root}/sslfr', 'up', '--config', str(config)))
    if namespace:
        up += ' --namespace ' + systemd_word(namespace)
    if layout:
        up += ' --layout ' + systemd_word(layout)
    env = [f'ROS_DOMAIN_ID={domain_id}', f'ROS_AUTOMATIC_DISCOVERY_RANGE={discovery_range}',
           'PYTHONUNBUFFERED=1', 'RCUTILS_COLORIZED_OUTPUT=0', 'RCUTILS_LOGGING_BUFFERED_STREAM=0']
    if peers:
        env.append(f'ROS_STATIC_PEERS={peers}')
    env_lines = '\n'.join(f'Environment={systemd_word(e)}' for e in env)
    user = systemd_word(user)
    root = systemd_word(str(root))
    return f"""# {UNIT_NAME}: the SSLFR tracker node set (written by `sslfr install-service`)
# Logs: journalctl -u {UNIT_NAME.removesuffix('.service')} -f     Docs: {root}/docs/deploy.md
[Unit]
Description=SSLFR solar tracker node set (sslfr up)
Documentation=file://{root}/docs/deploy.md
Wants=network-online.target
After=network-online.target time-sync.target
StartLimitIntervalSec=300
StartLimitBurst=10

[Service]
# sd_notify: `sslfr up` sends READY=1 once every node process's executor turns and
# WATCHDOG=1 from its supervision loop (at least every 1 s); it watches its node
# processes itself (config/nodeset.yaml defaults.watchdog_timeout) and restarts a hung
# one. systemd restarts the whole set when `sslfr up` itself stops beating.
Type=notify
NotifyAccess=main
WatchdogSec={SUPERVISOR_WATCHDOG_S}
TimeoutStartSec={START_TIMEOUT_S}
User={user}
SupplementaryGroups=dialout
WorkingDirectory={root}
{env_lines}
Environment=ROS_LOG_DIR=%S/sslfr/roslog
StateDirectory=sslfr
ExecStart={up}
# SIGTERM to the supervisor only: it stops the axes first, then the rest (<= 5 s);
# systemd SIGKILLs whatever is left after TimeoutStopSec.
KillMode=mixed
KillSignal=SIGTERM
TimeoutStopSec=10
Restart=on-failure
RestartSec=5
StandardOutput=journal
StandardError=journal
SyslogIdentifier=sslfr
Nice=-5

[Install]
WantedBy=multi-user.target
"""


def unix_user(text: str) -> str:
    """argparse type: a POSIX user name (useradd's default rule, <= 32 characters)."""
    if not re.fullmatch(r'[a-z_][a-z0-9_-]{0,30}\$?', text):
        raise argparse.ArgumentTypeError(f'{text!r} is not a user name (lower-case letters, digits, _ and -, '
                                         'starting with a letter or _, at most 32 characters)')
    return text


def static_peers(text: str) -> str:
    """argparse type: ROS_STATIC_PEERS, host names or IP addresses separated by ``;``
    ('' = none)."""
    if text == '':
        return text
    for peer in (t.strip() for t in text.split(';')):
        try:
            ipaddress.ip_address(peer)
            continue
        except ValueError:
            pass
        if not re.fullmatch(r'(?=.{1,253}$)[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?'
                            r'(\.[A-Za-z0-9]([A-Za-z0-9-]{0,61}[A-Za-z0-9])?)*', peer):
            raise argparse.ArgumentTypeError(f'{peer!r} is not an IP address or host name '
                                             '(separate several peers with ;)')
    return text


def parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog='sslfr install-service', description=__doc__.split('\n\n')[0])
    p.add_argument('--config', default=None,
                   help='site params file (path or name in sslfr_bringup/config; default almeria_sslfr.yaml)')
    p.add_argument('--user', type=unix_user, default=None,
                   help='user the node set runs as (default: the invoking user)')
    p.add_argument('--domain-id', type=bounded_int(1, 232), default=None,
                   help='ROS_DOMAIN_ID, 1..232 (default: the node set\'s, 42)')
    p.add_argument('--discovery-range', default=None, choices=['LOCALHOST', 'SUBNET', 'SYSTEM_DEFAULT', 'OFF'],
                   help='ROS_AUTOMATIC_DISCOVERY_RANGE (default LOCALHOST; SUBNET opens it to the LAN)')
    p.add_argument('--peers', type=static_peers, default='',
                   help='ROS_STATIC_PEERS, e.g. the monitoring laptop\'s IP (several: a;b)')
    p.add_argument('--namespace', type=ros_namespace, default='', help='namespace of the tracker, e.g. /sslfr1')
    p.add_argument('--layout', default='', help='process layout of the node set (composed: the choice for a Pi 3; '
                                                'default: the node set\'s)')
    p.add_argument('--unit-dir', type=output_dir, default=Path('/etc/systemd/system'),
                   help='where to write the unit (an existing or creatable directory)')
    p.add_argument('--dry-run', action='store_true', help='print the unit, write nothing')
    p.add_argument('--no-enable', action='store_true', help='write the unit but do not enable/start it')
    return p


def main(argv: list[str]) -> int:
    return run('install-service', _body, argv)


def _body(argv: list[str]) -> int:
    args = parser().parse_args(argv)
    try:
        ns = nodeset_mod.load()
        config = nodeset_mod.resolve_config(args.config, default=ns.config)
        nodeset_mod.checked_params(nodeset_mod.for_config(ns, config, args.namespace), config, args.namespace)   # what `sslfr up` will check at start
    except nodeset_mod.NodeSetError as exc:
        why = ' '.join(part.strip() for part in str(exc).splitlines() if part.strip())
        raise CliError(f'argument --config: {why}') from None
    if args.layout and args.layout not in ns.layouts:
        raise CliError(f'argument --layout: no layout {args.layout!r} (known: {", ".join(ns.layouts)})')
    domain = args.domain_id if args.domain_id is not None else ns.domain_id
    user = args.user or os.environ.get('SUDO_USER') or getpass.getuser()
    text = render_unit(root=repo_root(), config=str(config), user=user, domain_id=domain,
                       discovery_range=args.discovery_range or ns.discovery_range,
                       namespace=args.namespace, peers=args.peers, layout=args.layout)
    if args.dry_run:
        print(text, end='')
        return 0
    path = Path(args.unit_dir) / UNIT_NAME
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomically(str(path), lambda tmp: Path(tmp).write_text(text))
    except PermissionError:
        print(f'sslfr install-service: cannot write {path}: run with sudo (or --dry-run to see the unit)',
              file=sys.stderr)
        return 1
    print(f'wrote {path}')
    if args.no_enable or not shutil.which('systemctl'):
        print(f'enable with: sudo systemctl daemon-reload && sudo systemctl enable --now {UNIT_NAME}')
        return 0
    for cmd in (['systemctl', 'daemon-reload'], ['systemctl', 'enable', '--now', UNIT_NAME]):
        res = subprocess.run(cmd, check=False)
        if res.returncode != 0:
            print(f'sslfr install-service: {" ".join(cmd)} failed ({res.returncode})', file=sys.stderr)
            return 1
    print(f'started; follow the log with: journalctl -u {UNIT_NAME} -f')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
