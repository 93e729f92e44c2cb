"""The board's requests as blocking calls (each returns the answer or raises the
request's error, see :meth:`BoardLink.request`)."""
from __future__ import annotations

from sslfr_drivers.link import messages as m


class BoardCalls:
    """PING, GET_INFO, GET_STATUS, MOVE_TO, STOP, HOME, SET_ZERO and RESET over
    ``self.request`` (keyword arguments: its ``timeout`` and ``retries``)."""

    def ping(self, **kw) -> m.Ack:
        """PING carrying the host clock [ms, modulo 2**32]; the board's ACK."""
        return self.request(m.Ping(int(self.clock() * 1000) & 0xFFFFFFFF), **kw)

    def get_info(self, **kw) -> m.Info:
        return self.request(m.GetInfo(), **kw)

    def get_status(self, **kw) -> m.Status:
        return self.request(m.GetStatus(), **kw)

    def move_to(self, steps: int, speed: float, **kw) -> m.Ack:
        """MOVE_TO absolute ``steps`` [steps] at ``speed`` [steps/s]."""
        return self.request(m.MoveTo(int(steps), float(speed)), **kw)

    def stop_motor(self, **kw) -> m.Ack:
        """STOP: decelerate to rest."""
        return self.request(m.Stop(), **kw)

    def home(self, switch: int, speed: float, position: int = 0, **kw) -> m.Ack:
        """Home toward ``switch`` (:class:`messages.Switch`) at signed ``speed``
        [steps/s]; the counter becomes ``position`` [steps] at the switch."""
        return self.request(m.Home(int(switch), float(speed), int(position)), **kw)

    def set_zero(self, position: int = 0, **kw) -> m.Ack:
        """SET_ZERO: the counter becomes ``position`` [steps], the axis homed."""
        return self.request(m.SetZero(int(position)), **kw)

    def reset_board(self, **kw) -> m.Ack:
        """RESET: reboot the board (position lost)."""
        return self.request(m.Reset(), **kw)
