"""``sslfr doctor``: check that the installation can run the node graph."""
from __future__ import annotations

import os
import shutil
import sys

from sslfr_common.cliargs import CliError, OneLineParser, one_line

from .host import executable_path, find_executable, install_prefix

#: package -> {executable: kind} that ``ros2 run <package> <exe>`` must find after a
#: build. kind 'cli' answers ``--help``; kind 'node' starts with defaults and stops
#: cleanly on SIGINT. Kept in one place; tests/test_foundation.py checks every one.
EXECUTABLES: dict[str, dict[str, str]] = {
    'sslfr_bringup': {'sslfr': 'cli', 'liveness_watchdog': 'cli'},
    'sslfr_recording': {'recorder': 'node'},
    'sslfr_web': {'web': 'node'},
    'sslfr_gateway': {'modbus_gateway': 'node', 'foxglove_bridge': 'node'},
    'sslfr_safety': {'safety': 'node'},
    'sslfr_drivers': {'axis_driver': 'node', 'lifecycle_ctl': 'cli', 'xbee_hub': 'cli', 'gps': 'node',
                      'absorber_board': 'node', 'irradiance': 'node'},
    'sslfr_sim': {'sim_board': 'cli'},
    'sslfr_planner': {'planner': 'node'},
}


def check_site_config(config: str | None, nodeset_path: str | None = None) -> int:
    """``sslfr doctor --config FILE``: the site config checked against the node set's
    parameter tables (what `sslfr up`, `sslfr sim` and the launch file refuse); exit 0
    when valid, 2 with every problem listed otherwise."""
    from . import nodeset
    try:
        ns = nodeset.load(nodeset_path)
        path = nodeset.resolve_config(config, default=ns.config)
        problems = nodeset.check_config(nodeset.for_config(ns, path), nodeset.read_params(path), where=str(path))
    except nodeset.NodeSetError as exc:
        print(f'sslfr doctor: {one_line(exc, keep_newlines=True)}', file=sys.stderr)
        return 2
    for line in problems:
        print(line, file=sys.stderr)
    print(f'config        {path}: ' + ('ok' if not problems else f'{len(problems)} problem(s), see above'))
    return 0 if not problems else 2


def main(argv: list[str]) -> int:
    parser = OneLineParser(prog='sslfr doctor', description=__doc__)
    parser.add_argument('--config', default=None,
                        help='also check this site config (path or name in sslfr_bringup/config) '
                             'against the parameter tables of the nodes')
    try:
        args = parser.parse_args(argv)
    except CliError as exc:
        print(f'sslfr doctor: error: {one_line(exc)}', file=sys.stderr)
        return 2
    if args.config is not None:
        return check_site_config(args.config)
    ok = True
    print(f'python        {sys.version.split()[0]} ({sys.executable})')
    print(f'ROS underlay  {os.environ.get("SSLFR_ROS_SOURCE", "?")} (ROS_DISTRO={os.environ.get("ROS_DISTRO", "?")})')
    print(f'RMW           {os.environ.get("RMW_IMPLEMENTATION", "?")}, '
          f'ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0 (default)")}, '
          f'discovery range={os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "?")}')
    try:
        import rclpy  # noqa: F401
        from sslfr_interfaces.msg import SafetyState  # noqa: F401
        print('interfaces    sslfr_interfaces imports')
    except ImportError as exc:  # pragma: no cover - reported to the user
        ok = False
        print(f'interfaces    NOT importable: {exc}')
    for package, exes in EXECUTABLES.items():
        for exe in exes:  # noqa: B007 - kind is for the tests
            path = find_executable(package, exe)         # what `sslfr up` would run
            ok &= path is not None
            prefix = install_prefix()
            where = path or (executable_path(package, exe, prefix) if prefix else 'ros_ws/install not built')
            print(f'executable    {package}/{exe}: {"ok" if path else "MISSING"} ({where})')
    for tool in ('socat',):
        print(f'optional      {tool}: {"found" if shutil.which(tool) else "not found"}')
    print('verdict       ' + ('ok' if ok else 'PROBLEMS: run make setup'))
    return 0 if ok else 1
