"""The agent nodes' side of the lockstep ring (README, Running the ROS 2 node graph).

The simulator publishes one observation per step and resends it when no action came back
in time (a node started late, or a message was lost). Every node of the ring therefore
computes each step id once and answers a step id it has already handled with the output it
cached, so a resend never changes what is learnt; an older step id is stale and dropped.
"""

from __future__ import annotations

from typing import Any, Callable

from tmgwr_common.node import CallbackTimer


class Lockstep:
    """Per-step dedupe and resend for one node: its output publisher and callback timer."""

    def __init__(self, publisher, timer: CallbackTimer | None = None, last_step: int = -1):
        self.publisher = publisher
        self.timer = timer or CallbackTimer()
        self.last_step = last_step          # the newest step id computed
        self.last_out: Any = None           # its output

    def on_step(self, step_id: int, compute: Callable[[], Any],
                answer_again: Callable[[], Any] | None = None) -> None:
        """``compute()`` the output of a new step and publish it; answer the newest step
        again with the cached output (or ``answer_again()`` when nothing is cached, e.g.
        a learner restored from a saved map); drop older steps."""
        if step_id <= self.last_step:
            if step_id == self.last_step:
                out = self.last_out if self.last_out is not None else (
                    answer_again() if answer_again is not None else None)
                if out is not None:
                    self.publisher.publish(out)
            return
        with self.timer:
            out = compute()
            self.last_step, self.last_out = step_id, out
            self.timer.publish(self.publisher, out)

    def forget(self, last_step: int = -1) -> None:
        """Start over from ``last_step`` (a map loaded with the step it learnt last)."""
        self.last_step, self.last_out = last_step, None
