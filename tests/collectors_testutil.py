"""Test support for the prototypes' runs: a collector no seed describes, written as
files (issue 34 item 7), and what their recorded days are judged on."""
from __future__ import annotations

import math

import numpy as np
import yaml

from sslfr_common.contract import Phase


def site_of(day) -> tuple[float, float]:
    """(latitude, longitude) [deg] the planner reported in the day's ``tracker/phase``."""
    k = np.asarray(day.phase['site_source']) != ''
    return float(np.median(day.phase['latitude'][k])), float(np.median(day.phase['longitude'][k]))


def tracking(day):
    """(the mirrors' status series, mask): the statuses while TRACKING and on their
    setpoint (following it, holding it or waiting for its next motor step; moves and
    stows excluded), with a measured position and a setpoint (NaN: not known yet, as
    in a driver's first status after its activation)."""
    s = day.axes['mirrors']
    phase_t, phase = np.asarray(day.phase.t), np.asarray(day.phase['phase'])
    k = np.searchsorted(phase_t, s.t, side='right') - 1
    on = (k >= 0) & (phase[np.clip(k, 0, None)] == Phase.TRACKING)
    known = np.isfinite(np.asarray(s['measured'])) & np.isfinite(np.asarray(s['setpoint']))
    return s, on & known & np.isin(np.asarray(s['state']), ('following', 'holding', 'waiting'))


def planned_steps(day, t0: float, t1: float, joint: str = 'mirrors', least: float = math.radians(0.5)):
    """The steps of ``joint`` in the planner's recorded trajectories (1 s points) within
    [t0, t1] [s]: (times [s], positions [rad], indices of the points that jump by more
    than ``least`` [rad] from the previous one)."""
    planned = {}
    for tr in day.trajectories:
        if joint in tr.joints:
            planned.update(zip(np.round(tr.times).tolist(), tr.positions[:, tr.joints.index(joint)].tolist()))
    pt = np.array(sorted(planned))
    pv = np.array([planned[k] for k in pt])
    inside = (pt >= t0) & (pt <= t1)
    pt, pv = pt[inside], pv[inside]
    return pt, pv, np.flatnonzero(np.abs(np.diff(pv)) > least) + 1


def write_fourth_collector(tmp_path):
    """A two-movement collector no seed describes, at Barcelona: thirteen 0.2 m lines with
    a central one on one stepper without switches (seed 000's half-angle law, eq. 13) and
    a mobile structure tilting the rows on seed 000's stepper (open loop) with its home switch under
    seed 000 eq. 16 (beta_M = theta_z / 2: the reflected rays vertical in the longitudinal
    plane at solar noon, seed 001 eq. 3) below a fixed horizontal receiver. A description
    and a site config, nothing else."""
    col = {
        'name': 'fourth_rooftop', 'source': 'test: a collector from its description only',
        'movements': {
            'mirrors': {
                'drive': 'stepper_no_switches', 'feedback': 'steps', 'law': 'half_transversal',
                'range_deg': [-50.0, 60.0], 'sleep_deg': 0.0, 'stow_deg': 60.0, 'reference_deg': 0.0,
                'step_deg': 0.05, 'gear_ratio': 1.0},
            'mobile_structure': {
                'drive': 'stepper_switches', 'feedback': 'steps', 'law': 'eq16',
                'range_deg': [-30.0, 60.0], 'sleep_deg': 0.0, 'stow_deg': 0.0, 'step_deg': 0.006,
                'gear_ratio': 1.0, 'switches_deg': {'longitudinal_1': 0.0}}},
        'boards': [{'name': 'mirrors', 'kind': 'axis', 'movement': 'mirrors'},
                   {'name': 'mobile_structure', 'kind': 'axis', 'movement': 'mobile_structure'},
                   {'name': 'absorber', 'kind': 'absorber'}, {'name': 'irradiance', 'kind': 'irradiance'}],
        'sensors': [{'name': 'inlet', 'kind': 'thermocouple', 'board': 'absorber'},
                    {'name': 'outlet', 'kind': 'thermocouple', 'board': 'absorber'},
                    {'name': 'dni', 'kind': 'pyrheliometer', 'board': 'irradiance'}],
        'optics': {'lines': 13, 'central_line': True, 'line_width': 0.2, 'line_length': 2.0, 'gap': 0.03,
                   'receiver_height': 1.2, 'receiver_width': 0.1, 'tube_diameter': 0.04, 'tube_count': 1,
                   'receiver_length': 2.0, 'azimuth_deg': 0.0}}
    (tmp_path / 'fourth.yaml').write_text(yaml.safe_dump(col))
    site = {'/**': {'ros__parameters': {'site.latitude_deg': 41.39, 'site.longitude_deg': 2.17, 'site.elevation': 12.0}},
            'planner': {'ros__parameters': {'collector.description': 'fourth.yaml'}}}
    (tmp_path / 'site.yaml').write_text(yaml.safe_dump(site))
    return tmp_path / 'site.yaml'
