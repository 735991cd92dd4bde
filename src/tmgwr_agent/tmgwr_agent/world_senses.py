"""The senses a world gives an agent (:class:`~tmgwr_agent.core.senses.Senses`).

The maze simulator's observation is the agent's (row, col) and its four actions move one
cell up, down, left or right: its declared motor primitives are those unit vectors
(``maze_sim.maze.ACTION_VECTORS``). Another world (``maze_sim.worlds``) declares its own:
its sensation as ``observation_space``, its actions as ``action_space`` and their motor
vectors as ``primitive_vectors`` (:func:`world_senses`), and how near the goal sensation
a sensation must be for it to end an episode at the goal as ``goal_tolerance`` (sensation
units; 0 when absent: the goal is one sensation), and its sensor's resolution step as
``sensor_resolution`` (sensation units; 1 when absent). This is the one place outside the
simulator that says so; the core is handed the result and knows nothing of mazes.
"""

from __future__ import annotations

import numpy as np

from maze_sim.maze import ACTION_VECTORS
from tmgwr_agent.core.senses import Senses


def maze_senses(dim: int = 2) -> Senses:
    """The grid world's senses: a sensation of ``dim`` values (2: the cell's coordinates;
    more under a sensing transform such as a local view) and its four unit moves."""
    return Senses(dim, ACTION_VECTORS)


def env_senses(env, goal_tolerance: float = 0.0, resolution: float = 1.0) -> Senses:
    """The senses of a Gymnasium env: its spaces, and its declared motor primitives
    (``primitive_vectors`` of the unwrapped env) when it has them; ``goal_tolerance`` and
    ``resolution``: what the world that drives it declares."""
    return Senses.from_spaces(env.observation_space, env.action_space,
                              getattr(env.unwrapped, "primitive_vectors", None),
                              goal_tolerance, resolution)


def world_senses(world) -> Senses:
    """The senses of a world hosted by name (``maze_sim.worlds``): those a world declares
    itself (``observation_space``, ``action_space``, ``primitive_vectors``: PointMaze),
    else those of the Gymnasium env it drives (``env``, seen through its sensation
    wrapper: MiniGrid, ``gym:ID``), else the grid world's (:func:`maze_senses`); each with
    the world's declared ``goal_tolerance`` (0 when it declares none) and
    ``sensor_resolution`` (1 when it declares none)."""
    tol = float(getattr(world, "goal_tolerance", 0.0))
    res = float(getattr(world, "sensor_resolution", 1.0))
    if hasattr(world, "observation_space"):
        return Senses.from_spaces(world.observation_space, world.action_space,
                                  getattr(world, "primitive_vectors", None), tol, res)
    if getattr(world, "env", None) is not None:
        return env_senses(world.env, tol, res)
    return maze_senses()


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
