"""Action selector (section 3.4, Eq. 6) with the exploration of section 5.1 and Eq. 7.

Eq. 6 picks the action vector of the link towards the most motivating neighbour::

    a_i = a_{i k_max},   k_max = argmax_k E[i, k] V(k)   over the links i -> k

We rank neighbours by ``E[i, k] V(k)``, the term that Eq. 5 maximises, so the selector
follows the same neighbour the motivation estimator credited (with a plain ``V(k)`` a
link that has become unreliable, e.g. into a new wall, would keep being chosen). Ties are
broken by the agent's generator. The chosen action vector is mapped to the nearest motor
primitive of the action map (the world's primitives, :class:`~tmgwr_agent.core.senses.
Senses`). A node with no outgoing link, or whose
neighbours have no motivation yet, has no greedy opinion: the random walk acts.

Options (``try_untried``, our addition, on by default; off = the paper's selector). The
motivation estimator's Eq. 5' also credits *options*, the value of an untried or stale
(node, primitive) pair (motivation.py). They reach the selector as virtual links of the
winner to itself (target = the winner, ``E V(target)`` = the option's value, action = the
primitive; :meth:`MotivationEstimator.options_of`), so the same argmax ranks links and
options and the agent takes the primitive whose outcome is worth finding out exactly when
Eq. 5' says so. With ``try_untried`` off such self-links are ignored (no real link is a
self-link: a bump is not stored). This replaces the former rule "take every primitive
once from each node first", which explored every node alike, wherever the goal was.

Goal search (``goal_search``, off by default: superseded by Eq. 5', which has no goal node
until the goal is sensed; kept for the ablation). The random walk for the rest of the
episode once the agent stood on the goal node without the episode ending.

The walk while it discovers (``walk_while_novel``, our addition, on by default; off = the
paper's first episode, a blind random walk until the goal is found). Eq. 7 starts from
epsilon 1, so before the goal is first attained every step is the random walk; on a small
maze it covers the maze on the way (a map of the detours the blocks later need), but a
random walk's time to hit a goal grows faster than the maze (on the 1100-1300-cell suite
mazes five episodes of 237,200 steps each never found it). So before the goal is first
attained the walk acts only while it still discovers: it is held, and Eq. 6 acts over the
options of Eq. 5' (the nearest plausible unknown towards the goal sensation), once the
last ``N`` steps found no node the selector had not acted from before, ``N`` the nodes it
has acted from (the time a walk needs to see the known map again, as in Eq. 5''s stale
horizon: no constant). A new node ends the hold; so do N held steps that found none (Eq. 6
had nowhere to lead: the walk resumes until a new node turns up). After the first goal,
Eq. 7 runs as in the paper. Whether a step is held is fixed with its epsilon draw
(:class:`EpsilonGreedy`), so the graph's ``walk_next`` and the selector agree.

The state needed to continue a run (epsilon, the walk's direction, the search flag) is
plain data: :meth:`ActionSelector.state_dict` / :meth:`load_state_dict`; the generator's
state is the caller's (``rng.bit_generator.state``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from tmgwr_agent.core import kernels
from tmgwr_agent.core.exploration import EpsilonGreedy, ExplorationConfig
from tmgwr_agent.core.motivation import OptionTerms, grown
from tmgwr_agent.core.outcome import Outcome
from tmgwr_agent.core.sensorimotor_map import Links
from tmgwr_common.params import param


@dataclass(frozen=True)
class SelectorConfig(ExplorationConfig):
    """The shared exploration parameters plus our additions to Eq. 6. The floor of Eq. 7
    is 0 here (the paper's 0.1 with ``+paper``): after the goal is found the value of the
    unknown (Eq. 5') explores with purpose, and a random step at the floor costs steps
    and can end an episode at a terminal cell (action_selector.py)."""

    eps_min: float = param(0.0, "Eq. 7: floor of epsilon (0: the random walk gives way "
                           "to Eq. 5' once the goal is found; the paper's 0.1 with +paper)",
                           low=0.0, high=1.0)

    goal_search: bool = param(False, "random walk for the rest of an episode once the agent "
                              "stood on the goal node without reaching the goal (superseded "
                              "by the value of the unknown; action_selector.py)")
    try_untried: bool = param(True, "Eq. 6 also ranks the options of Eq. 5' (untried or "
                              "stale primitives, virtual self-links of the winner; "
                              "action_selector.py; false: the paper's Eq. 6 selector)")
    walk_while_novel: bool = param(True, "before the goal is first attained, hold the random "
                                   "walk once the last N steps (N: nodes acted from) found "
                                   "no new node; Eq. 6 acts instead (action_selector.py; "
                                   "false: the paper's blind first episode)")


#: No options (the terms of :func:`kernels.eq6_choices` for links alone).
_NO_OPTIONS = (0.0, 0.0, np.zeros((0, 0)), np.zeros((0, 0)), np.zeros((0, 0), np.int64),
               np.zeros((0, 0, 0), np.int64), np.zeros((0, 0, 0)))


class ActionSelector:
    def __init__(self, rng: np.random.Generator, config: SelectorConfig = SelectorConfig(),
                 *, primitives: np.ndarray):
        """``primitives``: the motor vector of each action (:class:`~tmgwr_agent.core.
        senses.Senses`)."""
        kernels.announce_compilation()
        self.rng = rng
        self.config = config
        self.primitives = np.ascontiguousarray(primitives, dtype=float)
        self.policy = EpsilonGreedy(rng, config, len(self.primitives))
        self.goal_search = config.goal_search
        self.searching = False      # stood on the goal node this episode, goal not there
        self.try_untried = config.try_untried
        self.took_option = False    # the last Eq. 6 choice was an option of Eq. 5'
        # Eq. 6's choices (kernels.eq6_choices): slots, primitives, whether options
        self._slots = self._acts = np.empty(0, dtype=np.int64)
        self._took = np.empty(0, dtype=np.bool_)
        # walk_while_novel: nodes acted from, learning steps, the step that found the last
        # new one, whether a goal was ever attained
        self.acted = np.zeros(64, dtype=bool)
        self.n_acted = 0
        self.steps = 0
        self.last_new = 0
        self.attained = False
        if config.walk_while_novel:
            self.policy.hold = self.walk_stalled

    def walk_stalled(self) -> bool:
        """Before the first goal: the last N steps found no new node (N = nodes acted
        from), so the random walk is held and Eq. 6 acts; for N steps at most: when Eq. 6
        found nothing new either (no option leads anywhere, or the paper's Eq. 5 without
        options), the walk acts again until a new node turns up."""
        n = max(1, self.n_acted)
        return not self.attained and n <= self.steps - self.last_new < 2 * n

    def record(self, node: int, outcome: Outcome, learn: bool = True) -> None:
        """What the last action did, taken from ``node`` (the winner it acted from): an
        episode start ends the goal search; otherwise the exploration policy continues
        from the outcome (walk direction, Eq. 7 at the goal)."""
        if outcome.episode_start:
            self.searching = False
            return
        if learn and node >= 0 and self.policy.hold is not None and not self.attained:
            self.acted = grown(self.acted, node + 1, False)     # (the hold's bookkeeping,
            self.steps += 1                                     # needed until the goal)
            if not self.acted[node]:
                self.acted[node] = True
                self.n_acted += 1
                self.last_new = self.steps
        if learn and outcome.goal_reached:
            self.attained = True
        self.policy.observe(outcome.action, outcome.bumped, outcome.goal_reached, learn)

    def greedy(self, links: Links, V: np.ndarray, node: int = -1,
               options: OptionTerms | None = None) -> int | None:
        """Eq. 6 over a node's links (and options, virtual links to ``node`` itself, or
        with ``options`` the terms of node's options ranked alongside its links, as
        :meth:`~tmgwr_agent.core.motivation.MotivationEstimator.options_of` would make
        them, without building them): the discrete action of a_{i k_max}, or None
        without opinion (no link, or no neighbour with motivation)."""
        exclude = node >= 0 and not self.try_untried
        R_i, gamma, U, rho, osucc, onb, ong = options or _NO_OPTIONS
        size = len(links.targets) + rho.shape[1]
        if len(self._slots) < size:
            self._slots, self._acts = (np.empty(2 * size, dtype=np.int64) for _ in range(2))
            self._took = np.empty(2 * size, dtype=np.bool_)
        c = kernels.eq6_choices(links.targets, links.E, links.actions, V, node, exclude, R_i,
                                gamma, U, rho, osucc, onb, ong, self.primitives,
                                self._slots, self._acts, self._took)
        if not c:
            return None
        k = 0 if c == 1 else self.rng.integers(c)
        self.took_option = bool(node >= 0 and self._took[k])
        return int(self._acts[k])

    def action_index(self, a: np.ndarray) -> int:
        """The motor primitive nearest the action vector (the action map's codebook)."""
        return int(kernels.nearest_row(self.primitives, a))

    def select(self, links_of: Callable[[int], Links], node: int, V: np.ndarray,
               goal_node: int, explore: bool = True,
               options: Callable[[int], OptionTerms | None] | None = None
               ) -> tuple[int, bool]:
        """(action, explored) at the winner ``node``, whose outgoing links and options
        ``links_of(node)`` gives (read only when Eq. 6 acts), under the potentials V
        (``V[-1]`` = 0 for empty slots) of the goal node ``goal_node``: the random walk with
        probability epsilon, else Eq. 6; the random walk for the rest of the episode once
        the agent stood on the goal node with the episode still running (``goal_search``).
        ``explored`` is True for a random-walk step or an option taken. ``options``: the
        terms of a node's options (:meth:`~tmgwr_agent.core.motivation.
        MotivationEstimator.option_terms`), when ``links_of`` gives its links alone.
        """
        if explore and self.goal_search and node >= 0 and node == goal_node:
            self.searching = True
        if self.policy.explores(explore) or (explore and self.searching):
            return self.policy.walk.action(), True
        if node < 0:
            return self.policy.walk.action(), True
        links = links_of(node)
        a = self.greedy(links, V, node, options(node) if options is not None else None)
        if a is None:
            return self.policy.walk.action(), True
        return a, bool(self.took_option)

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict[str, np.ndarray | float | int]:
        """Epsilon, the walk's state, the search flag and the novelty bookkeeping of
        ``walk_while_novel``, as plain numbers and one array."""
        return {**self.policy.state_dict(), "searching": int(self.searching),
                "acted": self.acted.copy(), "steps": int(self.steps),
                "last_new": int(self.last_new), "attained": int(self.attained)}

    def load_state_dict(self, d: dict) -> None:
        self.policy.load_state_dict(d)
        self.searching = bool(d.get("searching", 0))
        if "acted" in d:                    # absent from older checkpoints: start afresh
            self.acted = np.array(d["acted"], dtype=bool).reshape(-1)
            self.n_acted = int(self.acted.sum())
            self.steps, self.last_new = int(d["steps"]), int(d["last_new"])
            self.attained = bool(d["attained"])
