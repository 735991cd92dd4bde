"""The fused paths of a converged step (motivation.py's ``_prepare_rows``, one kernel call,
kernels.prepare_rows, and ``_fused_update``, the update in one call, kernels.converged_step)
leave the agent in the same state, to the bit, as the general path
(the estimator's ``fused`` False): two agents of one seed, one on each path, take the same
actions and hold the same potentials, rewards, absorbing flags, options and map after every
step of a training run, under identity, rotated and noisy sensing (noise moves the goal's
node and the frame more often, so the fallbacks run too)."""

import numpy as np
import pytest

from maze_sim import GridWorld, Maze
from maze_sim.maze import maze_file
from tmgwr_agent.core import kernels
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.world_senses import maze_senses

#: What must be equal after each step: the estimator's and the map's arrays.
ESTIMATOR = ("V", "R", "U", "rho", "osucc", "onb", "ong", "_abs", "_abs_terminal", "delta")
MAP = ("w", "c", "h", "won", "alive", "out", "E", "a", "age", "terminal")


def sense(obs, A, rng, noise):
    return A @ obs + (rng.normal(0.0, noise, 2) if noise else 0.0)


def pair_run(A, noise, steps, seed=5, before_step=None, until=None, most=10_000,
             goal_at=None):
    """Two agents of one seed on two worlds of one seed, the second on the general path;
    returns them after ``steps`` steps checked equal at each (``before_step(agent)``
    called before each step's observation, when given); with ``until``, the run goes on
    past ``steps`` until ``until(first agent)`` holds, ``most`` steps in all. ``goal_at``:
    (step, cell), the goal moved there at that step (the old one kept terminal, as in
    the goal-change scenario) and told to both agents."""
    maze = Maze.from_file(maze_file())
    agents, worlds, rngs = [], [], []
    for fused in (True, False):
        world = GridWorld(maze, "G", seed=0, max_episode_steps=400)
        agent = TMGWRAgent(maze_senses(), np.random.default_rng(seed))
        agent.motivation.fused = fused
        rng = np.random.default_rng(seed + 1)
        agent.set_goal(world.goal, A @ world.goal_observation())
        obs, _ = world.reset()
        agent.begin_episode(sense(obs, A, rng, noise))
        agents.append(agent)
        worlds.append(world)
        rngs.append(rng)
    for t in range(most):
        if t >= steps and (until is None or until(agents[0])):
            break
        if goal_at is not None and t == goal_at[0]:
            for agent, world in zip(agents, worlds):
                world.set_goal(goal_at[1], keep_previous=True)
                agent.set_goal(world.goal, A @ world.goal_observation())
        acts = [agent.act() for agent in agents]
        assert acts[0] == acts[1]
        for agent, world, rng in zip(agents, worlds, rngs):
            obs, _, terminated, truncated, info = world.step(acts[0])
            if before_step is not None:
                before_step(agent)
            agent.observe(sense(obs, A, rng, noise), info)
            if terminated or truncated:
                obs, _ = world.reset()
                agent.begin_episode(sense(obs, A, rng, noise))
        f, g = agents
        assert f.motivation.goal_node == g.motivation.goal_node
        assert f.motivation._abs_count == g.motivation._abs_count
        for name in ESTIMATOR:
            assert np.array_equal(getattr(f.motivation, name), getattr(g.motivation, name)), name
        for name in MAP:
            assert np.array_equal(getattr(f.map, name), getattr(g.map, name)), name
    return agents


@pytest.mark.parametrize("deg,noise", [(0, 0.0), (30, 0.0), (0, 0.2)])
def test_the_fused_step_is_the_general_step_to_the_bit(deg, noise):
    t = np.radians(deg)
    A = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    # The fused path runs once the goal's node is known, that is, after the agent first
    # reached the goal (sensed); under noise when that happens in a run of exploration
    # depends on the seed, so the run goes on until it has and the fused path ran a while.
    fused, general = pair_run(A, noise, steps=2500,
                              until=lambda agent: agent.motivation.fused_steps >= 50)
    assert general.motivation.fused_steps == 0
    # the fused path was taken (on steps where only logged rows changed)
    assert fused.motivation.fused_steps > 0



def test_the_fused_step_runs_while_the_closed_cells_are_to_recompute():
    """The trusted closed cells are recomputed at the solve (``closed_cells``); a fused
    preparation that comes first, after a mark changed them (``_closed`` None), runs
    (it brings no flags up to date) and leaves the agent as the general path does."""
    def forget(agent):
        agent.motivation._closed = None
    fused, general = pair_run(np.eye(2), 0.0, steps=1500, before_step=forget)
    assert fused.motivation.fused_steps > 0


def test_the_fused_update_is_the_general_update_across_a_goal_change(monkeypatch):
    """The fused update (``_fused_update``: the preparation and the incremental solve in
    one call, kernels.converged_step) before and after the goal moves (a new goal node,
    the potentials from 0, the map growing towards it) leaves the agent as the general
    path does."""
    goals = []                          # the goal of each fused update
    converged_step = kernels.converged_step

    def counted(*args):
        goals.append(tuple(args[8]))    # (its goal_x)
        return converged_step(*args)
    monkeypatch.setattr(kernels, "converged_step", counted)
    maze = Maze.from_file(maze_file())
    goal = maze.goal_cell("G")
    far = max(maze.free_cells(), key=lambda c: abs(c[0] - goal[0]) + abs(c[1] - goal[1]))
    fused, _ = pair_run(np.eye(2), 0.0, steps=6000, goal_at=(3000, far))
    new = tuple(fused.motivation.goal_x)
    assert new != goals[0] and goals.count(goals[0]) > 0 and goals.count(new) > 0
