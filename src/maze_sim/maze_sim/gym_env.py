"""Our mazes as a ``gymnasium.Env``, so Gymnasium wrappers and other RL code can drive them.

An adapter over :class:`maze_sim.world.GridWorld` rather than a second simulator: moves,
bumps, goals, events and truncation stay the ones the experiments use, so a Gymnasium run
and an experiment run of the same maze agree step for step. What the adapter adds is the
Gymnasium contract: spaces, ``reset(seed=, options=)`` with the sensor noise drawn from
``self.np_random``, and an ``info`` dict of per-step facts only (the world's global step and
episode counters would make two seeded runs differ).

Importing this module registers ``maze_sim/Maze-v0``::

    import gymnasium
    env = gymnasium.make("maze_sim.gym_env:maze_sim/Maze-v0", goal="2", sensor_noise=0.1)
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from maze_sim.maze import DEFAULT_MAZE, N_ACTIONS, Cell, Maze, maze_file
from maze_sim.world import GridWorld

ENV_ID = "maze_sim/Maze-v0"

#: With sensor noise the observation box is widened by this many standard deviations on each
#: side and observations are clipped to it: Gaussian noise is unbounded, while check_env
#: warns about infinite bounds. A draw beyond 6 sigma has probability 2e-9 per coordinate.
NOISE_BOUND_SIGMAS = 6.0


class MazeEnv(gymnasium.Env):
    """A maze with one agent; observation = sensed (row, col), action = ``maze.ACTIONS`` index.

    Parameters
    ----------
    maze : a :class:`Maze`, a maze file path, or the name of an installed maze
    goal : goal name ('G', '1'..'9') or (row, col) cell
    sensor_noise : standard deviation of the Gaussian noise on the sensed coordinates (cells)
    max_episode_steps : the world truncates an episode after this many steps (None = never),
        with the experiments' rule: a step that reaches a goal is never also truncated.
        ``gymnasium.make(..., max_episode_steps=N)`` adds a ``TimeLimit`` wrapper instead.
    render_mode : None or "ansi" (the grid as text, ``@`` = agent)
    world : an existing :class:`GridWorld` to adapt instead of a new one (``maze``, ``goal``,
        ``sensor_noise`` and ``max_episode_steps`` are then the world's): the experiments
        step their world themselves and put the sensor wrappers of
        :mod:`maze_sim.sensors` over it

    ``reset`` options (both optional): ``{"goal": "2" or (r, c)}`` moves the goal from this
    episode on; ``{"start": (r, c)}`` starts this episode at another free cell. Events persist
    across episodes: fire them with ``env.unwrapped.fire_event("a")``.
    """

    metadata = {"render_modes": ["ansi"], "render_fps": 4}

    def __init__(self, maze: Maze | str | Path = DEFAULT_MAZE, goal: str | Cell = "G",
                 sensor_noise: float = 0.0, max_episode_steps: int | None = None,
                 render_mode: str | None = None, *, world: GridWorld | None = None):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of "
                             f"{self.metadata['render_modes']}, got {render_mode!r}")
        if world is not None:
            maze = world.maze
        elif not isinstance(maze, Maze):
            maze = Maze.from_file(maze_file(maze))
        self.world = world or GridWorld(maze, goal, sensor_noise, max_episode_steps)
        self.render_mode = render_mode
        margin = NOISE_BOUND_SIGMAS * self.world.sensor_noise
        rows, cols = maze.shape
        self.observation_space = spaces.Box(
            low=np.array([-margin, -margin]),
            high=np.array([rows - 1 + margin, cols - 1 + margin]), dtype=np.float64)
        self.action_space = spaces.Discrete(N_ACTIONS)

    def _observe(self, sensed: np.ndarray) -> np.ndarray:
        return np.clip(sensed, self.observation_space.low, self.observation_space.high)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.world.rng = self.np_random   # the sensor noise comes from Gymnasium's generator
        options = options or {}
        unknown = set(options) - {"goal", "start"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)} (known: goal, start)")
        if "goal" in options:
            self.world.set_goal(options["goal"])
        start = options.get("start")
        sensed, _ = self.world.reset(start=None if start is None else tuple(map(int, start)))
        return self._observe(sensed), {"cell": self.world.cell, "goal": self.world.goal}

    def step(self, action):
        sensed, reward, terminated, truncated, step = self.world.step(int(action))
        info = {"cell": step.cell, "bumped": step.bumped, "reached_goal": step.reached_goal,
                "reached_previous_goal": step.reached_previous_goal}
        return self._observe(sensed), reward, terminated, bool(truncated), info

    def set_goal(self, goal: str | Cell, keep_previous: bool = False) -> Cell:
        """Move the goal now; with ``keep_previous`` the old goal stays terminal (sec. 5.2.1)."""
        return self.world.set_goal(goal, keep_previous)

    def fire_event(self, name: str) -> None:
        """Fire a maze event: its lowercase cells become walls, its uppercase walls open."""
        self.world.fire_event(name)

    def render(self) -> str | None:
        if self.render_mode != "ansi":
            return None
        grid = np.where(self.world.walls, "#", ".").astype("<U1")
        grid[self.world.goal] = "G"
        if self.world.previous_goal is not None:
            grid[self.world.previous_goal] = "g"
        grid[self.world.cell] = "@"
        return "\n".join("".join(row) for row in grid) + "\n"


if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="maze_sim.gym_env:MazeEnv")
