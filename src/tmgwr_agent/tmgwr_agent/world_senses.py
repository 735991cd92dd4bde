"""The senses the grid world gives an agent (:class:`~tmgwr_agent.core.senses.Senses`).

The maze simulator's observation is the agent's (row, col) and its four actions move one
cell up, down, left or right: its declared motor primitives are those unit vectors
(``maze_sim.maze.ACTION_VECTORS``). This is the one place outside the simulator that says
so; the core is handed the result and knows nothing of mazes.
"""

from __future__ import annotations

from maze_sim.maze import ACTION_VECTORS
from tmgwr_agent.core.senses import Senses


def maze_senses(dim: int = 2) -> Senses:
    """The grid world's senses: a sensation of ``dim`` values (2: the cell's coordinates;
    more under a sensing transform such as a local view) and its four unit moves."""
    return Senses(dim, ACTION_VECTORS)


def env_senses(env) -> Senses:
    """The senses of a Gymnasium env: its spaces, and its declared motor primitives
    (``primitive_vectors`` of the unwrapped env) when it has them."""
    return Senses.from_spaces(env.observation_space, env.action_space,
                              getattr(env.unwrapped, "primitive_vectors", None))
