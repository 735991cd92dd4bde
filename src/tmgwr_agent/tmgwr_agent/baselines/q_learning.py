"""The model-free baseline: tabular Q-learning (section 5.1, Eq. 8, Table 2).

The state ``s`` is the agent's cell (``info.cell``, or the cell given to
``begin_episode``); the four actions are those of ``maze.ACTIONS``. The reward of Eq. 8
depends on the state-action pair through where it led::

    r(s, a) = +88   if a in s leads to the goal
              -131  if a in s leads to a wall (the move bumped)
              -29   if a in s leads to an empty cell

and the one-step Q-learning update (the paper's beta is the learning rate, Table 2)::

    Q(s, a) <- Q(s, a) + beta * (r(s, a) + gamma * max_a' Q(s', a') - Q(s, a))

with gamma = 0.86 and beta = 0.39. A transition that ends the episode (the current goal,
or the previous goal in the goal-change scenario, which counts as an empty cell with
reward -29 but is terminal, section 5.2.1) bootstraps 0. A truncated episode is not a
terminal transition. Q starts at 0 everywhere.

Acting: the greedy action is ``argmax_a Q(s, a)`` with ties broken by the agent's
generator; a state from which no action has been tried yet gives no greedy opinion and the
random walk acts (as for the TMGWR agent on a node without links). Per step the work is
O(1): Q is a list of 4-float lists indexed by ``row * cols + col``.

Under ``--sensor`` (``sensed_states=True``) the state handed to the agent is not a cell but
the discretised sensation (:func:`tmgwr_agent.experiments.sensing.discretise`, any hashable
key): states are then numbered in the order first seen and the tables grow as new ones
appear (:meth:`QLearningAgent.index`). In a world with other motor primitives
(``--world minigrid``: turn left, turn right, forward) ``n_actions`` says how many; the
state is that world's declared discretisation of its sensation (for MiniGrid the cell and
the heading's quarter), and the goal's key may leave a component open (``None``: the goal
cell is reached facing any way), which :func:`key_matches` honours.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from maze_sim.maze import Cell, Maze
from maze_sim.world import StepInfo
from tmgwr_agent.core.exploration import EpsilonGreedy, ExplorationConfig
from tmgwr_common.params import make_config, param

N_ACTIONS = 4


def key_matches(key, goal) -> bool:
    """Is the sensed state ``key`` the goal's key? Equal, or equal on every component of
    a tuple key that the goal fixes (``None`` in the goal's key: any value)."""
    if key == goal:
        return True
    if not (isinstance(key, tuple) and isinstance(goal, tuple)) or len(key) != len(goal) \
            or None not in goal:
        return False
    return all(g is None or k == g for k, g in zip(key, goal))

@dataclass(frozen=True)
class QLearningConfig(ExplorationConfig):
    """Eq. 8 and the Q-learning column of Table 2 (shared with Dyna-Q+), plus the shared
    exploration parameters."""

    gamma: float = param(0.86, "discount factor (Table 2)", low=0.0, high=1.0,
                         high_open=True)
    beta: float = param(0.39, "learning rate of the Q update (Table 2)", low=0.0, high=1.0,
                        low_open=True)
    r_goal: float = param(88.0, "Eq. 8: reward of an action that leads to the goal",
                          low=-1e6, high=1e6)
    r_wall: float = param(-131.0, "Eq. 8: reward of an action that leads into a wall "
                          "(bump)", low=-1e6, high=1e6)
    r_empty: float = param(-29.0, "Eq. 8: reward of an action that leads to an empty cell",
                           low=-1e6, high=1e6)


def argmax_ties(values, rng: np.random.Generator) -> int:
    """The index of the largest of ``values``, ties broken by the generator (no draw when
    there is none): the greedy choice of every tabular agent."""
    top = max(values)
    best = [a for a in range(len(values)) if values[a] == top]
    if len(best) == 1:
        return best[0]
    return best[int(rng.integers(len(best)))]


class QLearningAgent:
    """Tabular Q-learning with the rewards of Eq. 8 and the exploration of section 5.1."""

    name = "q_learning"
    Config = QLearningConfig

    def __init__(self, maze: Maze, rng: np.random.Generator,
                 config: QLearningConfig | Mapping[str, Any] | None = None,
                 sensed_states: bool = False, n_actions: int = N_ACTIONS):
        """``config``: the agent's config, or a dict of parameter overrides;
        ``sensed_states``: states are sensed keys, not cells (module docstring);
        ``n_actions``: the world's motor primitives (4: the grid's moves)."""
        if not isinstance(config, self.Config):
            config = make_config(self.Config, config, where=self.name)
        self.config = c = config
        self.gamma, self.beta = c.gamma, c.beta
        self.r_goal, self.r_wall, self.r_empty = c.r_goal, c.r_wall, c.r_empty
        self.rng = rng
        self.n_actions = int(n_actions)
        self.policy = EpsilonGreedy(rng, c, self.n_actions)
        self.rows, self.cols = maze.shape
        n = self.rows * self.cols
        self.Q: list[list[float]] = [[0.0] * self.n_actions for _ in range(n)]
        self.tried = [False] * n       # some action has been tried from the state
        self.sensed: dict | None = {} if sensed_states else None   # key -> state index
        self.goal: Cell | None = None
        self.state = -1                # index of the current cell, -1 before an episode
        self.last_explored = False

    # -------------------------------------------------------------- helpers
    def index(self, cell: Cell) -> int:
        """The state index of a cell (``row * cols + col``) or, with sensed states, of a
        sensed key (numbered when first seen)."""
        if self.sensed is None:
            return int(cell[0]) * self.cols + int(cell[1])
        s = self.sensed.get(cell)
        if s is None:
            s = self.sensed[cell] = len(self.sensed)
            if s >= len(self.tried):
                self.grow()
        return s

    def grow(self) -> None:
        """One more state in every per-state table."""
        self.Q.append([0.0] * self.n_actions)
        self.tried.append(False)

    def states_seen(self) -> int:
        """States from which some action has been tried."""
        return sum(self.tried)

    def reward(self, info: StepInfo) -> float:
        """Eq. 8 for the step just taken (the previous goal is an empty cell)."""
        reached = info.reached_goal if self.goal is None else \
            key_matches(info.cell, self.goal)
        if reached:
            return self.r_goal
        if info.bumped:
            return self.r_wall
        return self.r_empty

    def greedy(self, s: int, Q: list[list[float]] | None = None) -> int | None:
        """argmax_a Q(s, a) (of table ``Q``, default ``self.Q``), ties broken by the
        generator; None for an untried state."""
        if s < 0 or not self.tried[s]:
            return None
        return argmax_ties((self.Q if Q is None else Q)[s], self.rng)

    def q_update(self, s: int, a: int, r: float, s2: int, terminal: bool) -> None:
        """The Q-learning update (one-step, off-policy)."""
        q = self.Q[s]
        target = r if terminal else r + self.gamma * max(self.Q[s2])
        q[a] += self.beta * (target - q[a])
        self.tried[s] = True

    # -------------------------------------------------------------- Agent protocol
    @property
    def epsilon(self) -> float:
        return self.policy.epsilon

    def set_goal(self, goal_cell: Cell, goal_obs: np.ndarray | None = None) -> None:
        """The goal's state: a cell, or with sensed states the goal sensation's key."""
        if self.sensed is not None:
            self.goal = goal_cell
            return
        self.goal = (int(goal_cell[0]), int(goal_cell[1]))

    def begin_episode(self, obs: np.ndarray, cell: Cell, learn: bool = True) -> None:
        self.state = self.index(cell)

    def act(self, explore: bool = True) -> int:
        a, self.last_explored = self.policy.choose(lambda: self.greedy(self.state), explore)
        return a

    def observe(self, obs: np.ndarray, info: StepInfo, learn: bool = True) -> None:
        s2 = self.index(info.cell)
        if learn and self.state >= 0:
            self.learn(self.state, info.action, self.reward(info), s2, info.terminated)
        self.state = s2
        self.policy.observe(info.action, info.bumped, info.reached_goal, learn)

    def learn(self, s: int, a: int, r: float, s2: int, terminal: bool) -> None:
        """What a real transition teaches (overridden by Dyna-Q+)."""
        self.q_update(s, a, r, s2, terminal)

