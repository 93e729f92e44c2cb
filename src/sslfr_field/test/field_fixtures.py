"""What the field page's tests share (imported by name: a second conftest.py would
shadow the root one's ``from conftest import ...`` under pytest-xdist)."""
from __future__ import annotations

from sslfr_field.live import FieldState

PASSWORD = 'field-pass-123'


class Backend:
    """The field page's backend without ROS: two collectors, a fixed clock; records
    the log lines and the service calls ``(collector, service, request)``, and answers
    them as the collector's planner would, refusing those of ``refuse``."""

    def __init__(self, refuse: tuple[str, ...] = ()):
        self.state = FieldState([('c1', '/c1', ''), ('c2', '/c2', '')])
        self.calls, self.logs = [], []
        self.refuse = refuse

    def snapshot(self):
        return self.state.snapshot(1.0)

    def ros_time(self):
        return 1.0

    def log(self, level, text):
        self.logs.append((level, text))

    async def call(self, cid, cmd):
        self.calls.append((cid, cmd.service, dict(cmd.request)))
        refused = cid in self.refuse
        return {'success': not refused, 'message': 'refused: maintenance' if refused else ''}
