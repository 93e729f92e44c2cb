"""The ``sslfr`` command-line tool: one dispatcher, one module per subcommand.

Each subcommand lives in its own module exposing ``main(argv: list[str]) -> int``;
this file only maps names to modules, so adding a subcommand is one line in
:data:`SUBCOMMANDS`. Degrees appear only here, at the CLI/CSV edge; everything
behind it works in SI units and radians (REP-103).
"""
from __future__ import annotations

import importlib
import importlib.util
import io
import sys

#: name -> (module, one-line help). The module must define ``main(argv) -> int``; it is
#: imported by name only when its command runs, and listed only when installed. The
#: ``sim`` entry is the product's one reference to the simulation package (sslfr_sim,
#: checked by test_code_map.py).
SUBCOMMANDS: dict[str, tuple[str, str]] = {
    'plan': ('sslfr_planner.cli_plan', 'per-step day table (sun, incidence angles, axis setpoints) as CSV'),
    'field': ('sslfr_planner.cli_field', 'LEPTEN mirror lines: exact model fitted with the common-drive law'),
    'analyse': ('sslfr_planner.analysis.cli', 'optical power with tracking error, annual energy, EAR, LCOE, tilts'),
    'up': ('sslfr_bringup.up', 'start the whole node set (real boards) as supervised processes'),
    'sim': ('sslfr_sim.sim_cli', 'run the node set against simulated boards over a simulated day'),
    'station': ('sslfr_field.station', 'the operations station of a field: discovery servers, field recorder, gateway'),
    'field-report': ('sslfr_field.report', 'the field\'s day summed from its collectors\' bags'),
    'record': ('sslfr_recording.record_cli', 'record tracker topics to an MCAP bag (rosbag2 layout)'),
    'bag': ('sslfr_recording.bag_cli', 'bag utilities: info, check (rosbag2 rules), recover'),
    'replay': ('sslfr_recording.replay', 'replay a recorded bag with /clock'),
    'report': ('sslfr_recording.report_cli', 'day report of a recorded bag (text, Markdown, PNG plots)'),
    'install-service': ('sslfr_bringup.service', 'install systemd units for the node set (Raspberry Pi)'),
    'web-password': ('sslfr_web.password_cli', 'set the operator password of the web page (stored as a scrypt hash)'),
    'doctor': ('sslfr_bringup.doctor', 'check the installation: ROS underlay, interfaces, executables'),
    'keys': ('sslfr_drivers.link.keys_cli', 'installation key: new key file, key id, provision a board over USB'),
    'flash': ('sslfr_drivers.firmware.flash', 'build and flash a board\'s firmware (avrdude), read INFO back, set its EEPROM'),
}


def _available() -> dict[str, tuple[str, str]]:
    out = {}
    for name, (module, text) in SUBCOMMANDS.items():
        try:
            found = importlib.util.find_spec(module) is not None
        except ModuleNotFoundError:  # parent package not installed
            found = False
        if found:
            out[name] = (module, text)
    return out


def usage() -> str:
    """Return the top-level help text listing the installed subcommands."""
    lines = ['usage: sslfr SUBCOMMAND [ARGS...]   (sslfr SUBCOMMAND --help for details)', '',
             'subcommands:']
    for name, (_, text) in _available().items():
        lines.append(f'  {name:<16}{text}')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Dispatch ``argv[0]`` to its subcommand module; return the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    for stream in (sys.stdout, sys.stderr):   # a path of undecodable bytes is shown escaped, never a crash
        try:
            stream.reconfigure(errors='backslashreplace')
        except (AttributeError, ValueError, io.UnsupportedOperation):
            pass
    if not argv or argv[0] in ('-h', '--help', 'help'):
        print(usage())
        return 0
    name, rest = argv[0], argv[1:]
    entry = _available().get(name)
    if entry is None:
        print(f'sslfr: unknown subcommand {name!r}\n\n{usage()}', file=sys.stderr)
        return 2
    try:
        module = importlib.import_module(entry[0])  # Ctrl-C while importing: no traceback
        code = int(module.main(rest) or 0)
    except KeyboardInterrupt:
        code = 130
    except BrokenPipeError:
        return 0
    supervisor = sys.modules.get('sslfr_bringup.supervisor')
    if supervisor is not None:           # sslfr up / sim: never hang at exit on a stuck ROS side
        supervisor.exit_if_stuck(code, f'sslfr {name}')
    return code


if __name__ == '__main__':
    sys.exit(main())
