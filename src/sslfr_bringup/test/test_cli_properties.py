"""Property tests (Hypothesis): random and adversarial input never raises an uncaught
exception, in every ``sslfr`` subcommand and every parser of outside input.

A subcommand gets command lines made of its own options (read from its parser) with
adversarial values (NaN, infinities, overflowing numbers, NUL bytes, undecodable
bytes, paths into /proc, at a file, very long names, a PNG as a config, a bag).
Each must end with exit status 0, 1 or 2 (2: one line on stderr, no traceback), or
reach the point where the real work starts: that point is replaced by a marker
(:class:`Reached`) so no test starts nodes, flashes a board or writes a systemd unit;
everything before it (parsing and every check) runs for real.
"""
from __future__ import annotations

import argparse
import collections
import io
import math
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Temperature

from sslfr_bringup import cli
from sslfr_recording.bag import BagWriter, WriterOptions, profile

FIELD = Path(__file__).resolve().parents[1] / 'config' / 'fields' / 'example_field.yaml'
PNG = b'\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR' + bytes(range(256))


class Reached(Exception):
    """The command got past every check to the work itself."""


def _reached(*_a, **_k):
    raise Reached()


#: subcommand -> (module attribute paths replaced by the marker)
WORK = {
    'plan': ['sslfr_planner.cli_plan.tabulate_day'],
    'field': ['sslfr_planner.cli_field.fit_linear'],
    'analyse': ['sslfr_planner.analysis.performance.error_table',
                'sslfr_planner.analysis.cli.YearSky.compute'],
    'up': ['sslfr_bringup.up.RosSide'],
    'sim': ['sslfr_sim.sim_cli.SimClock', 'sslfr_field.station.run'],
    'station': ['sslfr_field.station.run'],
    'field-report': ['sslfr_recording.report.analyse'],
    'record': ['sslfr_recording.recorder_node.main'],
    'bag': [],
    'replay': ['sslfr_recording.replay.run_player', 'sslfr_recording.replay.run_whatif'],
    'report': ['sslfr_recording.report_cli.analyse'],
    'install-service': ['sslfr_bringup.service.write_atomically'],
    'web-password': ['sslfr_web.password_cli.write_password_file'],
    'doctor': ['sslfr_bringup.doctor.find_executable'],
    'keys': ['sslfr_drivers.link.keys_cli.write_key_file', 'sslfr_drivers.link.keys_cli._open_serial'],
    'flash': ['sslfr_drivers.firmware.flash.build', 'sslfr_drivers.firmware.flash.run_avrdude',
              'sslfr_drivers.firmware.flash.read_board'],
}


def _patch(monkeypatch, dotted: str) -> None:
    import importlib
    parts = dotted.split('.')
    for k in range(len(parts) - 1, 0, -1):
        try:
            obj = importlib.import_module('.'.join(parts[:k]))
        except ImportError:
            continue
        for name in parts[k:-1]:
            obj = getattr(obj, name)
        monkeypatch.setattr(obj, parts[-1], _reached)
        return
    raise AssertionError(dotted)


def _parser_of(name: str) -> argparse.ArgumentParser | None:
    import importlib
    mod = importlib.import_module(cli.SUBCOMMANDS[name][0])
    return mod.parser() if hasattr(mod, 'parser') else None


def _options(parser: argparse.ArgumentParser | None) -> tuple[list[str], list[str]]:
    """(option strings, sub-command names) of a parser (and its sub-parsers)."""
    opts, subs = [], []
    if parser is None:
        return ['--config', '--out', '--bag'], []
    for action in parser._actions:                      # noqa: SLF001 - introspection of our own parsers
        if isinstance(action, argparse._SubParsersAction):  # noqa: SLF001
            for sub_name, sub in action.choices.items():
                subs.append(sub_name)
                opts += _options(sub)[0]
        elif action.option_strings and '-h' not in action.option_strings:
            opts.append(max(action.option_strings, key=len))
    return sorted(set(opts)), subs


@pytest.fixture(scope='module')
def places(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('cli_props')
    bag = tmp / 'bag'
    w = BagWriter(bag, WriterOptions(fsync=False))
    w.add_topic('/t', 'sensor_msgs/msg/Temperature', [profile()])
    for k in range(5):
        w.write('/t', bytes(serialize_message(Temperature(temperature=float(k)))), 10**18 + k * 10**8)
    w.close()
    (tmp / 'file').write_text('a file')
    (tmp / 'pic.png').write_bytes(PNG)
    (tmp / 'notutf8.yaml').write_bytes(b'planner:\n  ros__parameters:\n    x: \xff\xfe\n')
    (tmp / 'deep.yaml').write_text('a: ' + '[' * 5000 + ']' * 5000 + '\n')
    return tmp


VALUES = ['nan', 'inf', '-inf', '1e308', '-1e308', '1e-320', '1e999', '0', '-0', '-1', '2', '37', '',
          ' ', '\x00', 'x\x00y', '\udcff\udcfe', 'ü', 'a\x85b', 'a\u2028b', 'a\r\nb', '\x1b[31m', '9' * 400, 'a' * 5000, '/proc/x', '/proc/x/y', '/dev/null',
          '{tmp}/file', '{tmp}/file/sub', '{tmp}', '{tmp}/new', '{tmp}/pic.png', '{tmp}/notutf8.yaml',
          '{tmp}/deep.yaml', '{tmp}/bag', '-5:5', '99:99', '10:00', '2026-02-30', '2026-06-21',
          '/a//b', '/1bad', '/sslfr1', 'a:=b', '/t:=/u', 'separate', 'composed', 'axis', 'stow', 'A=1',
          'planner:use_sim_time=true', 'gps:dropout@10:00+60', 'node:key=nan']


#: a valid command line of each subcommand: most examples change one or two of its
#: options to adversarial values, so the checks behind the parser are reached too
BASES = {
    'plan': [['--lat', '37', '--lon', '-2', '--step', '3600']],
    'field': [['--positions', '1,2', '--height', '5', '--radius', '0.1']],
    'analyse': [['error'], ['year'], ['tilts']],
    'up': [['--print'], []],
    'sim': [[], ['--collectors', '2']],
    'station': [['--field', str(FIELD), '--print'], ['--field', str(FIELD)]],
    'field-report': [['{tmp}/bag'], ['{tmp}']],
    'record': [['-o', '{tmp}/rec']],
    'bag': [['info', '{tmp}/bag'], ['check', '{tmp}/bag'], ['recover', '--dry-run', '{tmp}/bag']],
    'replay': [['{tmp}/bag'], ['{tmp}/bag', '--what-if']],
    'report': [['{tmp}/bag', '--no-plots']],
    'install-service': [['--dry-run'], []],
    'web-password': [['--stdin'], ['--unlock'], []],
    'doctor': [[]],
    'keys': [['id', '{tmp}/key'], ['new', '{tmp}/key2'], ['provision', '--port', '/dev/null']],
    'flash': [['axis', '--port', '/dev/null'], ['axis', '--port', '/dev/null', '--config-only']],
}


def _argv_strategy(name: str):
    opts, subs = _options(_parser_of(name))
    value = st.one_of(st.sampled_from(VALUES), st.text(max_size=20),
                      st.floats(allow_nan=True, allow_infinity=True).map(repr),
                      st.integers(min_value=-10**30, max_value=10**30).map(str))
    pair = st.tuples(st.sampled_from(opts), value) if opts else st.tuples(value, value)
    head = st.lists(st.sampled_from(subs), min_size=0, max_size=1) if subs else st.just([])
    positional = st.lists(value, max_size=2)
    wild = st.tuples(head, positional, st.lists(pair, max_size=5)).map(
        lambda t: [*t[0], *t[1], *[x for p in t[2] for x in p]])
    based = st.tuples(st.sampled_from(BASES[name]), st.lists(pair, max_size=3)).map(
        lambda t: [*t[0], *[x for p in t[1] for x in p]])
    return st.one_of(based, based, wild)


OUTCOMES: dict = collections.defaultdict(collections.Counter)


def _check_run(name, argv, places, monkeypatch, capsys):
    argv = [a.replace('{tmp}', str(places)) for a in argv]
    if name == 'install-service':
        argv = [*argv, '--unit-dir', str(places / 'units')]
    if name == 'keys':
        monkeypatch.setattr('sslfr_drivers.link.keys_cli.default_key_path', lambda: str(places / 'key'))
    if name == 'web-password':
        monkeypatch.setattr('getpass.getpass', lambda prompt='': 'a-password-1')
        monkeypatch.setattr('sys.stdin', io.StringIO('a-password-1\n'))
        argv = [*argv, '--file', str(places / 'pw')] if '--file' not in argv else argv
    for dotted in WORK[name]:
        _patch(monkeypatch, dotted)
    try:
        rc = cli.main([name, *argv])
    except Reached:
        OUTCOMES[name]['reached the work'] += 1
        return
    except SystemExit as exc:              # only argparse's --help/--version may exit
        assert exc.code == 0, (name, argv)
        return
    finally:
        out, err = capsys.readouterr()
    OUTCOMES[name][f'exit {rc}'] += 1
    assert rc in (0, 1, 2), (name, argv, rc)
    assert 'Traceback' not in err, (name, argv, err)
    if rc == 2:
        assert len(err.strip().splitlines()) == 1, (name, argv, err)


COMMANDS = [n for n in cli.SUBCOMMANDS if n in WORK]


@pytest.mark.parametrize('name', COMMANDS)
def test_cli_entry_point_never_raises(name, places, monkeypatch, capsys, tmp_path):
    monkeypatch.chdir(tmp_path)                 # relative outputs (sim's out/...) land here
    monkeypatch.setenv('HOME', str(tmp_path))   # so do ~/... defaults

    @settings(max_examples=int(os.environ.get('SSLFR_CLI_EXAMPLES', '60')), deadline=None,
              suppress_health_check=list(HealthCheck),
              database=None)
    @given(argv=_argv_strategy(name))
    def prop(argv):
        _check_run(name, argv, places, monkeypatch, capsys)
    prop()
    print(f'sslfr {name}: {dict(OUTCOMES[name])}')


def test_every_subcommand_has_a_property_test():
    assert set(cli.SUBCOMMANDS) == set(WORK) == set(BASES)


# ------------------------------------------------------------------------ parsers of input
@settings(max_examples=300, deadline=None)
@given(raw=st.one_of(st.binary(max_size=200), st.text(max_size=200).map(str.encode),
                     st.integers(1, 3000).map(lambda n: b'[' * n + b']' * n),
                     st.integers(1, 3000).map(lambda n: b'{"a":' * n + b'1' + b'}' * n)))
def test_web_body_parser_refuses_cleanly(raw):
    from sslfr_web import commands
    try:
        body = commands.parse_body(raw)
    except commands.CommandError as exc:
        assert '\n' not in str(exc)
        return
    assert isinstance(body, dict)
    for name in ('stow', 'mode', 'jog', 'home', 'estop', 'release', 'reset', 'replan', 'x'):
        try:
            cmd = commands.validate(name, body, {'mirrors': commands.JogLimits(0.2)})
        except commands.CommandError:
            continue
        for v in cmd.request.values():
            assert not isinstance(v, float) or math.isfinite(v)


@settings(max_examples=300, deadline=None)
@given(spec=st.one_of(st.text(max_size=40), st.sampled_from(['1e999', '9' * 400, '-' + '9' * 400, '99:99:99',
                                                              '0001-01-01T00:00:00', '9999-12-31T23:59:59'])))
def test_replay_time_spec_parser_refuses_cleanly(spec):
    from sslfr_recording.bag.playback import parse_time_spec
    try:
        assert isinstance(parse_time_spec(spec, 10**18, 10**18 + 10**9), int)
    except ValueError:
        pass


@settings(max_examples=50, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.one_of(st.binary(max_size=300), st.text(max_size=300).map(lambda t: t.encode('utf-8', 'surrogatepass')),
                      st.integers(1, 1500).map(lambda n: b'a: ' + b'[' * n + b']' * n),
                      st.integers(1, 1500).map(lambda n: b'{a: ' * n + b'1' + b'}' * n)))
def test_site_config_and_node_set_readers_refuse_cleanly(data, tmp_path_factory):
    from sslfr_bringup import nodeset
    path = tmp_path_factory.mktemp('cfg') / 'x.yaml'
    path.write_bytes(data)
    for read in (nodeset.read_params, nodeset.load):
        try:
            read(path)
        except nodeset.NodeSetError as exc:
            assert str(exc)


@settings(max_examples=300, deadline=None)
@given(text=st.text(max_size=300))
def test_bag_metadata_parser_refuses_cleanly(text):
    from sslfr_recording.bag.metadata import MetadataError, parse_metadata
    try:
        parse_metadata(text)
    except MetadataError:
        pass


@settings(max_examples=300, deadline=None)
@given(spec=st.text(max_size=60))
def test_fault_and_set_parsers_refuse_cleanly(spec):
    from sslfr_sim import faults, sim_cli
    try:
        faults.parse(spec)
    except ValueError:
        pass
    try:
        sim_cli.parse_set(spec, ['planner', 'safety'])
    except ValueError:
        pass


@settings(max_examples=300, deadline=None)
@given(values=st.tuples(st.integers(-3, 3), *[st.floats(allow_nan=True, allow_infinity=True)] * 3,
                        st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=10),
                        st.integers(-1, 4)))
def test_gps_fix_check_never_accepts_a_non_finite_site(values):
    from sslfr_planner.site_source import check_fix
    status, lat, lon, alt, cov, cov_type = values
    if check_fix(status, lat, lon, alt, cov, cov_type, 500.0) is None:
        assert math.isfinite(lat) and math.isfinite(lon) and (math.isnan(alt) or math.isfinite(alt))


@settings(max_examples=300, deadline=None)
@given(text=st.text(max_size=80))
def test_network_list_parser_refuses_cleanly(text):
    from sslfr_web.params import networks_error
    assert networks_error(text) is None or isinstance(networks_error(text), str)

