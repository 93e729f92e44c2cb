"""Parameters of the three sensor-board nodes, each declared once as a
:class:`sslfr_common.params.ParamTable` (pure Python, no rclpy).

The nodes declare them with ``sslfr_common.node.declare_parameters`` and check run-time
changes with ``ParameterGuard``; the CLI can validate a site config's ``gps``,
``absorber_board`` and ``irradiance`` sections with the same tables (:data:`TABLES`).
Every node has the board parameters ``port``, ``baudrate``, ``heartbeat`` and
``max_sample_age``; a change of ``port``, ``baudrate``, ``heartbeat`` (and the GPS's
``framing``) reopens the board.
"""
from __future__ import annotations

from sslfr_common.params import ParamSpec, ParamTable

from sslfr_drivers.link.keys import KEY_FILE_PARAM
from sslfr_drivers.sensors import anemometer, thermal
from sslfr_drivers.sensors.veml7700 import LUMINOUS_EFFICACY

HEARTBEAT = ParamSpec('heartbeat', 0.5, 'board link PING period [s]', 's', 0.05, 5.0)

#: Parameters whose change reopens the board (``framing``: the GPS only).
SOURCE_KEYS: tuple[str, ...] = ('port', 'framing', 'baudrate', 'heartbeat', 'key_file')


def _board_table(board: str, sample: str, max_age: float, *specs: ParamSpec,
                 baudrate: str = 'serial line speed [bit/s]', cross_check=None) -> ParamTable:
    """The board parameters every sensor node has, around the node's own ``specs``."""
    return ParamTable((
        ParamSpec('port', '', f'{board} port: device path, pyserial URL or xbee:<dev>?addr=<hex>; '
                              'empty = no board (the node stays up and reports it) [-]'),
        ParamSpec('baudrate', 115200, baudrate, 'bit/s', 1200, 921600),
        KEY_FILE_PARAM,
        *specs,
        ParamSpec('max_sample_age', max_age, f'diagnostics WARN when no {sample} for this long [s]',
                  's', 0.1, 3600.0),
        HEARTBEAT), cross_check)


#: ``gps`` node.
GPS = _board_table(
    'GPS board', 'NMEA sentence', 3.0,
    ParamSpec('framing', 'protocol', 'protocol: NMEA in board-protocol frames; raw_nmea: a bare GPS '
                                     'module streaming NMEA text [-]', choices=('protocol', 'raw_nmea')),
    ParamSpec('frame_id', 'gps', 'frame_id of gps/fix (the antenna) [-]'),
    ParamSpec('time_ref_source', 'gps', 'TimeReference.source [-]'),
    ParamSpec('uere', 4.0, 'user-equivalent range error of an autonomous fix, GGA quality 1 '
                           '(nmea_navsat_driver epe_quality1) [m]', 'm', 0.01, 100.0),
    ParamSpec('uere_sbas', 0.1, 'UERE for GGA quality 2 (DGPS/SBAS) [m]', 'm', 0.001, 100.0),
    ParamSpec('time_jump_threshold', 2.0, 'step of (receiver UTC - ROS time) between RMCs flagged as '
                                          'a time jump [s]', 's', 0.01, 1.0e9),
    ParamSpec('time_ref_without_fix', False, 'also publish gps/time_reference from RMC status V [-]'),
    baudrate='serial line speed [bit/s] (board protocol: 115200; a bare NEO-6M module with '
             'framing raw_nmea: 9600)')

def _pulse_pin(name: str, counts: str, none: str) -> ParamSpec:
    """The absorber board pin counting ``counts`` (its one pulse input); -1 = none."""
    return ParamSpec(name, -1, f'Arduino pin of the absorber board that counts {counts} (7, 8, 11, '
                               f'14..17 = A0..A3); -1 = no {none} [-]', '-', -1, 17,
                     validator=lambda v: None if v == -1 or v in anemometer.FREE_PINS
                     else f'not a free pin of the absorber board: -1 or one of {anemometer.FREE_PINS}')


def _one_pulse_input(v: dict) -> list[str]:
    """The absorber board counts one pulse input: an anemometer or a flow meter."""
    if v['anemometer_pin'] >= 0 and v['flow_meter_pin'] >= 0:
        return [f'anemometer_pin {v["anemometer_pin"]} and flow_meter_pin {v["flow_meter_pin"]}: the '
                'absorber board counts one pulse input (docs/firmware.md): set one of them to -1']
    return []


#: ``absorber_board`` node.
ABSORBER_BOARD = _board_table(
    'absorber board', 'thermocouple sample', 1.5,
    ParamSpec('inlet_frame_id', 'absorber_inlet', 'frame_id of absorber/inlet_temperature [-]'),
    ParamSpec('outlet_frame_id', 'absorber_outlet', 'frame_id of absorber/outlet_temperature [-]'),
    ParamSpec('converter_error', 2.0, 'MAX6675 error bound, uniform [degC]', 'degC', 0.0, 50.0),
    ParamSpec('thermocouple_error', 2.5, 'type-K tolerance bound, absolute part, uniform [degC]',
              'degC', 0.0, 50.0),
    ParamSpec('thermocouple_error_relative', 0.0075,
              'type-K tolerance bound, relative part of |T| [-]', '-', 0.0, 0.1),
    ParamSpec('debounce_time', 0.03, 'a raw switch change must hold this long to count [s]',
              's', 0.0, 5.0),
    ParamSpec('switch_rate', 10.0, 'limit_switches publication rate besides changes [Hz]',
              'Hz', 0.5, 100.0),
    _pulse_pin('anemometer_pin', 'the cup anemometer pulses', 'anemometer, no wind topic'),
    ParamSpec('anemometer_slope', anemometer.SLOPE, 'anemometer calibration: wind speed per pulse '
                                                    'frequency (typical 3-cup: 0.765) [m/s/Hz]',
              'm/s/Hz', 0.01, 20.0),
    ParamSpec('anemometer_offset', anemometer.OFFSET, 'anemometer calibration: speed added while '
                                                      'the cups turn (starting threshold, typical 0.35) [m/s]',
              'm/s', 0.0, 5.0),
    ParamSpec('wind_rate', 1.0, 'wind publication rate [Hz]: every pulse sample (4 Hz) enters the '
                                'means; a sample whose gust is a new maximum is published at once',
              'Hz', 0.1, 10.0),
    _pulse_pin('flow_meter_pin', 'the flow meter pulses', 'flow meter, no flow and thermal power topics'),
    ParamSpec('flow_meter_k_factor', thermal.K_FACTOR, 'flow meter calibration: pulses per litre '
                                                       '(data sheet; YF-S201 type: 450) [1/L]', '1/L', 0.1, 1.0e5),
    ParamSpec('flow_window', thermal.FLOW_WINDOW, 'the flow is the mean over this window [s]', 's', 0.5, 600.0),
    ParamSpec('aperture_area', 0.0, 'aperture of the primary mirrors, lines x line_width x line_length '
                                    'of the collector description (checked against it) [m^2]; 0 = '
                                    'unknown: no efficiency', 'm^2', 0.0, 1000.0),
    ParamSpec('efficiency_min_beam', thermal.MIN_BEAM, 'no efficiency below this beam irradiance '
                                                       '[W/m^2]', 'W/m^2', 0.0, 1500.0),
    ParamSpec('beam_max_age', 5.0, 'a beam irradiance older than this (steady clock) is not used '
                                   'for the efficiency [s]', 's', 0.5, 600.0),
    cross_check=_one_pulse_input)

#: ``irradiance`` node.
IRRADIANCE = _board_table(
    'irradiance board', 'sample', 3.0,
    ParamSpec('frame_id', 'irradiance', 'frame_id of the published messages [-]'),
    ParamSpec('luminous_efficacy', LUMINOUS_EFFICACY,
              'luminous efficacy of beam sunlight [lm/W] (seed 000: 104)', 'lm/W', 50.0, 250.0),
    ParamSpec('relative_uncertainty', 0.1, '1-sigma relative error of illuminance (sensor '
                                           'calibration and spectrum) [-]', '-', 0.0, 1.0))

#: Node name -> its table.
TABLES: dict[str, ParamTable] = {'gps': GPS, 'absorber_board': ABSORBER_BOARD, 'irradiance': IRRADIANCE}
