"""systemd_word: every value written into the systemd unit comes back unchanged when
read with systemd's own rules (systemd.syntax(7) quoting, systemd.service(5)
"Command lines": ``%%`` and ``$$`` escapes), and a control character is refused.

The reader below is written from those man pages, independently of the writer.
"""
from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st

from sslfr_bringup.service import render_unit, systemd_word


def read_words(line: str) -> list[str]:
    """Split a unit-file command line into words as systemd does: whitespace separates
    words; a word may be double-quoted, where ``\\\\`` and ``\\"`` are escapes; then
    ``%%`` -> ``%`` (specifiers) and ``$$`` -> ``$`` (variable expansion)."""
    words, i, n = [], 0, len(line)
    while i < n:
        while i < n and line[i] in ' \t':
            i += 1
        if i >= n:
            break
        word = []
        if line[i] == '"':
            i += 1
            while True:
                assert i < n, f'unterminated quote in {line!r}'
                ch = line[i]
                if ch == '\\':
                    assert i + 1 < n and line[i + 1] in '\\"', f'unknown escape in {line!r}'
                    word.append(line[i + 1])
                    i += 2
                elif ch == '"':
                    i += 1
                    break
                else:
                    word.append(ch)
                    i += 1
            assert i >= n or line[i] in ' \t', f'text right after a closing quote in {line!r}'
        else:
            while i < n and line[i] not in ' \t':
                assert line[i] not in '"\\\'', f'unquoted special character in {line!r}'
                word.append(line[i])
                i += 1
        words.append(''.join(word))
    out = []
    for w in words:
        assert '%' not in w.replace('%%', ''), f'a lone % (a specifier) in {w!r}'
        assert '$' not in w.replace('$$', ''), f'a lone $ (a variable) in {w!r}'
        out.append(w.replace('%%', '%').replace('$$', '$'))
    return out


printable = st.text(st.characters(min_codepoint=0x20, max_codepoint=0x2FF, exclude_characters='\x7f'))


@settings(max_examples=400, deadline=None)
@given(printable)
def test_every_printable_value_reads_back_unchanged(value):
    assert read_words(systemd_word(value)) == [value]


@settings(max_examples=100, deadline=None)
@given(st.lists(printable, min_size=1, max_size=5))
def test_a_command_line_of_words_reads_back_word_for_word(values):
    assert read_words(' '.join(systemd_word(v) for v in values)) == values


@pytest.mark.parametrize('value,written', [
    ('/home/pi/sslfr', '/home/pi/sslfr'),
    ('/home/pi/my site.yaml', '"/home/pi/my site.yaml"'),
    ('100%', '100%%'),
    ('$HOME', '$$HOME'),
    ('a"b', '"a\\"b"'),
    ('a\\b', '"a\\\\b"'),
    ('', '""'),
])
def test_written_forms(value, written):
    assert systemd_word(value) == written


@pytest.mark.parametrize('value', ['a\nExecStartPre=/bin/false', 'tab\there', 'bell\x07', 'del\x7f'])
def test_control_characters_refused(value):
    with pytest.raises(ValueError, match='control character'):
        systemd_word(value)


def test_the_unit_execstart_reads_back_as_the_command():
    text = render_unit(root='/home/pi/my sslfr', config='/home/pi/site 100%.yaml', user='pi',
                       domain_id=42, discovery_range='LOCALHOST', namespace='/sslfr1')
    exec_start = next(ln for ln in text.splitlines() if ln.startswith('ExecStart='))
    assert read_words(exec_start[len('ExecStart='):]) == [
        '/home/pi/my sslfr/sslfr', 'up', '--config', '/home/pi/site 100%.yaml', '--namespace', '/sslfr1']
