"""A lifecycle node that answers every request and can reach its goal state by itself.

:class:`ManagedNode` is ``rclpy.lifecycle.LifecycleNode`` (Node + LifecycleNodeMixin,
built the same way) with the policy of :mod:`.activation` wired in:

- ``<node>/change_state`` always answers: a transition that is not possible from
  the current state (an unknown id, configure while active) gets ``success = False``
  with the reason logged and counted (rclpy would raise inside the service callback
  and leave the caller waiting). An accepted request sets the goal state;
- :meth:`start_self_activation` adds a steady timer that walks the node to its goal
  (configure retried with back-off, then activate): 10 Hz while below the goal,
  1 Hz once there (to climb back if the node ever falls);
- the lifecycle services and that timer share one mutually exclusive callback group:
  transitions never overlap, and they never block the node's other callbacks.

Subclasses implement ``on_configure`` etc. as usual and set :attr:`last_error` to
the reason of a failed transition (it is recorded with the attempt).
"""
from __future__ import annotations

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.lifecycle import LifecycleNodeMixin, TransitionCallbackReturn
from rclpy.node import Node
from sslfr_common.node import LeanEvents, steady_now
from sslfr_common.timeconv import to_ns

from sslfr_drivers.axis.activation import SelfActivation, check_request


class ManagedNode(LeanEvents, LifecycleNodeMixin, Node):
    """Lifecycle node with answered requests and optional self-activation."""

    def __init__(self, node_name: str, **kwargs):
        Node.__init__(self, node_name, **kwargs)
        self.lifecycle_group = MutuallyExclusiveCallbackGroup()
        LifecycleNodeMixin.__init__(self, callback_group=self.lifecycle_group)
        # the one documented hook rclpy leaves: the service's callback attribute
        self._service_change_state.callback = self._on_change_state
        self.steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.activation = SelfActivation(False, origin=steady_now(self.steady))
        self.last_error = ''

    def lifecycle_state(self) -> str:
        """Current state label (unconfigured, inactive, active, finalized, or a
        transition state such as configuring)."""
        return self._state_machine.current_state[1]

    def start_self_activation(self, retry_min: float, retry_max: float) -> None:
        """Walk to the goal (``active``) by itself, retrying after ``retry_min`` [s],
        doubling up to ``retry_max`` [s]."""
        self.activation = SelfActivation(True, retry_min, retry_max, origin=self.activation.origin)
        self._activation_timer = self.create_timer(0.1, self._self_activate, self.lifecycle_group, self.steady)

    def _on_change_state(self, req, resp):
        state = self.lifecycle_state()
        available = [(t[0], t[1]) for t in self._state_machine.available_transitions]
        label, why = check_request(state, req.transition.id, req.transition.label, available)
        if why:
            self.activation.refuse(why)
            self.get_logger().warning(f'lifecycle request refused: {why}')
            resp.success = False
            return resp
        self.activation.external(label)
        resp.success = self._transition(label, 'external')
        return resp

    def _self_activate(self) -> None:
        now = steady_now(self.steady)
        label = self.activation.next_transition(self.lifecycle_state(), now)
        if label is not None:
            self._transition(label, 'self')
        period = to_ns(0.1 if self.activation.pending(self.lifecycle_state(), now) else 1.0)
        if self._activation_timer.timer_period_ns != period:
            self._activation_timer.timer_period_ns = period

    def _transition(self, label: str, source: str) -> bool:
        trigger = {'configure': self.trigger_configure, 'activate': self.trigger_activate,
                   'deactivate': self.trigger_deactivate, 'cleanup': self.trigger_cleanup,
                   'shutdown': self.trigger_shutdown}[label]
        try:
            ok, why = trigger() == TransitionCallbackReturn.SUCCESS, self.last_error
        except RuntimeError as exc:      # rclpy's RCLError: the state machine refused it
            ok, why = False, str(exc)
        self.activation.record(steady_now(self.steady), label, ok, '' if ok else why, source)
        return ok
