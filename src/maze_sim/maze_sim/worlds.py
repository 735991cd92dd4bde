"""The worlds built from a maze file, by name (``--world NAME``, the node's ``world``).

Minimal registry (``grid``, ``pointmaze``); the full one (``minigrid``, ``gym:ID``,
``--world-kwargs``) keeps this signature. A world class is imported on first use, so a
``grid`` run loads neither Gymnasium-Robotics nor MuJoCo.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

from maze_sim.maze import Cell, Maze


class WorldError(ValueError):
    """An unknown world name, or a world this build cannot load."""


#: World names -> (module, class).
WORLDS: dict[str, tuple[str, str]] = {
    "grid": ("maze_sim.world", "GridWorld"),
    "pointmaze": ("maze_sim.pointmaze_world", "PointMazeWorld"),
}


def world_class(name: str) -> type:
    """The class of world ``name``; :class:`WorldError` naming it when unknown."""
    if name not in WORLDS:
        raise WorldError(f"unknown world {name!r}; worlds: {', '.join(WORLDS)}")
    module, cls = WORLDS[name]
    return getattr(import_module(module), cls)


def make_world(name: str, maze: Maze, goal: str | Cell = "G",
               max_episode_steps: int | None = None, seed: int | None = None,
               **kwargs: Any):
    """World ``name`` built from ``maze`` with ``goal``, the episode cap and ``seed``;
    ``kwargs`` go to the world's class."""
    cls = world_class(name)
    try:
        return cls(maze, goal=goal, max_episode_steps=max_episode_steps, seed=seed, **kwargs)
    except TypeError as exc:
        if "unexpected keyword" in str(exc):
            raise WorldError(f"world {name!r}: {exc}") from None
        raise
