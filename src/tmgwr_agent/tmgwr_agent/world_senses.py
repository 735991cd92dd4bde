"""The senses a world gives an agent (:class:`~tmgwr_agent.core.senses.Senses`).

The maze simulator's observation is the agent's (row, col) and its four actions move one
cell up, down, left or right: its declared motor primitives are those unit vectors
(``maze_sim.maze.ACTION_VECTORS``). Another world (``maze_sim.worlds``) declares its own:
its sensation as ``observation_space``, its actions as ``action_space`` and their motor
vectors as ``primitive_vectors`` (:func:`world_senses`), and how near the goal sensation
a sensation must be for it to end an episode at the goal as ``goal_tolerance`` (sensation
units; 0 when absent: the goal is one sensation), and its sensor's resolution step as
``sensor_resolution`` (sensation units; 1 when absent). Which of them a world declares is
read in one place, ``maze_sim.worlds.declared`` (the simulator node publishes the same for
the graph's agent); this module turns it into ``Senses``: the core is handed the result and
knows nothing of mazes.
"""

from __future__ import annotations

import numpy as np

from maze_sim.maze import ACTION_VECTORS
from maze_sim.worlds import declared, env_spaces
from tmgwr_agent.core.senses import Senses


def maze_senses(dim: int = 2) -> Senses:
    """The grid world's senses: a sensation of ``dim`` values (2: the cell's coordinates;
    more under a sensing transform such as a local view) and its four unit moves."""
    return Senses(dim, ACTION_VECTORS)


def env_senses(env, goal_tolerance: float = 0.0, resolution: float = 1.0) -> Senses:
    """The senses of a Gymnasium env: its spaces, and its declared motor primitives
    (``maze_sim.worlds.env_spaces``); ``goal_tolerance`` and ``resolution``: what the world
    that drives it declares."""
    return Senses.from_spaces(*env_spaces(env), goal_tolerance, resolution)


def world_senses(world) -> Senses:
    """The senses of a world hosted by name (``maze_sim.worlds``): what it declares
    (``maze_sim.worlds.declared``: its own spaces, else those of the Gymnasium env it
    drives, with its goal tolerance and resolution), else the grid world's
    (:func:`maze_senses`)."""
    d = declared(world)
    if d.observation_space is None:
        return maze_senses()
    return Senses.from_spaces(d.observation_space, d.action_space, d.primitives,
                              d.goal_tolerance, d.resolution)


#: The worlds the ROS graph hosts (the agent nodes know their senses by name).
GRAPH_WORLDS = ("grid", "minigrid", "pointmaze")


def named_world_senses(name: str, **kwargs) -> Senses:
    """The senses of world ``name`` without building it (what the agent nodes are given:
    they host no world): the grid's, MiniGrid's (``(row, col, cos h, sin h)`` and its three
    native actions, one-hot), or PointMaze's (``velocity``: 4 values). The sensor's range
    depends on the maze file, so it is not here: the graph's estimator is told it, with the
    goal tolerance, by the simulator that hosts the world (``SensorInfo`` on
    ``/world_senses``, docs/graph.md)."""
    if name == "grid":
        return maze_senses()
    if name == "minigrid":
        from maze_sim.minigrid_world import N_ACTIONS, PoseSensation
        return Senses(4, np.eye(N_ACTIONS), PoseSensation.GOAL_TOLERANCE)
    if name == "pointmaze":
        from maze_sim.pointmaze_world import PRIMITIVES, SUCCESS_RADIUS, step_length
        return Senses(4 if kwargs.get("velocity") else 2, PRIMITIVES, SUCCESS_RADIUS,
                      step_length())
    raise ValueError(f"unknown world {name!r}; worlds the graph hosts: "
                     f"{', '.join(GRAPH_WORLDS)}")


def named_declaration(name: str) -> tuple[float, None] | None:
    """The sensor declaration of world ``name`` when its name says it in full, in any units
    and for any maze: the grid's, which declares neither a goal tolerance nor a range (it
    has no spaces: ``maze_sim.worlds.declared``), so ``(0.0, None)``. None for a world whose
    range lies in its maze file (MiniGrid, PointMaze): the graph's agent must be told it
    (``SensorInfo``). A recording made before the declarations existed carries none; what
    the graph's agent was told then is exactly the grid's."""
    if name == "grid":
        senses = maze_senses()
        return senses.goal_tolerance, None
    return None


def drawn_at(name: str, sensation) -> tuple[float, float]:
    """Where a sensation of world ``name`` lies in the simulator's ``maze`` frame (its map
    markers, its /agent_pose): the grid's (row, col) at x = col, y = row; PointMaze's
    (x, y) as it is."""
    if name == "pointmaze":
        return float(sensation[0]), float(sensation[1]) if len(sensation) > 1 else 0.0
    return float(sensation[1]) if len(sensation) > 1 else 0.0, float(sensation[0])


def node_senses(name: str) -> Senses:
    """:func:`named_world_senses` of a node's ``world`` parameter; an unknown world is a
    parameter error naming it (the node does not start)."""
    from tmgwr_common.params import ParamError
    try:
        return named_world_senses(name)
    except ValueError as exc:
        raise ParamError(f"parameter 'world' = {name!r}: {exc}") from None
