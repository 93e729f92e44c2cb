"""The SunSpec register image on numbers: header, model chain, lengths from the model
definitions, scale factors, 'not implemented' values, the write decoder."""
from __future__ import annotations

import math

import pytest

from sslfr_gateway import sunspec
from sslfr_gateway.sunspec import Tracker, Unit


def _unit(**kw):
    base = dict(serial='c7', unit_id=3, trackers=[Tracker('c7', 44.5, 44.494, True, 0)], beam_wm2=812.6)
    base.update(kw)
    return Unit(**base)


def _chain(regs):
    """(model id, length, offset of its first point) along the chain after 'SunS'."""
    out, i = [], 2
    while True:
        mid, length = regs[i], regs[i + 1]
        out.append((mid, length, i + 2))
        if mid == 0xFFFF:
            return out
        i += 2 + length


def _string(regs):
    return b''.join(r.to_bytes(2, 'big') for r in regs).rstrip(b'\0').decode()


def test_header_and_model_chain_with_lengths_from_the_definitions():
    regs = sunspec.encode(_unit())
    assert regs[:2] == [0x5375, 0x6E53]                              # 'SunS'
    chain = _chain(regs)
    assert [m for m, _, _ in chain] == [1, 601, 302, 0xFFFF]
    lengths = {m: n for m, n, _ in chain}
    assert lengths[1] == 66                                          # SunSpec common model: L = 66
    assert lengths[601] == 26 + 1 * 22                               # fixed points + one 22-register block
    assert lengths[302] == 5                                         # one repeat of 5 uint16
    assert lengths[0xFFFF] == 0
    two = sunspec.encode(_unit(trackers=[Tracker('a'), Tracker('b')]))
    assert {m: n for m, n, _ in _chain(two)}[601] == 26 + 2 * 22


def test_common_model_names_the_collector():
    regs = sunspec.encode(_unit())
    a = sunspec.point_addresses(1)
    at = (lambda name, n: regs[a[name] - sunspec.BASE:a[name] - sunspec.BASE + n])
    assert _string(at('1.Mn', 16)) == 'SSLFR tracker'
    assert _string(at('1.SN', 16)) == 'c7'
    assert at('1.DA', 1) == [3]


def test_tracker_points_in_millidegrees_with_their_scale_factor():
    regs = sunspec.encode(_unit())
    a = sunspec.point_addresses(1)
    word = (lambda name: regs[a[name] - sunspec.BASE])
    int32 = (lambda name: int.from_bytes(((word(name) << 16) | regs[a[name] - sunspec.BASE + 1])
                                         .to_bytes(4, 'big'), 'big', signed=True))
    assert word('601.Dgr_SF') == (-3) & 0xFFFF
    assert word('601.Typ') == 2                                      # horizontal single axis
    assert word('601.N') == 1
    assert int32('601.tracker[0].ElPos') == 44494                    # 44.494 deg
    assert int32('601.tracker[0].ElTrgt') == 44500
    assert int32('601.tracker[0].AzPos') == -2 ** 31                  # not implemented (0x80000000)
    assert word('601.tracker[0].Ctl') == 0 and word('601.GlblCtl') == 0
    neg = sunspec.encode(_unit(trackers=[Tracker('c7', -60.0, -59.999, False, 3)]))
    val = (neg[a['601.tracker[0].ElPos'] - sunspec.BASE] << 16) | neg[a['601.tracker[0].ElPos'] - sunspec.BASE + 1]
    assert int.from_bytes(val.to_bytes(4, 'big'), 'big', signed=True) == -59999
    assert neg[a['601.tracker[0].Ctl'] - sunspec.BASE] == 1              # manual
    assert neg[a['601.GlblAlm'] - sunspec.BASE] == 3                     # OR of the trackers' alarms
    # one motor step (0.006 deg) is 6 counts: the register resolves every step
    assert 10.0 ** sunspec.DEG_SF < math.degrees(__import__('sslfr_common.contract', fromlist=['x']).STEP_ANGLE)


def test_unknown_values_are_the_types_not_implemented_values():
    regs = sunspec.encode(_unit(trackers=[Tracker('c7')], beam_wm2=None))
    a = sunspec.point_addresses(1)
    word = (lambda name: regs[a[name] - sunspec.BASE])
    assert (word('601.tracker[0].ElPos'), regs[a['601.tracker[0].ElPos'] - sunspec.BASE + 1]) == (0x8000, 0)
    assert word('601.tracker[0].Ctl') == 0xFFFF and word('601.GlblCtl') == 0xFFFF
    assert word('302.repeating[0].DNI') == 0xFFFF and word('302.repeating[0].GHI') == 0xFFFF
    nan = sunspec.encode(_unit(trackers=[Tracker('c7', math.nan, math.inf)]))
    assert nan[a['601.tracker[0].ElPos'] - sunspec.BASE] == 0x8000


def test_beam_is_dni_rounded_and_clamped():
    a = sunspec.point_addresses(1)
    dni = (lambda b: sunspec.encode(_unit(beam_wm2=b))[a['302.repeating[0].DNI'] - sunspec.BASE])
    assert dni(812.6) == 813
    assert dni(-3.0) == 0
    assert dni(1e9) == 65534


def test_writes_decode_to_modes_and_anything_else_is_refused():
    a = sunspec.point_addresses(2)
    assert sunspec.decode_write(2, a['601.tracker[1].Ctl'], [1]) == [(1, 'stow')]
    assert sunspec.decode_write(2, a['601.tracker[0].Ctl'], [0]) == [(0, 'auto')]
    assert sunspec.decode_write(2, a['601.GlblCtl'], [1]) == [(None, 'stow')]
    with pytest.raises(sunspec.WriteRefused) as e:
        sunspec.decode_write(2, a['601.tracker[0].Ctl'], [2])           # Calibrate: not offered
    assert e.value.code == sunspec.ILLEGAL_VALUE
    for name in ('601.tracker[0].ElCtl', '1.DA', '601.tracker[0].ElPos'):
        with pytest.raises(sunspec.WriteRefused) as e:
            sunspec.decode_write(2, a[name], [0])
        assert e.value.code == sunspec.ILLEGAL_ADDRESS
    with pytest.raises(sunspec.WriteRefused):                          # Ctl plus its neighbour
        sunspec.decode_write(2, a['601.tracker[0].Ctl'], [1, 0])


def test_alarm_bits():
    assert sunspec.tracker_alarm(0.10, 0.10, 0.035, False) == 0
    assert sunspec.tracker_alarm(0.20, 0.10, 0.035, False) == sunspec.ALM_SETPOINT
    assert sunspec.tracker_alarm(None, 0.10, 0.035, True) == sunspec.ALM_OBS_EL
    assert sunspec.tracker_alarm(math.nan, 0.1, 0.035, False) == 0
