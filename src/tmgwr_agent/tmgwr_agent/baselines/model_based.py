"""The model-based baseline: value iteration on a hard-coded model (Eq. 9, 11, Table 2).

The states are the free cells of the maze *as given to the constructor* (``maze.walls``,
the layout before any event fires). The transition model is deterministic (Eq. 11)::

    T(s, a, s') = 1  if s' is the cell a leads to from s and contains no obstacle
    T(s, a, s)  = 1  if the cell a leads to contains an obstacle (the agent stays)

and it is never updated: when an event later blocks a cell, the agent keeps believing it
can walk through it (section 5.2.2: "the transition model ... is not updated when the
environment changes"). The reward of Eq. 9 depends on the state only::

    r(s) = +75 if s contains the goal,  -18 if s is empty.

When a goal is set, value iteration with the learning rate beta of Table 2 runs to a fixed
point (synchronous sweeps, vectorised with numpy)::

    V(s) <- V(s) + beta * (r(s) + gamma * max_a sum_s' T(s, a, s') V(s') - V(s))

with gamma = 0.94, beta = 0.23. The goal is terminal: ``V(goal) <- V(goal) + beta * (r(goal)
- V(goal))``, so at the fixed point V(goal) = 75 and a cell k steps from the goal has
``V = -300 + 375 gamma^k`` (-300 = -18 / (1 - gamma)): strictly decreasing with the
distance, so the greedy choice below is the shortest path.

Tolerance: sweeps stop when ``max_s |beta * Delta_V(s)| <= vi_tol`` (default 1e-10, in
reward units). A sweep contracts the error by ``1 - beta (1 - gamma) = 0.986``, and the
remaining error is at most ``vi_tol / (beta (1 - gamma)) ~ 72 vi_tol``, while the values of
two cells k and k+1 steps from the goal differ by ``22.5 * 0.94^k``: with 1e-10 the greedy
choice is exact up to about 340 steps from the goal (double precision itself resolves
these gaps up to about 530 steps). This costs about 2000 sweeps (milliseconds) and is
done once per goal: the solution is cached per goal cell, since T never changes.

Acting: one-step look-ahead with T, ``argmax_a sum_s' T(s, a, s') V(s')`` (r(s) is the
same for every action), ties broken by the agent's generator. A cell that is not a state
of the model (a wall of the original maze opened by a shortcut event) gives no opinion and
the random walk acts. The agent learns nothing from experience: after an event that blocks
its path it keeps choosing the blocked move and bumps (only epsilon-exploration can move it
away, and the greedy policy pulls it back), which is the paper's result (Fig. 5, 7c).
Exploration follows section 5.1 / Eq. 7 like every other agent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from maze_sim.maze import Cell, Maze, move
from maze_sim.world import StepInfo
from tmgwr_agent.baselines.q_learning import argmax_ties
from tmgwr_agent.core.exploration import EpsilonGreedy, ExplorationConfig
from tmgwr_common.params import make_config, param

N_ACTIONS = 4

@dataclass(frozen=True)
class ModelBasedConfig(ExplorationConfig):
    """The model-based column of Table 2 and Eq. 9, plus the shared exploration parameters."""

    gamma: float = param(0.94, "discount factor of the value iteration (Table 2)", low=0.0,
                         high=1.0, high_open=True)
    beta: float = param(0.23, "learning rate of the value iteration (Table 2)", low=0.0,
                        high=1.0, low_open=True)
    r_goal: float = param(75.0, "Eq. 9: r(s) of the goal state", low=-1e6, high=1e6)
    r_empty: float = param(-18.0, "Eq. 9: r(s) of an empty state", low=-1e6, high=1e6)
    vi_tol: float = param(1e-10, "stop value iteration when max |beta Delta_V(s)| <= vi_tol",
                          low=0.0, low_open=True, high=1e3)
    vi_max_sweeps: int = param(100000, "upper bound on value-iteration sweeps per goal",
                               low=1, high=1e9, integer=True)


def transition_table(walls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 11 as a table: (free cells as (row, col), next[i, a] = index of s').

    ``next[i, a]`` is the index (into the free-cell list) of the cell action ``a`` leads to
    from free cell ``i``, or ``i`` itself when that cell is an obstacle.
    """
    rows, cols = walls.shape
    free = np.argwhere(~walls)
    index = -np.ones((rows, cols), dtype=np.intp)
    index[free[:, 0], free[:, 1]] = np.arange(len(free))
    nxt = np.empty((len(free), N_ACTIONS), dtype=np.intp)
    for i, (r, c) in enumerate(free):
        for a in range(N_ACTIONS):
            (nr, nc), _ = move(walls, (int(r), int(c)), a)
            nxt[i, a] = index[nr, nc]
    return free, nxt


def vi_sweep(V: np.ndarray, nxt: np.ndarray, r: np.ndarray, terminal: np.ndarray,
             gamma: float, beta: float) -> np.ndarray:
    """One synchronous sweep of Eq. 9-11 value iteration; returns beta * Delta_V (V updated).

    ``terminal`` is a boolean mask of states whose target is ``r(s)`` alone.
    """
    target = r + gamma * V[nxt].max(axis=1)
    target[terminal] = r[terminal]
    dV = beta * (target - V)
    V += dV
    return dV


class ModelBasedAgent:
    """Value iteration with T(s, a, s') of the original maze (never updated)."""

    name = "model_based"
    Config = ModelBasedConfig

    def __init__(self, maze: Maze, rng: np.random.Generator,
                 config: ModelBasedConfig | Mapping[str, Any] | None = None):
        """``config``: the agent's config, or a dict of parameter overrides."""
        if not isinstance(config, self.Config):
            config = make_config(ModelBasedConfig, config, where=self.name)
        self.config = c = config
        self.gamma, self.beta = c.gamma, c.beta
        self.r_goal, self.r_empty = c.r_goal, c.r_empty
        self.vi_tol, self.vi_max_sweeps = c.vi_tol, c.vi_max_sweeps
        self.rng = rng
        self.policy = EpsilonGreedy(rng, c)
        # T(s, a, s') from the original walls, hard-coded once (Eq. 11).
        self.free, self.next = transition_table(maze.walls.copy())
        self.cols = maze.shape[1]
        self.state_of = -np.ones(maze.walls.size, dtype=np.intp)   # flat cell -> state
        self.state_of[self.free[:, 0] * self.cols + self.free[:, 1]] = np.arange(len(self.free))
        self.next_list: list[list[int]] = self.next.tolist()
        self.V = np.zeros(len(self.free))
        self.V_list: list[float] = self.V.tolist()
        self.goal: Cell | None = None
        self.sweeps = 0                      # sweeps of the last solve (0 if cached)
        self._solved: dict[Cell, np.ndarray] = {}
        self.state = -1
        self.last_explored = False

    # -------------------------------------------------------------- planning
    def solve(self, goal: Cell) -> np.ndarray:
        """Value iteration for ``goal`` (terminal) from V = 0 until within ``vi_tol``."""
        n = len(self.free)
        r = np.full(n, self.r_empty)
        terminal = np.zeros(n, dtype=bool)
        g = int(self.state_of[goal[0] * self.cols + goal[1]])
        if g >= 0:                   # a goal in an original wall is no state of the model
            r[g] = self.r_goal
            terminal[g] = True
        V = np.zeros(n)
        self.sweeps = 0
        for self.sweeps in range(1, self.vi_max_sweeps + 1):
            dV = vi_sweep(V, self.next, r, terminal, self.gamma, self.beta)
            if np.abs(dV).max() <= self.vi_tol:
                break
        return V

    def value(self, cell: Cell) -> float:
        """V(s) of a cell (NaN for a cell that is not a state of the model)."""
        s = int(self.state_of[cell[0] * self.cols + cell[1]])
        return float(self.V[s]) if s >= 0 else float("nan")

    def greedy(self, s: int) -> int | None:
        """One-step look-ahead with T: argmax_a V(T(s, a)); ties broken by the generator."""
        if s < 0 or self.goal is None:
            return None
        V = self.V_list
        return argmax_ties([V[j] for j in self.next_list[s]], self.rng)

    # -------------------------------------------------------------- Agent protocol
    @property
    def epsilon(self) -> float:
        return self.policy.epsilon

    def set_goal(self, goal_cell: Cell, goal_obs: np.ndarray | None = None) -> None:
        goal = (int(goal_cell[0]), int(goal_cell[1]))
        if goal not in self._solved:
            self._solved[goal] = self.solve(goal)
        else:
            self.sweeps = 0
        self.goal = goal
        self.V = self._solved[goal]
        self.V_list = self.V.tolist()

    def begin_episode(self, obs: np.ndarray, cell: Cell, learn: bool = True) -> None:
        self.state = int(self.state_of[cell[0] * self.cols + cell[1]])

    def act(self, explore: bool = True) -> int:
        a, self.last_explored = self.policy.choose(lambda: self.greedy(self.state), explore)
        return a

    def observe(self, obs: np.ndarray, info: StepInfo, learn: bool = True) -> None:
        # Nothing is learnt: T and r(s) are the designer's (Table 1).
        self.state = int(self.state_of[info.cell[0] * self.cols + info.cell[1]])
        self.policy.observe(info.action, info.bumped, info.reached_goal, learn)

