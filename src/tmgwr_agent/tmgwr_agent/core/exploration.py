"""Exploration shared by every agent, so the comparison is fair (section 5.1, Eq. 7).

* :class:`RandomWalk`: keep the current direction; after a bump pick one of the other
  actions (probability 1); otherwise turn to one of the others with probability
  ``p_turn`` (0.3 in the paper, four actions).
* :class:`EpsilonSchedule`: Eq. 7, ``eps = max(eps - decay, eps_min)`` each time the goal
  is attained, starting from ``eps_start`` (1.0, 0.1, 0.1 in the paper).
* :class:`EpsilonGreedy`: with probability ``eps`` the random walk acts, otherwise the
  agent's greedy choice. Every agent draws from its own generator in the same order, so a
  seed fixes the whole run. The draw of a step can be made ahead
  (:meth:`EpsilonGreedy.draw_ahead`), as soon as the last action is chosen: the same
  number of the same stream when nothing else draws in between, so an agent knows before
  it plans whether the next action is the random walk (the TMGWR agent then skips Eq. 4-5:
  work that cannot change the next action is not done). An agent may *hold* the walk
  (:attr:`EpsilonGreedy.hold`, a callable; the TMGWR selector's ``walk_while_novel``): a
  held step does not walk whatever the draw. Whether a step is held is fixed when its draw
  is made, so a draw made ahead and its use agree.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from tmgwr_common.params import Config, ParamError, param


@dataclass(frozen=True)
class ExplorationConfig(Config):
    """The exploration parameters every agent shares (same names, defaults and ranges)."""

    p_turn: float = param(0.3, "random walk: probability of turning when not blocked (5.1)",
                          low=0.0, high=1.0)
    eps_start: float = param(1.0, "Eq. 7: initial exploration probability", low=0.0,
                             high=1.0)
    eps_decay: float = param(0.1, "Eq. 7: decrease of epsilon per goal attained", low=0.0,
                             high=1.0)
    eps_min: float = param(0.1, "Eq. 7: floor of epsilon", low=0.0, high=1.0)

    def __post_init__(self):
        super().__post_init__()
        if self.eps_min > self.eps_start:
            raise ParamError(f"parameter 'eps_min' ({self.eps_min}) must not exceed "
                             f"'eps_start' ({self.eps_start})")


class RandomWalk:
    """The random-walk exploration policy of section 5.1."""

    def __init__(self, rng: np.random.Generator, p_turn: float, n_actions: int = 4):
        self.rng = rng
        self.p_turn = p_turn
        self.n_actions = int(n_actions)
        self.direction = int(rng.integers(self.n_actions))
        self.bumped = False

    def _other(self) -> int:
        if self.n_actions == 1:
            return 0
        n = self.n_actions
        return int((self.direction + 1 + self.rng.integers(n - 1)) % n)

    def action(self) -> int:
        if self.bumped or self.rng.random() < self.p_turn:
            self.direction = self._other()
        return self.direction

    def observe(self, action: int, bumped: bool) -> None:
        """Whatever chose the action, the walk continues from what actually happened."""
        self.direction = int(action)
        self.bumped = bool(bumped)


class EpsilonSchedule:
    """Eq. 7: decay epsilon each time the goal is attained, never below ``eps_min``."""

    def __init__(self, eps_start: float, decay: float, eps_min: float):
        """Values as :class:`ExplorationConfig` checks them (ranges, eps_min <= eps_start)."""
        self.eps = float(eps_start)
        self.decay = float(decay)
        self.eps_min = float(eps_min)

    def goal_attained(self) -> float:
        self.eps = max(self.eps - self.decay, self.eps_min)
        return self.eps


class EpsilonGreedy:
    """Choose between the random walk and a greedy action (one draw per step)."""

    def __init__(self, rng: np.random.Generator,
                 config: ExplorationConfig = ExplorationConfig(), n_actions: int = 4):
        self.rng = rng
        self.walk = RandomWalk(rng, config.p_turn, n_actions)
        self.schedule = EpsilonSchedule(config.eps_start, config.eps_decay, config.eps_min)
        self.ahead: float | None = None     # the next step's draw, made ahead (draw_ahead)
        self.hold: Callable[[], bool] | None = None  # the agent holds the walk (no walk)
        self.ahead_held = False             # whether the draw made ahead was held

    @property
    def epsilon(self) -> float:
        return self.schedule.eps

    def observe(self, action: int, bumped: bool, goal_reached: bool, learn: bool = True
                ) -> None:
        """The outcome of the last action, whatever chose it: the walk continues from what
        happened, and Eq. 7 decays epsilon each time the goal is attained (never during a
        greedy probe, ``learn`` False)."""
        self.walk.observe(action, bumped)
        if learn and goal_reached:
            self.schedule.goal_attained()

    def state_dict(self) -> dict[str, float | int]:
        """Epsilon and the random walk's state (direction, last bump), plain numbers."""
        return {"epsilon": float(self.schedule.eps), "walk_direction": int(self.walk.direction),
                "walk_bumped": int(self.walk.bumped),
                "draw_ahead": -1.0 if self.ahead is None else float(self.ahead),
                "draw_ahead_held": int(self.ahead_held)}

    def load_state_dict(self, d: dict) -> None:
        self.schedule.eps = float(d["epsilon"])
        self.walk.direction = int(d["walk_direction"])
        self.walk.bumped = bool(d["walk_bumped"])
        ahead = float(d.get("draw_ahead", -1.0))
        self.ahead = ahead if ahead >= 0.0 else None
        self.ahead_held = bool(d.get("draw_ahead_held", 0))

    def _held(self) -> bool:
        return self.hold is not None and self.hold()

    def draw_ahead(self) -> bool:
        """Whether the next exploring step walks: its draw ``rng.random() < eps`` made now
        (once; :meth:`explores` then uses it), against epsilon as it is now (it only
        changes when the goal is attained, which ends the episode before the next
        choice)."""
        if self.ahead is None:
            self.ahead = float(self.rng.random())
            self.ahead_held = self._held()
        return self.ahead < self.schedule.eps and not self.ahead_held

    def explores(self, explore: bool = True) -> bool:
        """Draw whether this step explores (always draws when ``explore``, for determinism;
        the draw made ahead if there is one)."""
        if not explore:
            return False
        if self.ahead is None:
            u, held = self.rng.random(), self._held()
        else:
            u, held = self.ahead, self.ahead_held
        self.ahead = None
        return u < self.schedule.eps and not held

    def choose(self, greedy: Callable[[], int | None], explore: bool = True
               ) -> tuple[int, bool]:
        """(action, explored): the walk with probability epsilon, else ``greedy()``, the
        agent's choice, called only then (its tie-breaks draw after the epsilon draw);
        None from it means the agent has no opinion yet and the walk acts."""
        if self.explores(explore):
            return self.walk.action(), True
        a = greedy()
        if a is None:
            return self.walk.action(), True
        return int(a), False
