"""What the axis supervisor reads from the board (:class:`BoardState`) and decides to
send it (:class:`Action` of an :class:`ActionKind`), in the board's units (steps,
steps/s; docs/protocol.md). No rclpy, no I/O."""
from __future__ import annotations

import enum
from dataclasses import dataclass

HOME_SWITCHES = {'low': 0, 'high': 1, 'sleep': 2}   # messages.Switch indices
#: STATUS.fault_bits that make the driver latch a fault (docs/protocol.md FaultBits)
BOARD_FAULT_STALL = 1 << 2
BOARD_FAULT_DRIVER = 1 << 4


@dataclass(frozen=True)
class BoardState:
    """What the driver knows of the board from its last STATUS (docs/protocol.md).

    steps, target : step counter and board target [steps]; moving, homed, homing :
    status flags; sensor : joint angle from the board's sensor [rad] or None;
    limit_bits, fault_bits : as reported.
    """

    steps: int
    target: int
    moving: bool
    homed: bool
    homing: bool
    sensor: float | None
    limit_bits: int = 0
    fault_bits: int = 0


class ActionKind(enum.StrEnum):
    """The board commands the supervisor decides (a str: equal to its name's value)."""

    NONE = 'none'
    STOP = 'stop'
    HOME = 'home'
    SET_ZERO = 'set_zero'
    MOVE = 'move'


@dataclass(frozen=True)
class Action:
    """One board command decided by the supervisor.

    kind : :class:`ActionKind` (its value accepted too)
    steps : MOVE_TO target or SET_ZERO / HOME position [steps]
    speed : MOVE_TO / HOME step rate [steps/s] (HOME: signed, + increases steps)
    switch : HOME limit switch index (``HOME_SWITCHES``: low 0, high 1, sleep 2)
    """

    kind: ActionKind = ActionKind.NONE
    steps: int = 0
    speed: float = 0.0
    switch: int = 0

    def __post_init__(self):
        if type(self.kind) is not ActionKind:
            object.__setattr__(self, 'kind', ActionKind(self.kind))


#: The one STOP command: every stop of the axis puts this on the wire.
STOP = Action(ActionKind.STOP)
#: No command this tick.
NOTHING = Action()
