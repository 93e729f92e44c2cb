"""Flow meter and thermal output (sslfr_drivers.sensors.thermal) on numbers, with the
worked example of seed 003 section 3.2."""
import math

import pytest

from sslfr_drivers.sensors import anemometer, thermal

LPH = 1.0 / 3.6e6          # 1 L/h in m^3/s


def test_water_properties_against_the_tables():
    """IAPWS-95 saturated liquid (NIST WebBook): 20 degC 998.2 kg/m^3, 4184 J/(kg K);
    the minimum of c_p near 35-40 degC; NaN for ice and steam."""
    assert thermal.water_density(20.0) == pytest.approx(998.16)
    assert thermal.water_cp(20.0) == pytest.approx(4184.4)
    assert thermal.water_density(25.0) == pytest.approx((998.16 + 995.61) / 2)
    assert min(thermal.water_cp(t) for t in range(0, 151)) == pytest.approx(4179.6, abs=0.5)
    assert thermal.water_cp(100.0) == pytest.approx(4215.7)
    for t in (-1.0, 151.0, math.nan, math.inf):
        assert math.isnan(thermal.water_density(t)) and math.isnan(thermal.water_cp(t))


def test_flow_of_a_pulse_meter():
    """Seed 003's 150 L/h on a 450 pulse/L meter: 18.75 Hz; and back."""
    q = 150.0 * LPH
    assert thermal.pulse_rate(q, 450.0) == pytest.approx(18.75)
    assert thermal.volume_flow(18.75, 450.0) == pytest.approx(q)
    assert thermal.litres_per_hour(q) == pytest.approx(150.0)
    with pytest.raises(ValueError, match='K-factor'):
        thermal.check_k_factor(0.0)
    with pytest.raises(ValueError, match='K-factor'):
        thermal.FlowStats(k_factor=math.nan)


def test_flow_stats_average_the_quantised_counts():
    """4 Hz samples of a running count at 18.75 Hz count 4 or 5 pulses each; the 5 s
    mean is 150 L/h within 1.5 % once the window is full; a gap restarts it."""
    counter, stats = anemometer.PulseCounter(), thermal.FlowStats(450.0, window=5.0)
    readings = []
    for i in range(81):                                   # 20 s at 4 Hz
        t = 0.25 * i
        iv = counter.add(int(t * 1000), int(18.75 * t))
        if iv is not None:
            readings.append(stats.add(*iv, t=t))
    last = readings[-1]
    assert last.window == pytest.approx(5.0)
    assert thermal.litres_per_hour(last.volume_flow) == pytest.approx(150.0, rel=0.015)
    assert last.pulse_rate == pytest.approx(18.75, rel=0.015)
    stats.restart()
    r = stats.add(0.25, 4, t=30.0)
    assert r.window == pytest.approx(0.25) and r.pulse_rate == pytest.approx(16.0)
    r = stats.add(0.25, 5, t=29.0)                        # ROS time went back: start again
    assert r.window == pytest.approx(0.25) and r.pulse_rate == pytest.approx(20.0)


def test_seed_003_worked_example_as_printed():
    """Seed 003 section 3.2 prints eta = 0.032 * 4206 * (77.48 - 45.43) / (1 * 774.6 *
    0.77) = 7.16 % (tracking) and with (58.81 - 44.33) 3.26 % (manual). The same
    arithmetic here: the numerators are 4313.7 W and 1948.9 W and the fractions 7.23
    and 3.27, i.e. the printed percentages are the bare ratios (7.23 printed 7.16): a
    useful power 5.6 times the 774.6 W of beam on the 1 m^2 aperture, not physical."""
    p_track = thermal.useful_power(0.032, 4206.0, 45.43, 77.48)
    p_manual = thermal.useful_power(0.032, 4206.0, 44.33, 58.81)
    assert p_track == pytest.approx(4313.67, abs=0.01)
    assert p_manual == pytest.approx(1948.89, abs=0.01)
    assert thermal.efficiency(p_track, 774.6, 1.0 * 0.77) == pytest.approx(7.232, abs=0.001)
    assert thermal.efficiency(p_manual, 774.6, 1.0 * 0.77) == pytest.approx(3.268, abs=0.001)
    assert p_track / (774.6 * 1.0) > 5.5                   # more out than the beam brings in


def test_seed_003_worked_example_consistent():
    """The seed's reported efficiency taken as its definition states it: 7.16 % of the
    average beam 774.6 W/m^2 on A_a = 1 m^2 is 55.5 W of useful power; at the seed's
    constant 150 L/h (inlet 45.43 degC: 0.04125 kg/s) that is a temperature rise of
    0.32 K. thermal_output gives the 7.16 % back from those readings."""
    q = 150.0 * LPH
    m_dot = q * thermal.water_density(45.43)
    assert m_dot == pytest.approx(0.041246, rel=1e-4)
    power = 0.0716 * 774.6 * 1.0
    assert power == pytest.approx(55.46, abs=0.01)
    rise = power / (m_dot * thermal.water_cp(45.43 + 0.16))
    assert rise == pytest.approx(0.3216, abs=0.0005)
    r = thermal.thermal_output(q, 45.43, 45.43 + rise, 774.6, 1.0)
    assert r.mass_flow == pytest.approx(m_dot)
    assert r.power == pytest.approx(55.46, rel=1e-4)
    assert r.efficiency == pytest.approx(0.0716, rel=1e-4)


def test_thermal_output_unknowns_are_nan_never_numbers():
    q = 150.0 * LPH
    assert math.isnan(thermal.thermal_output(q, math.nan, 50.0, 800.0, 1.0).power)
    r = thermal.thermal_output(q, 40.0, 41.0, math.nan, 1.0)
    assert math.isfinite(r.power) and math.isnan(r.efficiency)
    assert math.isnan(thermal.thermal_output(q, 40.0, 41.0, 99.0, 1.0).efficiency)     # below MIN_BEAM
    assert math.isnan(thermal.thermal_output(q, 40.0, 41.0, 800.0, 0.0).efficiency)    # no aperture
    r = thermal.thermal_output(0.0, 40.0, 41.0, 800.0, 1.0)                            # pump stopped
    assert r.power == 0.0 and r.efficiency == 0.0


def test_tracker_from_board_samples_to_efficiency():
    """The node's pure core: samples at 4 Hz of a 150 L/h flow, the temperatures and a
    beam; the first sample and a board reset give nothing; a stale beam gives NaN."""
    tr = thermal.ThermalTracker(450.0, window=5.0, aperture=1.0, beam_max_age=5.0)
    tr.set_temperature('inlet', 30.0)
    tr.set_temperature('outlet', 31.0)
    tr.set_beam(800.0, steady=0.0)
    out = [tr.add(int(250 * i), int(18.75 * 0.25 * i), steady=0.25 * i) for i in range(21)]
    assert out[0] is None and all(o is not None for o in out[1:])
    f, r = out[-1]
    assert thermal.litres_per_hour(f.volume_flow) == pytest.approx(150.0, rel=0.015)
    # 0.04153 kg/s x 4180 J/(kg K) x 1 K = 173.6 W; / (800 W/m^2 x 1 m^2)
    assert r.power == pytest.approx(173.6, rel=0.02)
    assert r.efficiency == pytest.approx(r.power / 800.0)
    assert tr.add(100, 2, steady=5.5) is None                     # board reset
    assert tr.counts == {'samples': 22, 'restarts': 2}
    tr.add(350, 7, steady=5.75)
    _, r = tr.add(600, 12, steady=6.0)                           # beam heard 6 s ago
    assert math.isfinite(r.power) and math.isnan(r.beam) and math.isnan(r.efficiency)
