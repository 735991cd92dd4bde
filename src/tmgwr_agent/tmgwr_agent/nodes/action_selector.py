"""``ros2 run tmgwr_agent action_selector``: Eq. 6 plus the exploration of section 5.1.

Per step (lockstep): ``MotivationField`` in (the winner's outgoing links and this step's
potentials V of their targets: all Eq. 6 reads), ``Action`` out. The core
:class:`~tmgwr_agent.core.action_selector.ActionSelector` is called as
:class:`~tmgwr_agent.core.agent.TMGWRAgent` calls it in-process: ``record`` what the last
action did (walk direction, tried primitives, the Eq. 7 decay at the goal), then ``select``,
which draws from ``numpy.random.default_rng(seed)``, the generator the in-process agent is
given, so a seed fixes the trajectory over the graph as in-process. A terminal observation
is answered with ``Action.NONE`` (no draw: the episode is over). After every answer the
epsilon draw of the next choice is made ahead (:meth:`EpsilonGreedy.draw_ahead`, as the
in-process agent makes it before it plans) and ``Action.walk_next`` says whether it chose
the random walk: the motivation estimator then skips Eq. 4-5 for that step.
"""

from __future__ import annotations

import numpy as np
from rclpy.node import Node

from tmgwr_agent.core.action_selector import ActionSelector, SelectorConfig
from tmgwr_agent.core.sensorimotor_map import Links
from tmgwr_agent.nodes.step_messages import outcome_of
from tmgwr_agent.world_senses import node_senses
from tmgwr_common import topics
from tmgwr_common.cdr import codec
from tmgwr_common.checkpoint import (
    CHECKPOINT_SPECS,
    Checkpoint,
    Checkpointer,
    CheckpointError,
    joined_state,
    split_state,
)
from tmgwr_common.lockstep import Lockstep
from tmgwr_common.node import (
    NODE_OPTIONS,
    STEP_QOS,
    declare_parameters,
    np_f64,
    np_i64,
    run,
    subscribe_decoded,
)
from tmgwr_common.params import WORLD_PARAM, Param
from tmgwr_interfaces.msg import Action, MotivationField

ACTION = codec(Action)                # the per-step messages go serialized (tmgwr_common.cdr)

NODE_SPECS = (
    WORLD_PARAM,
    Param("seed", 0, "seed of the selector's generator (exploration and tie-breaks)",
          low=0, high=2 ** 63 - 1, integer=True),
    Param("explore", True, "epsilon-greedy exploration (false: greedy Eq. 6 only)"),
    *CHECKPOINT_SPECS,
)


class ActionSelectorNode(Node):
    def __init__(self):
        super().__init__("action_selector", **NODE_OPTIONS)
        config, self.p = declare_parameters(self, SelectorConfig, NODE_SPECS)
        self.core = ActionSelector(np.random.default_rng(self.p["seed"]), config,
                                  primitives=node_senses(self.p["world"]).primitives)
        self.prev_winner = -1               # the winner this selector last acted from
        pub = self.create_publisher(Action, topics.ACTION, STEP_QOS)
        self.lockstep = Lockstep(pub, logger=self.get_logger(), what="motivation field")
        subscribe_decoded(self, MotivationField, topics.MOTIVATION, self.on_motivation,
                          STEP_QOS)
        # epsilon, the walk and the generator survive any stop (tmgwr_common.checkpoint)
        self.checkpoints = Checkpointer("action_selector", self.p, self.get_logger(),
                                        namespace=self.get_namespace())
        self.checkpoints.resume(check=self.restore)
        self.load_kernels()
        self.get_logger().info(f"action_selector ready: seed {self.p['seed']}, "
                               f"epsilon {self.core.policy.epsilon:.3f}, "
                               f"{config.as_dict()}")

    def load_kernels(self) -> None:
        """Rank the links of a made-up node once (Eq. 6) with a spare selector, before the
        ready line: numba loads a kernel from its on-disk cache at the kernel's first call
        in a process, which otherwise fell on the first step after a (re)start, after the
        ready line, and delayed the ring's rejoin by as much."""
        spare = ActionSelector(np.random.default_rng(0), self.core.config,
                               primitives=self.core.primitives)
        P = spare.primitives
        links = Links(targets=np.arange(len(P), dtype=np.int64), E=np.ones(len(P)),
                      actions=P.copy())
        spare.greedy(links, np.ones(len(P) + 2))

    def on_motivation(self, f):
        """A MotivationField (its fields, read by tmgwr_common.cdr)."""
        self.lockstep.on_step(f.run_id, f.step_id, lambda: self.choose(f))
        self.checkpoints.step(self.lockstep.last_step, self.lockstep.run_id, self.checkpoint_state)

    def choose(self, f) -> bytes:
        """The Action answering field ``f``, serialized."""
        self.core.record(self.prev_winner, outcome_of(f))   # what TMGWRAgent.step does here
        a = ACTION.new()
        a.header = f.header
        a.run_id = f.run_id
        a.step_id = f.step_id
        a.epsilon = float(self.core.policy.epsilon)
        if f.terminal:
            a.action = Action.NONE          # no draw: the episode is over
        else:                               # what TMGWRAgent.act does
            # The winner's neighbourhood in local ids: slot k's target is k (looked up as
            # V[k], the potentials of the targets in slot order: the same E[i, k] V(k)
            # products as on the whole field), the winner itself is K (its options, virtual
            # links to itself, Eq. 5'), an empty slot -1 (V[-1] = 0).
            links, node, goal = None, -1, -1
            targets = np_i64(f.winner_link_targets)
            K = len(targets)
            V = np.append(np_f64(f.winner_link_potentials), [0.0, 0.0])
            if f.winner >= 0:
                self_slots = targets == f.winner
                if self_slots.any():
                    V[K] = V[np.flatnonzero(self_slots)[0]]
                local = np.where(targets >= 0, np.arange(K), -1)
                links = Links(targets=np.where(self_slots, K, local),
                              E=np_f64(f.winner_link_reliability),
                              actions=np_f64(f.winner_link_actions).reshape(
                                  K, f.action_dim or 1))
                node, goal = K, (K if f.goal_node == f.winner else -1)
            action, a.explored = self.core.select(lambda _node: links, node, V, goal,
                                                  self.p["explore"])
            a.action = int(action)
            a.motor = self.core.primitives[action]
        self.prev_winner = int(f.winner)
        a.walk_next = bool(self.p["explore"] and self.core.policy.draw_ahead())
        return ACTION.encode(a)

    def checkpoint_state(self):
        state, arrays = split_state(self.core.state_dict())
        return {**state, "rng": self.core.rng.bit_generator.state,
                "prev_winner": self.prev_winner}, arrays

    def restore(self, ck: Checkpoint) -> None:
        """Epsilon, the walk, the search flag and the generator from checkpoint ``ck``."""
        d = joined_state(ck)
        try:
            if not 0.0 <= float(d["epsilon"]) <= 1.0:
                raise ValueError(f"epsilon {d['epsilon']!r} outside [0, 1]")
            rng = self.core.rng.bit_generator
            before = rng.state
            rng.state = d.pop("rng")
            try:
                self.core.load_state_dict(d)
            except BaseException:
                rng.state = before
                raise
            self.prev_winner = int(d.get("prev_winner", -1))
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise CheckpointError(f"{ck.path}: {exc!r}: refused") from None
        self.get_logger().info(f"resumed epsilon {self.core.policy.epsilon:.3f}")

    def on_shutdown(self):
        print(f"action_selector: {self.lockstep.timer.summary()}", flush=True)
        self.checkpoints.stop(self.lockstep.last_step, self.lockstep.run_id,
                              self.checkpoint_state)


def main(args=None):
    raise SystemExit(run(ActionSelectorNode, "action_selector", args))


if __name__ == "__main__":
    main()
