"""``ros2 run tmgwr_agent action_selector``: Eq. 6 plus the exploration of section 5.1.

Per step (lockstep): ``MotivationField`` in (this step's potentials V and the winner's
outgoing links), ``Action`` out. The core :class:`~tmgwr_agent.core.action_selector.ActionSelector`
is called exactly as :class:`~tmgwr_agent.core.agent.TMGWRAgent` calls it in-process: first
the random walk learns what the last action did (``walk.observe``), the Eq. 7 schedule
decays when the goal was reached, and then ``select`` draws from the selector's generator
``numpy.random.default_rng(seed)``, the same generator the in-process agent is given, so
a seed fixes the trajectory over the graph as in-process. A terminal observation is
answered with ``Action.NONE`` (no draw: the episode is over).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from rclpy.node import Node

from tmgwr_interfaces.msg import Action, MotivationField

from maze_sim.maze import ACTION_VECTORS

from tmgwr_common import topics
from tmgwr_agent.core.action_selector import ActionSelector, SelectorConfig
from tmgwr_common.params import Param
from tmgwr_common.node import (
    STEP_QOS,
    CallbackTimer,
    NODE_OPTIONS,
    declare_parameters,
    f64,
    np_f64,
    np_i64,
    run,
)

NODE_SPECS = (
    Param("seed", 0, "seed of the selector's generator (exploration and tie-breaks)",
          low=0, high=2 ** 63 - 1, integer=True),
    Param("explore", True, "epsilon-greedy exploration (false: greedy Eq. 6 only)"),
)


class ActionSelectorNode(Node):
    def __init__(self):
        super().__init__("action_selector", **NODE_OPTIONS)
        config, self.p = declare_parameters(self, SelectorConfig, NODE_SPECS)
        self.core = ActionSelector(np.random.default_rng(self.p["seed"]), config)
        self.last_step = -1
        self.last_out: Action | None = None
        self.prev_winner = -1               # the winner this selector last acted from
        self.pub = self.create_publisher(Action, topics.ACTION, STEP_QOS)
        self.create_subscription(MotivationField, topics.MOTIVATION, self.on_motivation,
                                 STEP_QOS)
        self.timer = CallbackTimer()
        self.get_logger().info(f"action_selector ready: seed {self.p['seed']}, "
                               f"{config.as_dict()}")

    def on_motivation(self, f: MotivationField):
        if f.step_id <= self.last_step:      # a resent step: answer again, draw nothing
            if f.step_id == self.last_step and self.last_out is not None:
                self.pub.publish(self.last_out)
            return
        with self.timer:
            policy = self.core.policy
            if f.episode_start:             # TMGWRAgent.begin_episode
                self.core.begin_episode()
            else:                           # TMGWRAgent.observe / goal_attained
                self.core.observe(self.prev_winner, f.action)
                policy.walk.observe(f.action, f.bumped)
                if f.goal_reached:
                    policy.schedule.goal_attained()
            a = Action()
            a.header = f.header
            a.step_id = f.step_id
            a.epsilon = float(policy.epsilon)
            if f.terminal:
                a.action = Action.NONE
            else:
                # The winner's links as row 0 of a one-node map: the core's own select().
                K = len(f.winner_link_targets)
                links = SimpleNamespace(
                    out=np_i64(f.winner_link_targets).reshape(1, K),
                    E=np_f64(f.winner_link_reliability).reshape(1, K),
                    a=np_f64(f.winner_link_actions).reshape(1, K, f.action_dim or 1))
                V = np.append(np_f64(f.potentials), 0.0)    # V[n] = 0: empty link slots
                i = 0 if f.winner >= 0 else -1
                at_goal_node = f.winner >= 0 and f.winner == f.goal_node
                action, a.explored = self.core.select(links, i, V, self.p["explore"],
                                                      at_goal_node, node=int(f.winner))
                a.action = int(action)
                a.motor = f64(ACTION_VECTORS[action])
            self.prev_winner = int(f.winner)
            self.last_step, self.last_out = f.step_id, a
            self.timer.publish(self.pub, a)

    def on_shutdown(self):
        print(f"action_selector: {self.timer.summary()}", flush=True)


def main(args=None):
    raise SystemExit(run(ActionSelectorNode, "action_selector", args))


if __name__ == "__main__":
    main()
