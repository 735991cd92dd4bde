"""PointMaze (Gymnasium-Robotics, MuJoCo) built from one of our maze files: the world contract.

A point mass in a MuJoCo maze (``gymnasium_robotics.envs.maze.point_maze.PointMazeEnv``):
continuous position and velocity, a force action in ``[-1, 1]^2`` (``gear`` 100 N per
unit), physics in between. :class:`PointMazeWorld` offers the surface of the experiments'
grid world (:class:`maze_sim.world.GridWorld`), so every scenario drives it unchanged.

Geometry (the env's own, ``maze_size_scaling`` 1): the maze file's ``#`` cells are the env's
``maze_map`` walls (1), every other cell is free (0). Our cell ``(row, col)`` is the env's
``(i, j)``; its centre is at::

    x = (col + 1/2) * S - cols * S / 2        y = rows * S / 2 - (row + 1/2) * S

with ``S`` = :data:`CELL_SIZE` = 1 m (so ``x`` grows with the column, ``y`` *falls* with the
row, and the maze is centred on the origin), the env's ``Maze.cell_rowcol_to_xy``. The
reverse, ``Maze.cell_xy_to_rowcol`` (``floor``), is the cell a position lies in.

Sensation: the point's position ``(x, y)`` in metres (``velocity=True``: and its velocity
``(vx, vy)``, m/s). The goal sensation is the goal cell's centre (with zero velocity).

Motor primitives (:data:`PRIMITIVES`, the four force directions ``up`` = +y, ``down`` = -y,
``left`` = -x, ``right`` = +x, in the order of :data:`maze_sim.maze.ACTIONS`). A primitive
is ``K = K_push + K_brake`` physics steps of the env's own dynamics
(:func:`physics_step`, what ``PointEnv.step`` does): a constant force along the direction
for ``K_push`` steps, then a brake, the force opposing the velocity (``-v`` scaled so that one
physics step would stop the point, clipped to full force) for up to ``K_brake`` steps or
until the point is at rest. So a primitive is a move of :func:`step_length` that ends at rest:
the next primitive starts from rest and the position alone tells where the point is
(without the brake the point, damped by 1 N s/m for its 4.2 kg, would glide on for seconds
and a position would not tell what a force does next).

The move's length is one cell, ``S`` (:func:`step_length`, a fact of the maze): every
primitive is exact and a bumped one returns (below), so the point rests only on the
cells' centres, one place a cell, and every place a primitive reaches is a place of the
grid world's lattice. The goal's centre is one of them: a move from a neighbouring centre
into the goal cell passes the env's success test on the way (the success radius is less
than a cell) and comes to rest at the goal's centre, and no other centre lies within the
success radius. (A shorter move, ``S / n``, only adds resting places between the
centres, on the edges between free cells and at the corners where four meet: with half a
cell, about four a cell in the open, each a node of the agent's map and a state of a
discretisation at the move's resolution. The half-cell move was chosen while a move still
overshot and a bump left the point against the wall, so that some resting place always
lay within the success radius of the goal; exact moves and guarded bumps made that
reason moot.) ``K_push``, the force and ``K_brake`` are derived from the world by
:func:`primitive_steps`, measured once per process on the env's point model in free space
(no walls, the same XML): the point at rest pushed at full force for ``n``
steps and braked to rest travels ``d(n)``; ``K_push`` is the fewest ``n`` with ``d(n)`` at
least that length, the force the share of full force at which ``K_push`` steps travel it
exactly (bisection), ``K_brake`` the steps the brake took, plus :data:`BRAKE_MARGIN`. The
move is exact because the places must repeat: at full force an integer number of steps
overshoots the length by centimetres, and every move would leave the lattice a little more,
so that no two visits to a cell rested at the same place.

A move that bumps is guarded (a bumper's reflex): it stops pushing and drives the point
back to where the move started, at rest (:meth:`PointMazeWorld._return_to`, a velocity
servo of the same force limit, then the brake). So a blocked move leaves the point where it
was, as a bump leaves the grid world's agent in its cell, and the point never leaves the
move lattice. (Left against the wall, the point rested a point radius off the lattice's
line on that axis, and every move after kept that offset: each bump made new places, a
cell held dozens of them, and a wall bumped from one of them was open from the next.)

Resolution (``sensor_resolution``, told to the agent through its ``Senses`` as
``resolution``): the move's length. The agent's preprocessor scales one resolution step to
one feature step, as one cell is in the grid world, so its map's matching radius (the GWR
activity threshold) separates neighbouring places of the lattice and no more: a cell's
centre is one place, as a cell is in the grid world. (Declared coarser than the move,
neighbouring places lie within that radius and the map merges them into one node.)

Sensor's range (the bounds of ``observation_space``, told to the agent through its
``Senses`` as ``low``, ``high``): the positions the point's centre can take, per axis the
extent of the cells free in the maze or opened by one of its events, less the point's
radius (``particle_geom``'s) at each end, where the centre stops against a wall's face
(:meth:`PointMazeWorld.sensation_range`); the velocity within +-``MAX_SPEED``. A Gymnasium
``Box`` states the range its sensor can give; this is that range, a fact of the arena, not
of where its inner walls are. (The agent makes no option of a move predicted to end
outside it: core/unknown.py, ``outside_options``. Declared unbounded, every untried move
into the maze's outer wall was a way round as plausible as any other once a block broke
the route, and the agent walked the outer wall testing them.)

Outcome: ``bumped`` is the touch sensor: during the primitive the point met a wall ahead
of its push (a MuJoCo contact between the point's geom and a ``block_*`` geom whose normal
is within 60 degrees of the push direction; a wall slid along does not count). A goal counts
as reached by the env's own success test (``PointMazeEnv.compute_terminated`` of an
episodic env: within 0.45 m of the goal), checked after every physics step: a primitive
during which it held ends the episode at the goal. The primitive itself runs to its end,
as every primitive does, and the episode's last sensation is where it came to rest: the
goal's centre, a place of the lattice. (Were the sensation taken at the physics step the
test first held, the region's edge, it would be a place where no primitive rests and a
different one from each side the region is entered, each a node of the map that stands
for the goal.)

Tabular state (``info.cell``, :attr:`PointMazeWorld.state`, ``goal_state``: what
Q-learning and Dyna-Q+ key on): the sensed position discretised at the world's declared
resolution (:meth:`PointMazeWorld.discretise`), the point of the lattice of spacing
``sensor_resolution`` through the cells' centres nearest to it, numbered in resolution
steps from the centre of cell (0, 0) as ``(down, right)`` (``floor(d / resolution + 1/2)``
per axis, ``d`` the offset in metres; the velocity of a ``velocity`` sensation is left out:
at rest it is zero). So the tables are told what TMGWR is told (the sensation, at the
resolution its preprocessor scales by), never an index the point cannot sense. With the
move one cell, this is one state a cell, the cell's centre ``(r, c)`` (the discretisation
at one cell that users of PointMaze reach for), and it stays the sensation's: the point
rests only at the centres, so no two resting places share a state. The goal's state is
that of the goal sensation (the goal cell's centre); a move into the success region comes
to rest there (Outcome) and no other lattice point lies within the success radius (the
lattice's spacing exceeds it), so the tables
reach the goal's state exactly when the env's success test ends the episode there. The
true cell (:attr:`PointMazeWorld.cell`) stays the experimenter's, for the oracle, the
ROS graph's pose and the book-keeper.

Oracle (:meth:`PointMazeWorld.shortest_path_length`): the primitive steps a scripted
controller takes on the same physics: the point at rest at the start cell's centre, each
step it applies the primitive towards the next cell of a BFS shortest path from the cell it
is in, until the env's success test holds. Measured once per layout and goal (cached).
A primitive moves the point one cell or, bumped, none, so no route takes fewer primitives
than the breadth-first distance in cells, and the controller's route takes exactly that
many: the measurement checks the physics rather than finds a bound. The convergence probe
counts a greedy route as short as it, or shorter, as converged (:data:`PROBE_TOLERANCE`).

Goal region (``goal_tolerance``, told to the agent through its ``Senses``): the success
radius, in metres of the position sensation.

Events, cell edits and goal changes are validated by a :class:`~maze_sim.world.GridWorld`
kept as the book-keeper (the same refusals as the grid world); an edit of the walls rebuilds
the MuJoCo model from the new ``maze_map`` and puts the point back where it was, at the
same velocity. The agent is not told (its map is its own).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from maze_sim.maze import N_ACTIONS, Cell, Maze, MazeError, bfs_distances
from maze_sim.world import GridWorld, StepInfo

#: The env's ``maze_size_scaling`` (PointMazeEnv fixes it): metres per maze cell.
CELL_SIZE = 1.0
#: The env's success test: the point within this distance of the goal (maze_v4.py).
SUCCESS_RADIUS = 0.45
#: Force direction of each action (unit ``ctrl``), in the order of ``maze_sim.maze.ACTIONS``
#: (up, down, left, right): up is +y (a smaller row), right is +x (a larger column).
PRIMITIVES = np.array([(0.0, 1.0), (0.0, -1.0), (-1.0, 0.0), (1.0, 0.0)])
#: PointEnv clips the velocity to this before every physics step (point.py).
MAX_SPEED = 5.0
#: Extra brake steps over those a free move needs (a move that bounced off a wall).
BRAKE_MARGIN = 4
#: A wall contact whose normal is within 60 degrees of the push blocks the move (cosine).
BUMP_COSINE = 0.5
#: Speed (m/s) below which the brake counts the point at rest.
REST_SPEED = 1e-3
#: The guarded move's return (:meth:`PointMazeWorld._return_to`): the time constant (s) of
#: the velocity servo that drives the point back to where the move started, the largest
#: speed it commands (m/s), the distance (m) from that place at which it brakes to rest,
#: and the physics steps it may take at most.
RETURN_TAU = 0.05
RETURN_SPEED = 2.0
RETURN_TOL = 1e-6
RETURN_STEPS = 400
#: The share of the oracle's primitive steps by which a greedy probe's route may exceed
#: them and still count as converged (``probe_tolerance``, experiments/runner.py). 0: the
#: oracle is the fewest primitives any route takes (module doc, Oracle).
PROBE_TOLERANCE = 0.0


def import_gymnasium_robotics():
    """``gymnasium_robotics``, imported without the notice its releases 1.2.1 to 1.4.2 print
    on stderr at every import (through ``farama_notifications``): it concerns the rewards
    of the Adroit hand envs, which no world here hosts (the gym adapter maps no Adroit id),
    and would otherwise open every PointMaze run's output. Raises ImportError as the import
    does."""
    try:
        import farama_notifications
        farama_notifications.notifications.pop("gymnasium_robotics", None)
    except ImportError:          # pragma: no cover - a release without the notices
        pass
    import gymnasium_robotics
    return gymnasium_robotics


def _gym_robotics():
    """The PointMaze classes (imported on first use: MuJoCo is loaded only by this world)."""
    try:
        import_gymnasium_robotics()
        from gymnasium_robotics.envs.maze.point import PointEnv
        from gymnasium_robotics.envs.maze.point_maze import PointMazeEnv
    except ImportError as exc:   # pragma: no cover - packaging
        raise MazeError(f"the pointmaze world needs gymnasium-robotics and mujoco "
                        f"(pip install gymnasium-robotics mujoco): {exc}") from None
    return PointEnv, PointMazeEnv


def physics_step(model, data, ctrl: np.ndarray) -> None:
    """One physics step as ``PointEnv.step`` makes it: the control clipped to [-1, 1], the
    velocity clipped to +-MAX_SPEED, one ``mj_step`` (its ``frame_skip`` is 1)."""
    import mujoco
    np.clip(data.qvel, -MAX_SPEED, MAX_SPEED, out=data.qvel)
    data.ctrl[:] = np.clip(ctrl, -1.0, 1.0)
    mujoco.mj_step(model, data)


def brake_ctrl(model, data) -> np.ndarray:
    """The control that would stop the point in one physics step (clipped to full force
    by :func:`physics_step`): ``-v m / (gear dt)`` per axis."""
    gain = _brake_gain(model)
    return -data.qvel[:2] * gain


def _brake_gain(model) -> np.ndarray:
    mass = model.body_mass[model.jnt_bodyid[:2]]
    gear = model.actuator_gear[:2, 0]
    return mass / (gear * model.opt.timestep)


def step_length(cell: float = CELL_SIZE) -> float:
    """The distance a primitive moves the point from rest: one cell (module doc)."""
    return float(cell)


def _free_move(model, data, env, n: int, force: float) -> tuple[float, int]:
    """From rest at the origin: push along +x at ``force`` for ``n`` physics steps, brake to
    rest; the distance travelled and the brake's steps."""
    env.set_state(np.zeros(model.nq), np.zeros(model.nv))
    for _ in range(n):
        physics_step(model, data, np.array([force, 0.0]))
    brake = 0
    while np.abs(data.qvel[:2]).max() > REST_SPEED and brake < 1000:
        physics_step(model, data, brake_ctrl(model, data))
        brake += 1
    return float(data.qpos[0]), brake


@lru_cache(maxsize=8)
def primitive_steps(distance: float) -> tuple[int, int, float]:
    """``(K_push, K_brake, force)`` for a move of ``distance`` metres, measured on the env's
    point model in free space (module doc): ``K_push`` the fewest push steps at full force
    that reach ``distance``, ``force`` the share of full force at which ``K_push`` steps and
    the brake travel exactly ``distance`` (bisection)."""
    PointEnv, _ = _gym_robotics()
    env = PointEnv()                      # the point model alone: no maze, no walls
    try:
        model, data = env.model, env.data
        n = next(n for n in range(1, 1000) if _free_move(model, data, env, n, 1.0)[0]
                 >= distance)
        lo, hi = 0.0, 1.0
        for _ in range(60):               # d(n, f) grows with f
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _free_move(model, data, env, n, mid)[0] < distance \
                else (lo, mid)
        force = hi
        brake = max(_free_move(model, data, env, n, f)[1] for f in (force, 1.0))
        return n, brake + BRAKE_MARGIN, force
    finally:
        env.close()


def maze_map(walls: np.ndarray) -> list[list[int]]:
    """The env's ``maze_map`` of a wall layout: 1 wall, 0 free."""
    return [[int(w) for w in row] for row in walls]


@dataclass(frozen=True)
class Primitive:
    """What one primitive did."""

    bumped: bool
    reached: bool        # the env's success test held (the primitive stopped there)
    steps: int           # physics steps taken


class PointMazeWorld:
    """PointMaze built from ``maze`` (module doc), the world contract of the experiments.

    Parameters
    ----------
    maze : Maze
    goal : goal name ('G', '1'..'9') or (row, col) cell
    max_episode_steps : truncate an episode after this many primitive steps (None = never)
    seed : seed of the env's generator (nothing here draws from it: no position noise)
    velocity : sense the velocity too (a 4-D sensation) rather than the position alone
    """

    identity = True                       # the state *is* the discretised sensation
    n_actions = N_ACTIONS
    action_vectors = PRIMITIVES
    name = "pointmaze"

    def __init__(self, maze: Maze, goal: str | Cell = "G", max_episode_steps: int | None = None,
                 seed: int | None = None, velocity: bool = False):
        self.grid = GridWorld(maze, goal, 0.0, max_episode_steps, seed)
        self.maze = maze
        self.velocity = bool(velocity)
        self.step_length = step_length()
        self.per_cell = round(CELL_SIZE / self.step_length)
        self.k_push, self.k_brake, self.force = primitive_steps(self.step_length)
        self.seed = seed
        self._oracle: dict[tuple, int] = {}
        self.env = None
        self._build(self.grid.walls)
        self._place(self.grid.cell)

    @classmethod
    def from_layout(cls, walls: np.ndarray, start: Cell, goal: Cell, source: str,
                    max_episode_steps: int | None = None, seed: int | None = None,
                    velocity: bool = False) -> "PointMazeWorld":
        """The world of a wall layout (an env's ``maze_map``: truthy = wall) with one start
        and one goal cell ``G`` and no events; ``source`` names it in errors."""
        walls = np.asarray(walls, dtype=bool)
        maze = Maze(walls=walls, start=tuple(start), goals={"G": tuple(goal)},
                    source=source)
        maze.check_free(*maze.start)
        maze.check_free(*maze.goals["G"])
        maze._check_reachable()
        return cls(maze, "G", max_episode_steps, seed, velocity)

    # ------------------------------------------------------------------ the env
    def _build(self, walls: np.ndarray) -> None:
        """(Re)build the env's MuJoCo model from ``walls``; the point keeps its state."""
        _, PointMazeEnv = _gym_robotics()
        old = None if self.env is None else (self.data.qpos.copy(), self.data.qvel.copy())
        env = PointMazeEnv(maze_map=maze_map(walls), continuing_task=False)
        try:
            os.remove(env.tmp_xml_file_path)   # compiled already; the env never removes it
        except OSError:
            pass
        env.position_noise_range = 0.0         # the point and the goal at cell centres
        env.reset(seed=self.seed, options={"goal_cell": np.array(self.grid.goal),
                                           "reset_cell": np.array(self.grid.cell)})
        if self.env is not None:
            self.env.close()
        self.env = env
        self.model, self.data = env.point_env.model, env.point_env.data
        self._point_geom = env._model_names.geom_name2id["particle_geom"]
        self._wall_geoms = {i for name, i in env._model_names.geom_name2id.items()
                            if name and name.startswith("block_")}
        self._set_goal_xy()
        if old is not None:
            env.point_env.set_state(*old)

    def _set_goal_xy(self) -> None:
        self.env.goal = self.xy(self.grid.goal)
        self.env.update_target_site_pos()

    def xy(self, cell: Cell) -> np.ndarray:
        """The centre of ``cell`` (row, col) in the env's (x, y) metres (module doc)."""
        return self.env.maze.cell_rowcol_to_xy(np.array(cell, dtype=float))

    def cell_of(self, xy: np.ndarray) -> Cell:
        """The cell (row, col) a position lies in (module doc)."""
        i, j = self.env.maze.cell_xy_to_rowcol(np.asarray(xy, dtype=float))
        return int(i), int(j)

    def _place(self, cell: Cell) -> None:
        """The point at rest at the centre of ``cell``."""
        qpos = np.zeros(self.model.nq)
        qpos[:2] = self.xy(cell)
        self.env.point_env.set_state(qpos, np.zeros(self.model.nv))

    def _blocked(self, push: np.ndarray) -> bool:
        """The touch sensor: the point touches a wall geom head-on, the contact's normal
        within 60 degrees of the push (a wall alongside, touched while sliding past, does
        not block the move)."""
        d = self.data
        for k in range(d.ncon):
            g1, g2 = int(d.contact.geom1[k]), int(d.contact.geom2[k])
            if self._point_geom in (g1, g2) and (g1 in self._wall_geoms
                                                 or g2 in self._wall_geoms):
                normal = d.contact.frame[k][:2]
                if abs(float(normal @ push)) > BUMP_COSINE * float(np.linalg.norm(normal)):
                    return True
        return False

    def _success(self, goal_xy: np.ndarray) -> bool:
        """The env's own success test (episodic: terminated within 0.45 m)."""
        return bool(self.env.compute_terminated(self.data.qpos[:2].copy(), goal_xy, {}))

    def _primitive(self, action: int, goals: list[np.ndarray]) -> tuple[Primitive, int]:
        """Run primitive ``action`` to its end; the first of ``goals`` for which the env's
        test held at one of its physics steps (its index, else -1). A move that bumps is
        guarded: it returns to where it started (:meth:`_return_to`)."""
        model, data = self.model, self.data
        push = PRIMITIVES[action] * self.force
        start = data.qpos[:2].copy()
        bumped = False
        steps = 0
        reached = -1

        def check() -> None:
            nonlocal reached
            for gi, g in enumerate(goals if reached < 0 else ()):
                if self._success(g):
                    reached = gi
                    break

        for k in range(self.k_push + self.k_brake):
            if k >= self.k_push:
                if np.abs(data.qvel[:2]).max() <= REST_SPEED:
                    break
                ctrl = brake_ctrl(model, data)
            else:
                ctrl = push
            physics_step(model, data, ctrl)
            steps += 1
            bumped = self._blocked(PRIMITIVES[action])
            check()
            if bumped:
                break
        if bumped:
            steps += self._return_to(start, check)
        return Primitive(bumped, reached >= 0, steps), reached

    def _return_to(self, target: np.ndarray, each=lambda: None) -> int:
        """Drive the point back to ``target`` and brake it to rest there: a velocity servo
        (the velocity ``(target - x) / RETURN_TAU``, at most ``RETURN_SPEED``, reached in one
        physics step as far as full force allows), then the brake once within
        ``RETURN_TOL``; ``each()`` after every physics step. Returns the steps taken."""
        model, data = self.model, self.data
        gain = _brake_gain(model)
        for k in range(RETURN_STEPS):
            err = target - data.qpos[:2]
            if np.abs(err).max() <= RETURN_TOL:
                if np.abs(data.qvel[:2]).max() <= REST_SPEED:
                    return k
                ctrl = brake_ctrl(model, data)
            else:
                v = np.clip(err / RETURN_TAU, -RETURN_SPEED, RETURN_SPEED)
                ctrl = (v - data.qvel[:2]) * gain
            physics_step(model, data, ctrl)
            each()
        return RETURN_STEPS

    # ------------------------------------------------------------------ sensing
    def sense(self) -> np.ndarray:
        """The sensation: position (and velocity with ``velocity``)."""
        n = 4 if self.velocity else 2
        return np.concatenate([self.data.qpos[:2], self.data.qvel[:2]])[:n].astype(float)

    def goal_observation(self) -> np.ndarray:
        """The goal's sensation: the goal cell's centre (at rest)."""
        g = self.xy(self.grid.goal)
        return np.concatenate([g, np.zeros(2)]) if self.velocity else g

    @property
    def sensation_dim(self) -> int:
        return 4 if self.velocity else 2

    @property
    def observation_space(self):
        """The sensation as a Gymnasium space (what ``Senses.from_spaces`` reads), bounded
        by the sensor's range (:meth:`sensation_range`)."""
        from gymnasium import spaces
        low, high = self.sensation_range()
        return spaces.Box(low, high, dtype=np.float64)

    def sensation_range(self) -> tuple[np.ndarray, np.ndarray]:
        """The range of the sensation (module doc, Sensor's range): per axis, the extent
        of the cells that are free in the maze or that any of its events opens, less the
        point's radius at each end (the point's centre stays that far from a wall's face);
        with ``velocity``, +-``MAX_SPEED`` (the env clips the velocity to it)."""
        free = ~self.maze.walls
        for e in self.maze.events.values():
            for r, c in e.get("open", ()):
                free[r, c] = True
        rows, cols = np.nonzero(free)
        radius = float(self.model.geom_size[self._point_geom][0])
        half = 0.5 * CELL_SIZE - radius
        (x0, y1), (x1, y0) = (self.xy((rows.min(), cols.min())),
                              self.xy((rows.max(), cols.max())))
        low, high = np.array([x0 - half, y0 - half]), np.array([x1 + half, y1 + half])
        if self.velocity:
            low = np.concatenate([low, [-MAX_SPEED, -MAX_SPEED]])
            high = np.concatenate([high, [MAX_SPEED, MAX_SPEED]])
        return low, high

    @property
    def action_space(self):
        from gymnasium import spaces
        return spaces.Discrete(N_ACTIONS)

    #: The declared motor vector of each action (``Senses``): its force direction.
    primitive_vectors = PRIMITIVES
    #: How near the goal sensation a sensation ends an episode at the goal (``Senses``,
    #: metres): the env's success radius. With ``velocity`` it bounds the position part
    #: alone (the env's test ignores the velocity).
    goal_tolerance = SUCCESS_RADIUS
    #: The convergence probe's tolerance over the scripted oracle (:data:`PROBE_TOLERANCE`).
    probe_tolerance = PROBE_TOLERANCE

    @property
    def sensor_resolution(self) -> float:
        """The sensor's resolution step (``Senses.resolution``, metres): one primitive's
        move, the distance between neighbouring places of the move lattice (module doc)."""
        return self.step_length

    # ------------------------------------------------------------------ the contract
    def discretise(self, sensation: np.ndarray) -> tuple[int, int]:
        """The tabular state of a sensation (module doc): its position's nearest point of
        the move lattice, in resolution steps ``(down, right)`` from the centre of cell
        (0, 0). The one discretisation of this world's sensation."""
        d = (np.asarray(sensation[:2], dtype=float) - self.xy((0, 0))) / \
            self.sensor_resolution
        return int(math.floor(-d[1] + 0.5)), int(math.floor(d[0] + 0.5))

    @property
    def cell(self) -> Cell:
        """The cell the point's position lies in (the experimenter's truth, not an agent's
        input)."""
        return self.grid.cell

    @property
    def state(self) -> tuple[int, int]:
        """The tabular state: the sensation discretised (:meth:`discretise`)."""
        return self.discretise(self.sense())

    @property
    def goal(self) -> Cell:
        return self.grid.goal

    @property
    def goal_state(self) -> tuple[int, int]:
        """The goal sensation discretised (:meth:`discretise`)."""
        return self.discretise(self.goal_observation())

    @property
    def max_episode_steps(self) -> int | None:
        return self.grid.max_episode_steps

    def __getattr__(self, name: str):
        # the book-keeper's state: walls, fired, episode, total_steps, previous_goal, ...
        if name == "grid":
            raise AttributeError(name)
        return getattr(self.grid, name)

    def reset(self, seed: int | None = None, start: Cell | None = None):
        """A new episode: the point at rest at the centre of the start cell (or ``start``)."""
        _, info = self.grid.reset(seed, start)
        self._place(self.grid.cell)
        obs = self.sense()
        return obs, {**info, "state": self.discretise(obs)}

    def end_episode(self) -> None:
        self.grid.end_episode()

    def step(self, action: int):
        if not 0 <= int(action) < N_ACTIONS:
            raise ValueError(f"action must be in 0..{N_ACTIONS - 1}, got {action}")
        g = self.grid
        goals = [self.env.goal.copy()]
        if g.previous_goal is not None:
            goals.append(self.xy(g.previous_goal))
        prim, which = self._primitive(int(action), goals)
        g.cell = self.cell_of(self.data.qpos[:2])
        g.total_steps += 1
        g.episode_steps += 1
        obs = self.sense()
        info = StepInfo(cell=self.discretise(obs), action=int(action), bumped=prim.bumped,
                        reached_goal=which == 0, reached_previous_goal=which == 1,
                        step=g.total_steps, episode=g.episode)
        truncated = (g.max_episode_steps is not None
                     and g.episode_steps >= g.max_episode_steps and not info.terminated)
        if info.terminated or truncated:
            g.in_episode = False
        return obs, 1.0 if info.reached_goal else 0.0, info.terminated, truncated, info

    # ------------------------------------------------------------------ edits
    def check_goal(self, goal: str | Cell) -> Cell:
        return self.grid.check_goal(goal)

    def request_goal(self, goal: str | Cell) -> Cell:
        return self.grid.request_goal(goal)

    def set_goal(self, goal: str | Cell, keep_previous: bool = False) -> Cell:
        cell = self.grid.set_goal(goal, keep_previous)
        self._set_goal_xy()
        return cell

    def sync(self) -> None:
        """Rebuild the env from the book-keeper's walls and goal (after they were restored
        directly, e.g. from a checkpoint)."""
        self._build(self.grid.walls)

    def _rebuild_if_changed(self, before: np.ndarray) -> None:
        if not np.array_equal(before, self.grid.walls):
            self._build(self.grid.walls)

    def fire_event(self, name: str) -> None:
        """Fire a maze event (the grid world's rules and refusals); the MuJoCo model is
        rebuilt with the new walls, the point where it was."""
        before = self.grid.walls.copy()
        self.grid.fire_event(name)
        self._rebuild_if_changed(before)

    def set_cell(self, r: int, c: int, blocked: bool) -> None:
        before = self.grid.walls.copy()
        self.grid.set_cell(r, c, blocked)
        self._rebuild_if_changed(before)

    # ------------------------------------------------------------------ the oracle
    def shortest_path_length(self, a: Cell | None = None, b: Cell | None = None) -> int:
        """Primitive steps of the scripted controller from ``a`` (default: the start) to
        ``b`` (default: the goal) in the current layout (module doc); -1 when ``b`` cannot
        be reached. The point's state is restored afterwards."""
        a = tuple(a or self.maze.start)
        b = tuple(b or self.grid.goal)
        walls = self.grid.walls
        key = (walls.tobytes(), a, b)
        if key not in self._oracle:
            self._oracle[key] = self._scripted(walls, a, b)
        return self._oracle[key]

    def _scripted(self, walls: np.ndarray, a: Cell, b: Cell) -> int:
        if bfs_distances(walls, b)[a] < 0:
            return -1
        saved = (self.data.qpos.copy(), self.data.qvel.copy())
        try:
            return self._drive(walls, a, b)
        finally:
            self.env.point_env.set_state(*saved)

    def shortest_steps(self, walls: np.ndarray, goal: str | Cell = "G") -> int:
        """The oracle (scripted controller) from S to ``goal`` in the layout ``walls``."""
        target = self.maze.goal_cell(goal) if isinstance(goal, str) else tuple(goal)
        if np.array_equal(walls, self.grid.walls):
            return self.shortest_path_length(self.maze.start, target)
        return self._in_layout(walls, lambda: self._scripted(walls, self.maze.start, target))

    def event_oracle_steps(self, event: str, goal: str | Cell = "G") -> int:
        """The env-change bound of the grid (``env_change.oracle_steps``: an agent that
        knows the old maze walks an old shortest path up to the first blocked cell on it,
        bumps once, then walks a shortest path of the new maze) *measured* on the physics:
        the route of that bound (the old path to the cell ``c`` before the block, found on
        the grid) driven by the scripted controller: to ``c`` in the old layout, one
        primitive into the block, then to the goal in the new layout."""
        if event not in self.maze.events:
            raise MazeError(f"no event named {event!r}", self.maze.source)
        target = self.maze.goal_cell(goal) if isinstance(goal, str) else tuple(goal)
        old, new = self.maze.walls, self.maze.walls_after([event])
        route = _bump_route(old, new, self.maze.start, target)
        if route is None:                 # an old shortest path avoids the block
            return self.shortest_steps(old, target)
        c, into = route
        return self._in_layout(new, lambda: self._bump_then_go(old, new, c, into, target))

    def _in_layout(self, walls: np.ndarray, fn):
        """``fn()`` with the env built from ``walls``, the world's own layout restored."""
        keep = self.grid.walls
        if np.array_equal(walls, keep):
            return fn()
        saved = (self.data.qpos.copy(), self.data.qvel.copy())
        self._build(walls)
        try:
            return fn()
        finally:
            self._build(keep)
            self.env.point_env.set_state(*saved)

    def _bump_then_go(self, old, new, c: Cell, into: int, target: Cell) -> int:
        saved = (self.data.qpos.copy(), self.data.qvel.copy())
        try:
            n = self._drive(old, self.maze.start, c, stop_in_cell=True) if c != \
                self.maze.start else 0
            self._primitive(into, [])     # the bump
            return n + 1 + self._drive(new, None, target)
        finally:
            self.env.point_env.set_state(*saved)

    def _drive(self, walls: np.ndarray, a: Cell | None, b: Cell,
               stop_in_cell: bool = False) -> int:
        """Scripted primitives from ``a`` (None: where the point is) to ``b``: until the
        env's success test holds at ``b`` (or, ``stop_in_cell``, the point is at ``b``'s
        centre)."""
        to_b = bfs_distances(walls, b)
        if a is not None:
            self._place(a)
        here = self.cell_of(self.data.qpos[:2])
        if to_b[here] < 0:
            raise MazeError(f"{b} cannot be reached from {here}", self.maze.source)
        goal = [self.xy(b)]
        cap = 4 * int(to_b[here]) * self.per_cell + 8
        for n in range(0, cap + 1):
            if (stop_in_cell and self.cell_of(self.data.qpos[:2]) == b
                    and np.abs(self.data.qpos[:2] - goal[0]).max()
                    < 0.25 * self.step_length) or \
                    (not stop_in_cell and n == 0 and self._success(goal[0])):
                return n
            if n == cap:
                break
            action = self._towards(walls, to_b, b)
            _, which = self._primitive(action, [] if stop_in_cell else goal)
            if which == 0:
                return n + 1
        raise MazeError(f"the scripted controller did not reach {b} within {cap} primitive "
                        f"steps", self.maze.source)

    def _towards(self, walls: np.ndarray, to_b: np.ndarray, b: Cell) -> int:
        """The scripted controller's primitive: in ``b``, the one along the larger offset
        from its centre; elsewhere, the one towards the neighbour one BFS step nearer ``b``
        (the axis of that step), unless the point is off its cell's centre across that
        axis (on the edge it came in by): then the one back to the centre's line first (a
        turn taken from the edge would graze the corner of a wall)."""
        xy = self.data.qpos[:2]
        cell = self.cell_of(xy)
        off = xy - self.xy(cell)
        if cell == b:
            axis = int(np.argmax(np.abs(off)))
            return (3 if off[0] < 0 else 2) if axis == 0 else (0 if off[1] < 0 else 1)
        rows, cols = walls.shape
        best, best_a = None, 0
        for a, (dr, dc) in enumerate(((-1, 0), (1, 0), (0, -1), (0, 1))):
            r, c = cell[0] + dr, cell[1] + dc
            if 0 <= r < rows and 0 <= c < cols and to_b[r, c] >= 0 and \
                    (best is None or to_b[r, c] < best):
                best, best_a = int(to_b[r, c]), a
        across = 0 if best_a < 2 else 1           # x across a vertical step, y across a
        if abs(off[across]) > 0.25 * self.step_length:      # horizontal one
            if across == 0:
                return 3 if off[0] < 0 else 2
            return 0 if off[1] < 0 else 1
        return best_a

def _bump_route(old: np.ndarray, new: np.ndarray, start: Cell,
                target: Cell) -> tuple[Cell, int] | None:
    """The route of the grid's env-change bound: the cell ``c`` on an old shortest path
    (reached from S along unblocked old shortest-path cells) and the action from ``c``
    into a blocked cell of that path minimising ``ds[c] + 1 + dnew[c]``; None when an old
    shortest path avoids every blocked cell."""
    ds, dg, dnew = bfs_distances(old, start), bfs_distances(old, target), \
        bfs_distances(new, target)
    d = int(ds[target])
    blocked = new & ~old
    rows, cols = old.shape
    frontier, best = {start}, None
    for _ in range(d + 1):
        nxt = set()
        for c in frontier:
            if c == target:
                return None
            for a, (dr, dc) in enumerate(((-1, 0), (1, 0), (0, -1), (0, 1))):
                n = (c[0] + dr, c[1] + dc)
                if not (0 <= n[0] < rows and 0 <= n[1] < cols) or ds[n] != ds[c] + 1 \
                        or dg[n] < 0 or ds[n] + dg[n] != d:
                    continue
                if blocked[n]:
                    if dnew[c] >= 0:
                        total = int(ds[c]) + 1 + int(dnew[c])
                        if best is None or total < best[0]:
                            best = (total, c, a)
                else:
                    nxt.add(n)
        frontier = nxt
    if best is None:
        raise MazeError("the goal cannot be reached after the event")
    return best[1], best[2]
