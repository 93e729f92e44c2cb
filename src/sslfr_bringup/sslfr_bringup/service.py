"""``sslfr install-service``: a systemd unit that runs the node set at boot.

The unit runs ``<repo>/sslfr up --config CONFIG`` (which sources the ROS underlay
and the workspace itself), restarts it on failure, logs to the journal
(``journalctl -u sslfr-tracker``) and stops it with SIGTERM to the supervisor only
(``KillMode=mixed``), so the supervisor can stop the axes first; systemd kills any
leftover after ``TimeoutStopSec``. Step by step: docs/deploy.md.

``--dry-run`` prints the unit instead of writing it (no root needed).
"""
from __future__ import annotations

import argparse
import getpass
import os
import shutil
import subprocess
import sys
from pathlib import Path

from sslfr_bringup import nodeset as nodeset_mod

UNIT_NAME = 'sslfr-tracker.service'


def repo_root() -> Path:
    """The checkout holding the ``sslfr`` wrapper (``$SSLFR_ROOT`` when set)."""
    root = os.environ.get('SSLFR_ROOT')
    if root:
        return Path(root)
    return Path(__file__).resolve().parents[3]


def render_unit(*, root: Path, config: str, user: str, domain_id: int, discovery_range: str,
                namespace: str = '', peers: str = '') -> str:
    """Text of the systemd unit (pure; tested)."""
    up = f'{root}/sslfr up --config {config}'
    if namespace:
        up += f' --namespace {namespace}'
    env = [f'ROS_DOMAIN_ID={domain_id}', f'ROS_AUTOMATIC_DISCOVERY_RANGE={discovery_range}',
           'PYTHONUNBUFFERED=1', 'RCUTILS_COLORIZED_OUTPUT=0', 'RCUTILS_LOGGING_BUFFERED_STREAM=0']
    if peers:
        env.append(f'ROS_STATIC_PEERS={peers}')
    env_lines = '\n'.join(f'Environment={e}' for e in env)
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
Type=simple
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


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog='sslfr install-service', description=__doc__.split('\n\n')[0])
    p.add_argument('--config', default=None,
                   help='site params file (path or name in sslfr_bringup/config; default almeria_sslfr.yaml)')
    p.add_argument('--user', default=None, help='user the node set runs as (default: the invoking user)')
    p.add_argument('--domain-id', type=int, default=None, help='ROS_DOMAIN_ID (default: the node set\'s, 42)')
    p.add_argument('--discovery-range', default=None, choices=['LOCALHOST', 'SUBNET', 'SYSTEM_DEFAULT', 'OFF'],
                   help='ROS_AUTOMATIC_DISCOVERY_RANGE (default LOCALHOST; SUBNET opens it to the LAN)')
    p.add_argument('--peers', default='', help='ROS_STATIC_PEERS, e.g. the monitoring laptop\'s IP')
    p.add_argument('--namespace', default='', help='namespace of the tracker')
    p.add_argument('--unit-dir', default='/etc/systemd/system', help='where to write the unit')
    p.add_argument('--dry-run', action='store_true', help='print the unit, write nothing')
    p.add_argument('--no-enable', action='store_true', help='write the unit but do not enable/start it')
    return p


def main(argv: list[str]) -> int:
    args = parser().parse_args(argv)
    try:
        ns = nodeset_mod.load()
        config = nodeset_mod.resolve_config(args.config, default=ns.config)
    except nodeset_mod.NodeSetError as exc:
        print(f'sslfr install-service: {exc}', file=sys.stderr)
        return 2
    domain = args.domain_id if args.domain_id is not None else ns.domain_id
    if not 0 < domain <= 232:
        print('sslfr install-service: --domain-id must be 1..232', file=sys.stderr)
        return 2
    user = args.user or os.environ.get('SUDO_USER') or getpass.getuser()
    text = render_unit(root=repo_root(), config=str(config), user=user, domain_id=domain,
                       discovery_range=args.discovery_range or ns.discovery_range,
                       namespace=args.namespace, peers=args.peers)
    if args.dry_run:
        print(text, end='')
        return 0
    path = Path(args.unit_dir) / UNIT_NAME
    try:
        path.write_text(text)
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
