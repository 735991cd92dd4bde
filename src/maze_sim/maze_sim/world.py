"""The grid world the agents live in: a Gymnasium-style ``reset()`` / ``step()`` API.

The agent senses the coordinates of its cell (section 5.1 of the paper), optionally with
Gaussian noise. Four actions (``maze.ACTIONS``); a move into a wall leaves the agent in
place and is reported as a bump. An episode terminates at the current goal, or at the
previous goal while one is set (the goal-change scenario, section 5.2.1). Events fired at
runtime turn free cells into walls or open walls (README, Maze format).

``step`` returns ``(observation, reward, terminated, truncated, info)``; the reward is 1.0
on reaching the current goal and 0.0 otherwise: agents compute their own rewards (Eq. 8-10)
from ``info``, never from this number.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from maze_sim.maze import ACTION_VECTORS, N_ACTIONS, Cell, Maze, MazeError, move


@dataclass(frozen=True)
class StepInfo:
    """What a step did, in world terms (the simulator's truth, not the agent's)."""

    cell: Cell
    action: int
    bumped: bool
    reached_goal: bool            # the current goal
    reached_previous_goal: bool   # the previous goal (goal-change scenario)
    step: int                     # steps since the world was created
    episode: int

    @property
    def terminated(self) -> bool:
        return self.reached_goal or self.reached_previous_goal


class GridWorld:
    """A maze with an agent in it.

    Parameters
    ----------
    maze : Maze
    goal : goal name ('G', '1'..'9') or (row, col) cell
    sensor_noise : standard deviation of the Gaussian noise added to the sensed
        coordinates, in cells (0 = noise-free, as in the paper)
    max_episode_steps : truncate an episode after this many steps (None = never)
    seed : seed of the noise generator
    """

    action_vectors = ACTION_VECTORS
    n_actions = N_ACTIONS

    def __init__(self, maze: Maze, goal: str | Cell = "G", sensor_noise: float = 0.0,
                 max_episode_steps: int | None = None, seed: int | None = None):
        if not np.isfinite(sensor_noise) or sensor_noise < 0:
            raise ValueError(f"sensor_noise must be finite and >= 0, got {sensor_noise}")
        self.maze = maze
        self.walls = maze.walls.copy()
        self.fired: list[str] = []
        self.goal: Cell = maze.goal_cell(goal)
        self.previous_goal: Cell | None = None
        self.sensor_noise = float(sensor_noise)
        self.max_episode_steps = max_episode_steps
        self.rng = np.random.default_rng(seed)
        self.cell: Cell = maze.start
        self.total_steps = 0
        self.episode = 0
        self.episode_steps = 0

    # ---------------------------------------------------------------- sensing
    def sense(self, cell: Cell | None = None) -> np.ndarray:
        """The raw observation: (row, col) of the cell, plus sensor noise."""
        r, c = self.cell if cell is None else cell
        obs = np.array([r, c], dtype=float)
        if self.sensor_noise > 0:
            obs += self.rng.normal(0.0, self.sensor_noise, size=2)
        return obs

    def goal_observation(self) -> np.ndarray:
        """The noise-free sensation at the goal: what the agent is asked to reach."""
        return np.array(self.goal, dtype=float)

    # ---------------------------------------------------------------- control
    def reset(self, seed: int | None = None, start: Cell | None = None):
        """Start a new episode at the start cell (or ``start``)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        if start is not None:
            self.maze.check_free(*start, walls=self.walls)
        self.cell = start if start is not None else self.maze.start
        if self.walls[self.cell]:
            raise MazeError(f"the start cell {self.cell} is a wall after events "
                            f"{self.fired}", self.maze.source)
        self.episode += 1
        self.episode_steps = 0
        return self.sense(), {"cell": self.cell, "episode": self.episode}

    def step(self, action: int):
        if not 0 <= int(action) < N_ACTIONS:
            raise ValueError(f"action must be in 0..{N_ACTIONS - 1}, got {action}")
        self.cell, bumped = move(self.walls, self.cell, int(action))
        self.total_steps += 1
        self.episode_steps += 1
        info = StepInfo(cell=self.cell, action=int(action), bumped=bumped,
                        reached_goal=self.cell == self.goal,
                        reached_previous_goal=(self.previous_goal is not None
                                               and self.cell == self.previous_goal),
                        step=self.total_steps, episode=self.episode)
        truncated = (self.max_episode_steps is not None
                     and self.episode_steps >= self.max_episode_steps
                     and not info.terminated)
        return (self.sense(), 1.0 if info.reached_goal else 0.0, info.terminated, truncated,
                info)

    def set_goal(self, goal: str | Cell, keep_previous: bool = False) -> Cell:
        """Move the goal. With ``keep_previous`` the old goal stays a terminal cell."""
        new = self.maze.goal_cell(goal) if isinstance(goal, str) else tuple(map(int, goal))
        self.maze.check_free(*new, walls=self.walls)
        self.previous_goal = self.goal if keep_previous and self.goal != new else None
        self.goal = new  # type: ignore[assignment]
        return self.goal

    def fire_event(self, name: str) -> None:
        """Fire a maze event: its lowercase cells become walls, its uppercase walls open."""
        self.walls = self.maze.walls_after(self.fired + [name])
        self.fired.append(name)

    def set_cell(self, r: int, c: int, blocked: bool) -> None:
        rows, cols = self.walls.shape
        if not (0 <= r < rows and 0 <= c < cols):
            raise MazeError(f"cell (row {r}, col {c}) is outside the {rows}x{cols} maze",
                            self.maze.source)
        if blocked and (r, c) in (self.cell, self.goal):
            raise MazeError(f"cell (row {r}, col {c}) holds the agent or the goal and "
                            "cannot be blocked", self.maze.source)
        self.walls[r, c] = blocked

    def shortest_path_length(self, a: Cell | None = None, b: Cell | None = None) -> int:
        """BFS steps in the current layout (default: start to goal)."""
        return self.maze.shortest_path_length(a or self.maze.start, b or self.goal,
                                              walls=self.walls)
