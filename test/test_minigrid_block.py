"""After a block in MiniGrid (issue 26): the value of unknown space without a lattice.

An untried move is worth ``V* gamma^h`` (``OptionRules._unplaced_options``), h a lower
bound on the moves from its predicted successor to the goal. The bound in the sensation's
norm divides by the step of the primitive that moves farthest (a turn: ``sqrt 2`` in the
heading), so it counts every forward move as ``sqrt 2`` cells; the bound per coordinate
(``OptionRules._steps_to_goal``) counts the cells a forward move crosses one at a time."""

import math

import numpy as np
from small_mazes import SMALL

from maze_sim.maze import Maze
from maze_sim.minigrid_world import FORWARD, LEFT, MiniGridWorld
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.experiments.runner import run_episode
from tmgwr_agent.world_senses import world_senses


def trained(episodes: int = 8, seed: int = 0):
    """A default agent trained on G of SMALL in MiniGrid."""
    world = MiniGridWorld(Maze.from_text(SMALL), "G", max_episode_steps=3000)
    agent = TMGWRAgent(world_senses(world), np.random.default_rng(seed))
    agent.set_goal(world.goal, world.goal_observation())
    for _ in range(episodes):
        run_episode(world, agent)
    return world, agent


def test_a_move_changes_each_coordinate_by_at_most_one_cell_or_a_quarter_turn():
    """The reach per coordinate the agent reads off its own moves: a forward move changes
    row or column by one cell, a turn cos or sin by 1 (in the map's units; the nodes'
    weights are means of what they matched, a few per cent off the sensations)."""
    _, agent = trained()
    gain = agent.preprocessor.gain
    reach = agent.motivation._move_reach(agent.map)
    np.testing.assert_allclose(reach, gain, rtol=0.1)


def test_an_untried_move_far_from_the_goal_is_valued_by_the_cells_it_must_cross():
    """Untried forward and turn moves from nodes several cells from the goal: h is the most
    cells along one axis between the predicted successor and the goal (a forward move
    crosses one at a time), not the distance over the turn's longer step (before: h was
    up to sqrt 2 times smaller, and unknown corners of the map outranked known detours)."""
    _, agent = trained()
    m, mo = agent.map, agent.motivation
    gain = agent.preprocessor.gain
    goal = mo.goal_x
    checked = 0
    for a in (FORWARD, LEFT):
        far = [i for i in np.flatnonzero(m.alive[: m.n])
               if mo.tried[i, a] and mo.bump_t[i, a] < 0
               and np.abs(m.w[i, :2] - goal[:2]).max() >= 3.0 * gain]
        assert far, a
        i = int(far[len(far) // 2])
        mo.tried[i, a], mo.succ[i, a], mo.bump_t[i, a] = False, -1, -1
        mo._dirty.add(i)
        mo.update(m)
        x = mo._predicted(m, np.array([i]), a)[0]
        reach = mo._move_reach(m)
        cells = (np.abs(x - goal) / reach).max()
        step = math.sqrt(mo.delta_sq.max())
        norm = np.linalg.norm(x - goal) / step
        assert cells > norm + 0.5                       # the two bounds differ here
        assert mo.rho[i, a] > 0.0
        h = math.log(mo.U[i, a] / mo.v_star) / math.log(mo.gamma)
        assert abs(h - cells) < 1e-6, (i, a, h, cells, norm)
        checked += 1
    assert checked == 2
