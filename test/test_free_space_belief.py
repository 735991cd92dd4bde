"""The free-space belief after a break (core/unknown.py; kernels.belief_steps, belief_h):
unknown cells are free, what bumped is closed, and an option's cell is valued by the
fewest lattice moves to the goal round the walls the agent knows; an option no nearer the
goal than its node by that count is dropped. By hand on a small lattice, and in a blocking
maze where the L1 count ranked the maze's outer wall as near the goal as the far gap."""

import numpy as np
import pytest

from maze_sim import GridWorld, Maze
from maze_sim.maze import ACTION_VECTORS
from tmgwr_agent.core import kernels
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.world_senses import maze_senses

UP, DOWN, LEFT, RIGHT = range(4)       # the rows of ACTION_VECTORS


def belief(closed_node=None):
    """Nodes on rows 0 and 2 of a 3 x 4 lattice; row 1 known closed at columns 0-2 (bumped
    going down from row 0), unknown at column 3; the goal at (2, 0)."""
    cells = [(0, c) for c in range(4)] + [(2, c) for c in range(4)]
    n = len(cells)
    w = np.array(cells, dtype=float)
    tried = np.zeros((n, 4), dtype=bool)
    bump_t = np.full((n, 4), -1)
    for c in range(3):
        tried[c, DOWN], bump_t[c, DOWN] = True, 5
    closed = np.zeros(n, dtype=bool)
    if closed_node is not None:
        closed[closed_node] = True
    lattice = np.ones(4, dtype=bool)
    dist, origin = kernels.belief_steps(w, np.ones(n, dtype=bool), n, tried, bump_t, closed,
                                        ACTION_VECTORS, lattice, 1.0, np.array([2.0, 0.0]))
    return dist, origin, lattice


def at(dist, origin, cell):
    return dist[int(cell[0] - origin[0]), int(cell[1] - origin[1])]


def test_the_belief_counts_moves_round_the_known_walls_and_through_the_ring_by_hand():
    dist, origin, lattice = belief()
    assert dist.shape == (5, 6) and list(origin) == [-1.0, -1.0]   # the box and its ring
    assert [at(dist, origin, (1, c)) for c in range(3)] == [-2, -2, -2]
    assert at(dist, origin, (2, 0)) == 0 and at(dist, origin, (2, 3)) == 3
    assert at(dist, origin, (1, 3)) == 4                 # the unknown cell of the wall row
    assert at(dist, origin, (0, 0)) == 4                 # round the wall's end, in the ring
    assert at(dist, origin, (0, 2)) == 6                 # either way round
    h = kernels.belief_h
    assert h(dist, origin, 1.0, np.array([1.1, 1.0]), ACTION_VECTORS, lattice) == 2  # open
    assert h(dist, origin, 1.0, np.array([0.0, 3.1]), ACTION_VECTORS, lattice) == 5
    assert h(dist, origin, 1.0, np.array([0.0, 9.0]), ACTION_VECTORS, lattice) == -3


def test_a_cell_that_closed_is_closed_though_its_node_lives():
    dist, origin, _ = belief(closed_node=7)              # the node of (2, 3)
    assert at(dist, origin, (2, 3)) == -2
    assert at(dist, origin, (1, 3)) == 8                 # now round through the ring
    assert at(dist, origin, (0, 3)) == 7


def test_no_belief_in_other_dimensions():
    w = np.zeros((2, 3))
    dist, _ = kernels.belief_steps(w, np.ones(2, dtype=bool), 2, np.zeros((2, 2), bool),
                                   np.full((2, 2), -1), np.zeros(2, bool), np.eye(2, 3),
                                   np.ones(2, bool), 1.0, np.zeros(3))
    assert dist.shape == (0, 0)


#: The near gap ``a`` closes; the far gap ``A`` opens. By L1 the cells of the outer wall
#: left of the start are nearer the goal than the far gap.
BLOCKING = """\
###########
#....S....#
#a#######A#
#.........#
#G........#
###########
"""


@pytest.mark.parametrize("unknown", ["learnt", "grid"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_after_the_block_the_agent_never_tests_the_outer_wall(unknown, seed):
    """A way through the outer wall would have to come back in through the ring beyond
    it, which no shorter believed way needs: before the belief every trial bumped into the
    outer wall three to nine times after the block."""
    maze = Maze.from_text(BLOCKING)
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(seed), {"unknown": unknown})
    world = GridWorld(maze, "G")
    agent.set_goal(world.goal, world.goal_observation())

    def episode():
        obs, info = world.reset()
        agent.begin_episode(obs, info["cell"])
        cell, outer = info["cell"], []
        for _ in range(2000):
            a = agent.act()
            obs, _, term, trunc, info = world.step(a)
            agent.observe(obs, info)
            if info.bumped:
                r, c = np.array(cell) + ACTION_VECTORS[a].astype(int)
                if r in (0, maze.walls.shape[0] - 1) or c in (0, maze.walls.shape[1] - 1):
                    outer.append((int(r), int(c)))
            cell = info.cell
            if term or trunc:
                return info.reached_goal, outer
        return False, outer

    for _ in range(10):
        episode()
    world.fire_event("a")
    reached, outer = episode()
    assert reached and outer == []


@pytest.mark.parametrize("agent, sensor, hold", [
    ("tmgwr", "identity", True), ("tmgwr:grid", "identity", True),
    ("tmgwr", "rotate=30", True),            # the learnt frame's axes are the moves
    ("tmgwr:grid", "rotate=30", False),      # the sensor's axes: a move joins diagonals
    ("tmgwr:grid", "scale=1:2", False),      # two cells a move on one axis
    ("tmgwr", "noise=0.1", False)])          # the places scatter
def test_the_cells_hold_the_places_only_where_each_move_is_one_cell_along_an_axis(
        agent, sensor, hold):
    from tmgwr_agent.experiments.agent_factory import make_agent
    from tmgwr_agent.experiments.runner import Caps, make_world
    maze = Maze.from_text(BLOCKING)
    world = make_world(maze, "G", Caps.for_maze(maze), sensor, np.random.SeedSequence(0))
    ag = make_agent(agent, maze, np.random.default_rng(0), None, sensed=not world.identity,
                    senses=world.senses)
    ag.set_goal(world.goal, world.goal_observation())
    for _ in range(5):                       # until every primitive has moved
        obs, info = world.reset()
        ag.begin_episode(obs, None)
        for _ in range(300):
            obs, _, term, trunc, info = world.step(ag.act())
            ag.observe(obs, info)
            if term or trunc:
                break
        if ag.motivation.moves.min() > 0:
            break
    assert ag.motivation.moves.min() > 0 and ag.motivation.cells_hold() == hold

