"""Motivation estimator (section 3.3, Eq. 4-5, Algorithm 1): value iteration on the map.

For the goal node ``g`` (the node nearest the goal state, Algorithm 1 line 2) every node
gets the immediate reward ``R_i = sim(i, g)`` (Eq. 10), a Gaussian of the distance between
the nodes' weights, and the motivation potentials are iterated to a fixed point::

    V(i) <- V(i) + beta * Delta_V(i)                               (Eq. 4)
    Delta_V(i) = sim(i, g) + gamma * max_k E[i, k] V(k) - V(i)     (Eq. 5)

over the sensorimotor neighbourhood ``k`` of ``i`` (its outgoing links). The sweep is
synchronous (all nodes from the previous V) and stops when every node's change ``|beta
Delta_V(i)|`` is below ``vi_tol * V(i)`` (a relative tolerance: potentials fall
geometrically with the distance to the goal and the choice between two far neighbours needs
the same relative precision as near the goal), or after ``vi_max_sweeps``. V is
warm-started from the last solution, so a step that changed the map a little costs a few
sweeps; a new goal restarts from V = 0 (Algorithm 1 line 5).

The width of ``sim(i, g)`` is not in the paper. We take ``sigma_g = goal_sigma * L`` where
``L`` is the median length of the map's links in feature space, i.e. the distance between
consecutive sensations: the reward is then concentrated on the goal node and its
sensorimotor neighbours whatever the map's scale, so a node that is near the goal in
sensor space but far from it along the map (behind a wall) is not a rival attractor. The
Gaussian is cut below ``goal_sim_floor`` (1e-3: beyond about 1.9 link lengths): a node gets
a potential only through links that lead to the goal, so where the map knows no way to the
goal every potential is exactly 0, the action selector has no opinion and the agent
explores (instead of climbing the far tail of the Gaussian into a dead end).

Terminal nodes (``absorbing_terminals``, our addition, on by default; off = Eq. 5 on every
node). The agent notices when an episode ends short of its goal: it is moved back to the
start instead of walking on, and it did not sense the goal. The map flags the node it stood
on (:meth:`~tmgwr_agent.core.sensorimotor_map.SensorimotorMap.mark_terminal`) until it
walks on from it, and value iteration treats a flagged node as a terminal state, as any MDP
solver would: ``V(i) = R_i``, no successor. Without this a route through a cell that ends
the episode (the previous goal in the goal-change scenario of section 5.2.1, which stays a
termination point) looks as good as any other, and the agent keeps being sent home through
it: on the paper's maze the learnt way to goal 3's region ran through goal 2's cell, so
after the change 2 -> 3 many episodes ended there instead of at goal 3 (the README's
goal-change results compare the two). Episodes that end *at* the goal flag nothing (the
goal node keeps Eq. 5, so a goal that moves away leaves no trace), nor do episodes cut by a
step limit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tmgwr_agent.core import kernels
from tmgwr_agent.core.sensorimotor_map import SensorimotorMap
from tmgwr_common.params import Config, param

#: Potentials below this are 0: gamma**d for d > 10,000 steps, i.e. no path to the goal.
#: Without it a potential that lost its path decays geometrically for ever (to denormals)
#: and the agent follows that numerical dust instead of exploring.
V_FLOOR = 1e-150


@dataclass(frozen=True)
class MotivationConfig(Config):
    """Hyperparameters of the motivation estimator (Eq. 4-5, Algorithm 1)."""

    gamma: float = param(0.97, "Eq. 5: discount factor (Table 2)", low=0.0, high=1.0,
                         low_open=True, high_open=True)
    beta: float = param(0.80, "Eq. 4: learning rate of the value iteration (Table 2)",
                        low=0.0, high=1.0, low_open=True)
    goal_sigma: float = param(0.3, "width of sim(i, g) in units of the median link length",
                              low=0.0, low_open=True, high=100.0)
    goal_sim_floor: float = param(1e-3, "sim(i, g) below this counts as 0 (compact "
                                  "support)", low=0.0, high=1.0, high_open=True)
    vi_tol: float = param(1e-4, "stop when |beta Delta_V(i)| <= vi_tol * V(i) for every "
                          "node", low=0.0, low_open=True, high=1.0)
    vi_max_sweeps: int = param(5000, "upper bound on sweeps per call", low=1, high=1e9,
                               integer=True)
    absorbing_terminals: bool = param(True, "nodes where an episode ended have no successor "
                                      "in Eq. 5 (false: the paper's Eq. 5 on every node)")


def _no_absorbing(n: int) -> np.ndarray:
    return np.zeros(n, dtype=bool)


class MotivationEstimator:
    """Holds the goal and the potentials V; :meth:`update` re-solves Eq. 4-5."""

    def __init__(self, config: MotivationConfig = MotivationConfig()):
        kernels.announce_compilation()
        self.config = config
        self.gamma, self.beta = config.gamma, config.beta
        self.goal_sigma, self.goal_sim_floor = config.goal_sigma, config.goal_sim_floor
        self.vi_tol, self.vi_max_sweeps = config.vi_tol, config.vi_max_sweeps
        self.absorbing_terminals = config.absorbing_terminals
        self.goal_x: np.ndarray | None = None
        self.goal_node = -1
        self.V = np.zeros(1)          # V[:n]; V[n] stays 0 (target of empty link slots)
        self.sweeps = 0               # sweeps of the last update
        self._scale_version = -1      # map version the cached link scale belongs to
        self._scale = 1.0

    def set_goal(self, goal_x: np.ndarray) -> None:
        """A new goal state: the potentials restart from 0 (Algorithm 1, line 5)."""
        self.goal_x = np.asarray(goal_x, dtype=float)
        self.V[:] = 0.0

    def follow_goal(self, goal_x: np.ndarray) -> bool:
        """The goal sensation that came with this step: :meth:`set_goal` when it differs
        from the current goal (the graph's estimator learns goal changes this way);
        returns whether it did."""
        goal_x = np.asarray(goal_x, dtype=float)
        if self.goal_x is not None and np.array_equal(goal_x, self.goal_x):
            return False
        self.set_goal(goal_x)
        return True

    @staticmethod
    def link_scale(m: SensorimotorMap) -> float:
        """Median length of the map's links in feature space (0 if it has none)."""
        src, tgt = np.nonzero(m.out[: m.n] >= 0)
        if not len(src):
            return 0.0
        d = m.w[src] - m.w[m.out[src, tgt]]
        return float(np.median(np.sqrt(np.einsum("ij,ij->i", d, d))))

    def rewards(self, m: SensorimotorMap, g: int, scale: float) -> np.ndarray:
        """Eq. 10: R_i = sim(i, g) = exp(-|w_i - w_g|^2 / (2 sigma_g^2)), 0 for dead slots."""
        R = np.empty(m.n)
        kernels.goal_rewards(w=m.w, alive=m.alive, n=m.n, g=g, sigma=self.goal_sigma * scale,
                             floor=self.goal_sim_floor, R=R)
        return R

    def update(self, m: SensorimotorMap) -> np.ndarray:
        """Solve Eq. 4-5 on the current map; returns V[:n]."""
        n = m.n
        if len(self.V) != n + 1:                      # the map grew: extend, keep values
            V = np.zeros(n + 1)
            k = min(n, len(self.V) - 1)
            V[:k] = self.V[:k]
            self.V = V
        self.sweeps = 0
        g = m.nearest_by_weight(self.goal_x) if self.goal_x is not None else -1
        self.goal_node = g
        if g < 0:                                     # no goal yet, or an empty map
            self.V[:] = 0.0
            return self.V[:n]
        if self._scale_version != m.version:          # links only change with the version
            self._scale = self.link_scale(m) or 1.0
            self._scale_version = m.version
        R = self.rewards(m, g, self._scale)
        absorbing = m.terminal if self.absorbing_terminals else _no_absorbing(n)
        self.sweeps = kernels.value_iteration(
            out=m.out, E=m.E, R=R, V=self.V, n=n, beta=self.beta, gamma=self.gamma,
            tol=self.vi_tol, v_floor=V_FLOOR, max_sweeps=self.vi_max_sweeps,
            absorbing=absorbing, alive=m.alive)
        return self.V[:n]
