"""sslfr_common.files.atomic_write: all or nothing, with the requested permissions."""
import os
import stat

import pytest

from sslfr_common.files import atomic_write


def test_writes_text_bytes_and_through_a_writer(tmp_path):
    p = tmp_path / 'a.yaml'
    assert atomic_write(p, 'x: 1\n') == p and p.read_text() == 'x: 1\n'
    atomic_write(p, b'\x00\x01')
    assert p.read_bytes() == b'\x00\x01'
    atomic_write(p, write=lambda tmp: open(tmp, 'w').write('from writer'))
    assert p.read_text() == 'from writer'
    assert sorted(os.listdir(tmp_path)) == ['a.yaml']


def test_modes_secret_files_never_wider(tmp_path):
    p = atomic_write(tmp_path / 'key', 'secret', mode=0o600)
    assert stat.S_IMODE(p.stat().st_mode) == 0o600
    assert stat.S_IMODE(atomic_write(tmp_path / 'pub', 'x').stat().st_mode) == 0o644


def test_a_failing_writer_keeps_the_old_content_and_leaves_nothing(tmp_path):
    p = tmp_path / 'out.csv'
    p.write_text('old')

    def broken(tmp):
        open(tmp, 'w').write('half')
        raise OSError('disk full')
    with pytest.raises(OSError, match='disk full'):
        atomic_write(p, write=broken)
    assert p.read_text() == 'old' and sorted(os.listdir(tmp_path)) == ['out.csv']
    with pytest.raises(TypeError):
        atomic_write(p)
    with pytest.raises(TypeError):
        atomic_write(p, 'a', write=lambda t: None)
    with pytest.raises(FileNotFoundError):
        atomic_write(tmp_path / 'missing' / 'x', 'a')
