"""Test support: a collector no seed describes, written as files (issue 34 item 7)."""
from __future__ import annotations

import yaml


def write_fourth_collector(tmp_path):
    """A collector no seed describes (thirteen 0.2 m lines with a central one, one
    stepper without switches, seed 000's half-angle law, at Barcelona): a description
    and a site config, nothing else."""
    col = {
        'name': 'fourth_rooftop', 'source': 'test: a collector from its description only',
        'movements': {'mirrors': {
            'drive': 'stepper_no_switches', 'feedback': 'steps', 'law': 'half_transversal',
            'range_deg': [-50.0, 60.0], 'sleep_deg': 0.0, 'stow_deg': 60.0, 'reference_deg': 0.0,
            'step_deg': 0.05, 'gear_ratio': 1.0}},
        'boards': [{'name': 'mirrors', 'kind': 'axis', 'movement': 'mirrors'},
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
