"""A composed process's Python log lines reach the logger of the node they belong to
(sslfr_common.log_route, LogBridge): a board link working for the absorber board logs
under absorber_board, not under the first node of the process."""
import logging

from sslfr_common.log_route import NODE_ATTR, log_extra
from sslfr_common.node import LogBridge


class _Logger:
    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(('INFO', text))

    def warning(self, text):
        self.lines.append(('WARN', text))

    def error(self, text):
        self.lines.append(('ERROR', text))


class _Node:
    def __init__(self, name):
        self.name, self.logger = name, _Logger()

    def get_name(self):
        return self.name

    def get_logger(self):
        return self.logger


def test_lines_go_to_the_node_they_name_else_the_first():
    first, other = _Node('mirrors_driver'), _Node('absorber_board')
    bridge = LogBridge(first, ('sslfr_test_route',), [other])
    log = logging.getLogger('sslfr_test_route.link')
    try:
        log.warning('/dev/pts/7: board reset detected', extra=log_extra('absorber_board'))
        log.error('/dev/pts/3: auth refused', extra=log_extra('mirrors_driver'))
        log.info('no owner given')
        log.info('an unknown owner', extra=log_extra('gps'))
    finally:
        bridge.detach()
    assert other.logger.lines == [('WARN', '/dev/pts/7: board reset detected')]
    assert first.logger.lines == [('ERROR', '/dev/pts/3: auth refused'), ('INFO', 'no owner given'),
                                  ('INFO', 'an unknown owner')]
    assert log_extra('') == {} and log_extra('x') == {NODE_ATTR: 'x'}

