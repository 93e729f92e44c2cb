"""Fault-spec grammar of `sslfr sim --fault` (pure)."""
import pytest
from hypothesis import given, strategies as st

from sslfr_sim import faults
from sslfr_sim.faults import Fault, FaultSpecError, Schedule, format_fault, parse


@pytest.mark.parametrize('spec,kind,at,target,duration,board', [
    ('overtemp@13:05', 'overtemp', 13 * 3600 + 300, None, None, 'absorber'),
    ('thermocouple-open@11:00', 'thermocouple-open', 39600, 'outlet', None, 'absorber'),
    ('thermocouple-open:inlet@11:00+120', 'thermocouple-open', 39600, 'inlet', 120.0, 'absorber'),
    ('link-drop:mirrors@10:30+90', 'link-drop', 37800, 'mirrors', 90.0, 'mirrors'),
    ('board-reset:secondary_reflector@09:15:30', 'board-reset', 33330, 'secondary_reflector', None,
     'secondary_reflector'),
    ('gps-loss@06:00+600', 'gps-loss', 21600, None, 600.0, 'gps'),
    ('kill:planner@12:00', 'kill', 43200, 'planner', None, None),
    ('kill:safety@12:00+30', 'kill', 43200, 'safety', 30.0, None),
    ('hang:planner@12:00', 'hang', 43200, 'planner', None, None),
])
def test_parse_each_kind(spec, kind, at, target, duration, board):
    f = parse(spec, nodes=['planner', 'safety'])
    assert (f.kind, f.at, f.target, f.duration, f.board) == (kind, at, target, duration, board)
    assert parse(format_fault(f)) == Fault(kind, at, target, duration, format_fault(f))


@pytest.mark.parametrize('spec,needle', [
    ('overheat@10:00', 'unknown kind'),
    ('overtemp 10:00', 'expected KIND'),
    ('overtemp@25:00', 'not a time of day'),
    ('overtemp@10:61', 'not a time of day'),
    ('link-drop:mirrors@10:00', 'needs a duration'),
    ('link-drop@10:00+5', 'needs :BOARD'),
    ('link-drop:moon@10:00+5', 'unknown board'),
    ('board-reset:mirrors@10:00+5', 'instantaneous'),
    ('gps-loss:gps@10:00+5', 'takes no target'),
    ('gps-loss@10:00', 'needs a duration'),
    ('gps-loss@10:00+0', 'duration must be > 0'),
    ('kill@10:00', 'needs :NODE'),
    ('kill:nobody@10:00', 'unknown node'),
    ('hang@10:00', 'needs :NODE'),
    ('hang:nobody@10:00', 'unknown node'),
    ('hang:planner@10:00+30', 'instantaneous'),
    ('thermocouple-open:middle@10:00', 'inlet or outlet'),
    ('slip:mirrors@10:00+60', 'slipped angle'),
    ('slip:mirrors@10:00+60:0', 'slipped angle'),
    ('slip:mirrors@10:00+60:91', 'slipped angle'),
    ('slip:gps@10:00+60:0.5', 'needs an axis'),
    ('slip:mirrors@10:00:0.5', 'needs a duration'),
    ('link-drop:mirrors@10:00+5:0.5', 'takes no :DEG'),
])
def test_bad_specs_are_refused_with_the_reason(spec, needle):
    with pytest.raises(FaultSpecError, match=needle):
        parse(spec, nodes=['planner', 'safety'])


def test_slip_spec():
    f = parse('slip:secondary_reflector@10:05+600:-0.5')
    assert (f.kind, f.at, f.target, f.duration, f.amount, f.board) == \
        ('slip', 36300.0, 'secondary_reflector', 600.0, -0.5, 'secondary_reflector')
    assert format_fault(f) == 'slip:secondary_reflector@10:05+600:-0.5'


@given(kind=st.sampled_from(faults.KINDS), at=st.integers(0, 86399), dur=st.integers(1, 7200),
       board=st.sampled_from(faults.DEFAULT_BOARDS))
def test_format_parse_round_trip(kind, at, dur, board):
    target = {'link-drop': board, 'board-reset': board, 'kill': 'planner', 'hang': 'safety',
              'thermocouple-open': 'inlet', 'slip': 'mirrors'}.get(kind)
    duration = None if kind in ('board-reset', 'hang') else float(dur)
    f = Fault(kind, float(at), target, duration, '', amount=0.25 if kind == 'slip' else None)
    g = parse(format_fault(f))
    assert (g.kind, g.at, g.target, g.duration, g.amount) == (f.kind, f.at, f.target, f.duration, f.amount)


def test_schedule_returns_each_start_and_end_once_in_order():
    a = parse('link-drop:mirrors@10:00+60')
    b = parse('overtemp@10:00:30')
    s = Schedule([b, a])
    assert s.due(35999.0) == []
    assert s.due(36000.0) == [(a, 'start')]
    assert s.due(36000.0) == []
    assert s.due(36100.0) == [(b, 'start'), (a, 'end')]
    assert s.pending() == 0


def test_sim_set_option_parses_yaml_values():
    from sslfr_sim.sim_cli import parse_set
    assert parse_set('mirrors_driver:status_rate=20', ['mirrors_driver']) == ('mirrors_driver', 'status_rate', 20)
    assert parse_set('planner:collector.law=daily', ['planner']) == ('planner', 'collector.law', 'daily')
    for bad in ('planner=1', 'planner:x', 'ghost:x=1'):
        with pytest.raises(ValueError):
            parse_set(bad, ['planner'])


def test_sim_refuses_a_slip_on_firmware_boards(tmp_path, capsys):
    """The slipping coupling is a model of the Python boards: refused (exit 2, one line)
    before anything starts with --boards firmware."""
    from sslfr_sim.sim_cli import main
    code = main(['--boards', 'firmware', '--fault', 'slip:mirrors@10:00+60:0.5', '--out', str(tmp_path / 'o'),
                 '--start', '10:00', '--end', '10:05'])
    assert code == 2
    err = capsys.readouterr().err
    assert 'slipping coupling is simulated by the Python boards only' in err, err
    assert not (tmp_path / 'o').exists()
