"""Topic-level tests of ``irradiance`` against the simulated VEML7700 board."""
import datetime as dt

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from sensor_msgs.msg import Illuminance

from sslfr_interfaces.msg import Irradiance
from sslfr_sim.world import Sky
from sslfr_sim.runner import SimThread
from sslfr_sim.sensors import DEFAULT_SITE, IrradianceSim
from sslfr_common.contract import DIAGNOSTICS, IRRADIANCE_BEAM, IRRADIANCE_ILLUMINANCE

T = dt.datetime(2026, 3, 21, 11, 0, tzinfo=dt.timezone.utc).timestamp()


def _diag(arrays, name='irradiance: board'):
    for arr in reversed(arrays):
        for st in arr.status:
            if st.name == name:
                return st, {kv.key: kv.value for kv in st.values}
    return None, {}


@pytest.fixture
def sim(tmp_path):
    s = SimThread.plain(IrradianceSim({'start_utc': T, 'speed': 1.0, 'period': 0.25, 'noise': 0.0}),
                        link=str(tmp_path / 'irr0')).start()
    yield s
    s.stop()


def test_beam_saturation_and_unplug(sim, launch, ros, tmp_path):
    lux = ros.collect(Illuminance, IRRADIANCE_ILLUMINANCE.name)
    beam = ros.collect(Irradiance, IRRADIANCE_BEAM.name)
    diags = ros.collect(DiagnosticArray, DIAGNOSTICS.name)
    node = launch('sslfr_drivers', 'irradiance', params={'port': str(tmp_path / 'irr0')})
    # the board's auto-range settles within a few samples; then beam = clear-sky DNI
    assert ros.spin_until(lambda: len(beam) >= 6, 15), node.output()
    dni = Sky(**{k: DEFAULT_SITE[k] for k in ('latitude_deg', 'longitude_deg', 'elevation')}).dni(T)
    b = beam[-1]
    assert 800.0 < dni < 1100.0
    assert b.beam == pytest.approx(dni, rel=0.01)                      # W/m^2
    assert b.illuminance == pytest.approx(104.0 * b.beam, rel=1e-9)    # lx = 104 lm/W * W/m^2
    assert b.luminous_efficacy == 104.0 and not b.saturated
    assert b.variance == pytest.approx((0.1 * b.beam) ** 2, rel=0.01)
    assert lux[-1].illuminance == pytest.approx(b.illuminance, rel=0.02)
    assert lux[-1].header.frame_id == 'irradiance'

    # above the 120 klx range: flagged saturated, value a lower bound, diagnosed
    with sim.locked():
        sim.board.control({'cmd': 'fault', 'kind': 'lux', 'value': 150000.0})
    assert ros.spin_until(lambda: beam[-1].saturated, 5)
    assert 115000.0 < beam[-1].illuminance <= 150000.0
    assert ros.spin_until(lambda: 'saturated' in (_diag(diags)[0].message if _diag(diags)[0] else ''), 3)
    # dusk: the auto-range climbs to the most sensitive setting, still a number
    with sim.locked():
        sim.board.control({'cmd': 'fault', 'kind': 'lux', 'value': 3.0})
    assert ros.spin_until(lambda: abs(beam[-1].illuminance - 3.0) < 0.05, 12)
    assert not beam[-1].saturated
    assert ros.spin_until(lambda: _diag(diags)[1].get('gain') == '2', 3)   # x1/8 -> x2

    # the board vanishes and returns
    sim.command('unplug 1.5')
    ros.spin_for(2.0)
    n = len(beam)
    assert ros.spin_until(lambda: len(beam) > n + 2, 10), node.output()
    assert node.running()
    assert ros.spin_until(lambda: int(_diag(diags)[1].get('reconnects', '0')) >= 1, 3)
    assert _diag(diags)[0].level == DiagnosticStatus.OK


def test_behind_the_xbee_coordinator(launch, ros, tmp_path):
    """The same node reaches its board through a (simulated) XBee 802.15.4 coordinator;
    the luminous efficacy is a parameter, validated at runtime."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters
    from sslfr_sim.base import FaultInjector
    from sslfr_sim.xbee import XBeeSimCoordinator
    host = XBeeSimCoordinator()
    host.add_board(bytes.fromhex('0013A20040000012'),
                   IrradianceSim({'start_utc': T, 'period': 0.25, 'noise': 0.0}), FaultInjector())
    with SimThread(host, link=str(tmp_path / 'xbee')):
        beam = ros.collect(Irradiance, IRRADIANCE_BEAM.name)
        node = launch('sslfr_drivers', 'irradiance',
                      params={'port': f'xbee:{tmp_path / "xbee"}?addr=0013A20040000012',
                              'luminous_efficacy': 120.0})
        assert ros.spin_until(lambda: len(beam) >= 3, 25), node.output()
        b = beam[-1]
        assert not b.saturated and b.luminous_efficacy == 120.0
        assert b.beam == pytest.approx(b.illuminance / 120.0)
        assert 690.0 < b.beam < 960.0          # clear-sky DNI * 104 / 120
        # an invalid runtime value is refused; the node keeps its last good efficacy
        req = SetParameters.Request()
        req.parameters = [Parameter(name='luminous_efficacy', value=ParameterValue(
            type=ParameterType.PARAMETER_DOUBLE, double_value=-5.0))]
        assert not ros.call(SetParameters, 'irradiance/set_parameters', req).results[0].successful
        n = len(beam)
        assert ros.spin_until(lambda: len(beam) > n, 3) and beam[-1].luminous_efficacy == 120.0
