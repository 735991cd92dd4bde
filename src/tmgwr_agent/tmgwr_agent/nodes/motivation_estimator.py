"""``ros2 run tmgwr_agent motivation_estimator``: Eq. 4-5 on this step's map; hosts /set_goal.

Per step (lockstep): ``SensorimotorState`` in (it carries this step's map as flat arrays),
:meth:`MotivationEstimator.update` on that map, ``MotivationField`` out (the potentials V
of every node plus the winner's outgoing links, what Eq. 6 ranks). The goal is the goal
*sensation* that came with the observation (through the preprocessor and the map learner):
when it changes the potentials restart from 0 (Algorithm 1 line 5), exactly as
:meth:`TMGWRAgent.set_goal` does in-process.

``/set_goal`` (``tmgwr_interfaces/SetGoal``, x = column, y = row) changes the goal of the
whole system in one call: a non-finite goal is refused here; otherwise the request goes to
the simulator (``/maze_sim/set_goal``), which refuses a cell outside the maze or in a wall
and otherwise moves its terminal cell from its next observation on, whose goal sensation
then reaches this node. The node stays up whatever the request.
"""

from __future__ import annotations

import math

import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

from tmgwr_interfaces.msg import MotivationField, SensorimotorState
from tmgwr_interfaces.srv import SetGoal

from maze_sim.maze import ACTION_VECTORS

from .. import motivation, topics
from ..motivation import MotivationEstimator
from ..params import Param
from ..tmgwr_map import SensorimotorMap
from .common import (STEP_QOS, CallbackTimer, config_defaults, declare_specs, f64, i32,
                     np_bool, np_f64, np_i64, run)

NODE_SPECS = (
    Param("set_goal_timeout", 5.0, "seconds /set_goal waits for the simulator's answer",
          low=0.01, high=600.0),
)


def map_view(m: SensorimotorMap | None, s: SensorimotorState) -> SensorimotorMap:
    """A SensorimotorMap holding the flat arrays of a SensorimotorState (no link actions,
    contexts or ages: Eq. 4-5 needs weights, alive mask, link targets and E only)."""
    n, K, dim = s.n_slots, s.degree, s.dim
    if m is None or m.dim != dim:
        m = SensorimotorMap(dim=dim, action_dim=s.action_dim or ACTION_VECTORS.shape[1])
    m.n = n
    m.alive = np_bool(s.alive)
    m.w = np_f64(s.weights).reshape(n, dim)
    m.out = np_i64(s.link_targets).reshape(n, K)
    m.E = np_f64(s.link_reliability).reshape(n, K)
    m.version = s.map_version
    m.winner = s.winner
    return m


class MotivationEstimatorNode(Node):
    def __init__(self):
        super().__init__("motivation_estimator")
        p = declare_specs(self, motivation.SPECS, config_defaults(), section="tmgwr")
        self.p = declare_specs(self, NODE_SPECS)
        self.core = MotivationEstimator(**p)
        self.view: SensorimotorMap | None = None
        self.goal_x: np.ndarray | None = None
        self.last_step = -1
        self.last_out: MotivationField | None = None
        self._ids = np.zeros(0, dtype=np.int32)

        self.pub = self.create_publisher(MotivationField, topics.MOTIVATION, STEP_QOS)
        self.create_subscription(SensorimotorState, topics.SENSORIMOTOR_STATE, self.on_state,
                                 STEP_QOS)
        # /set_goal awaits the simulator's answer: service and client in groups of their
        # own so the per-step callbacks and the client's response run meanwhile.
        self.sim_goal = self.create_client(SetGoal, topics.SIM_SET_GOAL,
                                           callback_group=MutuallyExclusiveCallbackGroup())
        self.create_service(SetGoal, topics.SET_GOAL, self.on_set_goal,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.timer = CallbackTimer()
        self.get_logger().info(f"motivation_estimator ready: {p}")

    # ------------------------------------------------------------------ per step
    def on_state(self, s: SensorimotorState):
        if s.step_id <= self.last_step:      # a resent step: answer again, compute nothing
            if s.step_id == self.last_step and self.last_out is not None:
                self.pub.publish(self.last_out)
            return
        with self.timer:
            goal_x = np_f64(s.goal_features)
            if self.goal_x is None or not np.array_equal(goal_x, self.goal_x):
                self.goal_x = goal_x        # a new goal: V restarts from 0 (Algorithm 1)
                self.core.set_goal(goal_x)
                self.get_logger().info(f"step {s.step_id}: goal sensation {goal_x.tolist()}")
            self.view = map_view(self.view, s)
            V = self.core.update(self.view)
            out = MotivationField()
            out.header = s.header
            out.step_id = s.step_id
            out.map_version = s.map_version
            out.goal_node = int(self.core.goal_node)
            out.sweeps = int(self.core.sweeps)
            if len(self._ids) != len(V):
                self._ids = np.arange(len(V), dtype=np.int32)
            out.node_ids = i32(self._ids)
            out.potentials = f64(V)
            out.winner = s.winner
            if s.winner >= 0:
                out.winner_link_targets = i32(self.view.out[s.winner])
                out.winner_link_reliability = f64(self.view.E[s.winner])
            out.action_dim = s.action_dim
            out.winner_link_actions = s.winner_link_actions
            out.episode_start = s.episode_start
            out.action = s.action
            out.bumped = s.bumped
            out.goal_reached = s.goal_reached
            out.terminal = s.terminal
            self.last_step, self.last_out = s.step_id, out
            self.pub.publish(out)

    # ------------------------------------------------------------------ runtime goal
    async def on_set_goal(self, req, resp):
        g = req.goal
        if not all(math.isfinite(v) for v in (g.x, g.y, g.z)):
            resp.accepted = False
            resp.message = f"goal (x={g.x}, y={g.y}, z={g.z}) refused: not finite"
            self.get_logger().warn(resp.message)
            return resp
        if not self.sim_goal.service_is_ready():
            resp.accepted = False
            resp.message = (f"goal (x={g.x}, y={g.y}) refused: the simulator's "
                            f"{topics.SIM_SET_GOAL} is not available")
            self.get_logger().warn(resp.message)
            return resp
        future = self.sim_goal.call_async(SetGoal.Request(goal=g))
        timer = self.create_timer(self.p["set_goal_timeout"], lambda: future.cancel())
        try:
            answer = await future
        finally:
            timer.cancel()
            self.destroy_timer(timer)
        if answer is None or future.cancelled():
            resp.accepted = False
            resp.message = (f"goal (x={g.x}, y={g.y}) refused: no answer from "
                            f"{topics.SIM_SET_GOAL} within {self.p['set_goal_timeout']} s")
        else:
            resp.accepted, resp.message = answer.accepted, answer.message
        if resp.accepted:
            self.get_logger().info(resp.message)
        else:
            self.get_logger().warn(resp.message)
        return resp

    def on_shutdown(self):
        print(f"motivation_estimator: {self.timer.summary()}", flush=True)


def main(args=None):
    raise SystemExit(run(MotivationEstimatorNode, "motivation_estimator", args))


if __name__ == "__main__":
    main()
