"""The ``web`` node's parameters: one :class:`~sslfr_common.params.ParamTable` (pure).

The table type every node uses (:mod:`sslfr_common.params`): a default, a description
with the unit, a range or choices. Every parameter is read-only at runtime (the server
binds once); a bad value at start-up stops the node with one line naming each bad
parameter (exit code 2). Floating-point parameters also take integers (YAML ``8``).
"""
from __future__ import annotations


from sslfr_common.netguard import parse_networks
from sslfr_common.netguard import Limits, ip_address_error, limit_params
from sslfr_common.params import ParamSpec, ParamTable, writable_directory

#: The password file `./sslfr web-password` writes and the node reads.
DEFAULT_PASSWORD_FILE = '~/.config/sslfr/web_password'


def networks_error(text: str) -> str | None:
    """None for 'auto' or a comma-separated list of IP networks, else the reason."""
    if text.strip() == 'auto':
        return None
    try:
        parse_networks(text)
    except ValueError as exc:
        return str(exc)
    return None


WEB_PARAMS = ParamTable((
    ParamSpec('bind_address', '127.0.0.1',
              'IP address the page is served on: 127.0.0.1 (this machine only, the default), '
              "the Pi's LAN address to open it to the local network; never every interface "
              'unless 0.0.0.0 / :: is given explicitly', read_only=True, validator=ip_address_error),
    ParamSpec('port', 8080, 'TCP port of the page (0: any free port, logged at start-up)', '-',
              0, 65535, read_only=True),
    ParamSpec('open_view', True,
              'true: anyone who reaches the page sees the live view and the recorded days; '
              'false: viewing needs the operator login too. Commands always need it',
              read_only=True),
    ParamSpec('password_file', DEFAULT_PASSWORD_FILE,
              'scrypt hash of the operator password, written by `./sslfr web-password` '
              '(re-read when it changes; missing: commands are refused)', read_only=True),
    ParamSpec('session_timeout', 3600.0,
              'A login session ends after this long without a request [s]', 's', 60.0, 86400.0,
              read_only=True),
    ParamSpec('login_max_failures', 5,
              'Failed logins allowed per client address within login_window before it is '
              'refused until the window has passed [-]', '-', 1, 1000, read_only=True),
    ParamSpec('login_window', 300.0, 'Window of the login rate limit [s]', 's', 1.0, 86400.0,
              read_only=True),
    ParamSpec('login_lockout', 60.0,
              'An address that reached login_max_failures is refused for this long; each further '
              'lockout of the same address doubles it, up to login_lockout_max [s]', 's', 1.0, 86400.0,
              read_only=True),
    ParamSpec('login_lockout_max', 3600.0, 'Longest lockout of one address [s]', 's', 1.0, 604800.0,
              read_only=True),
    ParamSpec('login_trusted_networks', 'auto',
              "Networks the global login limit (10 x login_max_failures in login_window, all "
              "addresses together) never refuses: 'auto' = loopback and the subnet(s) of the "
              "interface bind_address is on; or comma-separated networks, e.g. "
              "'192.168.1.0/24' (loopback is always trusted). The per-address limit applies to all",
              read_only=True, validator=networks_error),
    *limit_params(Limits(16, 128, 10.0, 60.0)),
    ParamSpec('body_timeout', 10.0,
              'A request body must arrive within this time, else the request is refused (408) [s]',
              's', 0.5, 120.0, read_only=True),
    ParamSpec('max_json_depth', 8,
              'Request bodies nested deeper than this (JSON arrays/objects) are refused (400) [-]',
              '-', 2, 64, read_only=True),
    ParamSpec('max_streams_per_address', 4,
              'Live-update streams (/api/events) one address may hold; a new one ends its oldest [-]',
              '-', 1, 100, read_only=True),
    ParamSpec('max_streams', 32,
              'Live-update streams in all; a new one ends the oldest stream of the address '
              'holding the most [-]', '-', 1, 1000, read_only=True),
    ParamSpec('push_period', 0.25,
              'The page is sent the live state at most this often, when it changed [s, wall]',
              's', 0.05, 1.0, read_only=True),
    ParamSpec('plot_period', 30.0,
              'One sample of the day plots per this much ROS time [s]', 's', 1.0, 3600.0,
              read_only=True),
    ParamSpec('max_jog', 0.2,
              "Largest |delta| the page may ask of a jog [rad]; the driver's own max_jog and "
              'soft limits apply too', 'rad', 0.0, 3.1416, read_only=True),
    ParamSpec('bag_dir', '',
              "Directory of the recorded bags ('' = ask the recorder node for its output_dir)",
              read_only=True),
    ParamSpec('report_dir', '~/.cache/sslfr/web_reports',
              'Where day reports made for the page are kept [directory]', read_only=True,
              validator=writable_directory),
    ParamSpec('audit_file', '~/.local/state/sslfr/web_commands.jsonl',
              "Every command (and every refusal) is appended here as a JSON line with its origin "
              "('' = only the node's log)", read_only=True),
    ParamSpec('service_timeout', 5.0, 'Longest wait for a service answer [s, wall]', 's', 0.5, 60.0,
              read_only=True),
    ParamSpec('max_request_bytes', 16384, 'Larger request bodies are refused (HTTP 413) [bytes]',
              'bytes', 256, 1048576, read_only=True),
), cross_check=lambda v: [] if v['login_lockout_max'] >= v['login_lockout'] else
    [f"login_lockout_max ({v['login_lockout_max']} s) must be at least login_lockout ({v['login_lockout']} s)"],
    integers_for_floats=True)
