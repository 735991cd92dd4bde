"""The world as the agents sense it (``experiment --sensor SPEC``), and what a table keys on.

:class:`SensedWorld` is the experiments' world: a :class:`~maze_sim.world.GridWorld` (the
experimenter's truth: cells, goals, events, shortest paths) whose observations go through
the sensor wrappers of :mod:`maze_sim.sensors` (the same ``ObservationWrapper`` code a
Gymnasium user runs, applied by :func:`maze_sim.sensors.sense` because the loop steps the
world itself). What an agent is handed:

* every agent: the sensed observation, ``info.bumped`` and the outcome flags, and the goal
  *sensation* (:func:`maze_sim.sensors.goal_sensation`, noise-free);
* a tabular agent: ``state`` (and ``info.cell``, ``goal_state``) = :func:`discretise` of
  what is sensed, never the true cell. Under identity sensing that *is* the cell: the
  discretisation of a noise-free (row, col) on the one-cell grid gives (row, col) back, so
  the world's cell is passed as it always was (the JSON of a run without ``--sensor`` is
  unchanged).

Which agents run under a transform (:func:`check_sensor`): TMGWR (2-D sensations only
until its core takes any dimension), and the tabular agents that learn their table online
(:data:`SENSED_TABLE_AGENTS`). ``model_based`` is given the maze's cells as its model and
has no model of a sensed space, ``freespace`` the grid's cells and four moves: they run
under identity sensing only.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache
from typing import Hashable

import numpy as np

from maze_sim.gym_env import MazeEnv
from maze_sim.maze import Cell
from maze_sim.sensors import SensorSpec, goal_sensation, parse_sensor, sense, wrap
from maze_sim.world import GridWorld
from tmgwr_agent.core.senses import Senses
from tmgwr_agent.world_senses import maze_senses, world_senses

#: Agents whose table can key on :func:`discretise` of a sensation.
SENSED_TABLE_AGENTS = ("q_learning", "dyna_q_plus", "rmax")
#: Agents that take the sensation itself, of any dimension (core/senses.py).
SENSATION_AGENTS = ("tmgwr",)

#: The compass of a local view is read in this many sectors by a table (plus "at goal").
COMPASS_SECTORS = 8

#: Spawn-key entry of the sensor-noise stream beside a trial's seed (the agent's generator
#: is ``default_rng(seed)`` itself), so noise and agent draw from independent streams.
NOISE_STREAM = 0x5E4502


@lru_cache(maxsize=64)
def grid_step(spec: SensorSpec) -> tuple[float, float]:
    """The cell size of the table's grid in sensed units, per sensed axis.

    Axis-aligned sensing (rotation a multiple of 90 degrees): one cell's sensed extent
    along each axis (``|SX|``, ``|SY|``, swapped by 90 / 270 degrees), and the grid is
    centred on the cells, so every cell is one state and noise below half a cell keeps it
    there. Any other rotation: no axis grid can be centred on a rotated lattice; the side is
    ``min(SX, SY) / sqrt 2``, the largest square on which no two cells (at least
    ``min(SX, SY)`` apart in sensed space) can share a state.
    """
    M = spec.linear_map()
    if all(np.count_nonzero(row) == 1 for row in M):
        ext = np.abs(M).sum(axis=1)
        return float(ext[0]), float(ext[1])
    side = min(spec.scale) / math.sqrt(2.0)
    return side, side


def discretise(obs: np.ndarray, spec: SensorSpec) -> Hashable:
    """The tabular state of a sensation: the one discretisation every tabular agent uses.

    * a position: ``floor(obs / step + 1/2)`` per axis on the grid of :func:`grid_step`;
    * a local view: the window's wall bits and the compass sector (``COMPASS_SECTORS``
      sectors of the direction to the goal, centred on the axes; -1 at the goal).
    """
    if spec.view:
        window = tuple(int(x) for x in obs[:-2])
        dr, dc = float(obs[-2]), float(obs[-1])
        sector = -1 if dr == 0 and dc == 0 else \
            int(math.floor(math.atan2(dc, dr) / (2 * math.pi / COMPASS_SECTORS) + 0.5)) \
            % COMPASS_SECTORS
        return window + (sector,)
    hx, hy = grid_step(spec)
    return (int(math.floor(obs[0] / hx + 0.5)), int(math.floor(obs[1] / hy + 0.5)))


def noise_rng(seed: np.random.SeedSequence | None) -> np.random.Generator:
    """The sensor-noise generator of a trial (its own stream beside the agent's)."""
    if seed is None:
        return np.random.default_rng()
    return np.random.default_rng(np.random.SeedSequence(
        seed.entropy, spawn_key=tuple(seed.spawn_key) + (NOISE_STREAM,)))


class SensedWorld:
    """A :class:`GridWorld` seen through a sensor spec. Attributes it does not define are
    the world's (``cell``, ``goal``, ``set_goal``, ``fire_event``, ... : the experimenter's
    truth); ``reset`` / ``step`` return sensed observations, ``info.cell`` replaced by the
    tabular ``state``."""

    def __init__(self, world: GridWorld, spec: SensorSpec | str | None = None,
                 rng: np.random.Generator | None = None):
        self.world = world
        self.spec = spec if isinstance(spec, SensorSpec) else parse_sensor(spec)
        self.identity = self.spec.identity
        self.env = wrap(MazeEnv(world=world), self.spec, rng)
        self.state: Hashable = world.cell

    def __getattr__(self, name: str):
        if name == "world":              # not set yet (copy, unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.world, name)

    def _sensed(self, raw: np.ndarray) -> np.ndarray:
        obs = sense(self.env, raw)
        self.state = discretise(obs, self.spec)
        return obs

    def reset(self, seed: int | None = None, start: Cell | None = None):
        obs, info = self.world.reset(seed, start)
        if self.identity:
            self.state = self.world.cell
            return obs, info
        return self._sensed(obs), {"episode": info["episode"], "state": self.state}

    def step(self, action: int):
        obs, reward, terminated, truncated, info = self.world.step(action)
        if self.identity:
            self.state = info.cell
            return obs, reward, terminated, truncated, info
        obs = self._sensed(obs)
        return obs, reward, terminated, truncated, replace(info, cell=self.state)

    def goal_observation(self) -> np.ndarray:
        """The noise-free sensation at the goal."""
        if self.identity:
            return self.world.goal_observation()
        return goal_sensation(self.env, self.world.goal)

    @property
    def senses(self) -> Senses:
        """What an agent that learns from its sensation is given: the sensed dimension and
        the grid world's four motor primitives."""
        return maze_senses(self.spec.dim)

    @property
    def goal_state(self) -> Hashable:
        """The tabular state of the goal sensation."""
        if self.identity:
            return self.world.goal
        return discretise(self.goal_observation(), self.spec)


class HostedWorld:
    """A world of :mod:`maze_sim.worlds` other than the grid (``--world minigrid``,
    ``gym:ID``, ...), sensed as it senses: its own sensation wrapper, its own motor
    primitives, its own declared discretisation for the tables (``state``,
    ``goal_state``, ``info.cell``). Attributes it does not define are the world's."""

    identity = False

    def __init__(self, world):
        self.world = world

    def __getattr__(self, name: str):
        if name == "world":
            raise AttributeError(name)
        return getattr(self.world, name)

    def reset(self, seed: int | None = None, start: Cell | None = None):
        return self.world.reset(seed, start)

    def step(self, action: int):
        return self.world.step(action)

    @property
    def senses(self) -> Senses:
        """The world's senses (:func:`~tmgwr_agent.world_senses.world_senses`): the
        sensation's dimension and one motor vector per action (one-hot unless the world
        declares ``primitive_vectors``)."""
        return world_senses(self.world)


def given_cells(agents) -> str | None:
    """The first of ``agents`` (specs such as ``tmgwr:paper``) that is given the grid
    world's true cells rather than learning from what it senses, or None."""
    for a in agents:
        name = a.partition(":")[0]
        if name not in SENSATION_AGENTS and name not in SENSED_TABLE_AGENTS:
            return a
    return None


def check_world(agents, world) -> str | None:
    """Why ``agents`` cannot run in ``world`` (a :class:`maze_sim.worlds.WorldSpec`), or
    None: in a world other than the grid only the agents that learn from what they sense
    run (model_based and freespace are given the grid's cells and moves)."""
    if world is None or world.name == "grid":
        return None
    a = given_cells(agents)
    if a is None:
        return None
    return (f"agent {a!r} cannot run in --world {world.text}: it is given the grid "
            f"world's cells and four moves (agents that learn from what they "
            f"sense: tmgwr, {', '.join(SENSED_TABLE_AGENTS)})")


def check_sensor(agents, spec: SensorSpec) -> str | None:
    """Why ``agents`` (specs such as ``tmgwr:paper``) cannot run under ``spec``, or None."""
    if spec.identity:
        return None
    a = given_cells(agents)
    if a is None:
        return None
    return (f"agent {a!r} cannot run under --sensor {spec.text}: it keys on the "
            f"true cell (agents that learn from what they sense: tmgwr, "
            f"{', '.join(SENSED_TABLE_AGENTS)})")
