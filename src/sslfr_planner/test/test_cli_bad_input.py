"""Bad input to ``sslfr plan`` and ``sslfr analyse`` (issue 22): exit 2, one line naming the
argument or key and what is allowed, no traceback, nothing written."""
from __future__ import annotations

import os
import zlib
from pathlib import Path

import pytest

from sslfr_planner import cli_plan
from sslfr_planner.analysis import cli as cli_analyse

PNG = (b'\x89PNG\r\n\x1a\n' + b'\x00\x00\x00\rIHDR\x00\x00\x00\x01\x00\x00\x00\x01\x08\x06\x00\x00\x00\x1f\x15\xc4\x89'
       + b'\x00\x00\x00\nIDATx\x9cc\x00\x01\x00\x00\x05\x00\x01' + zlib.compress(b'')[:2] + b'\x00\x00\x00\x00IEND\xaeB`\x82')
CONFIGS = {   # name -> file content
    'image.png': PNG,
    'random.bin': bytes(range(256)) * 8,
    'list.yaml': b'- 1\n- 2\n',
    'scalar.yaml': b'just a string\n',
    'bad_yaml.yaml': b'/**:\n  ros__parameters: {site.latitude_deg: [\n',
    'section_list.yaml': b'/**:\n  - 1\n',
    'params_list.yaml': b'/**:\n  ros__parameters: [1, 2]\n',
    'north.yaml': b'/**:\n  ros__parameters:\n    site.latitude_deg: north\n',
    'lat95.yaml': b'/**:\n  ros__parameters:\n    site.latitude_deg: 95.0\n',
    'latnan.yaml': b'/**:\n  ros__parameters:\n    site.latitude_deg: .nan\n',
    'nper.yaml': b'planner:\n  ros__parameters:\n    collector.n_per_side: 12.5\n',
    'optics.yaml': b'analysis:\n  ros__parameters:\n    optics.shininess: 0.5\n',
    'aim.yaml': b'analysis:\n  ros__parameters:\n    optics.mirror_aim: sideways\n',
    'tube.yaml': b'analysis:\n  ros__parameters:\n    tube.eq16.left: left\n',
}

# (argv with {dir} / {cfg:NAME} placeholders, words that must be in the message)
CASES = [
    # plan
    (['plan', '--lat', '36', '--lon', '0', '--step', '1e-9'], ['--step', 'at most 864,000', '0.1 s']),
    (['plan', '--lat', '36', '--lon', '0', '--step', 'nan'], ['--step', 'finite']),
    (['plan', '--lat', '36', '--lon', '0', '--step', '-1'], ['--step', '> 0']),
    (['plan', '--lat', '36', '--lon', '0', '--step', '1e9'], ['--step', '86400']),
    (['plan', '--lat', '36', '--lon', '0', '--out', '{dir}'], ['--out', 'directory']),
    (['plan', '--lat', '36', '--lon', '0', '--out', '{dir}/missing/x.csv'], ['--out', 'does not exist']),
    (['plan', '--lat', '36', '--lon', '0', '--out', '{dir}/file.txt/x.csv'], ['--out', 'not a directory']),
    (['plan', '--lat', '36', '--lon', '0', '--out', '/proc/x.csv'], ['--out', 'cannot write']),
    # analyse year
    (['year', '--step', '1e-9'], ['--step', 'at most 527,040', 'step >= 60 s']),
    (['year', '--step', 'nan'], ['--step', 'finite']),
    (['year', '--step', 'inf'], ['--step', 'finite']),
    (['year', '--step', '-600'], ['--step', '> 0']),
    (['year', '--year', '9999'], ['--year', '[1800, 2200]']),
    (['year', '--year', '-5'], ['--year', '[1800, 2200]']),
    (['year', '--year', 'soon'], ['--year', 'integer']),
    (['year', '--mode', 'wobble'], ['--mode', 'continuous']),
    (['year', '--mode', ','], ['--mode', 'empty']),
    (['year', '--model', 'magic'], ['--model']),
    (['year', '--dni-csv', '{cfg:image.png}'], ['--dni-csv']),
    # analyse tilts
    (['tilts', '--max-area', 'nan'], ['--max-area', 'finite']),
    (['tilts', '--max-area', '-5'], ['--max-area', '(0, 1000000]']),
    (['tilts', '--max-area', '0'], ['--max-area', '(0, 1000000]']),
    (['tilts', '--grid', '1'], ['--grid', '[2, 101]']),
    (['tilts', '--step', '10'], ['--step', 'at most 105,408', 'step >= 300 s']),
    (['tilts', '--out', '{dir}/missing/h.png'], ['--out', 'does not exist']),
    (['tilts', '--out', '{dir}'], ['--out', 'is a directory']),
    (['tilts', '--out', '{dir}/file.txt/h.png'], ['--out', 'not a directory']),
    (['tilts', '--out', '/proc/h.png'], ['--out', 'cannot write']),
    (['tilts', '--out', ''], ['--out', 'empty']),
    # analyse error
    (['error', '--errors', 'nan'], ['--errors', 'finite']),
    (['error', '--errors', '20'], ['--errors', '0..10']),
    (['error', '--days', '2024-02-30'], ['--days', 'YYYY-MM-DD']),
    (['error', '--days', '0005-06-21'], ['--days', '1800..2200']),
    (['error', '--hours', '25'], ['--hours', '0..24']),
    # configs
    (['year', '--config', '{dir}/absent.yaml'], ['absent.yaml', 'No such file']),
    (['year', '--config', '{cfg:image.png}'], ['image.png', 'not a text file']),
    (['error', '--config', '{cfg:random.bin}'], ['random.bin', 'UTF-8']),
    (['tilts', '--config', '{cfg:list.yaml}'], ['list.yaml', 'mapping']),
    (['year', '--config', '{cfg:scalar.yaml}'], ['scalar.yaml', 'mapping']),
    (['year', '--config', '{cfg:bad_yaml.yaml}'], ['bad_yaml.yaml', 'not valid YAML']),
    (['year', '--config', '{cfg:section_list.yaml}'], ['section_list.yaml', "'/**'", 'mapping']),
    (['year', '--config', '{cfg:params_list.yaml}'], ['params_list.yaml', 'ros__parameters']),
    (['year', '--config', '{cfg:north.yaml}'], ['north.yaml', 'site.latitude_deg', '-90..90', "'north'"]),
    (['year', '--config', '{cfg:lat95.yaml}'], ['lat95.yaml', 'site.latitude_deg', '95']),
    (['error', '--config', '{cfg:latnan.yaml}'], ['latnan.yaml', 'site.latitude_deg']),
    (['year', '--config', '{cfg:nper.yaml}'], ['nper.yaml', 'collector.n_per_side', 'integer']),
    (['year', '--config', '{cfg:optics.yaml}'], ['optics.yaml', 'shininess']),
    (['year', '--config', '{cfg:aim.yaml}'], ['aim.yaml', 'mirror_aim', 'focused']),
    (['year', '--config', '{cfg:tube.yaml}', '--mode', 'eq16', '--step', '86400'], ['tube.yaml', 'tube.eq16.left']),
]


@pytest.fixture(scope='module')
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp('bad')
    (d / 'file.txt').write_text('x')
    for name, data in CONFIGS.items():
        (d / name).write_bytes(data)
    return d


def _fill(args, d: Path):
    out = []
    for a in args:
        a = a.replace('{dir}', str(d))
        if a.startswith('{cfg:'):
            a = str(d / a[5:-1])
        out.append(a)
    return out


@pytest.mark.parametrize('args,words', CASES, ids=[' '.join(c[0])[:60] for c in CASES])
def test_bad_input_is_refused_with_one_line(args, words, workdir, capsys):
    argv = _fill(args, workdir)
    before = sorted(os.listdir(workdir))
    if argv[0] == 'plan':
        prog, code = 'sslfr plan', cli_plan.main(argv[1:])
    else:
        prog, code = 'sslfr analyse', cli_analyse.main(argv)
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == 2, (argv, captured.err)
    assert len(err) == 1 and err[0].startswith(f'{prog}: error:'), err
    for w in words:
        assert w in err[0], (w, err[0])
    assert 'Traceback' not in captured.err and captured.out == ''
    assert sorted(os.listdir(workdir)) == before          # nothing written, no temporary left


def test_a_good_heat_map_is_written_whole(workdir, tmp_path, capsys, monkeypatch):
    """--out is written through a temporary file renamed into place: a failure leaves nothing."""
    from sslfr_planner.analysis import cli

    def boom(res, site, path):
        Path(path).write_bytes(b'partial')
        raise OSError(28, 'No space left on device')
    monkeypatch.setattr(cli, 'write_heatmap', boom)
    target = tmp_path / 'h.png'
    code = cli.main(['tilts', '--step', '86400', '--grid', '2', '--out', str(target)])
    assert code == 1 and not target.exists() and os.listdir(tmp_path) == []
    assert 'No space left' in capsys.readouterr().err
