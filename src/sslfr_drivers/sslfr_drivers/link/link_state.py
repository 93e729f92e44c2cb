"""The board link's state machine: ``down`` (port closed/unopenable), ``connecting``
(port open, no session or INFO not read yet), ``up``, ``silent`` (port open but the
board stopped answering), ``refused`` (another protocol version, or the board does not
accept this host's key). A (re)connection, a silence or a board reset leads through
a new session and a re-read of INFO and STATUS (its own thread) back to ``up``."""
from __future__ import annotations

import enum
import logging
import threading
from typing import Callable

from sslfr_drivers.link import messages as m
from sslfr_drivers.link.auth import NULL_KEY
from sslfr_drivers.link.link_errors import AuthError, LinkError, NackError, NoSession
from sslfr_drivers.link.protocol import PROTOCOL_V1, PROTOCOL_VERSION, ProtocolError, ProtocolVersionError
from sslfr_drivers.link.reader import Backoff

_log = logging.getLogger('sslfr_drivers.link.board_link')

#: [s] least time between two checks for a board reboot triggered by the board's
#: frames of no session (a flood of replayed BOOT frames costs one HELLO per period)
PROBE_INTERVAL = 1.0


class BoardLinkState(str, enum.Enum):
    """State of one board link (its value is the text shown in diagnostics).
    Not the ``AxisStatus.LINK_*`` codes (``sslfr_common.contract.LinkState``)."""

    DOWN = 'down'
    CONNECTING = 'connecting'
    UP = 'up'
    SILENT = 'silent'
    REFUSED = 'refused'


#: The former name, kept for existing call sites (axis/board_session.py).
LinkState = BoardLinkState
_RETRYING = (BoardLinkState.CONNECTING, BoardLinkState.SILENT, BoardLinkState.REFUSED)


class LinkStateMachine:
    """The state of ``link`` (the :class:`~.board_link.BoardLink` it is part of) and
    the work that moves it: listeners, the re-read (:meth:`refresh`), the reboot check
    (:meth:`probe`), a detected board reset.

    ``state`` is the link's own view (changed first); ``shown`` is what
    ``BoardLink.state`` and :meth:`wait_up` show, once the listeners were told.
    """

    def __init__(self, link, backoff_min: float, backoff_max: float):
        self.link = link
        self.state = BoardLinkState.DOWN
        self.shown = BoardLinkState.DOWN
        self.cv = threading.Condition()
        self.listeners: list[Callable[[BoardLinkState, object], None]] = []
        self.refreshing = False
        self.next_refresh = 0.0
        self.next_probe = 0.0
        self.backoff = Backoff(backoff_min, backoff_max)

    def set(self, state: BoardLinkState, why: str = '') -> None:
        """Change state: the link's own view at once, then the listeners, then what
        is shown (unless a newer change came meanwhile, from a listener or the other
        thread)."""
        with self.cv:
            if state == self.state:
                return
            old, self.state = self.state, state
        _log.info('%s: link %s -> %s %s', self.link.name, old.value, state.value, why, extra=self.link.log_extra)
        for fn in list(self.listeners):
            try:
                fn(state, self.link)
            except Exception:  # noqa: BLE001 - a listener bug must not kill the link
                _log.exception('%s: state listener failed', self.link.name, extra=self.link.log_extra)
        with self.cv:
            if self.state == state:
                self.shown = state
                self.cv.notify_all()
        self.link.poke()                      # the deadlines depend on the state

    def wait_up(self, timeout: float) -> bool:
        """Block until ``up`` is shown or ``timeout`` [s] passes."""
        with self.cv:
            return self.cv.wait_for(lambda: self.shown == BoardLinkState.UP, timeout)

    # ------------------------------------------------------------- timers (reader)
    def refresh_due(self, now: float) -> bool:
        return self.state in _RETRYING and not self.refreshing and now >= self.next_refresh

    def next_refresh_at(self) -> float | None:
        """When the next re-read is due [s], None while none is (up, down, under way)."""
        return self.next_refresh if self.state in _RETRYING and not self.refreshing else None

    def heard_board(self) -> None:
        """A frame of the session came: a connecting or silent link re-reads now."""
        if self.state in (BoardLinkState.SILENT, BoardLinkState.CONNECTING) and not self.refreshing:
            self.schedule_refresh()

    def heard_no_session(self, now: float) -> None:
        """A frame of the board's key but of no session (BOOT after a reboot, NACK
        NO_SESSION; perhaps a recording): while UP check (one HELLO per PROBE_INTERVAL)
        whether the board rebooted; while connecting or silent re-read."""
        if self.state == BoardLinkState.UP:
            if not self.refreshing and now >= self.next_probe:
                self.next_probe = now + PROBE_INTERVAL
                self.refreshing = True
                threading.Thread(target=self.probe, name=f'probe-{self.link.name}', daemon=True).start()
        elif self.state in (BoardLinkState.SILENT, BoardLinkState.CONNECTING) and not self.refreshing:
            self.schedule_refresh()

    # ------------------------------------------------------------- board resets
    def note(self, msg: m.Message, now: float) -> None:
        """Keep the board's last STATUS (its uptime going back is a reset) and INFO."""
        link = self.link
        if isinstance(msg, m.Status):
            old = link.last_status
            if old is not None and msg.uptime_ms < old.uptime_ms \
                    and old.uptime_ms - msg.uptime_ms < 1 << 31:
                self.board_reset('uptime went back')
            link.last_status = msg
            link.last_status_time = now
        elif isinstance(msg, m.Info):
            link.info = msg

    def boot_count(self, count: int, in_session: bool = False) -> None:
        """The board's boot count from an authenticated HELLO_REPLY: a change is a reset
        (``in_session``: the reply opened the session now in use, which stays)."""
        link = self.link
        old, link.boot_count = link.boot_count, count
        if old is not None and count != old:
            link.last_status = None           # its uptime restarted: not a second reset
            self.board_reset(f'boot count {old} -> {count}', end_session=not in_session)

    def board_reset(self, why: str, end_session: bool = True) -> None:
        """The board rebooted: its session is gone (``end_session``: nothing more is sent
        in it, requests waiting in it end with NoSession, never re-sent to a board that
        lost its position); a new session and the re-read follow."""
        link = self.link
        _log.warning('%s: board reset detected (%s): position lost until re-homed', link.name, why,
                     extra=link.log_extra)
        if end_session:
            link.end_session()
            link.requests.fail_all(NoSession(f'{link.name}: the board was reset ({why})'), session_only=True)
        if self.state == BoardLinkState.UP:
            self.set(BoardLinkState.CONNECTING, f'board reset ({why})')
        link.resets += 1    # counted once the link no longer shows UP
        if not self.refreshing:
            self.schedule_refresh()

    # ------------------------------------------------ session and re-read (own thread)
    def schedule_refresh(self) -> None:
        self.refreshing = True
        threading.Thread(target=self.refresh, name=f'refresh-{self.link.name}', daemon=True).start()

    def probe(self) -> None:
        """While UP, after a frame of no session: has the board rebooted? A new session
        is opened but not used; only a changed boot count counts (a reset, then the
        usual re-read adopts a new session)."""
        count = None
        try:
            count = self.link.auth.handshake(adopt=False).boot_count
        except (LinkError, ProtocolError):
            pass                       # the link's own time-outs handle a silent board
        finally:
            self.refreshing = False
        if count is not None:
            self.boot_count(count)     # a reset: the re-read adopts a new session

    def refresh(self) -> None:
        """Start a session and re-read INFO and STATUS; the link is UP only after this
        succeeds. A version-1 board is only read for INFO (it stays refused)."""
        link = self.link
        try:
            link.auth.handshake()
            info = link.request(m.GetInfo())
            if not isinstance(info, m.Info):
                raise ProtocolError(f'GET_INFO answered with {type(info).__name__}')
            if info.protocol != PROTOCOL_VERSION:
                raise ProtocolVersionError(info.protocol)
            try:
                link.request(m.GetStatus())
            except NackError:
                pass   # boards without STATUS (some sensor boards) are fine
            self.backoff.reset()
            self.set(BoardLinkState.UP, f'{info.name_str} fw {info.firmware}'
                     + ('' if link.key != NULL_KEY else ' (NOT authenticated: no key)'))
        except ProtocolVersionError as exc:
            link.version_error = exc
            link.last_error = str(exc)
            link.auth.session = None
            self.set(BoardLinkState.REFUSED, str(exc))
            try:
                link.auth.null_request(m.GetInfo(), version=PROTOCOL_V1)
            except (LinkError, ProtocolError):
                pass
        except AuthError as exc:
            if str(exc) != link.auth_error:
                _log.error('%s', exc, extra=link.log_extra)
            link.auth_error = link.last_error = str(exc)
            link.auth.session = None
            self.set(BoardLinkState.REFUSED, str(exc))
        except (LinkError, ProtocolError) as exc:
            link.last_error = str(exc)
            if link.connected and self.state == BoardLinkState.UP:
                self.set(BoardLinkState.SILENT, str(exc))
        finally:
            delay = self.backoff.next()
            self.next_refresh = link.clock() + delay
            self.refreshing = False
            link.poke(delay)
