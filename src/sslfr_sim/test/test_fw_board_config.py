"""What ``fw_board`` gives the firmware boards of the drives without switches, from the
simulators' options and the collector description (pure Python: no simavr, no build)."""
from __future__ import annotations

import dataclasses
import math

import pytest

from sslfr_drivers.link import messages as m
from sslfr_sim.actuator import ActuatorConfig, shipped_description
from sslfr_sim.fw_board import axis_config, config_record
from sslfr_sim.fw_harness import (ACTUATOR_PARAMS, actuator_mech, actuator_params, actuator_params_header,
                                  compiled_actuator_params, mech_of)

R = math.radians
SEED003 = shipped_description('bucaramanga_single_axis')
SEED004 = shipped_description('florianopolis_lepten')


def test_switchless_axis_and_record_from_the_description():
    """axis_noswitch: the description's range, stow and step (step_deg / gear_ratio) in the
    mechanism model, the options' speeds in the EEPROM record, the joint where asked."""
    opts = {'description': str(SEED003.path), 'initial_angle_deg': '12.5', 'max_speed': '2000', 'accel': '8000'}
    cfg = axis_config('axis_noswitch', opts)
    mv = SEED003.movement('mirrors')
    lo, hi, sleep, step, _, _, angle = mech_of(cfg)
    assert (lo, hi, sleep) == (mv.range[0], mv.range[1], mv.stow)
    assert step == pytest.approx(R(0.1125) / mv.gear_ratio) and angle == pytest.approx(R(12.5))
    rec = config_record('axis_noswitch', opts, 3, cfg)
    assert (rec.kind, rec.board_id, rec.axis, rec.max_speed, rec.accel, rec.flags) == (
        m.BoardKind.AXIS_STEPPER, 3, 0, 2000.0, 8000.0, 0)
    assert rec.check(m.BoardKind.AXIS_STEPPER) == 0


def test_switchless_refuses_a_description_of_another_drive():
    with pytest.raises(ValueError, match='not a stepper_no_switches movement'):
        axis_config('axis_noswitch', {'description': str(SEED004.path)})
    with pytest.raises(ValueError, match='not a linear_actuator_inclinometer movement'):
        axis_config('actuator', {'description': str(SEED003.path)})


def test_actuator_model_and_record_from_the_options():
    """actuator: the record of an AXIS_ACTUATOR board for the axis; the drive model from
    the description with the true inclinometer offset of the options (the board keeps the
    description's as its calibration) and the line where asked."""
    opts = {'initial_angle_deg': '-20', 'inclinometer_offset_deg': '0.2'}
    cfg = axis_config('actuator', opts)
    rec = config_record('actuator', opts, 4, cfg)
    assert (rec.kind, rec.board_id, rec.axis) == (m.BoardKind.AXIS_ACTUATOR, 4, 0)
    mech = actuator_mech(cfg, cfg.initial_angle)
    assert mech[7] == pytest.approx(R(0.2)) and mech[9] == pytest.approx(R(-20.0))
    assert actuator_params(cfg)['ACT_OFFSET_CAL'] == 0.0


def test_the_shipped_actuator_build_is_the_seed_004_description():
    """boards/actuator_params.h is the shipped description's drive (no variant needed)."""
    want = actuator_params(ActuatorConfig.from_description(SEED004))
    have = compiled_actuator_params()
    assert set(have) == set(ACTUATOR_PARAMS)
    for k in ACTUATOR_PARAMS:
        assert have[k] == pytest.approx(want[k], rel=1e-6, abs=1e-12), k


def test_a_variant_header_carries_another_drive():
    """The header of another drive reads back as its parameters; a stall window the
    firmware cannot hold (block means in RAM) is refused."""
    cfg = dataclasses.replace(ActuatorConfig.from_description(SEED004), deadband=R(0.2), stall_window=3.0,
                              stall_min=2e-5)
    want = actuator_params(cfg)
    text = actuator_params_header(want)
    back = compiled_actuator_params(text)
    for k in ACTUATOR_PARAMS:
        assert back[k] == pytest.approx(want[k], rel=1e-12, abs=1e-15), k
    for window in (0.3, 6.0, 2.05):
        with pytest.raises(ValueError, match='stall_window_s'):
            actuator_params(dataclasses.replace(cfg, stall_window=window))


def test_fw_board_takes_the_node_sets_drive_simulators():
    """The command lines config/nodeset.yaml gives each drive kind's simulated board
    (``./sslfr sim``; ``--boards firmware`` runs fw_board with the same arguments) parse in
    fw_board and give a firmware configuration for the shipped collectors (a simulated
    actuator faster than the description's: an image built for it)."""
    from sslfr_bringup.nodeset import load
    from sslfr_sim.fw_board import parser
    collectors = {'stepper_no_switches': SEED003, 'linear_actuator_inclinometer': SEED004}
    sims = load().drive_sims
    for drive, desc in collectors.items():
        values = {'axis': 'mirrors', 'pty': '/tmp/p', 'control': '/tmp/c', 'seed': 1, 'key_file': '/tmp/k',
                  'description': desc.path, 'sleep_deg': math.degrees(desc.movement('mirrors').stow)}
        argv = [a.format(**values) for a in sims[drive]['args']]
        args = parser().parse_args(argv)
        opts = dict(o.split('=', 1) for o in args.opt)
        opts.setdefault('axis', args.axis)
        cfg = axis_config(args.kind, opts)
        rec = config_record(args.kind, opts, 1, cfg)          # ValueError if the firmware refused it
        assert rec.axis == 0 and rec.check(rec.kind) == 0
        assert cfg.initial_angle == pytest.approx(desc.movement('mirrors').stow)
        if args.kind == 'actuator':
            assert actuator_params(cfg)['ACT_MAX_SPEED'] == cfg.max_speed
