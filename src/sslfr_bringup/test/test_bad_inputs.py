"""Table-driven bad-input test of the bag commands (issue 22).

Every case is a command line of ``sslfr bag|record|replay|report`` with one bad
input. Each must be refused with exit status 2, one line on stderr naming the input
and what is allowed, no traceback, nothing on stdout, and no file created, changed
or removed anywhere under the test directory. The cases run in-process through the
``sslfr`` dispatcher (an uncaught exception fails the case); a few run through the
real ``./sslfr`` script as well.
"""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Temperature

from sslfr_bringup import cli
from sslfr_recording.bag import BagWriter, WriterOptions, profile

ROOT = Path(__file__).resolve().parents[3]
PNG = b'\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR' + bytes(range(256))

#: (subcommand argv with {placeholders}, text the one-line refusal must contain)
CASES = [
    # -- sim / up / install-service arguments (values for generated files included) ------------
    ('sim --flow nan', '--flow'),
    ('sim --flow 1e9', '--flow'),
    ('sim --speed 0', '--speed'),
    ('sim --speed inf', '--speed'),
    ('sim --date 1000-06-21', '--date'),
    ('sim --date 2026-02-30', '--date'),
    ('sim --domain-id -1', '--domain-id'),
    ('sim --seed x', '--seed'),
    ('up --domain-id 0', '--domain-id'),
    ('up --domain-id 999', '--domain-id'),
    ("install-service --dry-run --namespace '/a\nExecStartPre=/bin/false'", '--namespace'),
    ("install-service --dry-run --user 'pi\nExecStartPre=/bin/false'", '--user'),
    ("install-service --dry-run --peers '10.0.0.1\nExecStartPre=/bin/false'", '--peers'),
    ('install-service --dry-run --namespace relative', '--namespace'),
    ('install-service --dry-run --domain-id 0', '--domain-id'),
    ('install-service --unit-dir {file} --no-enable', '--unit-dir'),
    ('install-service --unit-dir /proc/x --no-enable', '--unit-dir'),
    ('install-service --dry-run --config {png}', '--config'),
    ('install-service --dry-run --config {badsite}', 'horizonn'),   # what `up` refuses
    ('sim --out /proc/x', '--out'),
    ('sim --out {file}', '--out'),
    ('sim --record /proc/x', '--record'),
    ('sim --record {file}/sub', '--record'),
    ('sim --out {withlogs}', 'did not make'),          # never replaces someone else's logs/
    ('sim --nodeset {pngfile}', 'not a text file'),
    ('up --log-dir /proc/x', '--log-dir'),
    ('up --log-dir {file}', '--log-dir'),
    ('up --nodeset {pngfile}', 'not a text file'),
    ('up --print --nodeset {pngfile}', 'not a text file'),
    ('up --print --namespace /1bad', '--namespace'),
    ('up --print --namespace relative', '--namespace'),
    ('plan --lat 37 --lon -2 --collector-azimuth 1e308', '--collector-azimuth'),
    ('plan --lat 37 --lon -2 --collector-azimuth nan', '--collector-azimuth'),
    ('plan --lat 37 --lon -2 --delta-t 1e300', '--delta-t'),
    ('field --positions 1e308 --height 5 --radius 0.1', '--positions'),
    ('field --positions 1,2 --height 1e308 --radius 0.1', '--height'),
    # -- wrong-kind and missing bags ------------------------------------------------------
    ('bag info {png}', 'metadata.yaml'),
    ('bag info {binary}', 'metadata.yaml'),
    ('bag info {types}', 'topics_with_message_count'),
    ('bag info {qos_string}', 'offered_qos_profiles'),
    ('bag info {nometa}', 'metadata.yaml'),
    ('bag info {tmp}/missing', 'no such file'),
    ('bag info {pngfile}', 'bad magic'),
    ('bag info {empty}', 'metadata.yaml'),
    ('bag check {tmp}/missing', 'no such file'),
    ('bag check', 'BAG'),
    ('bag recover {tmp}/missing', 'no such file'),
    ('bag recover {pngfile}', 'not a file'.replace('not a file', 'bag directory')),
    ('bag recover {empty}', 'no .mcap file'),
    ('bag frobnicate {good}', 'frobnicate'),
    ('report {png}', 'metadata.yaml'),
    ('report {types}', 'topics_with_message_count'),
    ('report {binary}', 'metadata.yaml'),
    ('report {tmp}/missing', 'no such bag'),
    ('report {good} --out {file}', '--out'),
    ('report {good} --out {file}/sub', '--out'),
    ('report {good} --out /proc/x', '--out'),
    ('report {good} --config {pngfile}', '--config'),
    ('report {good} --config {tmp}/missing.yaml', '--config'),
    ('report {good} --config {badsite}', 'horizonn'),
    ('report {good} --config {badsite}', 'collector.n_per_side'),
    ('replay {png}', 'metadata.yaml'),
    ('replay {types}', 'topics_with_message_count'),
    ('replay {tmp}/missing', 'no such bag'),
    ('replay {pngfile}', 'MCAP'),
    # -- replay numbers, names, remaps, domains, outputs -----------------------------------
    ('replay {good} --rate nan', '--rate'),
    ('replay {good} --rate 1e-300', '--rate'),
    ('replay {good} --rate inf', '--rate'),
    ('replay {good} --rate -1', '--rate'),
    ('replay {good} --rate fast', '--rate'),
    ('replay {good} --wait-subscribers inf', '--wait-subscribers'),
    ('replay {good} --wait-subscribers -1', '--wait-subscribers'),
    ('replay {good} --clock-hz 0', '--clock-hz'),
    ('replay {good} --clock-hz nan', '--clock-hz'),
    ('replay {good} --remap garbage', '--remap'),
    ('replay {good} --remap :=', '--remap'),
    ('replay {good} --remap /t:=bad\\ name!', '--remap'),
    ('replay {good} --remap /t:=/u/', '--remap'),
    ('replay {good} --remap /t:=/1abc', '--remap'),
    ('replay {good} --remap /t:=/u //u:=/v', '--remap'),
    ('replay {good} --remap /nothere:=/v', '--remap'),
    ('replay {good} --remap /t:=/u2', '--remap'),  # collides with the recorded /u2
    ('replay {good} --topics bad\\ name!', '--topics'),
    ('replay {good} --topics /nothere', '--topics'),
    ('replay {good} --start noon', '--start'),
    ('replay {good} --start 100', 'outside the bag'),
    ('replay {good} --end -100', 'outside the bag'),
    ('replay {good} --start 1.5 --end 0.5', 'inverted'),
    ('replay {good} --start 1 --end 1', 'empty'),
    ('replay {good} --start 9' + '9' * 400, '--start'),
    ('replay {good} --start 2000-01-01T00:00:00Z --end 2000-01-02T00:00:00Z', 'outside the bag'),
    ('replay {good} --what-if --start 100', 'outside the bag'),
    ('replay {good} --end 25:99:99x', '--start/--end'),
    ('replay {good} --what-if --domain -1', '--domain'),
    ('replay {good} --what-if --domain 233', '--domain'),
    ('replay {good} --what-if --domain abc', '--domain'),
    ('replay {good} --domain 5', '--domain'),
    ('replay {good} --what-if --out {file}', '--out'),
    ('replay {good} --what-if --out {file}/sub', '--out'),
    ('replay {good} --what-if --out /proc/x', '--out'),
    ('replay {good} --what-if --config {pngfile}', '--config'),
    ('replay {good} --what-if --config {tmp}/missing.yaml', '--config'),
    ('replay {good} --inputs bad\\ name!', '--inputs'),
    # -- record numbers, names, outputs -------------------------------------------------------
    ('record -o {tmp}/r --chunk-duration nan', '--chunk-duration'),
    ('record -o {tmp}/r --chunk-duration 0', '--chunk-duration'),
    ('record -o {tmp}/r --chunk-duration -1', '--chunk-duration'),
    ('record -o {tmp}/r --chunk-duration inf', '--chunk-duration'),
    ('record -o {tmp}/r --chunk-duration 1e9', '--chunk-duration'),
    ('record -o {tmp}/r --max-file-size-mib -5', '--max-file-size-mib'),
    ('record -o {tmp}/r --max-file-size-mib nan', '--max-file-size-mib'),
    ('record -o {tmp}/r --max-file-size-mib 1e300', '--max-file-size-mib'),
    ('record -o {tmp}/r --max-file-size-mib 0.001', '--max-file-size-mib'),
    ('record -o {tmp}/r --min-free-mib -1', '--min-free-mib'),
    ('record -o {tmp}/r --min-free-mib nan', '--min-free-mib'),
    ('record -o {tmp}/r --min-free-mib 1e300', '--min-free-mib'),
    ('record -o {tmp}/r --max-file-duration -1', '--max-file-duration'),
    ('record -o {tmp}/r --max-file-duration nan', '--max-file-duration'),
    ('record -o {tmp}/r --max-file-duration inf', '--max-file-duration'),
    ('record -o {tmp}/r --prefix ""', '--prefix'),
    ('record -o {tmp}/r --prefix a/b', '--prefix'),
    ('record -o {tmp}/r --node-name bad\\ name!', '--node-name'),
    ('record -o {tmp}/r --node-name ""', '--node-name'),
    ('record -o {tmp}/r --node-name 1abc', '--node-name'),
    ('record -o {tmp}/r --topics bad\\ name!', '--topics'),
    ('record -o {tmp}/r --topics /a//b', '--topics'),
    ('record -o {tmp}/r --compression gzip', '--compression'),
    ('record -o {file}', '--output'),
    ('record -o {file}/sub', '--output'),
    ('record -o /proc/x', '--output'),
    ('record -o ""', '--output'),
]


def _bag(path: Path, topics=('/t', '/u2')) -> None:
    w = BagWriter(path, WriterOptions(fsync=False))
    for t in topics:
        w.add_topic(t, 'sensor_msgs/msg/Temperature', [profile()])
    for k in range(20):
        for t in topics:
            w.write(t, bytes(serialize_message(Temperature(temperature=float(k)))), 10**18 + k * 10**8)
    w.close()


@pytest.fixture(scope='module')
def corpus(tmp_path_factory):
    tmp = tmp_path_factory.mktemp('bad_inputs')
    paths = {'tmp': tmp, 'good': tmp / 'good', 'file': tmp / 'a_file'}
    _bag(tmp / 'good')
    meta = (tmp / 'good' / 'metadata.yaml').read_text()
    variants = {
        'png': PNG,
        'binary': bytes(range(256)) * 4,
        'types': b'rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n'
                 b'  duration: {nanoseconds: 1}\n  starting_time: {nanoseconds_since_epoch: 1}\n'
                 b'  message_count: 1\n  topics_with_message_count: 5\n',
        'qos_string': meta.replace('        offered_qos_profiles:\n',
                                   '        offered_qos_profiles: "- history: keep_last"\n'
                                   '        old_qos:\n', 1).encode(),
    }
    for name, data in variants.items():
        d = tmp / name
        d.mkdir()
        for f in (tmp / 'good').glob('*.mcap'):
            (d / f.name).write_bytes(f.read_bytes())
        (d / 'metadata.yaml').write_bytes(data)
        paths[name] = d
    paths['nometa'] = tmp / 'nometa'
    paths['nometa'].mkdir()
    for f in (tmp / 'good').glob('*.mcap'):
        (paths['nometa'] / f.name).write_bytes(f.read_bytes())
    paths['withlogs'] = tmp / 'withlogs'
    (paths['withlogs'] / 'logs').mkdir(parents=True)
    (paths['withlogs'] / 'logs' / 'mine.txt').write_text('not the simulation\'s')
    paths['empty'] = tmp / 'empty'
    paths['empty'].mkdir()
    paths['pngfile'] = tmp / 'picture.png'
    paths['pngfile'].write_bytes(PNG)
    paths['file'].write_text('I am a file')
    paths['badsite'] = tmp / 'bad_site.yaml'     # a misspelt key and a wrong type
    paths['badsite'].write_text('planner:\n  ros__parameters:\n    horizonn: 60.0\n'
                                '    collector.n_per_side: 12.5\n')
    return paths


def _snapshot(root: Path) -> dict:
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = p.lstat()
            out[str(p.relative_to(root))] = (st.st_mode, st.st_size, st.st_mtime_ns)
    return out


def _argv(template: str, paths: dict) -> list[str]:
    import shlex
    return shlex.split(template.format(**{k: str(v) for k, v in paths.items()}))


@pytest.mark.parametrize('template,needle', CASES, ids=[c[0] for c in CASES])
def test_bad_input_refused_in_one_line(template, needle, corpus, capsys):
    before = _snapshot(corpus['tmp'])
    rc = cli.main(_argv(template, corpus))
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert rc == 2, (template, err)
    assert len(lines) == 1, err
    assert needle in lines[0], (needle, lines[0])
    assert 'Traceback' not in err and out == ''
    assert _snapshot(corpus['tmp']) == before, 'a file was created, changed or removed'
    assert not Path('/proc/x').exists()


def test_case_count():
    print(f'bad-input table: {len(CASES)} cases')
    assert len(CASES) >= 80


@pytest.mark.parametrize('template', ['bag info {png}', 'record -o {file}', 'replay {good} --rate nan',
                                      'report {types}', 'bag recover {pngfile}'])
def test_bad_input_through_the_sslfr_script(template, corpus):
    before = _snapshot(corpus['tmp'])
    proc = subprocess.run([str(ROOT / 'sslfr'), *_argv(template, corpus)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and 'Traceback' not in proc.stderr
    assert _snapshot(corpus['tmp']) == before


def _schema_bag(path: Path, type_name: str, schema_text: str) -> None:
    w = BagWriter(path, WriterOptions(fsync=False))
    w.add_topic('/t', type_name, [profile()], schema_text=schema_text, type_hash='RIHS01_' + '0' * 64)
    for k in range(5):
        w.write('/t', bytes(serialize_message(Temperature(temperature=float(k)))), 10**18 + k * 10**8)
    w.close()


@pytest.mark.parametrize('text', ['float64 temperature\nfloat64 variance\nstd_msgs/Header header\n',
                                  '\0garbage [[['])
def test_recover_rebuilds_a_damaged_schema_that_info_refuses(tmp_path, capsys, text):
    bag = tmp_path / 'bag'
    _schema_bag(bag, 'sensor_msgs/msg/Temperature', text)
    assert cli.main(['bag', 'info', str(bag)]) == 2
    assert 'sslfr bag recover' in capsys.readouterr().err
    assert cli.main(['bag', 'recover', str(bag)]) == 0
    assert 'rebuilt from the installed message definitions' in capsys.readouterr().out
    assert cli.main(['bag', 'info', str(bag)]) == 0          # recover and info agree
    assert 'sensor_msgs/msg/Temperature' in capsys.readouterr().out


def test_recover_says_plainly_when_it_cannot_rebuild_a_schema(tmp_path, capsys):
    bag = tmp_path / 'bag'
    _schema_bag(bag, 'nowhere_msgs/msg/Thing', 'garbage [[[')
    assert cli.main(['bag', 'info', str(bag)]) == 2
    err = capsys.readouterr().err
    assert 'cannot repair it' in err and 'nowhere_msgs' in err and 'try sslfr bag recover' not in err
    assert cli.main(['bag', 'recover', str(bag)]) == 1
    out, err = capsys.readouterr()
    assert 'cannot repair' in out and ': ok' not in out
    assert len(err.strip().splitlines()) == 1 and 'would still refuse' in err
