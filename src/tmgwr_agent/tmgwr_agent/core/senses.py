"""What the agent senses and what it can do: the only facts of the world the core is given.

The paper's agent (Table 1) senses a vector and acts with motor primitives; it is told no
cell, no geometry and no transition model. :class:`Senses` is that contract: the
sensation's dimension and the motor primitives' vectors (the action labels of the
sensorimotor links, Eq. 1-2), and how near the goal sensation a sensation must be for the
world to count the goal reached (``goal_tolerance``, in sensation units: 0 where the goal
is one exact sensation, as a grid cell's coordinates; PointMaze's success radius), and the
sensor's resolution step (``resolution``, sensation units: how far apart two places lie
that the world's moves tell apart; 1 for a grid cell's coordinates, PointMaze's
primitive move in metres), which the preprocessor scales to one feature step. It
comes from the world, as Gymnasium spaces
(:meth:`Senses.from_spaces`): a ``Box`` observation, and ``Discrete`` actions whose
primitives are the world's declared vectors, or one-hot vectors when it declares none.
Nothing in the core assumes more of the sensation than this: the value of the unknown
(:mod:`tmgwr_agent.core.unknown`) learns whatever geometry it uses from the agent's own
moves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


class SensesError(ValueError):
    """A world whose spaces the agent cannot take, with the reason."""


@dataclass(frozen=True, eq=False)
class Senses:
    """``dim``: the sensation's dimension; ``primitives``: one motor vector per action
    (row a is the vector of action a, the label a link made with it carries);
    ``goal_tolerance``: the largest distance (Euclidean, sensation units) from the goal
    sensation at which the world ends an episode at the goal (0: only the goal sensation
    itself); ``resolution``: the sensor's resolution step (sensation units; the module
    doc); ``low``, ``high``: the sensor's range per value (sensation units; None or
    -inf / +inf: unbounded), the bounds of the observation ``Box``."""

    dim: int
    primitives: np.ndarray
    goal_tolerance: float = 0.0
    resolution: float = 1.0
    low: np.ndarray | None = None
    high: np.ndarray | None = None

    def __post_init__(self):
        p = np.ascontiguousarray(self.primitives, dtype=float)
        if p.ndim != 2 or len(p) < 1 or p.shape[1] < 1:
            raise SensesError(f"motor primitives must be a non-empty 2-D array (one vector "
                              f"per action), got shape {p.shape}")
        if not np.all(np.isfinite(p)):
            raise SensesError("motor primitives must be finite")
        if len({tuple(r) for r in p}) != len(p):
            raise SensesError("two actions have the same motor vector: links could not "
                              "tell them apart")
        if int(self.dim) < 1:
            raise SensesError(f"the sensation's dimension must be >= 1, got {self.dim}")
        tol = float(self.goal_tolerance)
        if not math.isfinite(tol) or tol < 0.0:
            raise SensesError(f"the goal tolerance must be a finite distance >= 0 (sensation "
                              f"units), got {self.goal_tolerance}")
        object.__setattr__(self, "primitives", p)
        object.__setattr__(self, "dim", int(self.dim))
        object.__setattr__(self, "goal_tolerance", tol)
        res = float(self.resolution)
        if not math.isfinite(res) or res <= 0.0:
            raise SensesError(f"the sensor's resolution step must be a finite distance > 0 "
                              f"(sensation units), got {self.resolution}")
        object.__setattr__(self, "resolution", res)
        for name, inf in (("low", -np.inf), ("high", np.inf)):
            b = getattr(self, name)
            b = np.full(self.dim, inf) if b is None else np.array(b, dtype=float).reshape(-1)
            if b.shape != (self.dim,) or np.isnan(b).any():
                raise SensesError(f"the sensor's range ({name}) must give {self.dim} "
                                  f"values, none NaN, got {getattr(self, name)}")
            object.__setattr__(self, name, b)
        if np.any(self.low > self.high):
            raise SensesError(f"the sensor's range is empty: low {self.low} exceeds high "
                              f"{self.high}")

    @property
    def bounded(self) -> bool:
        """The world declares a finite range for some value of the sensation."""
        return bool(np.isfinite(self.low).any() or np.isfinite(self.high).any())

    @property
    def n_actions(self) -> int:
        return len(self.primitives)

    @property
    def action_dim(self) -> int:
        return self.primitives.shape[1]

    @classmethod
    def from_spaces(cls, observation_space: Any, action_space: Any,
                    primitives: np.ndarray | None = None,
                    goal_tolerance: float = 0.0, resolution: float = 1.0) -> Senses:
        """From Gymnasium spaces: a 1-D ``Box`` observation and ``Discrete`` actions (their
        ``primitives`` declared by the world, else one-hot), and the world's declared
        ``goal_tolerance`` and ``resolution``; the ``Box``'s bounds are the sensor's range.
        Refused with the reason otherwise."""
        from gymnasium import spaces  # the only place the core meets Gymnasium
        if not isinstance(observation_space, spaces.Box) or \
                len(observation_space.shape) != 1:
            raise SensesError(f"the agent senses a vector: the observation space must be a "
                              f"1-D Box, got {observation_space}")
        if not isinstance(action_space, spaces.Discrete):
            raise SensesError(f"the agent acts with motor primitives: the action space must "
                              f"be Discrete, got {action_space}")
        n = int(action_space.n)
        if primitives is None:
            primitives = np.eye(n)
        primitives = np.asarray(primitives, dtype=float)
        if len(primitives) != n:
            raise SensesError(f"{len(primitives)} motor primitives declared for {n} actions")
        return cls(int(observation_space.shape[0]), primitives, goal_tolerance, resolution,
                   observation_space.low, observation_space.high)
