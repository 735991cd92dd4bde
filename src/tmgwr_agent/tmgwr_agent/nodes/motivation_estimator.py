"""``ros2 run tmgwr_agent motivation_estimator``: Eq. 4-5 on this step's map; hosts /set_goal.

Per step (lockstep): ``SensorimotorState`` in (it carries this step's map as flat arrays),
:meth:`MotivationEstimator.update` on that map, ``MotivationField`` out (the potentials V
of every node plus the winner's outgoing links, what Eq. 6 ranks). The goal is the goal
*sensation* that came with the observation (through the preprocessor and the map learner):
when it changes the potentials restart from 0 (Algorithm 1 line 5), exactly as
:meth:`TMGWRAgent.set_goal` does in-process.

``/set_goal`` (``tmgwr_interfaces/SetGoal``, x = column, y = row) changes the goal of the
whole system in one call: a goal that is not finite, outside the maze or in a wall (per the
simulator's latched grid) is refused with a message; otherwise the cell goes to the
simulator (``/maze_sim/set_goal``), which moves its terminal cell from its next observation
on, and that observation's goal sensation reaches this node. The node stays up whatever the
request.
"""

from __future__ import annotations

import math

import numpy as np
from nav_msgs.msg import OccupancyGrid
from rclpy.node import Node

from tmgwr_agent.core.motivation import MotivationConfig, MotivationEstimator
from tmgwr_agent.core.sensorimotor_map import MapSnapshot
from tmgwr_common import topics
from tmgwr_common.lockstep import Lockstep
from tmgwr_common.node import (
    LATCHED_QOS,
    NODE_OPTIONS,
    STEP_QOS,
    declare_parameters,
    f64,
    i32,
    np_bool,
    np_f64,
    np_i64,
    run,
)
from tmgwr_interfaces.msg import MotivationField, SensorimotorState
from tmgwr_interfaces.srv import SetGoal


def snapshot_of(s: SensorimotorState) -> MapSnapshot:
    """The map of this step from the flat arrays of a SensorimotorState (no link actions,
    contexts or ages: Eq. 4-5 need weights, alive mask, link targets and E only)."""
    n, K, dim = s.n_slots, s.degree, s.dim
    return MapSnapshot(w=np_f64(s.weights).reshape(n, dim), alive=np_bool(s.alive),
                       out=np_i64(s.link_targets).reshape(n, K),
                       E=np_f64(s.link_reliability).reshape(n, K),
                       terminal=np_bool(s.terminal_nodes), version=s.map_version)


class MotivationEstimatorNode(Node):
    def __init__(self):
        super().__init__("motivation_estimator", **NODE_OPTIONS)
        config = declare_parameters(self, MotivationConfig)
        self.core = MotivationEstimator(config)
        self._ids = np.zeros(0, dtype=np.int32)
        pub = self.create_publisher(MotivationField, topics.MOTIVATION, STEP_QOS)
        self.lockstep = Lockstep(pub, logger=self.get_logger(), what="state")
        self.create_subscription(SensorimotorState, topics.SENSORIMOTOR_STATE, self.on_state,
                                 STEP_QOS)
        # /set_goal checks the cell against the simulator's grid (latched: it arrives
        # whenever this node starts) and hands it to the simulator's own service.
        self.walls: np.ndarray | None = None
        self.create_subscription(OccupancyGrid, topics.GRID, self.on_grid, LATCHED_QOS)
        self.sim_goal = self.create_client(SetGoal, topics.SIM_SET_GOAL)
        self.create_service(SetGoal, topics.SET_GOAL, self.on_set_goal)
        self.get_logger().info(f"motivation_estimator ready: {config.as_dict()}")

    # ------------------------------------------------------------------ per step
    def on_state(self, s: SensorimotorState):
        self.lockstep.on_step(s.run_id, s.step_id, lambda: self.motivate(s))

    def motivate(self, s: SensorimotorState) -> MotivationField:
        goal_x = np_f64(s.goal_features)
        if self.core.follow_goal(goal_x):       # a new goal: V restarts from 0 (Algorithm 1)
            self.get_logger().info(f"step {s.step_id}: goal sensation {goal_x.tolist()}")
        m = snapshot_of(s)
        V = self.core.update(m)
        out = MotivationField()
        out.header = s.header
        out.run_id = s.run_id
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
            out.winner_link_targets = i32(m.out[s.winner])
            out.winner_link_reliability = f64(m.E[s.winner])
        out.action_dim = s.action_dim
        out.winner_link_actions = s.winner_link_actions
        out.episode_start = s.episode_start
        out.action = s.action
        out.bumped = s.bumped
        out.goal_reached = s.goal_reached
        out.terminal = s.terminal
        return out

    # ------------------------------------------------------------------ runtime goal
    def on_grid(self, grid: OccupancyGrid):
        self.walls = (np.asarray(grid.data, dtype=np.int16) >= 50).reshape(
            grid.info.height, grid.info.width)

    def on_set_goal(self, req, resp):
        """Validate against the simulator's latched grid, then hand the cell to maze_sim.

        Answers at once (no nested wait on another service, so any executor can run it);
        maze_sim checks the cell again when it applies it at its next observation.
        """
        g = req.goal
        resp.accepted = False
        if not all(math.isfinite(v) for v in (g.x, g.y, g.z)):
            resp.message = f"goal (x={g.x}, y={g.y}, z={g.z}) refused: not finite"
        elif self.walls is None or not self.sim_goal.service_is_ready():
            resp.message = (f"goal (x={g.x}, y={g.y}) refused: the simulator is not "
                            f"available ({topics.GRID} / {topics.SIM_SET_GOAL})")
        else:
            col, row = int(math.floor(g.x + 0.5)), int(math.floor(g.y + 0.5))
            rows, cols = self.walls.shape
            if not (0 <= row < rows and 0 <= col < cols):
                resp.message = (f"goal (x={g.x}, y={g.y}) refused: cell (row {row}, col "
                                f"{col}) is outside the {rows}x{cols} maze")
            elif self.walls[row, col]:
                resp.message = (f"goal (x={g.x}, y={g.y}) refused: cell (row {row}, col "
                                f"{col}) is a wall")
            else:
                future = self.sim_goal.call_async(SetGoal.Request(goal=g))
                future.add_done_callback(self.on_sim_goal)
                resp.accepted = True
                resp.message = (f"goal set to row {row}, col {col} (x={col}, y={row}); the "
                                "simulator applies it at its next observation")
        if resp.accepted:
            self.get_logger().info(resp.message)
        else:
            self.get_logger().warn(resp.message)
        return resp

    def on_sim_goal(self, future):
        answer = future.result()
        if answer is None or not answer.accepted:
            self.get_logger().error("maze_sim dropped the goal: "
                                    f"{answer.message if answer else 'no answer'}")

    def on_shutdown(self):
        print(f"motivation_estimator: {self.lockstep.timer.summary()}", flush=True)


def main(args=None):
    raise SystemExit(run(MotivationEstimatorNode, "motivation_estimator", args))


if __name__ == "__main__":
    main()
