"""PointMaze built from our maze files (maze_sim/pointmaze_world.py): geometry, the primitive
length and its physics steps, the env's success test, the scripted oracle, an event that
rebuilds the MuJoCo model, goals and the senses the agent is given."""

import numpy as np
import pytest

pytest.importorskip("gymnasium_robotics")
pytest.importorskip("mujoco")

from maze_sim.maze import Maze, MazeError  # noqa: E402
from maze_sim.pointmaze_world import (  # noqa: E402
    CELL_SIZE,
    PRIMITIVES,
    SUCCESS_RADIUS,
    PointMazeWorld,
    primitive_steps,
    step_length,
)
from maze_sim.world import EditRefused  # noqa: E402
from maze_sim.worlds import WorldError, make_world  # noqa: E402

# Rows 0-4, cols 0-6. A block event 'a' at (1, 3) leaves the way round by row 3.
SMALL = """\
#######
#S.a.G#
#.###.#
#.....#
#######
"""
UP, DOWN, LEFT, RIGHT = range(4)
# An open room, rows 0-4, cols 0-5: several resting places a cell in every direction.
OPEN = """\
######
#S..G#
#....#
#....#
######
"""


@pytest.fixture(scope="module")
def world():
    return PointMazeWorld(Maze.from_text(SMALL), "G")


def test_walls_and_cells_at_the_documented_coordinates(world):
    rows, cols = 5, 7
    for r, c in [(0, 0), (1, 1), (3, 5), (4, 6)]:
        x, y = world.xy((r, c))
        assert (x, y) == (c + 0.5 - cols / 2, rows / 2 - r - 0.5)
        assert world.cell_of((x, y)) == (r, c)
    # every '#' is a MuJoCo box at its cell's centre, nothing else is
    names = world.env._model_names.geom_name2id
    blocks = {tuple(map(int, n.split("_")[1:])) for n in names if n and n.startswith("block_")}
    assert blocks == {tuple(map(int, rc)) for rc in zip(*np.nonzero(world.maze.walls))}
    for r, c in blocks:
        pos = world.model.geom_pos[names[f"block_{r}_{c}"]][:2]
        assert np.allclose(pos, world.xy((r, c)))


def test_step_length_and_k_are_derived_from_the_physics(world):
    # one cell of the maze, the env's maze_size_scaling
    assert step_length() == CELL_SIZE == world.step_length == 1.0
    assert world.per_cell == 1
    assert step_length(2.5) == 2.5
    k_push, k_brake, force = primitive_steps(1.0)
    assert (world.k_push, world.k_brake, world.force) == (k_push, k_brake, force)
    assert k_push > 0 and k_brake > 0 and 0.0 < force <= 1.0
    # a shorter move needs a shorter push
    assert primitive_steps(0.5)[0] < k_push


def test_a_primitive_moves_one_cell_and_ends_at_rest(world):
    obs, info = world.reset()
    assert np.allclose(obs, world.xy((1, 1))) and info["cell"] == (1, 1)
    obs, _, _, _, info = world.step(RIGHT)
    assert np.abs(obs - world.xy((1, 2))).max() < 1e-3          # the next cell's centre
    assert np.abs(world.data.qvel[:2]).max() < 1e-2
    assert world.cell == (1, 2) and not info.bumped
    obs, _, _, _, info = world.step(RIGHT)
    assert world.cell == (1, 3) and not info.bumped
    assert np.abs(obs - world.xy((1, 3))).max() < 1e-3


def test_a_wall_ahead_bumps_a_wall_alongside_does_not(world):
    world.reset()
    _, _, _, _, info = world.step(UP)            # row 0 is wall: touched head-on
    assert info.bumped and world.cell == (1, 1)
    _, _, _, _, info = world.step(UP)
    assert info.bumped
    _, _, _, _, info = world.step(RIGHT)         # sliding along the top wall: not a bump
    assert not info.bumped


def test_a_bumped_move_returns_to_where_it_started():
    w = PointMazeWorld(Maze.from_text(SMALL), "G")
    before, _ = w.reset()
    obs, _, _, _, info = w.step(UP)              # into the top wall
    assert info.bumped
    assert np.abs(obs - before).max() < 1e-3     # back where it was, not at the wall
    assert np.abs(w.data.qvel[:2]).max() <= 1e-3


@pytest.mark.parametrize("text", [SMALL, OPEN])
def test_the_point_rests_only_at_the_cells_centres(text):
    # every primitive moves exactly one cell or, bumped, returns: after a random walk with
    # bumps every resting place is a cell's centre (a bumped move left against the wall
    # rested a point radius, 0.1 m, off it, and every move after kept it), also the goal's
    w = PointMazeWorld(Maze.from_text(text), "G")
    w.reset()
    rng = np.random.default_rng(3)
    bumps, ends, worst = 0, 0, 0.0
    for _ in range(300):
        before = w.sense()
        obs, _, terminated, _, info = w.step(int(rng.integers(4)))
        bumps += info.bumped
        if info.bumped:
            assert np.abs(obs - before).max() < 5e-3
        worst = max(worst, float(np.abs(obs - w.xy(w.cell)).max()))
        if terminated:
            assert w.cell == w.goal
            ends += 1
            w.reset()
    assert bumps >= 10 and ends >= 1
    assert worst < 5e-3


def test_the_goal_is_reached_by_the_envs_success_test():
    w = PointMazeWorld(Maze.from_text(SMALL), "G")
    w.reset(start=(1, 3))
    obs, reward, terminated, _, info = w.step(RIGHT)
    assert not terminated                        # the goal's neighbour: 1 m from its centre
    obs, reward, terminated, _, info = w.step(RIGHT)
    assert terminated and info.reached_goal and reward == 1.0
    assert np.linalg.norm(obs - w.goal_observation()) <= SUCCESS_RADIUS
    assert w.env.compute_terminated(obs, w.env.goal, {})


def test_the_move_into_the_goal_region_runs_to_its_end():
    # the test holds 0.45 m from the centre, 0.55 m into the move from the neighbour's
    # centre; the move still comes to rest, at the goal's centre (a place of the lattice)
    w = PointMazeWorld(Maze.from_text(SMALL), "G")
    before, _ = w.reset(start=(1, 4))
    obs, _, terminated, _, info = w.step(RIGHT)
    assert terminated and info.reached_goal
    assert np.linalg.norm(before - w.goal_observation()) > SUCCESS_RADIUS
    assert np.linalg.norm(obs - w.goal_observation()) < 0.1
    assert np.abs(w.data.qvel[:2]).max() < 0.05
    assert np.linalg.norm(obs - before) > 0.8 * step_length()


def test_oracle_by_the_scripted_controller(world):
    # S (1,1) to G (1,5): 4 m straight right, a cell a primitive; the success test holds
    # within the fourth move: as many as RIGHT takes, the cells of a shortest path
    n = world.shortest_path_length()
    assert n == 4 == world.maze.shortest_path_length((1, 1), (1, 5))
    world.reset()
    for k in range(1, 9):
        if world.step(RIGHT)[2]:
            break
    assert k == n
    assert world.shortest_path_length((1, 4), (1, 5)) == 1
    assert world.shortest_path_length((3, 1), (1, 5)) == 6
    before = world.data.qpos.copy()
    world.shortest_path_length((3, 1), (1, 5))
    assert np.array_equal(world.data.qpos, before)   # the point is put back


def test_an_event_rebuilds_the_model_and_the_oracle_follows():
    w = PointMazeWorld(Maze.from_text(SMALL), "G")
    w.reset()
    w.step(RIGHT)
    here = w.data.qpos.copy()
    old_model = w.model
    w.fire_event("a")
    assert w.model is not old_model and np.array_equal(w.data.qpos, here)
    assert w.walls[1, 3] and "block_1_3" in w.env._model_names.geom_name2id
    # round by row 3: 2 + 4 + 2 = 8 cells, a primitive a cell
    assert w.shortest_path_length() == 8
    # the point cannot enter the new wall
    w.reset(start=(1, 2))
    _, _, _, _, info = w.step(RIGHT)
    assert info.bumped and w.cell == (1, 2)
    # the grid's bound, driven: S to (1, 2), the bump, back to S and round by row 3
    assert w.event_oracle_steps("a") == 1 + 1 + 1 + 8


def test_edits_are_refused_as_in_the_grid_world():
    w = PointMazeWorld(Maze.from_text(SMALL), "G")
    w.reset()
    with pytest.raises(EditRefused, match="wall in the start"):
        w.set_cell(1, 1, True)
    with pytest.raises(MazeError, match="no event named 'z'"):
        w.fire_event("z")


def test_set_goal_moves_the_target_and_the_goal_sensation():
    w = PointMazeWorld(Maze.from_text(SMALL), "G")
    assert w.set_goal((3, 1)) == (3, 1)
    assert np.allclose(w.env.goal, w.xy((3, 1)))
    assert np.allclose(w.goal_observation(), w.xy((3, 1)))
    assert w.goal_state == (3, 1)               # the goal sensation discretised
    assert w.shortest_path_length() == 2


def test_senses_from_the_world():
    from tmgwr_agent.world_senses import named_world_senses, world_senses

    w = PointMazeWorld(Maze.from_text(SMALL), "G", velocity=True)
    s = world_senses(w)
    assert s.dim == 4 and np.array_equal(s.primitives, PRIMITIVES)
    assert len(w.reset()[0]) == 4 and len(w.goal_observation()) == 4
    assert named_world_senses("pointmaze").dim == 2
    assert np.array_equal(named_world_senses("grid").primitives[0], (-1, 0))


def test_the_resolution_is_the_move_and_the_map_tells_places_apart():
    from tmgwr_agent.core.agent import TMGWRAgent
    from tmgwr_agent.core.senses import Senses, SensesError
    from tmgwr_agent.world_senses import maze_senses, named_world_senses, world_senses

    w = PointMazeWorld(Maze.from_text(SMALL), "G")
    assert world_senses(w).resolution == step_length() == w.sensor_resolution
    assert named_world_senses("pointmaze").resolution == step_length()
    assert maze_senses().resolution == 1.0                   # the grid: one cell
    with pytest.raises(SensesError, match="resolution step must be a finite distance"):
        Senses(2, PRIMITIVES, 0.0, 0.0)

    def places(senses):
        # S down the corridor and along row 3 to (3, 5), one cell per move: 7 places
        ag = TMGWRAgent(senses, np.random.default_rng(0))
        obs, _ = w.reset()
        ag.begin_episode(obs)
        for a in (DOWN, DOWN, RIGHT, RIGHT, RIGHT, RIGHT):
            obs, _, _, _, info = w.step(a)
            assert not info.bumped
            ag.observe(obs, info)
        return int(ag.map.alive[:ag.map.n].sum())

    assert places(world_senses(w)) == 7                     # one node a cell
    # declared coarser than the move: neighbouring places lie within the map's matching
    # radius, and one node stands for several of them
    assert places(Senses(2, PRIMITIVES, SUCCESS_RADIUS, 2.0 * CELL_SIZE)) < 7


def test_in_an_open_room_the_map_holds_one_node_a_cell():
    # a random walk over an open room, bumps into its walls included: the point rests at
    # the centres of the cells it visits, and the agent's map holds one node for each (with
    # half-cell moves it rested on edges and corners too, and held a node for each)
    from tmgwr_agent.core.agent import TMGWRAgent
    from tmgwr_agent.world_senses import world_senses

    w = PointMazeWorld(Maze.from_text(OPEN), "G")
    ag = TMGWRAgent(world_senses(w), np.random.default_rng(0))
    obs, _ = w.reset()
    ag.begin_episode(obs)
    rng = np.random.default_rng(7)
    visited = {w.cell}
    for _ in range(120):
        obs, _, terminated, _, info = w.step(int(rng.integers(4)))
        ag.observe(obs, info)
        visited.add(w.cell)
        if terminated:
            obs, _ = w.reset()
            ag.begin_episode(obs)
    assert len(visited) >= 8
    assert int(ag.map.alive[:ag.map.n].sum()) == len(visited)


def test_make_world_by_name():
    m = Maze.from_text(SMALL)
    assert isinstance(make_world("pointmaze", m, "G", 10), PointMazeWorld)
    with pytest.raises(WorldError, match="unknown world 'mars'"):
        make_world("mars", m)
    with pytest.raises(WorldError, match="unexpected keyword"):
        make_world("pointmaze", m, colour="red")


def test_the_goal_region_is_declared_and_told_to_the_agent():
    from tmgwr_agent.core.senses import Senses, SensesError
    from tmgwr_agent.world_senses import maze_senses, named_world_senses, world_senses

    w = PointMazeWorld(Maze.from_text(SMALL), "G")
    assert world_senses(w).goal_tolerance == SUCCESS_RADIUS
    assert named_world_senses("pointmaze").goal_tolerance == SUCCESS_RADIUS
    assert maze_senses().goal_tolerance == 0.0          # the grid: one exact sensation
    with pytest.raises(SensesError, match="goal tolerance must be a finite distance"):
        Senses(2, PRIMITIVES, -0.1)


def _goal_node(goal_tolerance):
    """The goal node of an estimator over a corridor of places half a metre apart (feature
    gain 0.2 a metre: the preprocessor's 0.1 a resolution step, PointMaze's move) that ends
    0.5 m short of the goal sensation, where an episode stops by a goal region of 0.45 m."""
    from maze_sim.maze import ACTION_VECTORS
    from tmgwr_agent.core.motivation import MotivationEstimator
    from tmgwr_agent.core.sensorimotor_map import MapConfig, SensorimotorMap

    m = SensorimotorMap(dim=2, config=MapConfig(a_T=0.99, h_T=0.75, alpha_c=0.0,
                                                insert_at=1.0), primitives=ACTION_VECTORS)
    for k in range(4):                          # 0, 0.5, 1.0, 1.5 m, moved along by 'right'
        m.step(np.array([0.0, 0.1 * k]), ACTION_VECTORS[RIGHT] if k else None)
        m.h[m.winner] = 0.5
    assert m.size == 4
    est = MotivationEstimator(primitives=ACTION_VECTORS, goal_tolerance=goal_tolerance)
    est.set_goal(np.array([0.0, 0.4]))          # 2.0 m: 0.5 m beyond the last place
    est.update(m)
    return est.goal_node


def test_a_node_near_the_goal_region_represents_the_goal():
    # the nearest place is a step (0.5 m) from the goal sensation, more than the half step
    # a point goal allows, but within half a step of the region the world declares: told
    # the region, the estimator has a goal node and plans to it; not told, it never does
    assert _goal_node(0.2 * SUCCESS_RADIUS) == 3
    assert _goal_node(0.0) == -1


class _DetourAgent:
    """Takes ``detour`` moves down and as many back up, then the oracle's own scripted
    primitives: a route longer than the oracle's."""

    def __init__(self, world, detour):
        self.world, self.detour, self.k = world, detour, 0

    def begin_episode(self, obs, cell=None, learn=True):
        self.k = 0

    def act(self, explore=True):
        from maze_sim.maze import bfs_distances
        self.k += 1
        if self.k <= 2 * self.detour:
            return DOWN if self.k <= self.detour else UP
        w = self.world
        return w._towards(w.grid.walls, bfs_distances(w.grid.walls, w.goal), w.goal)

    def observe(self, obs, info, learn=True):
        pass


def test_the_greedy_probe_allows_the_worlds_declared_tolerance():
    from maze_sim.worlds import parse_world
    from tmgwr_agent.experiments.runner import (
        declared_probe_tolerance,
        greedy_optimal,
        run_episode,
    )

    w = PointMazeWorld(Maze.from_text(SMALL), "G")
    assert w.probe_tolerance >= 0
    assert declared_probe_tolerance(parse_world("pointmaze")) == w.probe_tolerance
    assert declared_probe_tolerance(parse_world("grid")) == 0.0
    d = w.shortest_path_length()
    assert greedy_optimal(w, _DetourAgent(w, 0))              # the oracle's own route
    ep = run_episode(w, _DetourAgent(w, 1), max_steps=4 * d)
    assert ep.reached_goal and ep.steps > d
    w.probe_tolerance = (ep.steps - d + 0.5) / d                # cap: that route's length
    assert greedy_optimal(w, _DetourAgent(w, 1))
    w.probe_tolerance = (ep.steps - d - 0.5) / d                # one step short of it
    assert not greedy_optimal(w, _DetourAgent(w, 1))
    w.probe_tolerance = 0.0                     # an exact oracle: exactly D steps
    assert not greedy_optimal(w, _DetourAgent(w, 1))
    assert greedy_optimal(w, _DetourAgent(w, 0))


def _walk(w, steps, seed):
    """A random walk of ``steps`` primitives (a new episode after each end): the
    sensation, the world's tabular state, ``info`` and the true cell of every step."""
    w.reset()
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps):
        obs, _, terminated, truncated, info = w.step(int(rng.integers(4)))
        out.append((obs, w.state, info, w.cell))
        if terminated or truncated:
            w.reset()
    return out


@pytest.mark.parametrize("velocity", [False, True])
def test_the_tabular_state_is_the_sensation_at_the_declared_resolution(velocity):
    # the tables key on the lattice point the sensed position rests on, in resolution steps
    # from cell (0, 0)'s centre: the point rests only at the cells' centres, one state a
    # cell, and the state is the sensation's, not the true cell read from the world
    w = PointMazeWorld(Maze.from_text(OPEN), "G", velocity=velocity)
    obs, info = w.reset()
    assert info["state"] == w.state == w.discretise(obs) == (1, 1)
    res, origin = w.sensor_resolution, w.xy((0, 0))
    states_of_cell: dict = {}
    for obs, state, info, cell in _walk(w, 200, 5):
        assert info.cell == state == w.discretise(obs)
        on_lattice = origin + res * np.array([state[1], -state[0]])
        assert np.abs(obs[:2] - on_lattice).max() < 5e-3        # the nearest lattice point
        states_of_cell.setdefault(cell, set()).add(state)
    assert len(states_of_cell) >= 8
    assert all(s == {cell} for cell, s in states_of_cell.items())
    # a sensation off the centres is discretised to the nearest one
    assert w.discretise(w.xy((2, 3)) + (0.45, -0.45)) == (2, 3)
    assert w.discretise(w.xy((2, 3)) + (0.55, 0.0)) == (2, 4)


def test_the_goal_state_is_reached_exactly_when_the_env_reports_success():
    w = PointMazeWorld(Maze.from_text(OPEN), "G")
    assert w.goal_state == w.discretise(w.goal_observation()) == (1, 4)
    walk = _walk(w, 600, 11)
    reached = [info.reached_goal for _, _, info, _ in walk]
    assert sum(reached) >= 2
    assert reached == [state == w.goal_state for _, state, _, _ in walk]
    w.set_goal((3, 1))                            # the goal's state follows the goal
    assert w.goal_state == (3, 1)


def test_the_tables_in_pointmaze_key_on_the_lattice():
    # Q-learning run by the experiments' loop in the hosted world: the keys it learnt are
    # lattice points (one a cell), its goal the goal sensation's
    from tmgwr_agent.experiments.agent_factory import make_agent
    from tmgwr_agent.experiments.runner import run_episode, set_goal
    from tmgwr_agent.experiments.sensing import HostedWorld

    w = HostedWorld(PointMazeWorld(Maze.from_text(OPEN), "G", max_episode_steps=150))
    agent = make_agent("q_learning", w.maze, np.random.default_rng(2),
                       sensed=not w.identity, senses=w.senses)
    set_goal(w, agent, "G")
    assert agent.goal == w.goal_state
    for _ in range(3):
        run_episode(w, agent)
    assert next(iter(agent.sensed)) == w.discretise(w.xy(w.maze.start)) == (1, 1)
    assert set(agent.sensed) <= set(w.maze.free_cells())    # one state a cell


def test_the_sensor_range_is_declared_and_no_option_leads_outside_it():
    from tmgwr_agent.core.agent import TMGWRAgent
    from tmgwr_agent.core.senses import Senses
    from tmgwr_agent.world_senses import world_senses

    w = PointMazeWorld(Maze.from_text(SMALL), "G")
    low, high = w.observation_space.low, w.observation_space.high
    free = [tuple(c) for c in zip(*np.nonzero(~w.maze.walls))]
    centres = np.array([w.xy(c) for c in free])
    assert (centres >= low).all() and (centres <= high).all()
    # a move into the outer wall would end beyond it, by the point's radius
    radius = float(w.model.geom_size[w._point_geom][0])
    assert np.allclose(low, centres.min(axis=0) - (0.5 - radius))
    assert np.allclose(high, centres.max(axis=0) + (0.5 - radius))
    s = world_senses(w)
    assert s.bounded and np.array_equal(s.low, low) and np.array_equal(s.high, high)
    v = PointMazeWorld(Maze.from_text(SMALL), "G", velocity=True).observation_space
    assert np.array_equal(v.low[2:], (-5.0, -5.0)) and np.array_equal(v.high[2:], (5.0, 5.0))

    def options(senses):
        # from S (1, 1): down to (3, 1) and back, right and back; then the untried moves
        # of the node at S and of the one at (2, 1)
        ag = TMGWRAgent(senses, np.random.default_rng(0))
        ag.set_goal(None, w.goal_observation())
        obs, _ = w.reset()
        ag.begin_episode(obs)
        seen = {}
        for a in (DOWN, DOWN, UP, UP, RIGHT, LEFT):
            if np.allclose(obs, w.xy((2, 1))):
                seen["(2, 1)"] = obs
            obs, _, _, _, info = w.step(a)
            ag.observe(obs, info)
        seen["S"] = obs
        ag.motivation.update(ag.map)
        feats = {k: ag.preprocessor(x) for k, x in seen.items()}
        nodes = {k: int(np.argmin(np.linalg.norm(ag.map.w[:ag.map.n] - f, axis=1)))
                 for k, f in feats.items()}
        rho = {(k, a): float(ag.motivation.rho[i, a]) for k, i in nodes.items()
               for a in (UP, LEFT, RIGHT)}
        return rho, ag.motivation.rho_new

    (told, prior), (untold, untold_prior) = \
        options(s), options(Senses(2, PRIMITIVES, SUCCESS_RADIUS, step_length()))
    outward = [("S", UP), ("S", LEFT), ("(2, 1)", LEFT)]
    assert all(untold[k] > 0.0 for k in outward)      # untried: options when not told
    assert all(told[k] == 0.0 for k in outward)       # told the range: none
    assert told[("(2, 1)", RIGHT)] > 0.0              # a move into an inner wall stays one
    # the moves the range closes count as tried moves that did not open (open_prior)
    assert prior < untold_prior


def test_senses_refuse_a_range_that_does_not_fit():
    from tmgwr_agent.core.senses import Senses, SensesError
    from tmgwr_agent.world_senses import maze_senses

    assert not Senses(2, PRIMITIVES).bounded
    assert not maze_senses().bounded          # the grid world declares no range
    with pytest.raises(SensesError, match="must give 2 values"):
        Senses(2, PRIMITIVES, low=[0.0])
    with pytest.raises(SensesError, match="range is empty"):
        Senses(2, PRIMITIVES, low=[0.0, 1.0], high=[1.0, 0.0])
