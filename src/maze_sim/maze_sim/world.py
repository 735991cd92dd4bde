"""The grid world the agents live in: a Gymnasium-style ``reset()`` / ``step()`` API.

The agent senses the coordinates of its cell (section 5.1 of the paper), optionally with
Gaussian noise. Four actions (``maze.ACTIONS``); a move into a wall leaves the agent in
place and is reported as a bump. An episode terminates at the current goal, or at the
previous goal while one is set (the goal-change scenario, section 5.2.1). Events fired at
runtime turn free cells into walls or open walls (docs/mazes.md, Maze format).

Edits keep the task solvable or are refused: :meth:`GridWorld.set_cell`,
:meth:`GridWorld.fire_event` and :meth:`GridWorld.set_goal` raise :class:`EditRefused` (a
:class:`MazeError` whose message gives the reason), leaving the world unchanged, rather than
wall in the start, the goal (or a goal requested for later, :meth:`GridWorld.request_goal`),
or the agent during an episode, or cut the last route to the goal from the start or from the
agent. The maze_sim node answers its services with that message.

``step`` returns ``(observation, reward, terminated, truncated, info)``; the reward is 1.0
on reaching the current goal and 0.0 otherwise: agents compute their own rewards (Eq. 8-10)
from ``info``, never from this number.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from maze_sim.maze import ACTION_VECTORS, N_ACTIONS, Cell, Maze, MazeError, bfs_distances, move


class EditRefused(MazeError):
    """A goal, cell or event change refused because the task would become unsolvable."""


def _at(cell: Cell) -> str:
    return f"(row {cell[0]}, col {cell[1]})"


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
        self.cell: Cell = maze.start
        self.in_episode = False          # the agent's cell matters (reset .. terminal step)
        self.pending_goal: Cell | None = None
        self.goal: Cell = self.check_goal(goal)
        self.previous_goal: Cell | None = None
        self.sensor_noise = float(sensor_noise)
        self.max_episode_steps = max_episode_steps
        self.rng = np.random.default_rng(seed)
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
        self.in_episode = True
        return self.sense(), {"cell": self.cell, "episode": self.episode}

    def end_episode(self) -> None:
        """The episode was cut from outside (an experimenter's step limit, not the world's
        cap): the agent is no longer in one, so edits need not keep its cell reachable
        (the next :meth:`reset` moves it to the start)."""
        self.in_episode = False

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
        if info.terminated or truncated:
            self.in_episode = False      # the next reset moves the agent to the start
        return (self.sense(), 1.0 if info.reached_goal else 0.0, info.terminated, truncated,
                info)

    # ---------------------------------------------------------------- edits
    def check_goal(self, goal: str | Cell) -> Cell:
        """The cell of ``goal`` (a name or (row, col)) if it can be the goal: inside the
        maze, free, and reachable from the start (and from the agent during an episode);
        otherwise :class:`MazeError` saying why."""
        new = self.maze.goal_cell(goal) if isinstance(goal, str) else tuple(map(int, goal))
        self.maze.check_free(*new, walls=self.walls)
        what = f"goal {_at(new)}"
        if bfs_distances(self.walls, self.maze.start)[new] < 0:
            raise EditRefused(f"{what} refused: it cannot be reached from the start "
                              f"{_at(self.maze.start)}", self.maze.source)
        if self.in_episode and bfs_distances(self.walls, self.cell)[new] < 0:
            raise EditRefused(f"{what} refused: it cannot be reached from the agent at "
                              f"{_at(self.cell)}", self.maze.source)
        return new  # type: ignore[return-value]

    def set_goal(self, goal: str | Cell, keep_previous: bool = False) -> Cell:
        """Move the goal now. With ``keep_previous`` the old goal stays a terminal cell."""
        new = self.check_goal(goal)
        self.previous_goal = self.goal if keep_previous and self.goal != new else None
        self.goal = new
        if self.pending_goal == new:
            self.pending_goal = None
        return self.goal

    def request_goal(self, goal: str | Cell) -> Cell:
        """Check a goal that :meth:`set_goal` will apply later (the simulator moves the goal
        at its next observation) and keep it safe from walls until then: cell and event
        edits treat it as the goal. A later request replaces it."""
        self.pending_goal = self.check_goal(goal)
        return self.pending_goal

    def fire_event(self, name: str) -> None:
        """Fire a maze event: its lowercase cells become walls, its uppercase walls open
        (on the current layout, cell edits included). Refused (:class:`EditRefused`, the
        world unchanged) when its walls would leave the task unsolvable."""
        ev = self.maze.events.get(name)
        if ev is None:
            known = ", ".join(sorted(self.maze.events)) or "none"
            raise MazeError(f"no event named {name!r} (events: {known})", self.maze.source)
        walls = self.walls.copy()
        for r, c in ev["block"]:
            walls[r, c] = True
        for r, c in ev["open"]:
            walls[r, c] = False
        self.check_layout(walls, f"event {name!r}")
        self.walls = walls
        self.fired.append(name)

    def set_cell(self, r: int, c: int, blocked: bool) -> None:
        """Make a cell a wall (``blocked``) or free it. Blocking is refused
        (:class:`EditRefused`, the world unchanged) when the task would become unsolvable."""
        rows, cols = self.walls.shape
        if not (0 <= r < rows and 0 <= c < cols):
            raise MazeError(f"cell (row {r}, col {c}) is outside the {rows}x{cols} maze",
                            self.maze.source)
        walls = self.walls.copy()
        walls[r, c] = bool(blocked)
        self.check_layout(walls, f"blocking cell {_at((r, c))}")
        self.walls = walls

    def check_layout(self, walls: np.ndarray, what: str) -> None:
        """Refuse (:class:`EditRefused` naming ``what`` and the reason) a new wall layout
        that walls in the start, the goal, a requested goal or the agent (during an
        episode), or cuts the last route to a goal from the start or from the agent.
        Layouts that only open cells are always accepted."""
        if not (walls & ~self.walls).any():
            return
        keep = [("the start", self.maze.start), ("the goal", self.goal)]
        goals = [("the goal", self.goal)]
        if self.pending_goal is not None and self.pending_goal != self.goal:
            keep.append(("the requested goal", self.pending_goal))
            goals.append(("the requested goal", self.pending_goal))
        if self.in_episode:
            keep.append(("the agent", self.cell))
        for role, cell in keep:
            if walls[cell]:
                raise EditRefused(f"{what} refused: it would wall in {role} at {_at(cell)}",
                                  self.maze.source)
        sources = [("the start", self.maze.start)]
        if self.in_episode:
            sources.append(("the agent", self.cell))
        for src_role, src in sources:
            dist = bfs_distances(walls, src)
            for role, goal in goals:
                if dist[goal] < 0:
                    raise EditRefused(
                        f"{what} refused: it would cut the last route from {src_role} "
                        f"{_at(src)} to {role} {_at(goal)}", self.maze.source)

    def shortest_path_length(self, a: Cell | None = None, b: Cell | None = None) -> int:
        """BFS steps in the current layout (default: start to goal)."""
        return self.maze.shortest_path_length(a or self.maze.start, b or self.goal,
                                              walls=self.walls)
