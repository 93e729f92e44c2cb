"""The errors a board request can end with (raised by the board link, no I/O)."""
from __future__ import annotations

from sslfr_drivers.link import messages as m


class LinkError(Exception):
    """Base of the errors a request can end with."""


class LinkTimeout(LinkError, TimeoutError):
    """No answer after all retries."""


class LinkDown(LinkError):
    """The port is closed or was lost while the request was pending."""


class AuthError(LinkError):
    """The board does not accept this host's key, or has none (message says which and
    what to do)."""


class NoSession(LinkError):
    """No authenticated session with the board yet (the link is starting one)."""


class NackError(LinkError):
    """The board refused the request. ``code`` is a :class:`messages.ErrorCode`."""

    def __init__(self, request_type: int, code: int):
        try:
            name = m.ErrorCode(code).name
        except ValueError:
            name = f'code {code}'
        req = m.registry().get(request_type)
        super().__init__(f'board refused {req.__name__ if req else hex(request_type)}: {name}')
        self.request_type = request_type
        self.code = code
