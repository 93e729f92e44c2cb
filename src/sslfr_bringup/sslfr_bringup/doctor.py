"""``sslfr doctor``: check that the installation can run the node graph."""
from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

#: package -> {executable: kind} that ``ros2 run <package> <exe>`` must find after a
#: build. kind 'cli' answers ``--help``; kind 'node' starts with defaults and stops
#: cleanly on SIGINT. Kept in one place; tests/test_foundation.py checks every one.
EXECUTABLES: dict[str, dict[str, str]] = {
    'sslfr_bringup': {'sslfr': 'cli', 'recorder': 'node', 'web': 'node'},
    'sslfr_drivers': {'axis_driver': 'node', 'lifecycle_ctl': 'cli', 'safety': 'node',
                      'sim_board': 'cli', 'xbee_hub': 'cli', 'gps': 'node', 'absorber_board': 'node',
                      'irradiance': 'node'},
    'sslfr_planner': {'planner': 'node'},
}


def install_prefix() -> Path | None:
    """Return ros_ws/install (the colcon overlay), or None when not built."""
    root = os.environ.get('SSLFR_ROOT')
    if root and (Path(root) / 'ros_ws' / 'install').is_dir():
        return Path(root) / 'ros_ws' / 'install'
    return None


def executable_path(package: str, exe: str) -> Path | None:
    """Where ``ros2 run package exe`` looks: <install>/<pkg>/lib/<pkg>/<exe>."""
    prefix = install_prefix()
    return None if prefix is None else prefix / package / 'lib' / package / exe


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog='sslfr doctor', description=__doc__)
    parser.parse_args(argv)
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
            path = executable_path(package, exe)
            good = path is not None and path.is_file() and os.access(path, os.X_OK)
            ok &= good
            print(f'executable    {package}/{exe}: {"ok" if good else "MISSING"} ({path})')
    for tool in ('socat',):
        print(f'optional      {tool}: {"found" if shutil.which(tool) else "not found"}')
    print('verdict       ' + ('ok' if ok else 'PROBLEMS: run make setup'))
    return 0 if ok else 1
