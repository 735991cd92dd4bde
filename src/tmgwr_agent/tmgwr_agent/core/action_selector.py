"""Action selector (section 3.4, Eq. 6) with the exploration of section 5.1 and Eq. 7.

Eq. 6 picks the action vector of the link towards the most motivating neighbour::

    a_i = a_{i k_max},   k_max = argmax_k E[i, k] V(k)   over the links i -> k

We rank neighbours by ``E[i, k] V(k)``, the term that Eq. 5 maximises, so the selector
follows the same neighbour the motivation estimator credited (with a plain ``V(k)`` a
link that has become unreliable, e.g. into a new wall, would keep being chosen). Ties are
broken by the agent's generator. The chosen action vector is mapped to the nearest motor
primitive of the action map (the four unit moves). A node with no outgoing link, or whose
neighbours have no motivation yet, has no greedy opinion: the random walk acts.

Search at the goal node (``goal_search``, our addition, on by default; off = the paper's
selector). Eq. 6 climbs the potentials to the goal node ``g = argmax_i sim(i, g)``. When
the goal's sensation is not yet represented in the map (a goal moved into a part of the
maze never visited), ``g`` is only the node *most like* the goal, often a dead end behind
a wall from it; reaching it without the episode ending tells the agent that its map does
not know the way. Eq. 6 would then keep it oscillating around ``g`` (only epsilon's random
steps leave), and measured on the paper's maze some trials never reached the new goal.
With ``goal_search`` the selector switches to the random walk of section 5.1 for the rest
of the episode once it has stood on the goal node without the episode ending; the map
grows where the walk goes, and once the goal has been sensed its node exists and Eq. 6
leads there directly from the next episode on. Only the map's own goal node is used
(no maze knowledge), and the greedy probe (``explore=False``) never searches.

Untried actions first (``try_untried``, our addition, on by default). Eq. 6 only knows
the links the agent has made; an action never taken from a node has no link and so no
say, and with epsilon at its floor a side corridor glimpsed once may never be entered
again. The selector remembers which motor primitives it has taken from each node and,
where Eq. 6 would act, first takes one it has not (uniformly among them), once each: a
bump or a new link then records the outcome. This is the optimism Q-learning gets from its
zero-initialised table under negative rewards, at most four extra steps per node. On the
paper's maze it shortens env-change b, as the detour is mapped before the block (README
results).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from maze_sim.maze import ACTION_VECTORS
from tmgwr_agent.core import kernels
from tmgwr_agent.core.exploration import EpsilonGreedy, ExplorationConfig
from tmgwr_agent.core.outcome import Outcome
from tmgwr_agent.core.sensorimotor_map import Links
from tmgwr_common.params import param


@dataclass(frozen=True)
class SelectorConfig(ExplorationConfig):
    """The shared exploration parameters plus our two additions to Eq. 6."""

    goal_search: bool = param(True, "random walk for the rest of an episode once the agent "
                              "stood on the goal node without reaching the goal "
                              "(action_selector.py; false: the paper's Eq. 6 selector)")
    try_untried: bool = param(True, "take each motor primitive once from every node before "
                              "following Eq. 6 there (action_selector.py; false: the "
                              "paper's Eq. 6 selector)")


class ActionSelector:
    def __init__(self, rng: np.random.Generator, config: SelectorConfig = SelectorConfig()):
        kernels.announce_compilation()
        self.rng = rng
        self.config = config
        self.policy = EpsilonGreedy(rng, config)
        self.goal_search = config.goal_search
        self.searching = False      # stood on the goal node this episode, goal not there
        self.try_untried = config.try_untried
        self.tried: dict[int, int] = {}   # node id -> bitmask of primitives taken from it

    def record(self, node: int, outcome: Outcome, learn: bool = True) -> None:
        """What the last action did, taken from ``node`` (the winner it acted from): an
        episode start ends the goal search; otherwise the primitive counts as tried at the
        node and the exploration policy continues from the outcome (walk direction,
        Eq. 7 at the goal). A greedy probe (``learn`` False) marks nothing tried."""
        if outcome.episode_start:
            self.searching = False
            return
        if learn and node >= 0:
            self.tried[node] = self.tried.get(node, 0) | (1 << outcome.action)
        self.policy.observe(outcome.action, outcome.bumped, outcome.goal_reached, learn)

    def untried(self, node: int) -> int | None:
        """A primitive never taken from ``node`` (uniform among them), or None."""
        mask = self.tried.get(node, 0)
        free = [a for a in range(len(ACTION_VECTORS)) if not mask >> a & 1]
        if not free:
            return None
        return free[0] if len(free) == 1 else free[int(self.rng.integers(len(free)))]

    def greedy(self, links: Links, V: np.ndarray) -> int | None:
        """Eq. 6 over a node's links: the discrete action of a_{i k_max}, or None without
        opinion (no link, or no neighbour with motivation)."""
        best = kernels.best_links(links.targets, links.E, V)
        if not len(best):
            return None
        slot = best[0] if len(best) == 1 else best[self.rng.integers(len(best))]
        return self.action_index(links.actions[slot])

    @staticmethod
    def action_index(a: np.ndarray) -> int:
        """The motor primitive nearest the action vector (the action map's codebook)."""
        return int(kernels.nearest_row(ACTION_VECTORS, a))

    def select(self, links_of: Callable[[int], Links], node: int, V: np.ndarray,
               goal_node: int, explore: bool = True) -> tuple[int, bool]:
        """(action, explored) at the winner ``node``, whose outgoing links
        ``links_of(node)`` gives (read only when Eq. 6 acts), under the potentials V
        (``V[-1]`` = 0 for empty slots) of the goal node ``goal_node``: the random walk with
        probability epsilon, else an untried primitive of the node (``try_untried``), else
        Eq. 6; the random walk for the rest of the episode once the agent stood on the goal
        node with the episode still running (``goal_search``).
        """
        if explore and self.goal_search and node >= 0 and node == goal_node:
            self.searching = True
        if self.policy.explores(explore) or (explore and self.searching):
            return self.policy.walk.action(), True
        if explore and self.try_untried and node >= 0:
            u = self.untried(node)
            if u is not None:
                return u, True
        a = self.greedy(links_of(node), V) if node >= 0 else None
        if a is None:
            return self.policy.walk.action(), True
        return a, False
