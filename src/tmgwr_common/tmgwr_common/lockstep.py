"""The agent nodes' side of the lockstep ring (DESIGN.md sections 2 and 6).

The simulator publishes one observation per step and resends it when no action came back
in time (a node started late, or a message was lost). Every node of the ring therefore
computes each step once and answers a step it has already handled with the output it
cached, so a resend never changes what is learnt.

**A step is identified by (run_id, step_id), not by the step id alone.** ``maze_sim``
chooses a ``run_id`` when it starts (nonzero: the wall clock in nanoseconds, so a
simulator started later has a larger id) and numbers its observations 0, 1, 2, ... within
that run; every node copies both fields of its input into its output, so every per-step
message (Observation, Features, SensorimotorState, MotivationField, Action) carries them.
``run_id`` 0 means *no run*: it is what a hand-made message (``ros2 topic pub`` with the
defaults) carries. A ``/maze_sim/reset`` starts an episode, not a run: step ids go on.

Each node follows one run. For every message it receives, in this order:

1. ``run_id`` 0: ignored, with a warning (at most one per ``WARN_PERIOD`` s per kind).
2. The node follows no run yet (it just started, or restored a map saved without a run
   id): it follows this run from this step and computes it (``following run R from step
   N``).
3. A newer run (larger id): the simulator restarted. The node forgets its newest step and
   cached output, follows the new run and computes the step (``maze_sim restarted (run X
   -> Y): following the new run from step N``). What the node has *learnt* stays: the map
   learner keeps its map (learning continues), the estimator its potentials, the selector
   its epsilon. A run starts with an ``episode_start`` observation, which cuts the
   previous-winner chain in the map and the selector exactly as any episode start does.
4. An older run: dropped (logged once, then at most every ``WARN_PERIOD`` s with a count):
   messages still in flight from a simulator that was replaced, or a second simulator on
   the domain (the newer one wins). Except: when the same (run, step) arrives again with
   nothing accepted in between, its simulator is resending it and nothing else drives the
   ring, so the node follows that run (rule 3's reset; this covers a clock set back
   between two starts, or a stray carrying a larger run id).
5. The run it follows: a new step (larger id) is computed; the newest step again (a
   resend) is answered with the cached output (or ``answer_again()``); an older step
   means the node's newest step was not the simulator's: a stray message carrying this
   run's id and a large step id. The simulator publishes one step at a time over
   reliable, in-order QoS, so a sound ring never delivers an older step of the followed
   run; the node resynchronises to it with a warning and computes it.

So no message can freeze a node for ever: a stray (run 0) is ignored; a restarted
simulator is followed at its first observation; a map saved in another run brings its
(run, step) along and the new run is newer; anything else that put the node ahead of the
simulator is undone by the simulator's next resend (``resend_period``, 1 s by default).
"""

from __future__ import annotations

import time
from typing import Any, Callable

from tmgwr_common.node import CallbackTimer

WARN_PERIOD = 10.0      # seconds between two warnings of the same kind


class Lockstep:
    """Per-step identity, dedupe and resend for one node: its output publisher, callback
    timer and logger (an rclpy logger, or anything with ``info`` and ``warning``)."""

    def __init__(self, publisher, timer: CallbackTimer | None = None, last_step: int = -1,
                 run_id: int = 0, logger=None, what: str = "message"):
        self.publisher = publisher
        self.timer = timer or CallbackTimer()
        self.logger = logger
        self.what = what                    # the input's name in log lines
        self.run_id = int(run_id)           # the run followed (0: none yet)
        self.last_step = last_step if run_id else -1    # the newest step id computed
        self.last_out: Any = None           # its output
        self._dropped: tuple[int, int] | None = None    # last dropped (run, step)
        self._warned: dict[str, tuple[float, int]] = {}  # kind -> (time, count since)

    # ------------------------------------------------------------------ the rules
    def on_step(self, run_id: int, step_id: int, compute: Callable[[], Any],
                answer_again: Callable[[], Any] | None = None) -> None:
        """Apply the rules of the module docstring to one input message: ``compute()`` the
        output of a step to follow and publish it; answer the newest step again with the
        cached output (or ``answer_again()`` when nothing is cached, e.g. a learner
        restored from a saved map); drop the rest."""
        run_id, step_id = int(run_id), int(step_id)
        if run_id == 0:
            self._warn("norun", f"ignored a {self.what} without a run id (run_id 0, step "
                                f"{step_id}): a stray publisher? maze_sim stamps every "
                                "step with its run")
            return
        if run_id != self.run_id:
            if self.run_id == 0:
                self._info(f"following run {run_id} from step {step_id}")
            elif run_id > self.run_id:
                self._info(f"maze_sim restarted (run {self.run_id} -> {run_id}): following "
                           f"the new run from step {step_id}")
            elif self._dropped == (run_id, step_id):
                self._warn("resync", f"run {run_id} resends step {step_id} and run "
                                     f"{self.run_id} is silent: following run {run_id} from "
                                     f"step {step_id}", always=True)
            else:
                self._dropped = (run_id, step_id)
                self._warn(f"old{run_id}", f"dropped a {self.what} of an older run "
                                           f"({run_id}, step {step_id}): following run "
                                           f"{self.run_id}")
                return
            self.run_id, self.last_step, self.last_out = run_id, -1, None
        elif step_id <= self.last_step:
            if step_id == self.last_step:
                self._dropped = None
                out = self.last_out if self.last_out is not None else (
                    answer_again() if answer_again is not None else None)
                if out is not None:
                    self.publisher.publish(out)
                return
            self._warn("behind", f"step {step_id} of run {run_id} after step "
                                 f"{self.last_step}: that step was not the simulator's (a "
                                 f"stray message?); following step {step_id}", always=True)
        self._dropped = None
        with self.timer:
            out = compute()
            self.last_step, self.last_out = step_id, out
            self.timer.publish(self.publisher, out)

    def forget(self, last_step: int = -1, run_id: int | None = None) -> None:
        """Start over from ``last_step`` of ``run_id`` (default: the run followed), with no
        cached output (a learner that loaded another map answers from the new one)."""
        if run_id is not None:
            self.run_id = int(run_id)
        self.last_step, self.last_out = (last_step if self.run_id else -1), None

    # ------------------------------------------------------------------ logging
    def _info(self, text: str) -> None:
        if self.logger is not None:
            self.logger.info(text)

    def _warn(self, kind: str, text: str, always: bool = False) -> None:
        """A warning, at most one per ``WARN_PERIOD`` s of each kind (with the count of
        those left out) unless ``always``."""
        now = time.monotonic()
        last, count = self._warned.get(kind, (-WARN_PERIOD, 0))
        if not always and now - last < WARN_PERIOD:
            self._warned[kind] = (last, count + 1)
            return
        self._warned[kind] = (now, 0)
        if self.logger is not None:
            more = f" ({count} more like it in the last {now - last:.0f} s)" if count else ""
            self.logger.warning(text + more)
