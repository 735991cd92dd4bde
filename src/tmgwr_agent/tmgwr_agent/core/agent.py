"""The TMGWR-based agent (Fig. 1a): preprocessor -> sensorimotor map -> motivation
estimator -> action selector, one step at a time.

Each step: the sensation reached by the last action is preprocessed, presented to the
TMGWR map with the action vector that produced it (growth, adaptation, Eq. 1-2 on the
link between the previous and the current winner), the motivation potentials are
re-solved (Eq. 4-5, warm-started), and the action selector picks the next action (Eq. 6,
or the random walk with probability epsilon, Eq. 7). The agent sees only the sensed
coordinates, its touch sensor (``bumped``) and the goal's sensation: no reward, no cell
index, no transition model (Table 1).

The ROS nodes run exactly these four pieces in separate processes, in the same order, so
a seed gives the same trajectory in-process and over the graph.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from maze_sim.maze import ACTION_VECTORS, Cell, Maze
from maze_sim.world import StepInfo

from tmgwr_agent.core import exploration, motivation, preprocessor, sensorimotor_map as tmgwr_map
from tmgwr_agent.core.action_selector import ActionSelector
from tmgwr_agent.core.motivation import MotivationEstimator
from tmgwr_common.params import Param, config_params
from tmgwr_agent.core.preprocessor import SensoryPreprocessor
from tmgwr_agent.core.sensorimotor_map import SensorimotorMap

EXPLORATION_SPECS = exploration.SPECS + (
    Param("goal_search", True, "random walk for the rest of an episode once the agent "
          "stood on the goal node without reaching the goal (action_selector.py; "
          "false: the paper's Eq. 6 selector)"),
    Param("try_untried", True, "take each motor primitive once from every node before "
          "following Eq. 6 there (action_selector.py; false: the paper's Eq. 6 selector)"),
)

SPECS = preprocessor.SPECS + tmgwr_map.SPECS + motivation.SPECS + EXPLORATION_SPECS


def split_params(p: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """The flat parameter dict split per module (keys of each module's SPECS)."""
    return {name: {s.name: p[s.name] for s in specs} for name, specs in (
        ("preprocessor", preprocessor.SPECS), ("map", tmgwr_map.SPECS),
        ("motivation", motivation.SPECS), ("exploration", EXPLORATION_SPECS))}


def tmgwr_params(overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Defaults from config/tmgwr_agent.yaml (section ``tmgwr``) updated by overrides."""
    return config_params(SPECS, "tmgwr_agent.yaml", "tmgwr", overrides)


class TMGWRAgent:
    name = "tmgwr"

    def __init__(self, maze: Maze | None, rng: np.random.Generator,
                 params: Mapping[str, Any] | None = None):
        self.params = tmgwr_params(params)
        parts = split_params(self.params)
        self.preprocessor = SensoryPreprocessor(**parts["preprocessor"])
        self.map = SensorimotorMap(dim=2, action_dim=ACTION_VECTORS.shape[1], **parts["map"])
        self.motivation = MotivationEstimator(**parts["motivation"])
        self.selector = ActionSelector(rng, **parts["exploration"])
        self.winner = -1
        self.last_action = -1
        self.last_explored = False

    # -------------------------------------------------------------- Agent protocol
    @property
    def epsilon(self) -> float:
        return self.selector.policy.epsilon

    def set_goal(self, goal_cell: Cell | None, goal_obs: np.ndarray) -> None:
        self.motivation.set_goal(self.preprocessor.goal_features(goal_obs))
        self.motivation.update(self.map)

    def begin_episode(self, obs: np.ndarray, cell: Cell | None = None,
                      learn: bool = True) -> None:
        self.map.begin_episode()
        self.selector.begin_episode()
        x = self.preprocessor(obs, episode_start=True)
        self.winner = self.map.step(x, None, learn=learn)
        if learn:
            self.motivation.update(self.map)

    def act(self, explore: bool = True) -> int:
        at_goal_node = self.winner >= 0 and self.winner == self.motivation.goal_node
        a, self.last_explored = self.selector.select(self.map, self.winner,
                                                     self.motivation.V, explore, at_goal_node)
        self.last_action = a
        return a

    def observe(self, obs: np.ndarray, info: StepInfo, learn: bool = True) -> None:
        x = self.preprocessor(obs)
        if learn:
            self.selector.observe(self.winner, info.action)
        self.winner = self.map.step(x, ACTION_VECTORS[info.action], learn=learn)
        if learn and info.terminated and not info.reached_goal:
            self.map.mark_terminal(self.winner)     # ended here, short of the goal
        self.selector.policy.walk.observe(info.action, info.bumped)
        if learn:
            self.motivation.update(self.map)

    def goal_attained(self) -> None:
        self.selector.policy.schedule.goal_attained()
