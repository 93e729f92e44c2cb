"""The axis driver's hardware interface (no rclpy): one axis board, a thin adapter over
:class:`sslfr_drivers.link.board_link.BoardLink` that speaks in :mod:`.commands` terms.
It owns the board I/O of the driver's read -> update -> write cycle.

- :meth:`AxisBoardSession.open` starts the link, waits for INFO and refuses a board
  speaking another protocol version or that is not an axis board
  (:class:`BoardRefused`, message says why);
- :meth:`read` (once per control tick) reads STATUS (one try, short time-out) into
  a :class:`BoardReading`: the :class:`~sslfr_drivers.axis.commands.BoardState`, or
  None while the link is not UP (down, reconnecting, re-reading INFO/STATUS after a
  board reset), and whether the board reset or the port was reopened since the
  last read (the driver then forgets its commands);
- :meth:`write` executes an :class:`~sslfr_drivers.axis.commands.Action`
  (MOVE_TO / STOP / HOME / SET_ZERO) and returns a :class:`WriteResult`: the one place
  where the driver's commands, every STOP included, are put on the wire.

The link's own heartbeat (PING when idle for ``heartbeat`` s) keeps the board's 1 s
watchdog quiet even when the driver is inactive; STATUS polls count as traffic too.
"""
from __future__ import annotations

import math
import time
from typing import NamedTuple

from sslfr_common.contract import LinkState as Link

from sslfr_drivers.link import messages as m
from sslfr_drivers.axis.commands import Action, ActionKind, BoardState
from sslfr_drivers.axis.host_loss import configure_host_loss
from sslfr_drivers.axis.joint import Calibration
from sslfr_drivers.link.board_link import BoardLink, LinkError, LinkState, NackError
from sslfr_drivers.link.protocol import ProtocolError
from sslfr_drivers.link.keys import link_key
from sslfr_drivers.link.transport import make_transport

class BoardReading(NamedTuple):
    """One :meth:`AxisBoardSession.read`: the board state (None: no usable STATUS)
    and whether the board reset / the port was reopened since the previous read."""

    board: BoardState | None
    reset: bool = False
    reconnected: bool = False


class WriteResult(NamedTuple):
    """One :meth:`AxisBoardSession.write`: ACKed, else the reason (``nack``: the
    board refused, ``detail`` = the ErrorCode name; otherwise no valid answer)."""

    ok: bool
    detail: str = ''
    nack: bool = False


class BoardRefused(RuntimeError):
    """The board answers but must not be driven (protocol version, board kind)."""


def board_from_status(status: m.Status) -> BoardState:
    """Convert a STATUS message into the core's :class:`BoardState`.

    ``sensor`` is the sensor angle [rad] when the board flags HAS_SENSOR, the value
    is finite and the SENSOR fault bit is clear, else None (steps are used).
    """
    has = (bool(status.flags & m.StatusFlags.HAS_SENSOR) and math.isfinite(status.sensor_angle)
           and not status.fault_bits & m.FaultBits.SENSOR)
    return BoardState(int(status.position), int(status.target), status.moving, status.homed,
                      status.homing, float(status.sensor_angle) if has else None,
                      int(status.limit_bits), int(status.fault_bits))


def reusable_status(age: float, state: BoardState, max_age: float, rest_age: float) -> bool:
    """Whether a STATUS ``age`` [s] old stands in for a lost answer: younger than
    ``max_age`` [s], or, of a board at rest (neither moving nor homing: it moves only
    on a command, and the session does not extend the reuse past one), younger than
    ``rest_age`` [s].
    While idle the driver polls seldom, and one late answer would otherwise leave it
    without a board state until the next poll (an operator's jog refused meanwhile)."""
    if age <= max_age:
        return True
    return not state.moving and not state.homing and age <= rest_age


class AxisBoardSession:
    """One axis board reached on ``port`` (see module docstring).

    Parameters
    ----------
    port : str
        pyserial URL / device, or ``xbee:<uart>?addr=<hex>`` (transport.make_transport).
    baudrate : int
        [bit/s].
    request_timeout : float
        Answer time-out per try [s].
    link_timeout : float
        Silence after which the link is declared silent and re-read [s].
    heartbeat : float
        PING when nothing was sent for this long [s] (< the board's 1 s watchdog).
    key : bytes or None
        The installation key (link/keys.py); None: unprovisioned boards only.
    """

    def __init__(self, port: str, baudrate: int = 115200, request_timeout: float = 0.25,
                 link_timeout: float = 1.0, heartbeat: float = 0.25, key: bytes | None = None,
                 board_kind: int = m.BoardKind.AXIS_STEPPER, owner: str = ''):
        self.port = port
        self.board_kind = board_kind      # INFO.board_kind of the drive (axis.drive.Drive.board_kind)
        self.reference = None             # a switchless drive's kept reference (axis.drive.ReferenceKeeper)
        self.request_timeout = request_timeout
        self.link = BoardLink(make_transport(port, baudrate), name=port, timeout=request_timeout,
                              retries=2, heartbeat=heartbeat, silence=link_timeout,
                              backoff_min=0.1, backoff_max=2.0, key=key, owner=owner)
        self.board_info = ''
        self.host_loss_note = ''
        self.last_status: m.Status | None = None
        self.poll_failures = 0
        self.stale_polls = 0
        self._last_ok: tuple[float, BoardState] | None = None
        self._commanded = False           # a command went out after the last answered STATUS
        self._seen_resets = 0
        self._seen_reconnects = 0

    # ------------------------------------------------------------------ open / close
    def open(self, wait: float = 3.0) -> str:
        """Start the link and wait up to ``wait`` [s] for INFO; return the board text.

        Raises
        ------
        BoardRefused
            Another protocol version, or not an axis board.
        ConnectionError
            No answer (port missing, board silent).
        """
        self.link.start()
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline:
            if self.link.state in (LinkState.UP, LinkState.REFUSED):
                break
            if self.link.state == LinkState.DOWN and self.link.last_error.startswith('cannot open'):
                break       # the port does not open: no point waiting
            time.sleep(0.02)
        state = self.link.state
        if state == LinkState.REFUSED:
            why = str(self.link.version_error or self.link.last_error)
            self.link.stop()
            raise BoardRefused(why)
        if state != LinkState.UP or self.link.info is None:
            why = self.link.last_error or f'link {state.value}'
            self.link.stop()
            raise ConnectionError(f'no INFO from the board ({why})')
        info = self.link.info
        if info.board_kind != self.board_kind:
            self.link.stop()
            try:
                kind = m.BoardKind(info.board_kind).name
            except ValueError:
                kind = f'kind {info.board_kind}'
            raise BoardRefused(f'board {info.name_str!r} on {self.port} is a {kind} board, not the '
                               f'{m.BoardKind(self.board_kind).name} board of this axis\'s drive')
        self.board_info = (f'{info.name_str} fw {info.firmware} protocol {info.protocol} '
                           f'id {info.board_id:08x}')
        self._seen_resets = self.link.resets
        self._seen_reconnects = self.link.reconnects
        return self.board_info

    def close(self) -> None:
        """Stop the link and close the port."""
        self.link.stop()

    # ------------------------------------------------------------------ state
    def read(self, now: float, period: float, idle_period: float = 0.0) -> BoardReading:
        """The read of one control tick at steady ``now`` [s] with control ``period``
        [s]: STATUS with a ``2 * period`` time-out and the reset / reconnect events. A
        lost answer reuses the previous STATUS (:func:`reusable_status`) up to ``3 *
        period`` old, or, of a board at rest, up to one idle poll (``idle_period`` [s],
        the longest wait between polls while nothing moves) + ``2 * period`` old."""
        board = self.poll(now, 2 * period, 3 * period, idle_period + 2 * period)
        reading = BoardReading(board, self.take_reset(), self.take_reconnect())
        if self.reference is not None:
            self.reference.after_read(board, reading.reset, reading.reconnected, self.link.boot_count)
        return reading

    def poll(self, now: float, timeout: float, max_age: float, rest_age: float = 0.0) -> BoardState | None:
        """STATUS now (one try of ``timeout`` [s]).

        When the answer is lost (noisy link, a late board) the previous STATUS is
        returned if :func:`reusable_status` allows it (``max_age``; ``rest_age`` [s] only
        when no command went out since it; steady ``now`` [s]) and the link is still UP
        with no reset seen since;
        otherwise None (link down, reconnecting, or re-reading INFO/STATUS after a
        board reset).
        """
        if self.link.state != LinkState.UP:
            self._last_ok = None
            return None
        try:
            status = self.link.request(m.GetStatus(), timeout=min(timeout, self.request_timeout), retries=0)
        except (LinkError, ProtocolError):
            self.poll_failures += 1
            last = self._last_ok
            rest_age = 0.0 if self._commanded else rest_age     # a command may have ended the rest
            if (last is not None and reusable_status(now - last[0], last[1], max_age, rest_age)
                    and self.link.state == LinkState.UP and self.link.resets == self._seen_resets):
                self.stale_polls += 1
                return last[1]
            return None
        self.last_status = status
        state = board_from_status(status)
        self._last_ok, self._commanded = (now, state), False
        return state

    def take_reset(self) -> bool:
        """True once after each board reset detected by the link (BOOT, uptime, seq)."""
        if self.link.resets != self._seen_resets:
            self._seen_resets = self.link.resets
            return True
        return False

    def take_reconnect(self) -> bool:
        """True once after each reopening of the port."""
        if self.link.reconnects != self._seen_reconnects:
            self._seen_reconnects = self.link.reconnects
            return True
        return False

    def link_state(self) -> Link:
        """AxisStatus.LINK_* for the current link state."""
        st = self.link.state
        if st == LinkState.UP:
            return Link.LINK_UP
        if st == LinkState.REFUSED:
            return Link.LINK_FAULT
        if st in (LinkState.CONNECTING, LinkState.SILENT):
            return Link.LINK_CONNECTING
        return Link.LINK_DOWN

    def refusal(self) -> str:
        """'refused: <why>' while the link refuses the board (another protocol version, a
        key it does not accept), else ''."""
        return f'refused: {self.link.last_error}' if self.link.state == LinkState.REFUSED else ''

    def frames_lost(self) -> int:
        """Board frames lost so far (sequence-number gaps)."""
        return int(self.link.frames_lost)

    def frames_bad(self) -> int:
        """Frames dropped as corrupt or not authentic: CRC, length and decode errors and
        frames whose tag does not verify (forged, damaged, another key or session)."""
        fr = self.link.framer
        return int(fr.crc_errors + fr.length_errors + self.link.decode_errors + self.link.auth_failures)

    def counters(self) -> dict[str, int]:
        """Link counters plus STATUS poll failures and reuses, for diagnostics."""
        c = dict(self.link.counters())
        c['status_poll_failures'] = self.poll_failures
        c['status_reused'] = self.stale_polls
        c['link_state'] = self.link.state.value
        if self.reference is not None:
            c['reference'] = self.reference.state
        return c

    def velocity(self, cal: Calibration) -> float:
        """Joint velocity [rad/s] from the last STATUS speed [steps/s]."""
        if self.last_status is None or not math.isfinite(self.last_status.speed):
            return 0.0
        return self.last_status.speed * cal.joint_per_step

    # ------------------------------------------------------------------ commands
    def write(self, act: Action, wait: bool = True) -> WriteResult | None:
        """Put ``act`` on the wire (nothing for NONE). ``wait``: wait for its ACK (the
        link's time-out and retries) and return the result, a NACK's detail being the
        :class:`messages.ErrorCode` name (e.g. ``NOT_HOMED``). Not ``wait``: queue it
        and return None at once, errors ignored (safe from any thread: the e-stop at a
        safety message never waits behind a control tick that is retrying)."""
        msg = board_command(act)
        if msg is None:
            return WriteResult(True) if wait else None
        self._commanded = True
        if not wait:
            try:
                self.link.submit(msg)
            except (LinkError, ProtocolError, OSError):
                pass
            return None
        try:
            self.link.request(msg)
        except NackError as exc:
            try:
                return WriteResult(False, m.ErrorCode(exc.code).name, True)
            except ValueError:
                return WriteResult(False, str(exc), True)
        except (LinkError, ProtocolError) as exc:
            return WriteResult(False, str(exc) or type(exc).__name__)
        if self.reference is not None:
            self.reference.after_write(act, True, self.link.boot_count, time.time())
        return WriteResult(True)


def board_command(act: Action) -> m.Message | None:
    """The board message of ``act`` (None for NONE): MOVE_TO at >= 1 step/s, STOP,
    HOME toward ``act.switch``, SET_ZERO."""
    if act.kind is ActionKind.MOVE:
        return m.MoveTo(int(act.steps), float(max(1.0, abs(act.speed))))
    if act.kind is ActionKind.STOP:
        return m.Stop()
    if act.kind is ActionKind.HOME:
        return m.Home(int(m.Switch(act.switch)), float(act.speed), int(act.steps))
    if act.kind is ActionKind.SET_ZERO:
        return m.SetZero(int(act.steps))
    return None


def open_session(port: str, p: dict, owner: str = '') -> AxisBoardSession:
    """A session on ``port`` with the driver's parameters ``p``, opened (INFO read), for
    node ``owner`` (its log lines); the exceptions of :meth:`AxisBoardSession.open`."""
    from sslfr_drivers.axis.drive import drive_for, reference_keeper
    session = AxisBoardSession(port, p['baudrate'], p['request_timeout'], p['link_timeout'], p['heartbeat_period'],
                               key=link_key(p['key_file']), board_kind=drive_for(p['drive']).board_kind,
                               owner=owner)
    session.reference = reference_keeper(p, owner)
    session.open()
    session.host_loss_note = configure_host_loss(session.link, p)     # the board's own stow (EEPROM)
    return session
