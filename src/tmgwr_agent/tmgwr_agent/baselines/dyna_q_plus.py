"""Dyna-Q+ (Sutton & Barto 2018, section 8.3): Q-learning plus a learnt model.

Not in the paper: a model-*learning* reinforcement-learning agent, the fair rival of the
TMGWR agent in a changing maze. Real steps are exactly those of
:class:`~.q_learning.QLearningAgent` (rewards r(s, a) of Eq. 8: +88 goal, -131 wall, -29
empty; gamma = 0.86 and learning rate beta = 0.39 of Table 2; terminal transitions
bootstrap 0). In addition, after every real step (tabular Dyna-Q, steps (e)-(f)):

* the deterministic model remembers the latest outcome ``Model(s, a) = (r, s', terminal)``
  and the global time ``t`` (real steps taken while learning) at which (s, a) was tried;
* ``n`` planning updates follow, each on a pair drawn uniformly from the visited states x
  the four actions, with the exploration bonus of Dyna-Q+ added to the modelled reward::

      Q(s, a) <- Q(s, a) + beta * (r + kappa * sqrt(tau) + gamma * max_a' Q(s', a') - Q(s, a))

  where ``tau`` is the number of real time steps since (s, a) was last tried (bootstrap 0
  for a terminal model transition). As in the book, an action never tried from a visited
  state may be drawn: its model leads back to the same state with reward 0, and its tau
  counts from the first visit of the state.

Exploitation reads a bonus-free table. The bonus lives in ``Q`` (the book's Dyna-Q+), so
the greedy policy of ``Q`` keeps chasing whatever pair is stale: it is an exploration
policy and, measured on the paper's maze, a greedy rollout on it loops between two cells
forever even when the maze has been learnt (every sample-complexity trial hit its cap). What
the agent *knows* is a second table ``Q0`` learnt from the same real steps, the same model
and the same planning draws without the bonus (Dyna-Q; a draw of a never-tried pair leaves
it alone). ``act(explore=True)`` -- training -- acts epsilon-greedily on ``Q`` exactly as
the book; ``act(explore=False)`` -- the experimenter's greedy probe -- on ``Q0``. The
behaviour of the agent is unchanged; only the probe now measures its knowledge and not
its curiosity. Cost: a second update per planning draw.

A goal change relabels the model (``set_goal``): the model stores the next state of every
tried pair and whether it bumped, so its reward and terminal flag are recomputed for the
new goal (r_wall for a bump, r_goal and terminal into the new goal, r_empty otherwise).
Planning then propagates the new goal's values at once; without the relabel it would keep
replaying the old goal's rewards until every pair near the route was tried again. A
termination away from the goal (the previous goal of the goal-change scenario) is then an
ordinary empty cell in the model, as it is in Eq. 8's reward, until it is tried again.

Default kappa = 0.1 (the book's 0.001 is for a reward of 1 at the goal and 0 elsewhere).
Scaled to rewards of tens to hundreds: a pair untried for tau = 10^4 real steps gets
``kappa sqrt(tau) = 10``, a third of one step's cost (29), so an old detour is worth
re-testing in planning once it is stale by thousands of steps, while the bonus of a pair
tried in the last hundred steps (<= 1) stays small against the reward differences that
decide the route near the goal. Larger kappa (>= 1) makes the planned values so
optimistic about every stale pair that the greedy policy wanders and converges later
(``./tmgwr experiment env-change --agents dyna_q_plus --params F`` with a file setting
``kappa`` measures it: the detour after event 'a' and the episodes to an optimal greedy
path).

Default n = 10 planning steps per real step: enough to propagate a changed value along a
corridor within a few real steps (the book's maze examples use n between 5 and 50) while
keeping a step at about ten times the cost of a Q-learning step. Planning draws its n
uniforms with one generator call per real step and works on Python lists, so a step is
O(n) with a small constant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from maze_sim.maze import Cell, Maze
from tmgwr_agent.baselines.q_learning import (
    N_ACTIONS,
    QLearningAgent,
    QLearningConfig,
    key_matches,
)
from tmgwr_common.params import param


@dataclass(frozen=True)
class DynaQPlusConfig(QLearningConfig):
    """Q-learning's parameters (Table 2, Eq. 8) plus planning and the exploration bonus."""

    n_planning: int = param(10, "planning updates per real step (Dyna-Q step f)", low=0,
                            high=10000, integer=True)
    kappa: float = param(0.1, "exploration bonus kappa * sqrt(tau) added in planning",
                         low=0.0, high=1e6)


class DynaQPlusAgent(QLearningAgent):
    """Dyna-Q+ with the rewards and learning rate of the paper's Q-learning agent."""

    name = "dyna_q_plus"
    Config = DynaQPlusConfig

    def __init__(self, maze: Maze, rng: np.random.Generator,
                 config: DynaQPlusConfig | Mapping[str, Any] | None = None,
                 sensed_states: bool = False, n_actions: int = N_ACTIONS):
        super().__init__(maze, rng, config, sensed_states, n_actions)
        self.n_planning = self.config.n_planning
        self.kappa = self.config.kappa
        n = self.rows * self.cols * self.n_actions
        # Model(s, a), indexed by s * n_actions + a; next -1 = never tried.
        self.m_next = [-1] * n
        self.m_reward = [0.0] * n
        self.m_terminal = [False] * n
        self.m_bumped = [False] * n
        self.m_time = [0] * n          # real time step at which (s, a) was last tried
        self.visited: list[int] = []   # states in order of first visit
        self.is_visited = [False] * (self.rows * self.cols)
        self.t = 0                     # global clock: real learning steps
        # bonus-free twin of Q (Dyna-Q), read by act(explore=False)
        self.Q0: list[list[float]] = [[0.0] * self.n_actions
                                         for _ in range(self.rows * self.cols)]

    def grow(self) -> None:
        super().grow()
        self.m_next.extend([-1] * self.n_actions)
        self.m_reward.extend([0.0] * self.n_actions)
        self.m_terminal.extend([False] * self.n_actions)
        self.m_bumped.extend([False] * self.n_actions)
        self.m_time.extend([0] * self.n_actions)
        self.is_visited.append(False)
        self.Q0.append([0.0] * self.n_actions)

    def set_goal(self, goal_cell: Cell, goal_obs: np.ndarray | None = None) -> None:
        """The new goal, and the model's rewards and terminals relabelled for it."""
        super().set_goal(goal_cell, goal_obs)
        at_goal = self.goal_states()
        for sa, s2 in enumerate(self.m_next):
            if s2 < 0:
                continue
            bumped = self.m_bumped[sa]          # a bump stays put, it reaches nothing
            self.m_terminal[sa] = s2 in at_goal and not bumped
            self.m_reward[sa] = (self.r_wall if bumped else
                                 self.r_goal if s2 in at_goal else self.r_empty)

    def goal_states(self) -> set[int]:
        """The indices of the states at the goal: the goal's own, and with sensed states
        every key seen so far that falls on the goal's (:func:`key_matches`)."""
        g = {self.index(self.goal)}
        if self.sensed is not None:
            g.update(s for key, s in self.sensed.items() if key_matches(key, self.goal))
        return g

    def act(self, explore: bool = True) -> int:
        Q = self.Q if explore else self.Q0      # the probe reads the bonus-free twin
        a, self.last_explored = self.policy.choose(lambda: self.greedy(self.state, Q), explore)
        return a

    def learn(self, s: int, a: int, r: float, s2: int, terminal: bool) -> None:
        self.t += 1
        t = self.t
        if not self.is_visited[s]:
            self.is_visited[s] = True
            self.visited.append(s)
            base = s * self.n_actions
            for b in range(self.n_actions):       # untried actions: tau counts from here
                self.m_time[base + b] = t
        # (d) direct RL, on Q and on its bonus-free twin Q0
        self.q_update(s, a, r, s2, terminal)
        q0 = self.Q0[s]
        target0 = r if terminal else r + self.gamma * max(self.Q0[s2])
        q0[a] += self.beta * (target0 - q0[a])
        # (e) model learning
        sa = s * self.n_actions + a
        self.m_next[sa] = s2
        self.m_reward[sa] = r
        self.m_terminal[sa] = terminal
        self.m_bumped[sa] = r == self.r_wall and s2 == s
        self.m_time[sa] = t
        # (f) planning
        if self.n_planning:
            self.plan(self.n_planning)

    def plan(self, n: int) -> None:
        Q, Q0, visited = self.Q, self.Q0, self.visited
        m_next, m_reward, m_terminal, m_time = (self.m_next, self.m_reward,
                                                self.m_terminal, self.m_time)
        gamma, beta, kappa, t = self.gamma, self.beta, self.kappa, self.t
        n_a = self.n_actions
        scale = len(visited) * n_a
        sqrt = math.sqrt
        for u in self.rng.random(n).tolist():
            k = int(u * scale)
            s, a = divmod(k, n_a)
            s = visited[s]
            sa = s * n_a + a
            s2 = m_next[sa]
            if s2 < 0:                        # never tried: back to s with reward 0
                s2, r, terminal = s, 0.0, False
            else:
                r, terminal = m_reward[sa], m_terminal[sa]
                q0 = Q0[s]                    # Dyna-Q on the bonus-free twin
                target0 = r if terminal else r + gamma * max(Q0[s2])
                q0[a] += beta * (target0 - q0[a])
            r += kappa * sqrt(t - m_time[sa])
            q = Q[s]
            target = r if terminal else r + gamma * max(Q[s2])
            q[a] += beta * (target - q[a])
