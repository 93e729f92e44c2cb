"""Unit tests of the sensor-board pure cores: MAX6675, VEML7700, switch debouncing."""
import math

import pytest
from hypothesis import given, strategies as st

from sslfr_drivers.sensors import debounce

from sslfr_drivers.sensors import max6675

from sslfr_drivers.sensors import veml7700


# ------------------------------------------------------------------ MAX6675
def test_max6675_datasheet_words():
    # datasheet: D14..D3 = temperature code, LSB 0.25 degC
    assert max6675.decode(0x0000).temperature == 0.0
    assert max6675.decode(0b0_000000000001_000).temperature == 0.25
    assert max6675.decode(0b0_000110010000_000).temperature == 100.0   # 400 * 0.25
    assert max6675.decode(0b0_111111111111_000).temperature == 1023.75
    assert max6675.decode(0x0001).ok  # D0 three-state may read 1


def test_max6675_open_thermocouple_is_fault_not_number():
    r = max6675.decode(0b0_000110010000_100)   # 100 degC with D2 set
    assert not r.ok and r.fault == max6675.FAULT_OPEN
    assert math.isnan(r.temperature) and math.isnan(r.variance)


@pytest.mark.parametrize('word', [0xFFFF, 0x8000, 0x0002, -1, 0x10000])
def test_max6675_impossible_words(word):
    r = max6675.decode(word)
    assert r.fault == max6675.FAULT_INVALID and math.isnan(r.temperature)


def test_max6675_variance_model():
    m = max6675.ErrorModel()
    # at 25 degC: q^2/12 + 2^2/3 + 2.5^2/3
    assert m.variance(25.0) == pytest.approx(0.0625 / 12 + 4 / 3 + 6.25 / 3)
    # at 600 degC the relative part (0.75 % = 4.5 degC) dominates
    assert m.variance(600.0) == pytest.approx(0.0625 / 12 + 4 / 3 + 4.5 ** 2 / 3)
    assert max6675.decode(max6675.encode(100.0)).variance == pytest.approx(m.variance(100.0))


@given(st.floats(0.0, 1023.75))
def test_max6675_roundtrip(t):
    r = max6675.decode(max6675.encode(t))
    assert r.ok and abs(r.temperature - t) <= 0.125 + 1e-9


@given(st.integers(0, 0xFFFF))
def test_max6675_any_word_is_number_or_fault(word):
    r = max6675.decode(word)
    assert (r.ok and 0.0 <= r.temperature <= 1023.75) or (not r.ok and math.isnan(r.temperature))
    assert r.ok == (word & 0x8006 == 0)


def test_max6675_encode_clamps_and_open():
    assert max6675.decode(max6675.encode(-20.0)).temperature == 0.0
    assert max6675.decode(max6675.encode(5000.0)).temperature == 1023.75
    assert max6675.decode(max6675.encode(20.0, open_circuit=True)).fault == max6675.FAULT_OPEN


# ------------------------------------------------------------------ VEML7700
def test_veml7700_resolutions_and_range():
    assert veml7700.resolution(0b01, 0b0011) == pytest.approx(0.0036)        # x2, 800 ms
    assert veml7700.resolution(0b10, 0b1100) == pytest.approx(1.8432)        # x1/8, 25 ms
    s = veml7700.decode(65535, 0b10, 0b1100)
    assert s.illuminance == pytest.approx(120795.1, rel=1e-5) and s.saturated
    s = veml7700.decode(1000, 0b00, 0b0000)  # x1, 100 ms: 0.0576 lx/ct
    assert s.illuminance == pytest.approx(57.6) and not s.saturated and s.valid
    assert s.gain == 1.0 and s.integration_time == 0.1


def test_veml7700_invalid_codes():
    for args in ((10, 0b111, 0), (10, 0, 0b0101), (70000, 0, 0), (-1, 0, 0)):
        s = veml7700.decode(*args)
        assert not s.valid and math.isnan(s.illuminance)


def test_veml7700_saturation_at_sensitive_setting():
    s = veml7700.decode(65535, 0b01, 0b0011)
    assert s.saturated and s.illuminance == pytest.approx(65535 * 0.0036)


def test_veml7700_beam():
    b, v = veml7700.beam_irradiance(104000.0, 104.0 ** 2)
    assert b == pytest.approx(1000.0) and v == pytest.approx(1.0)
    assert veml7700.beam_irradiance(52000.0, efficacy=130.0)[0] == pytest.approx(400.0)


@pytest.mark.parametrize('lux', [0.5, 20.0, 800.0, 25000.0, 110000.0])
def test_veml7700_autorange_converges(lux):
    """The auto-range loop settles with the count in its window and lux within 1 %."""
    g, it = veml7700.LADDER[2]
    seen = []
    for _ in range(20):
        c = veml7700.encode(lux, g, it)
        seen.append((g, it))
        g, it = veml7700.next_setting(c, g, it)
    c = veml7700.encode(lux, g, it)
    s = veml7700.decode(c, g, it)
    assert seen[-1] == seen[-2] == (g, it)  # settled, no oscillation
    assert s.illuminance == pytest.approx(lux, rel=0.01, abs=0.01)
    idx = veml7700.LADDER.index((g, it))
    assert (veml7700.LOW_COUNT < c <= veml7700.HIGH_COUNT or idx in (0, len(veml7700.LADDER) - 1))


def test_veml7700_autorange_unknown_setting_restarts():
    assert veml7700.next_setting(5, 0b111, 0b0101) == veml7700.LADDER[2]


@given(st.floats(0.0, 150000.0), st.sampled_from(veml7700.LADDER))
def test_veml7700_encode_decode(lux, setting):
    s = veml7700.decode(veml7700.encode(lux, *setting), *setting)
    res = veml7700.resolution(*setting)
    if lux / res < 65534.5:
        assert abs(s.illuminance - lux) <= res / 2 + 1e-9
    else:
        assert s.saturated


# ------------------------------------------------------------------ debounce
def test_debounce_first_sample_sets_state():
    d = debounce.SwitchDebouncer(0.03)
    assert d.update(0b00101, 10.0) == []
    assert d.states['initial'].closed and d.states['sleeping'].closed
    assert not d.states['last'].closed and d.states['last'].changed == 10.0
    assert d.mask() == 0b00101


def test_debounce_accepts_after_hold_and_reports_first_edge_time():
    d = debounce.SwitchDebouncer(0.03)
    d.update(0, 0.0)
    assert d.update(0b10000, 1.00) == []
    assert d.update(0b10000, 1.02) == []
    assert d.update(0b10000, 1.04) == ['longitudinal_2']
    assert d.states['longitudinal_2'].closed and d.states['longitudinal_2'].changed == 1.00


def test_debounce_rejects_bounce():
    d = debounce.SwitchDebouncer(0.03)
    d.update(0, 0.0)
    for k, t in enumerate([1.0, 1.005, 1.01, 1.015, 1.02, 1.025]):
        assert d.update(0b00010 if k % 2 == 0 else 0, t) == []
    assert not d.states['last'].closed and d.bounces >= 2
    assert d.update(0, 2.0) == []


def test_debounce_zero_hold_and_bad_hold():
    d = debounce.SwitchDebouncer(0.0)
    d.update(0, 0.0)
    assert d.update(0b1, 0.1) == ['initial']
    with pytest.raises(ValueError):
        debounce.SwitchDebouncer(float('nan'))
    with pytest.raises(ValueError):
        debounce.SwitchDebouncer(-1.0)
