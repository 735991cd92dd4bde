"""Action selector (section 3.4, Eq. 6) with the exploration of section 5.1 and Eq. 7.

Eq. 6 picks the action vector of the link towards the most motivating neighbour::

    a_i = a_{i k_max},   k_max = argmax_k E[i, k] V(k)   over the links i -> k

We rank neighbours by ``E[i, k] V(k)``, the term that Eq. 5 maximises, so the selector
follows the same neighbour the motivation estimator credited (with a plain ``V(k)`` a
link that has become unreliable, e.g. into a new wall, would keep being chosen). Ties are
broken by the agent's generator. The chosen action vector is mapped to the nearest motor
primitive of the action map (the four unit moves). A node with no outgoing link, or whose
neighbours have no motivation yet, has no greedy opinion: the random walk acts.
"""

from __future__ import annotations

import numpy as np

from maze_sim.maze import ACTION_VECTORS

from . import kernels
from .exploration import EpsilonGreedy
from .tmgwr_map import SensorimotorMap


class ActionSelector:
    def __init__(self, rng: np.random.Generator, *, p_turn=0.3, eps_start=1.0, eps_decay=0.1,
                 eps_min=0.1):
        self.rng = rng
        self.policy = EpsilonGreedy(rng, p_turn, eps_start, eps_decay, eps_min)

    def greedy(self, m: SensorimotorMap, i: int, V: np.ndarray) -> int | None:
        """Eq. 6 at node i: the discrete action of a_{i k_max}, or None without opinion."""
        if i < 0:
            return None
        best = kernels.best_links(m.out[i], m.E[i], V)
        if not len(best):
            return None
        slot = best[0] if len(best) == 1 else best[self.rng.integers(len(best))]
        return self.action_index(m.a[i, slot])

    @staticmethod
    def action_index(a: np.ndarray) -> int:
        """The motor primitive nearest the action vector (the action map's codebook)."""
        d = ACTION_VECTORS - a
        return int(np.argmin(np.einsum("ij,ij->i", d, d)))

    def select(self, m: SensorimotorMap, i: int, V: np.ndarray, explore: bool = True
               ) -> tuple[int, bool]:
        """(action, explored): the random walk with probability epsilon, else Eq. 6."""
        if self.policy.explores(explore):
            return self.policy.walk.action(), True
        a = self.greedy(m, i, V)
        if a is None:
            return self.policy.walk.action(), True
        return a, False
