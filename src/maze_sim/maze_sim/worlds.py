"""The worlds an experiment (or the simulator node) can host, by name: ``--world NAME``.

* ``grid``: :class:`maze_sim.world.GridWorld`, our own grid world (four unit moves);
* ``minigrid``: :class:`maze_sim.minigrid_world.MiniGridWorld`, the maze as a MiniGrid env
  (turn left, turn right, forward; sensation (row, col, cos h, sin h));
* ``pointmaze``: ``maze_sim.pointmaze_world.PointMazeWorld``, the maze as MuJoCo's
  PointMaze (imported on first use; refused as "not available in this build" where that
  module is missing);
* ``gym:ID``: any registered Gymnasium env through :mod:`maze_sim.gym_adapter` (scenarios
  without events only), with keyword arguments from ``--world-kwargs JSON``.

Every name is checked before any work (:func:`parse_world`, :func:`parse_world_kwargs`):
an unknown world or env id, or kwargs that do not parse, raise :class:`WorldError` with a
message naming it (the CLI exits 2 with it, no traceback). The world classes are
imported lazily, so ``grid`` runs need neither MiniGrid nor MuJoCo loaded.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import import_module
from typing import Any, NamedTuple

from maze_sim.maze import Cell, Maze


class WorldError(ValueError):
    """An unknown world name or env id, unparsable kwargs, or a world not in this build."""


#: World names -> (module, class) of the worlds built from a maze file.
WORLDS: dict[str, tuple[str, str]] = {
    "grid": ("maze_sim.world", "GridWorld"),
    "minigrid": ("maze_sim.minigrid_world", "MiniGridWorld"),
    "pointmaze": ("maze_sim.pointmaze_world", "PointMazeWorld"),
}
#: The prefix of a registered Gymnasium env id (``gym:MiniGrid-FourRooms-v0``).
GYM_PREFIX = "gym:"


@dataclass(frozen=True)
class WorldSpec:
    """A parsed ``--world``: ``name`` (a key of :data:`WORLDS`, or ``gym``), the env id
    of a ``gym:ID``, and its kwargs."""

    name: str
    env_id: str | None = None
    kwargs: dict[str, Any] = field(default_factory=dict)

    @property
    def text(self) -> str:
        """The normalised ``--world`` (the JSON's ``world``)."""
        return f"{GYM_PREFIX}{self.env_id}" if self.name == "gym" else self.name

    @property
    def from_maze(self) -> bool:
        """Built from a maze file (events, named goals), not a registered env."""
        return self.name != "gym"


def world_names() -> str:
    return ", ".join(list(WORLDS) + [f"{GYM_PREFIX}ID"])


def parse_world_kwargs(text: str | None) -> dict[str, Any]:
    """``--world-kwargs``: a JSON object (None or empty: no kwargs)."""
    if text is None or not text.strip():
        return {}
    try:
        kwargs = json.loads(text)
    except json.JSONDecodeError as exc:
        raise WorldError(f"--world-kwargs {text!r} is not JSON: {exc.msg} at column "
                         f"{exc.colno}") from None
    if not isinstance(kwargs, dict):
        raise WorldError(f"--world-kwargs {text!r} must be a JSON object "
                         f'({{"name": value, ...}}), got {type(kwargs).__name__}')
    return kwargs


def parse_world(text: str | None, kwargs: str | dict[str, Any] | None = None) -> WorldSpec:
    """``--world`` and ``--world-kwargs`` checked: the world exists (a ``gym:ID`` is
    registered, its family one the adapter maps), the kwargs parse."""
    kw = kwargs if isinstance(kwargs, dict) else parse_world_kwargs(kwargs)
    name = (text or "grid").strip()
    if name.startswith(GYM_PREFIX):
        env_id = name[len(GYM_PREFIX):].strip()
        if not env_id:
            raise WorldError(f"--world {name!r}: give the env id after 'gym:' "
                             f"(gym:MiniGrid-FourRooms-v0)")
        from maze_sim.gym_adapter import AdapterError, check_env_id
        try:
            check_env_id(env_id)
        except AdapterError as exc:
            raise WorldError(str(exc)) from None
        return WorldSpec("gym", env_id, kw)
    if name not in WORLDS:
        raise WorldError(f"unknown world {name!r}; worlds: {world_names()}")
    world_class(name)                    # refuse a world this build does not have, now
    return WorldSpec(name, None, kw)


def world_class(name: str) -> type:
    """The class of a maze world (imported on first use)."""
    module, cls = WORLDS[name]
    try:
        mod = import_module(module)
    except ModuleNotFoundError as exc:
        if exc.name in (module, "minigrid", "mujoco", "gymnasium_robotics"):
            raise WorldError(f"world {name!r} is not available in this build "
                             f"({exc.name} is not installed)") from None
        raise
    return getattr(mod, cls)


def make_world(name: str, maze: Maze, goal: str | Cell = "G",
               max_episode_steps: int | None = None, seed: int | None = None,
               **kwargs: Any):
    """A world by name (``--world``) built from ``maze`` with ``goal``, the episode cap
    and ``seed``; ``kwargs`` go to the world's class (``--world-kwargs``), an unknown one
    refused naming it."""
    spec = name if isinstance(name, WorldSpec) else parse_world(name, kwargs)
    kwargs = {**spec.kwargs, **kwargs}
    if not spec.from_maze:
        from maze_sim.gym_adapter import AdapterError, make_gym_world
        try:
            return make_gym_world(spec.env_id, max_episode_steps=max_episode_steps,
                                  seed=seed, **kwargs)
        except AdapterError as exc:
            raise WorldError(str(exc)) from None
    cls = world_class(spec.name)
    try:
        return cls(maze, goal=goal, max_episode_steps=max_episode_steps, seed=seed,
                   **kwargs)
    except TypeError as exc:
        if "unexpected keyword" in str(exc):
            raise WorldError(f"world {spec.name!r}: {exc}") from None
        raise


class Declared(NamedTuple):
    """What a hosted world declares to an agent besides its sensations (:func:`declared`)."""

    #: how near the goal sensation a sensation ends an episode at the goal (sensation
    #: units; 0 when the world declares none: the goal is one sensation)
    goal_tolerance: float
    #: the sensor's resolution step (sensation units; 1 when the world declares none)
    resolution: float
    #: the ``Box`` the sensation lies in, its bounds the sensor's range (``None``: the grid
    #: world, which declares no spaces)
    observation_space: Any
    #: the ``Discrete`` actions and their motor vectors (``None``: one-hot)
    action_space: Any
    primitives: Any


def env_spaces(env) -> tuple[Any, Any, Any]:
    """A Gymnasium env's declared spaces: ``(observation_space, action_space, primitives)``,
    the motor vectors being the unwrapped env's ``primitive_vectors`` when it has them."""
    return (env.observation_space, env.action_space,
            getattr(env.unwrapped, "primitive_vectors", None))


def declared(world) -> Declared:
    """What a hosted world declares: its ``goal_tolerance`` and ``sensor_resolution``, and
    the spaces it declares itself (``observation_space``, ``action_space``,
    ``primitive_vectors``: PointMaze), else those of the Gymnasium env it drives (``env``,
    seen through its sensation wrapper: MiniGrid, ``gym:ID``), else none (the grid world).
    The one place that decides which ``Box`` holds the sensor's range: the in-process
    agent's ``Senses`` (``tmgwr_agent.world_senses``) and the simulator node's
    ``SensorInfo`` (:func:`declared_sensor`) both read it here."""
    tol = float(getattr(world, "goal_tolerance", 0.0))
    res = float(getattr(world, "sensor_resolution", 1.0))
    if getattr(world, "observation_space", None) is not None:
        return Declared(tol, res, world.observation_space, world.action_space,
                        getattr(world, "primitive_vectors", None))
    if getattr(world, "env", None) is not None:
        return Declared(tol, res, *env_spaces(world.env))
    return Declared(tol, res, None, None, None)


def declared_sensor(world) -> tuple[float, Any, Any]:
    """What a hosted world declares of its sensor (:func:`declared`), as the simulator
    node publishes it for the graph's agent (``SensorInfo``): ``(goal_tolerance, low,
    high)``, the range being the bounds of the sensation's ``Box`` (``None, None`` when the
    world declares none: the grid world)."""
    d = declared(world)
    if d.observation_space is None:
        return d.goal_tolerance, None, None
    return d.goal_tolerance, d.observation_space.low, d.observation_space.high
