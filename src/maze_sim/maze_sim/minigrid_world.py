"""A maze file as a MiniGrid world (``--world minigrid``): native turn / forward actions.

:class:`MazeMiniGridEnv` is a real :class:`minigrid.minigrid_env.MiniGridEnv` whose grid is
one of our maze files: a ``Wall`` on every ``#`` (and on a one-cell border around the
maze, so the agent can never leave it), a ``Goal`` on the current goal (and on the previous
goal while the goal-change scenario keeps it terminal), the agent at ``S`` facing
``start_dir`` (MiniGrid's numbering: 0 east (+col), 1 south (+row), 2 west, 3 north).
Maze cell (row, col) is MiniGrid position (x, y) = (col + 1, row + 1). Its action space is
cut to MiniGrid's first three actions, the native ones: 0 turn left, 1 turn right,
2 forward. A forward into a wall leaves the agent where it is (a bump); turns never bump.

The sensation (:class:`PoseSensation`, a declared Gymnasium ``ObservationWrapper``) is
``(row, col, cos h, sin h)`` with ``h = agent_dir * pi / 2`` measured from +col towards
+row: the heading as a unit vector, so the angle does not wrap. The *goal sensation* is
``(row, col, 0, 0)``: the goal is a cell, reached facing any way, and the zero heading is
equally far (1) from the four headings at that cell.

:class:`MiniGridWorld` offers the surface of :class:`maze_sim.world.GridWorld` that the
experiments drive (reset, step, set_goal, request_goal, check_goal, fire_event, set_cell,
shortest_path_length, ...). A :class:`~maze_sim.world.GridWorld` holds the layout and
decides what edits are allowed (refusals, reachability: with turns free in every cell, a
cell is reachable with turn / forward moves exactly when it is with the four moves);
every accepted edit is applied to the MiniGrid grid in place, mid-episode included, and
the agent keeps its pose (and whatever map it learnt).

The tabular state of a sensation (:meth:`MiniGridWorld.discretise`, what Q-learning and
Dyna-Q+ key on) is ``(round(row), round(col), sector)`` with ``sector`` the heading's
quarter (``round(atan2(sin h, cos h) / (pi / 2)) mod 4``), and ``None`` (any heading) for
a zero heading vector: the goal's key, which every heading at the goal cell matches
(:func:`key_matches`).

The oracle (:meth:`MiniGridWorld.shortest_path_length`, :meth:`MiniGridWorld.event_oracle_steps`)
is a BFS over (cell, heading) in primitive steps.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import replace
from typing import Hashable, Iterable

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from minigrid.core.grid import Grid
from minigrid.core.mission import MissionSpace
from minigrid.core.world_object import Goal, Wall
from minigrid.minigrid_env import MiniGridEnv

from maze_sim.maze import Cell, Maze, MazeError
from maze_sim.world import GridWorld, StepInfo

#: MiniGrid's native actions that the world keeps (MiniGrid's own numbers).
LEFT, RIGHT, FORWARD = 0, 1, 2
N_ACTIONS = 3
ACTION_NAMES = ("left", "right", "forward")
#: (d_row, d_col) of a forward move per MiniGrid heading (0 east, 1 south, 2 west, 3 north).
HEADING_STEP = ((0, 1), (1, 0), (0, -1), (-1, 0))
N_HEADINGS = 4

#: A pose: (row, col, heading).
Pose = tuple[int, int, int]


def pose_successor(walls: np.ndarray, pose: Pose, action: int) -> tuple[Pose, bool]:
    """(next pose, bumped) of a native action in a wall layout (MiniGrid's rules)."""
    r, c, h = pose
    if action == LEFT:
        return (r, c, (h - 1) % N_HEADINGS), False
    if action == RIGHT:
        return (r, c, (h + 1) % N_HEADINGS), False
    dr, dc = HEADING_STEP[h]
    n = (r + dr, c + dc)
    rows, cols = walls.shape
    if not (0 <= n[0] < rows and 0 <= n[1] < cols) or walls[n]:
        return pose, True
    return (n[0], n[1], h), False


def pose_distances(walls: np.ndarray, start: Pose) -> dict[Pose, int]:
    """BFS steps (turns and forwards) from ``start`` to every reachable pose."""
    dist = {start: 0}
    queue = deque([start])
    while queue:
        p = queue.popleft()
        for a in range(N_ACTIONS):
            q, _ = pose_successor(walls, p, a)
            if q not in dist:
                dist[q] = dist[p] + 1
                queue.append(q)
    return dist


def distances_to_cell(walls: np.ndarray, goal: Cell) -> dict[Pose, int]:
    """Steps from every pose to ``goal`` (any heading), by BFS over the reversed moves."""
    rows, cols = walls.shape
    poses = [(r, c, h) for r in range(rows) for c in range(cols) if not walls[r, c]
             for h in range(N_HEADINGS)]
    preds: dict[Pose, list[Pose]] = {p: [] for p in poses}
    for p in poses:
        for a in range(N_ACTIONS):
            q, _ = pose_successor(walls, p, a)
            if q != p:
                preds[q].append(p)
    dist = {(goal[0], goal[1], h): 0 for h in range(N_HEADINGS)}
    queue = deque(dist)
    while queue:
        q = queue.popleft()
        for p in preds.get(q, ()):
            if p not in dist:
                dist[p] = dist[q] + 1
                queue.append(p)
    return dist


def shortest_steps(walls: np.ndarray, start: Pose, goal: Cell) -> int:
    """Fewest native actions from ``start`` to the goal cell (any heading); -1 if none."""
    d = distances_to_cell(walls, goal)
    return d.get(start, -1)


def event_oracle_steps(old: np.ndarray, new: np.ndarray, start: Pose, goal: Cell) -> int:
    """The env-change lower bound in native actions (the grid world's, over poses): walk a
    shortest path of the old layout, bump once (a forward into the first newly blocked
    cell on it), then a shortest path of the new layout from that pose. The smallest such
    total over the old shortest paths, or the old length when one avoids every blocked
    cell."""
    to_goal_old = distances_to_cell(old, goal)
    to_goal_new = distances_to_cell(new, goal)
    d = to_goal_old.get(start, -1)
    if d < 0:
        raise ValueError("the goal cannot be reached from the start before the event")
    blocked = new & ~old
    best: int | None = None
    frontier = {start}
    for k in range(d + 1):
        nxt = set()
        for p in frontier:
            if (p[0], p[1]) == goal:
                return d
            for a in range(N_ACTIONS):
                q, bumped = pose_successor(old, p, a)
                if bumped or to_goal_old.get(q, -1) != d - k - 1:
                    continue
                if blocked[q[0], q[1]]:
                    rest = to_goal_new.get(p, -1)
                    if rest >= 0:
                        total = k + 1 + rest
                        best = total if best is None else min(best, total)
                else:
                    nxt.add(q)
        frontier = nxt
    if best is None:
        raise ValueError("the goal cannot be reached after the event")
    return best


def key_matches(key: Hashable, goal: Hashable) -> bool:
    """Does a tabular state ``key`` fall on the goal's key? Equal, or equal on every
    component the goal fixes (``None``: any)."""
    if key == goal:
        return True
    if not (isinstance(key, tuple) and isinstance(goal, tuple)) or len(key) != len(goal):
        return False
    return all(g is None or k == g for k, g in zip(key, goal))


class MazeMiniGridEnv(MiniGridEnv):
    """A MiniGrid env whose grid is a maze layout (module docstring). ``walls``: the
    layout, (rows, cols) bool; ``terminals``: the cells holding a ``Goal``."""

    def __init__(self, walls: np.ndarray, start: Cell, terminals: Iterable[Cell],
                 start_dir: int = 0, max_steps: int = 10**9, render_mode: str | None = None):
        if start_dir not in range(N_HEADINGS):
            raise ValueError(f"start_dir must be 0..3 (east, south, west, north), "
                             f"got {start_dir}")
        self.walls = np.array(walls, dtype=bool)
        self.start = (int(start[0]), int(start[1]))
        self.start_dir = int(start_dir)
        self.terminals = [tuple(map(int, t)) for t in terminals]
        rows, cols = self.walls.shape
        super().__init__(mission_space=MissionSpace(mission_func=lambda: "reach the goal"),
                         width=cols + 2, height=rows + 2, max_steps=int(max_steps),
                         see_through_walls=True, agent_view_size=3,
                         render_mode=render_mode)
        self.action_space = spaces.Discrete(N_ACTIONS)

    def _gen_grid(self, width: int, height: int) -> None:
        self.grid = Grid(width, height)
        self.grid.wall_rect(0, 0, width, height)
        self.put_layout()
        self.agent_pos = (self.start[1] + 1, self.start[0] + 1)
        self.agent_dir = self.start_dir

    def put_layout(self) -> None:
        """Write ``walls`` and ``terminals`` into the grid (every inner cell)."""
        rows, cols = self.walls.shape
        for r in range(rows):
            for c in range(cols):
                obj = Wall() if self.walls[r, c] else \
                    Goal() if (r, c) in self.terminals else None
                self.grid.set(c + 1, r + 1, obj)

    def edit(self, walls: np.ndarray, terminals: Iterable[Cell]) -> None:
        """A new layout in the running grid: the agent keeps its pose."""
        self.walls = np.array(walls, dtype=bool)
        self.terminals = [tuple(map(int, t)) for t in terminals]
        if self.grid is not None and self.grid.width == self.width:
            self.put_layout()

    def _reward(self) -> float:
        return 1.0

    @property
    def pose(self) -> Pose:
        x, y = self.agent_pos
        return int(y) - 1, int(x) - 1, int(self.agent_dir)


class PoseSensation(gym.ObservationWrapper):
    """What the agent senses of a MiniGrid env: ``(row, col, cos h, sin h)`` (module
    docstring). Works on any MiniGrid env (a maze's or a registered one); ``offset``: the
    grid position of maze cell (0, 0) (1 for :class:`MazeMiniGridEnv`'s border, 0 for a
    registered env, whose cells are its own)."""

    #: The goal sensation has a zero heading and any heading at the goal cell reaches it:
    #: every sensation there lies at the heading vector's length, 1, from it, every other
    #: sensation at sqrt(2) or farther (a neighbouring cell). Any radius in [1, sqrt 2)
    #: tells exactly which sensations end an episode at the goal; the world declares the
    #: one halfway (``Senses.goal_tolerance``), because the agent judges its map's nodes
    #: by it and a node's weights are a mean of the sensations it matched, a little off
    #: each of them: halfway, a node is counted with the sensations it lies nearer to.
    GOAL_TOLERANCE = (1.0 + math.sqrt(2.0)) / 2.0

    def __init__(self, env: gym.Env, offset: int = 0):
        super().__init__(env)
        self.offset = int(offset)
        w, h = env.unwrapped.width, env.unwrapped.height
        self.observation_space = spaces.Box(
            low=np.array([-self.offset, -self.offset, -1.0, -1.0]),
            high=np.array([h - 1 - self.offset, w - 1 - self.offset, 1.0, 1.0]),
            dtype=np.float64)

    @staticmethod
    def sensation(row: float, col: float, heading: int | None) -> np.ndarray:
        """The sensation of a pose (heading None: the goal's, any heading)."""
        if heading is None:
            return np.array([row, col, 0.0, 0.0])
        h = heading * math.pi / 2
        return np.array([row, col, round(math.cos(h)), round(math.sin(h))], dtype=float)

    def observation(self, observation) -> np.ndarray:
        env = self.env.unwrapped
        x, y = env.agent_pos
        return self.sensation(float(y) - self.offset, float(x) - self.offset,
                              int(env.agent_dir))


def discretise(sensation: np.ndarray) -> Hashable:
    """The tabular state of a MiniGrid sensation (module docstring)."""
    row, col, ch, sh = (float(v) for v in sensation[:4])
    if ch == 0.0 and sh == 0.0:
        sector = None
    else:
        sector = int(math.floor(math.atan2(sh, ch) / (math.pi / 2) + 0.5)) % N_HEADINGS
    return (int(math.floor(row + 0.5)), int(math.floor(col + 0.5)), sector)


class MiniGridWorld:
    """A maze file as a MiniGrid env, with the experiments' world surface (module
    docstring). ``start_dir``: the heading at S (default 0, east)."""

    identity = False                  # tabular agents key on discretise(sensation)
    goal_tolerance = PoseSensation.GOAL_TOLERANCE
    n_actions = N_ACTIONS
    name = "minigrid"

    def __init__(self, maze: Maze, goal: str | Cell = "G",
                 max_episode_steps: int | None = None, seed: int | None = None,
                 start_dir: int = 0, render_mode: str | None = None):
        self.truth = GridWorld(maze, goal=goal, max_episode_steps=max_episode_steps)
        self.maze = maze
        self.max_episode_steps = max_episode_steps
        self.base = MazeMiniGridEnv(maze.walls, maze.start, [self.truth.goal],
                                    start_dir=start_dir, render_mode=render_mode)
        self.env = PoseSensation(self.base, offset=1)
        self.seed = seed
        self.state: Hashable = None
        self.episode = 0
        self.episode_steps = 0
        self.total_steps = 0
        self.env.reset(seed=seed)
        self.state = discretise(self.env.observation(None))

    # ---------------------------------------------------------------- what it is
    @property
    def cell(self) -> Cell:
        return self.truth.cell

    @property
    def pose(self) -> Pose:
        return self.base.pose

    @property
    def goal(self) -> Cell:
        return self.truth.goal

    @property
    def previous_goal(self) -> Cell | None:
        return self.truth.previous_goal

    @property
    def walls(self) -> np.ndarray:
        return self.truth.walls

    @property
    def grid(self) -> GridWorld:
        """The book-keeper, as the simulator node restores it from a checkpoint (then
        :meth:`sync`)."""
        return self.truth

    @property
    def rng(self) -> np.random.Generator:
        """The book-keeper's generator (what a checkpoint keeps)."""
        return self.truth.rng

    @property
    def fired(self) -> list[str]:
        return self.truth.fired

    @property
    def start_pose(self) -> Pose:
        return (self.maze.start[0], self.maze.start[1], self.base.start_dir)

    def goal_observation(self) -> np.ndarray:
        """The goal sensation: the goal cell, any heading (zero heading vector)."""
        return PoseSensation.sensation(float(self.goal[0]), float(self.goal[1]), None)

    @property
    def goal_state(self) -> Hashable:
        return discretise(self.goal_observation())

    discretise = staticmethod(discretise)
    key_matches = staticmethod(key_matches)

    # ---------------------------------------------------------------- control
    def reset(self, seed: int | None = None, start: Cell | None = None):
        self.truth.reset(start=start)
        self.base.start = self.truth.cell
        obs, _ = self.env.reset(seed=seed)
        self.base.start = self.maze.start
        self.episode = self.truth.episode
        self.episode_steps = 0
        self.state = discretise(obs)
        return obs, {"episode": self.episode, "state": self.state}

    def end_episode(self) -> None:
        self.truth.end_episode()

    def step(self, action: int):
        if not 0 <= int(action) < N_ACTIONS:
            raise ValueError(f"action must be in 0..{N_ACTIONS - 1} "
                             f"({', '.join(ACTION_NAMES)}), got {action}")
        before = self.base.pose
        obs, reward, env_terminated, _, _ = self.env.step(int(action))
        after = self.base.pose
        cell = (after[0], after[1])
        self.truth.cell = cell
        self.total_steps += 1
        self.episode_steps += 1
        self.truth.total_steps = self.total_steps
        self.state = discretise(obs)
        info = StepInfo(cell=cell, action=int(action),
                        bumped=int(action) == FORWARD and after == before,
                        reached_goal=cell == self.goal,
                        reached_previous_goal=(self.previous_goal is not None
                                               and cell == self.previous_goal),
                        step=self.total_steps, episode=self.episode)
        if info.terminated != bool(env_terminated):
            raise RuntimeError(f"MiniGrid ended the episode ({env_terminated}) where the "
                               f"maze's goals say {info.terminated} at {cell}")
        truncated = (self.max_episode_steps is not None
                     and self.episode_steps >= self.max_episode_steps
                     and not info.terminated)
        if info.terminated or truncated:
            self.truth.in_episode = False
        return (obs, 1.0 if info.reached_goal else 0.0, info.terminated, truncated,
                replace(info, cell=self.state))

    # ---------------------------------------------------------------- edits
    def _sync(self) -> None:
        terminals = [self.goal] + ([self.previous_goal] if self.previous_goal else [])
        self.base.edit(self.truth.walls, terminals)

    def sync(self) -> None:
        """Follow the book-keeper after its walls, goal and counters were restored
        directly (a checkpoint): the running grid and the counters."""
        self.episode, self.total_steps = self.truth.episode, self.truth.total_steps
        self._sync()

    def check_goal(self, goal: str | Cell) -> Cell:
        return self.truth.check_goal(goal)

    def set_goal(self, goal: str | Cell, keep_previous: bool = False) -> Cell:
        new = self.truth.set_goal(goal, keep_previous)
        self._sync()
        return new

    def request_goal(self, goal: str | Cell) -> Cell:
        return self.truth.request_goal(goal)

    def fire_event(self, name: str) -> None:
        self.truth.fire_event(name)
        self._sync()

    def set_cell(self, r: int, c: int, blocked: bool) -> None:
        self.truth.set_cell(r, c, blocked)
        self._sync()

    # ---------------------------------------------------------------- oracle
    def shortest_path_length(self, a: Pose | None = None, b: Cell | None = None) -> int:
        """BFS native actions over (cell, heading) in the current layout (default: from S
        facing ``start_dir`` to the goal, any heading); -1 when unreachable."""
        return shortest_steps(self.walls, a or self.start_pose, b or self.goal)

    def event_oracle_steps(self, event: str, goal: str | Cell = "G") -> int:
        """:func:`event_oracle_steps` of the maze's ``event`` (from the maze's layout)."""
        if event not in self.maze.events:
            raise MazeError(f"no event named {event!r}", self.maze.source)
        target = self.maze.goal_cell(goal) if isinstance(goal, str) else goal
        return event_oracle_steps(self.maze.walls, self.maze.walls_after([event]),
                                  self.start_pose, target)

    def shortest_steps(self, walls: np.ndarray, goal: str | Cell = "G") -> int:
        """Fewest native actions from S to ``goal`` in the layout ``walls``."""
        target = self.maze.goal_cell(goal) if isinstance(goal, str) else goal
        return shortest_steps(walls, self.start_pose, target)
