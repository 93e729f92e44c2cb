"""Lifecycle policy of the axis driver (no rclpy): self-activation and the answer to
every lifecycle request.

**Self-activation** (parameter ``autostart``, on by default; issue 21). A driver
reaches and keeps the active state by itself, whoever starts it (``ros2 launch``,
``ros2 run``, ``./sslfr up``, systemd), after a respawn and when its board appears
late:

- it has a *goal* state, ``active`` at start;
- while below the goal it walks up one transition at a time: configure, retried
  with back-off while it fails (the wait doubles from ``retry_period`` up to
  ``retry_period_max``; a success resets it), then activate;
- an accepted request from outside sets the goal to where that transition leads:
  deactivate -> inactive, cleanup -> unconfigured, shutdown -> finalized, activate
  -> active; configure -> inactive unless the goal is already active. So an
  operator's ``deactivate`` or ``cleanup`` is respected and never undone by the
  driver; a new process (respawn, restart) starts again with the goal ``active``;
- if the node falls back by itself (a transition callback raising ends in
  ``unconfigured`` through ErrorProcessing), it climbs back to its goal.

With ``autostart`` false the driver never moves by itself (the ROS convention of a
lifecycle manager).

**Every request gets an answer** (issue 22). :func:`check_request` decides whether
a ``change_state`` request names a transition possible from the current state;
when it does not (an unknown id such as 99 or 255, configure while active) the
request is answered ``success = False`` with the reason logged and counted, instead
of rclpy's exception that leaves the caller without an answer.

Times are steady-clock seconds.
"""
from __future__ import annotations

from collections import deque

#: Where an accepted transition (by label) leads.
TARGET = {'configure': 'inactive', 'activate': 'active', 'deactivate': 'inactive',
          'cleanup': 'unconfigured', 'shutdown': 'finalized'}
_RANK = {'unconfigured': 0, 'inactive': 1, 'active': 2}


def check_request(state: str, transition_id: int, label: str,
                  available: list[tuple[int, str]]) -> tuple[str, str]:
    """Decide a ``lifecycle_msgs/srv/ChangeState`` request.

    Parameters
    ----------
    state : str
        Current primary state label.
    transition_id, label : int, str
        The request's transition (the label wins when given, as in rclpy).
    available : list of (int, str)
        Transitions possible from ``state``: (id, label).

    Returns
    -------
    (label, reason)
        ``(label, '')`` when accepted, ``('', reason)`` when refused.
    """
    possible = ', '.join(f'{lab} [{tid}]' for tid, lab in available) or 'none'
    for tid, lab in available:
        if (label and label == lab) or (not label and transition_id == tid):
            return lab, ''
    asked = repr(label) if label else str(transition_id)
    return '', f'transition {asked} is not possible from state {state} (possible: {possible})'


class SelfActivation:
    """The goal state, the back-off of configure attempts and their record.

    Parameters
    ----------
    enabled : bool
        Walk toward the goal by itself (``autostart``).
    retry_min, retry_max : float
        First and longest wait after a failed attempt [s] (doubling).
    keep : int
        Attempts kept in :attr:`history` (shown in diagnostics).
    origin : float
        Steady time the history's times count from [s] (the node's start).
    """

    def __init__(self, enabled: bool, retry_min: float = 2.0, retry_max: float = 10.0,
                 keep: int = 8, origin: float = 0.0) -> None:
        self.enabled = enabled
        self.origin = origin
        self.goal = 'active'
        self.retry_min = retry_min
        self.retry_max = max(retry_min, retry_max)
        self.wait = retry_min
        self.next_attempt = 0.0
        self.attempts = 0
        self.failures = 0
        self.history: deque[str] = deque(maxlen=keep)
        self.refused = 0
        self.last_refusal = ''

    def set_retry(self, retry_min: float, retry_max: float) -> None:
        """New back-off bounds [s] (a parameter change); applies from the next failure."""
        self.retry_min, self.retry_max = retry_min, max(retry_min, retry_max)
        self.wait = min(max(self.wait, retry_min), self.retry_max)

    def external(self, label: str) -> None:
        """An accepted request from outside: its target becomes the goal (configure
        keeps an ``active`` goal)."""
        if not (label == 'configure' and self.goal == 'active'):
            self.goal = TARGET[label]

    def next_transition(self, state: str, now: float) -> str | None:
        """The transition to try now from primary ``state``, or None (at the goal,
        waiting for the back-off, disabled, or the goal is below ``state``: going
        down is only ever asked from outside)."""
        if not self.enabled or state not in _RANK or self.goal not in _RANK or now < self.next_attempt:
            return None
        if _RANK[state] >= _RANK[self.goal]:
            return None
        return 'configure' if state == 'unconfigured' else 'activate'

    def record(self, now: float, label: str, ok: bool, reason: str = '', source: str = 'self') -> None:
        """Book one attempted transition (``source`` 'self' or 'external'); a failure
        schedules the next attempt after the current wait and doubles it."""
        self.attempts += 1
        if ok:
            self.wait = self.retry_min
            self.next_attempt = now
        else:
            self.failures += 1
            self.next_attempt = now + self.wait
            self.wait = min(2.0 * self.wait, self.retry_max)
        self.history.append(f'#{self.attempts} {source} {label} at +{now - self.origin:.1f} s: '
                            f'{"ok" if ok else "failed: " + (reason or "no reason given")}')

    def refuse(self, reason: str) -> None:
        """Book a refused lifecycle request."""
        self.refused += 1
        self.last_refusal = reason

    def pending(self, state: str, now: float) -> str:
        """One line for diagnostics while below the goal ('' at the goal)."""
        if not self.enabled or state not in _RANK or self.goal not in _RANK \
                or _RANK[state] >= _RANK[self.goal]:
            return ''
        return (f'self-activation toward {self.goal}: {self.failures} failed attempt(s), '
                f'next in {max(0.0, self.next_attempt - now):.1f} s')

    def values(self, now: float) -> dict[str, str]:
        """Diagnostics key/values (steady times as 'at T s')."""
        return {'autostart': str(self.enabled).lower(), 'lifecycle_goal': self.goal,
                'transition_attempts': str(self.attempts), 'failed_attempts': str(self.failures),
                'next_attempt_in': f'{max(0.0, self.next_attempt - now):.1f}',
                'attempts': ' | '.join(self.history),
                'lifecycle_requests_refused': str(self.refused), 'last_refused_request': self.last_refusal}
