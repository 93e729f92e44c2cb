"""foxglove-sdk's own log records as counts and rate-limited one-line reports (pure).

The SDK (Rust) logs through Python ``logging`` (loggers ``foxglove.*``,
``tungstenite.*``): one ERROR line per refused client message, one per message that
could not be sent to a client that left. Left alone they reach stderr one by one (a
hostile client floods the log). :class:`SdkLog` takes them over: each record is
counted by kind (:func:`kind_of`) and reported through a :class:`OneLineLog`.
"""
from __future__ import annotations

import logging

from sslfr_common.netguard import OneLineLog

LOGGERS = ('foxglove', 'tungstenite')

#: (text in the SDK's message, counter): the SDK's answers to a client, in its words
KINDS = (
    ('Invalid message', 'bad_messages'),                   # not JSON, not the protocol
    ('subscribe to unknown channel', 'unknown_channel'),
    ('message for unknown channel', 'client_data_refused'),  # a binary client message
    ('Error sending', 'send_errors'),                      # the client left or stalled
    ('Error receiving', 'receive_errors'),                 # the client left without a close
)


def kind_of(text: str) -> str:
    """The counter of an SDK log message (``server_errors`` for any other)."""
    for needle, kind in KINDS:
        if needle in text:
            return kind
    return 'server_errors'


class SdkLog(logging.Handler):
    """Takes over the SDK's loggers (WARNING and up) while attached."""

    def __init__(self, log: OneLineLog):
        super().__init__(logging.WARNING)
        self.log = log
        self.counters = {k: 0 for _, k in KINDS} | {'server_errors': 0}
        self._saved: list[tuple[logging.Logger, int, bool]] = []

    def emit(self, record: logging.LogRecord) -> None:
        try:
            text = record.getMessage()
        except Exception:  # noqa: BLE001 - a bad format string must not raise here
            text = str(record.msg)
        kind = kind_of(text)
        self.counters[kind] += 1
        self.log.report(f'sdk {kind}', f'foxglove server: {text}',
                        'error' if kind == 'server_errors' else 'warn')

    def attach(self) -> None:
        """Route the SDK's loggers here (before the server starts: the SDK caches levels)."""
        for name in LOGGERS:
            lg = logging.getLogger(name)
            self._saved.append((lg, lg.level, lg.propagate))
            lg.setLevel(logging.WARNING)
            lg.propagate = False
            lg.addHandler(self)

    def detach(self) -> None:
        for lg, level, propagate in self._saved:
            lg.removeHandler(self)
            lg.setLevel(level)
            lg.propagate = propagate
        self._saved.clear()
