"""The shipped Foxglove layout: valid JSON whose panels all exist in its tree, and every
message path names a topic of the graph contract and a field its message type has."""
from __future__ import annotations

import json
import re
from pathlib import Path

LAYOUT = Path(__file__).resolve().parents[1] / 'config' / 'foxglove_layout.json'
#: topic -> message type, as docs/architecture.md lists them
TYPES = {
    '/axes/mirrors/status': ('sslfr_interfaces.msg', 'AxisStatus'),
    '/axes/mobile_structure/status': ('sslfr_interfaces.msg', 'AxisStatus'),
    '/axes/secondary_reflector/status': ('sslfr_interfaces.msg', 'AxisStatus'),
    '/safety/state': ('sslfr_interfaces.msg', 'SafetyState'),
    '/tracker/phase': ('sslfr_interfaces.msg', 'TrackerPhase'),
    '/absorber/inlet_temperature': ('sensor_msgs.msg', 'Temperature'),
    '/absorber/outlet_temperature': ('sensor_msgs.msg', 'Temperature'),
    '/irradiance/beam': ('sslfr_interfaces.msg', 'Irradiance'),
}


def _leaves(node):
    if isinstance(node, str):
        return [node]
    return _leaves(node['first']) + _leaves(node['second'])


def _paths(obj):
    if isinstance(obj, dict):
        for k, v in obj.items():
            if k in ('value', 'topicPath') and isinstance(v, str):
                yield v
            else:
                yield from _paths(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _paths(v)


def test_layout_panels_and_message_paths_exist():
    layout = json.loads(LAYOUT.read_text())
    panels = set(layout['configById'])
    assert sorted(_leaves(layout['layout'])) == sorted(panels)
    paths = list(_paths(layout['configById']))
    assert len(paths) >= 10
    seen_topics = set()
    for p in paths:
        m = re.fullmatch(r'(/[a-z_/]+?)(?:\.([a-z_]+))?', p)
        assert m, p
        topic, fieldname = m.groups()
        assert topic in TYPES, p
        seen_topics.add(topic)
        module, cls = TYPES[topic]
        msg = getattr(__import__(module, fromlist=[cls]), cls)
        if fieldname:
            assert fieldname in msg.get_fields_and_field_types(), p
    # the tracker at a glance: angles, safety, temperatures, irradiance
    assert {'/axes/mirrors/status', '/safety/state', '/absorber/outlet_temperature',
            '/irradiance/beam'} <= seen_topics
