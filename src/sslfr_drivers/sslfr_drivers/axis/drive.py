"""What differs between drive kinds, for the axis driver (no rclpy): one strategy per
drive kind of the collector description (docs/collectors.md "Drives"), chosen by the
driver's ``drive`` parameter; the supervisor asks it and never branches on a prototype.

* ``stepper_switches`` (seed 000): a stepper board with limit switches; the position
  is re-established from the position sensor (SET_ZERO) or by HOME toward a switch.
* ``linear_actuator_inclinometer`` (seed 004): an actuator board closed on an
  inclinometer; its position is absolute, so it is always re-referenced from the
  sensor at rest (SET_ZERO); a target counts as reached within the deadband.
* ``stepper_no_switches`` (seed 003): a stepper board without switches or sensor; it
  is referenced only when the operator says where the axis is: the home service means
  "the axis is now at ``home_position``" (SET_ZERO there); never by itself.
"""
from __future__ import annotations

import logging

from sslfr_common.contract import DRIVE_KINDS, DriveKind
from sslfr_common.log_route import log_extra
from sslfr_drivers.axis.commands import NOTHING, Action, ActionKind, BoardState
from sslfr_drivers.axis.homing import home_action
from sslfr_drivers.link import messages as m

#: the drive kinds (the collector description's ``drive`` values)


class Drive:
    """Stepper with switches (seed 000): the behaviour the others refine."""

    kind = DriveKind.STEPPER_SWITCHES.value
    #: INFO.board_kind the driver accepts for this drive
    board_kind = m.BoardKind.AXIS_STEPPER

    def reached(self, cfg, target_steps: int, board_steps: int) -> bool:
        """A commanded ``target_steps`` is no longer pending at ``board_steps`` (stall
        check): within one step."""
        return abs(target_steps - board_steps) <= 1

    def settled(self, cfg, target_steps: int, board_steps: int) -> bool:
        """A board at rest at ``board_steps`` needs no MOVE_TO to ``target_steps``: exactly there."""
        return target_steps == board_steps

    def range_margin(self, cfg) -> float:
        """How far inside its range [rad] a MOVE_TO target stays: 0, the board's step
        counter is the host's (both set by SET_ZERO / HOME to the same count)."""
        return 0.0

    def reference(self, cfg, board: BoardState, samples: list, last_known: float | None,
                  requested: bool) -> tuple[Action, str]:
        """One re-referencing tick (``requested``: the home service was called)."""
        return home_action(cfg, board, samples, last_known)

    def references_itself(self, cfg, board: BoardState) -> bool:
        """Whether a lost position is re-established without the home service."""
        return cfg.auto_home or (cfg.use_sensor and board.sensor is not None)

    def home_message(self, cfg) -> str:
        """What the home service answers when it accepts."""
        return f'homing toward the {cfg.home_switch} switch'


class LinearActuator(Drive):
    """Linear actuator closed on an inclinometer (seed 004)."""

    kind = DriveKind.LINEAR_ACTUATOR_INCLINOMETER.value
    board_kind = m.BoardKind.AXIS_ACTUATOR

    def reached(self, cfg, target_steps: int, board_steps: int) -> bool:
        """Within the deadband (the board's loop rests anywhere inside it)."""
        tol = max(1, int(cfg.deadband / abs(cfg.calibration.joint_per_step)))
        return abs(target_steps - board_steps) <= tol

    settled = reached

    def range_margin(self, cfg):
        """The deadband: the board sets its step zero from its own inclinometer reading
        at SET_ZERO, the host sends the mean of several, so the board's angle of a step
        count differs from the host's by the reading noise (a few steps); a target on
        the range end (the sleeping and stow positions of seed 004's description) would
        then be refused OUT_OF_RANGE now and then. The loop rests anywhere within the
        deadband of its target anyway."""
        return cfg.deadband

    def reference(self, cfg, board, samples, last_known, requested):
        if board.sensor is None:
            return NOTHING, 'position lost and the board reports no inclinometer reading'
        return home_action(cfg, board, samples, last_known)      # SET_ZERO from the sensor at rest

    def references_itself(self, cfg, board):
        return board.sensor is not None

    def home_message(self, cfg):
        return 're-referencing from the inclinometer'


class StepperNoSwitches(Drive):
    """Stepper without switches (seed 003): referenced by the operator."""

    kind = DriveKind.STEPPER_NO_SWITCHES.value

    def reference(self, cfg, board, samples, last_known, requested):
        if not requested:
            return NOTHING, 'position lost: put the axis at its reference angle and call the home service'
        if board.moving:
            return Action(ActionKind.STOP), 'stopping before the reference'
        return (Action(ActionKind.SET_ZERO, cfg.calibration.steps(cfg.home_position)),
                'the operator referenced the axis at its reference angle')

    def references_itself(self, cfg, board):
        return False

    def home_message(self, cfg):
        return f'axis referenced at {cfg.home_position:.4f} rad (the operator put it there)'


_DRIVES = {d.kind: d() for d in (Drive, LinearActuator, StepperNoSwitches)}


def drive_for(kind: str) -> Drive:
    """The strategy of drive ``kind`` (:data:`DRIVE_KINDS`); KeyError naming the kinds."""
    try:
        return _DRIVES[kind]
    except KeyError:
        raise KeyError(f'unknown drive kind {kind!r}; known: {", ".join(DRIVE_KINDS)}') from None



class ReferenceKeeper:
    """The persisted reference of a ``stepper_no_switches`` axis, kept by the board
    session (:mod:`~.board_session`): recorded when a SET_ZERO is ACKed (the operator's
    reference at ``angle`` [rad], the driver's ``home_position``, with the board's boot
    count), checked on the first read and after every reset or reconnection
    (:meth:`sslfr_common.drives.ReferenceStore.check`: a new boot count or a board no
    longer HOMED marks it lost). ``state`` is for diagnostics; problems and losses are
    logged (logger ``sslfr_drivers.axis.reference``, forwarded to the node's)."""

    def __init__(self, store, angle: float, owner: str = ''):
        self.store, self.angle = store, angle
        self.owner = owner                   # the driver node (its log lines, log_route)
        self.state = 'unchecked'
        self._checked = False

    def after_write(self, act: Action, ok: bool, boot_count: int | None, stamp: float) -> str | None:
        """Book a written ``act``; a SET_ZERO that was ACKed records the reference.
        Returns the line logged."""
        if act.kind is not ActionKind.SET_ZERO or not ok:
            return None
        if boot_count is None:
            self.state = 'not kept: the board did not report its boot count'
        else:
            try:
                self.store.record(self.angle, act.steps, boot_count, stamp)
                self.state, self._checked = 'valid', True
                return _log(self.owner, f'reference at {self.angle:.4f} rad kept in {self.store.path} '
                            f'(board boot {boot_count})', logging.INFO)
            except OSError as exc:
                self.state = f'not kept: {exc}'
        return _log(self.owner, f'reference at {self.angle:.4f} rad {self.state}')

    def after_read(self, board: BoardState | None, reset: bool, reconnected: bool,
                   boot_count: int | None) -> str | None:
        """Check the stored reference on the first read and after a reset or a
        reconnection; returns the line logged when it is found lost or unreadable."""
        if reset or reconnected:
            self._checked = False            # checked at the next read with a board state
        if board is None or self._checked:
            return None
        self._checked = boot_count is not None
        try:
            state, ref = self.store.check(boot_count, board.homed)
        except (OSError, ValueError) as exc:
            self.state = f'unreadable: {exc}'
            return _log(self.owner, f'reference file: {exc}')
        was = self.state
        self.state = state if ref is None or not ref.lost else f'lost ({ref.why})'
        if state == 'lost' and was != self.state:
            return _log(self.owner, f'the reference of {ref.axis} is lost: {ref.why}; put the axis at its '
                        'reference angle and call the home service')
        return None


def _log(owner: str, line: str, level: int = logging.WARNING) -> str:
    logging.getLogger('sslfr_drivers.axis.reference').log(level, line, extra=log_extra(owner))
    return line


def reference_keeper(p: dict, owner: str = '') -> ReferenceKeeper | None:
    """The :class:`ReferenceKeeper` of the driver's parameters ``p``: for a
    stepper_no_switches drive with a ``state_dir`` (``~`` expanded), else None."""
    if p['drive'] != DriveKind.STEPPER_NO_SWITCHES.value or not p['state_dir']:
        return None
    import os
    from sslfr_common.drives import ReferenceStore
    return ReferenceKeeper(ReferenceStore(os.path.expanduser(p['state_dir']), p['axis']), p['home_position'], owner)
