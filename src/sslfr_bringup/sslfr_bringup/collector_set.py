"""The node set of ONE collector: what its description says is there (pure, no rclpy).

``config/nodeset.yaml`` lists every node a collector may have; a site config names
its collector description (planner ``collector.description``, docs/collectors.md;
none: the node set's ``defaults.collector``, seed 000's). :func:`for_collector`
narrows the set to that collector, the one place where the description becomes
processes, for the launch file, ``./sslfr up``, ``./sslfr sim`` and the systemd unit:

* one axis driver per movement (node parameter ``axis``), given the movement's facts
  as role parameters (:func:`driver_parameters`: drive kind, soft limits = the
  mechanical range, stow position, motor step or deadband); a site config that sets
  one of them otherwise is refused (:func:`contradictions`); the mirrors' driver also
  gets the collector's loss table at its site (``accuracy.loss_table``, the estimate
  its accuracy alarms quote: :func:`loss_table_param`);
* a board node (``gps``, ``absorber_board``, ``irradiance``) only when the collector
  lists its board;
* each axis board's simulator chosen by the movement's drive kind (``drive_sims`` of
  the node set, placeholders ``{description}``, ``{sleep_deg}`` added);
* the safety supervisor told which watchable nodes run (``collector.nodes``): the
  axes and boards the collector lacks are not faults, those it has still are.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any

from sslfr_common.contract import MIRRORS, DriveKind, driver_node

#: the safety parameter that lists the watchable nodes of the set (sslfr_safety.params)
SAFETY_NODES_PARAM = 'collector.nodes'
#: nodes safety can watch (sslfr_safety.config.WATCHABLE, without importing safety)
_ALWAYS = ('planner',)


def driver_parameters(mv) -> dict[str, Any]:
    """The axis driver's role parameters of movement ``mv``
    (:class:`sslfr_planner.description.Movement`, radians): what the description
    fixes about the axis. The host-loss stow goes to the stow position too (a board's
    EEPROM position must lie within the soft limits)."""
    p: dict[str, Any] = {'axis': mv.name, 'drive': mv.drive,
                         'lower_limit': float(mv.range[0]), 'upper_limit': float(mv.range[1]),
                         'stow_position': float(mv.stow), 'host_loss_stow_position': float(mv.stow)}
    if mv.step is not None:
        p['step_angle'] = float(mv.step)
        p['gear_ratio'] = float(mv.gear_ratio)
        p['use_sensor'] = mv.feedback != 'steps'   # open loop: the step count is the position
    if mv.deadband is not None:
        p['deadband'] = float(mv.deadband)
    if mv.drive != DriveKind.STEPPER_SWITCHES.value:
        # no home switch: the drive is referenced at its reference angle (an operator's
        # HOME, stepper_no_switches) or reads its angle (the inclinometer)
        p['home_position'] = float(mv.reference if mv.reference is not None else mv.stow)
        if mv.drive == DriveKind.STEPPER_NO_SWITCHES.value:
            p['auto_home'] = False       # never moves by itself before the operator's reference
    return p


def loss_table_param(desc, planner_params: dict) -> list[float]:
    """The mirrors' ``accuracy.loss_table`` (flat) of collector ``desc`` at the site of
    ``planner_params`` (the planner's ``site.*`` values; its defaults where absent):
    seed 000 section 5.2 on the collector's optics
    (:func:`sslfr_planner.analysis.ideal.loss_table`, ~0.05 s). A site the planner's
    parameter table refuses gives no table (the config check names the key)."""
    from sslfr_common.tracking_loss import to_flat
    from sslfr_planner.analysis.ideal import loss_table
    from sslfr_planner.planner_params import PLANNER_PARAMS

    site = PLANNER_PARAMS.defaults()
    site.update(PLANNER_PARAMS.coerce({k: v for k, v in planner_params.items() if k in site}))
    if PLANNER_PARAMS.validate(site):
        return [0.0, 0.0, 0.0]
    table = loss_table(desc, site['site.latitude_deg'], site['site.longitude_deg'], site['site.elevation'])
    return to_flat(table) if table else [0.0, 0.0, 0.0]


def board_node_present(node, desc) -> bool:
    """Whether a (non-axis) node bound to a board runs for ``desc``: its board is listed."""
    return node.board is None or node.board in desc.boards


def for_collector(ns, desc, planner_params: dict | None = None):
    """``ns`` (:class:`sslfr_bringup.nodeset.NodeSet`) narrowed to collector ``desc``
    (see the module doc) at the site of ``planner_params`` (the planner's parameters of
    the site config). ValueError when the node set cannot serve it (a movement without a
    driver node, a drive kind without a simulator)."""
    drivers = {n.parameters.get('axis'): n for n in ns.nodes if n.parameters.get('axis')}
    all_drivers = {n.parameters.get('axis') for n in (ns.all_nodes or ns.nodes) if n.parameters.get('axis')}
    missing = [m for m in desc.movements if m not in all_drivers]
    if missing:
        raise ValueError(f'collector {desc.path}: movement(s) {", ".join(missing)} have no driver node in '
                           f'the node set {ns.path} (nodes with parameters: {{axis: ...}})')
    nodes, boards = [], {}
    for n in ns.nodes:
        axis = n.parameters.get('axis')
        if axis:
            if axis not in desc.movements:
                continue
            mv = desc.movements[axis]
            role = driver_parameters(mv)
            if axis == MIRRORS:
                role['accuracy.loss_table'] = loss_table_param(desc, planner_params or {})
            n = dataclasses.replace(n, parameters={**n.parameters, **role})
        elif not board_node_present(n, desc):
            continue
        nodes.append(n)
    watchable = [*_ALWAYS, *(driver_node(m) for m in desc.movements),
                 *(n.name for n in nodes if n.board and not n.parameters.get('axis'))]
    nodes = [dataclasses.replace(n, parameters={**n.parameters, SAFETY_NODES_PARAM: watchable})
             if n.name == 'safety' else n for n in nodes]
    for n in nodes:
        if n.board is None:
            continue
        board = ns.boards[n.board]
        axis = n.parameters.get('axis')
        if axis:
            mv = desc.movements[axis]
            sim = ns.drive_sims.get(mv.drive)
            if sim is None:
                raise ValueError(f'collector {desc.path}: movements.{axis}.drive {mv.drive}: no simulated '
                                   f'board for this drive kind in the node set\'s drive_sims')
            args = tuple(a.replace('{description}', str(desc.path)).replace(
                '{sleep_deg}', f'{math.degrees(mv.sleep):.6g}') for a in sim['args'])
            board = dataclasses.replace(board, sim_package=sim['package'], sim_executable=sim['executable'],
                                        sim_args=args)
        boards[board.name] = board
    return dataclasses.replace(ns, nodes=tuple(nodes), boards=boards, all_nodes=(), collector=str(desc.path))


def contradictions(ns, given, where: str) -> list[str]:
    """Site config values that contradict the role parameters the collector gives its
    nodes (:func:`driver_parameters`): each names the file, node, key, both values.
    ``given(node_name)``: the parameters the site config gives that node."""
    out = []
    for n in ns.nodes:
        if not n.parameters.get('axis'):
            continue
        values = given(n.name)
        for key, fixed in n.parameters.items():
            if key not in _DRIVER_KEYS or key not in values:
                continue
            value = values[key]
            same = value == fixed if isinstance(fixed, (str, bool)) else (
                isinstance(value, (int, float)) and not isinstance(value, bool)
                and abs(float(value) - fixed) <= 1e-9 + 1e-9 * abs(fixed))
            if not same:
                out.append(f'{where}: {n.name}: {key}: {value!r} contradicts the collector description '
                           f'{ns.collector}: {fixed!r} (the description fixes it: remove it from the site config)')
    return out


#: the axis driver's role parameters a collector description fixes (:func:`driver_parameters`)
_DRIVER_KEYS = ('drive', 'lower_limit', 'upper_limit', 'stow_position', 'host_loss_stow_position',
                'step_angle', 'gear_ratio', 'deadband', 'home_position', 'auto_home', 'use_sensor')
