"""The frame of the value of the unknown (core/frame.py): the learnt frame measures places
in primitive steps, whatever linear transform the sensor applies, and the default agent's
trajectory does not depend on the sensor's rotation."""

import math

import numpy as np
import pytest

from maze_sim import GridWorld, Maze
from maze_sim.maze import ACTION_VECTORS, maze_file
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.core.frame import LearntFrame, SensorFrame, forward_model, make_frame
from tmgwr_agent.world_senses import maze_senses


def rotation(deg):
    t = math.radians(deg)
    return np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])


def test_the_learnt_frame_counts_primitive_steps_under_any_linear_sensor():
    A = rotation(30) @ np.diag([1.0, 5.0])           # units differ, axes rotated
    delta = 0.1 * ACTION_VECTORS @ A.T                # what the agent's moves measured
    f = LearntFrame()
    f.refresh(delta, np.array([3, 5, 7, 2]), L=0.3)
    assert f.complete and f.version == 1
    cells = np.array([[0.0, 0.0], [2.0, 3.0], [5.0, -1.0]])
    F = f.of(0.1 * cells @ A.T, 0.1 * np.array([2.0, 3.0]) @ A.T, delta, 0.3)
    assert F.L == 1.0
    # one primitive step is one unit along a basis axis; L1 between cells counts the steps
    np.testing.assert_allclose(np.abs(F.delta).sum(axis=1), 1.0, atol=1e-12)
    steps = np.abs(F.w[:, None] - F.w[None]).sum(axis=2)
    np.testing.assert_allclose(steps, np.abs(cells[:, None] - cells[None]).sum(axis=2),
                               atol=1e-9)
    np.testing.assert_allclose(np.abs(F.goal - F.w[1]).sum(), 0.0, atol=1e-12)


def test_the_basis_waits_for_a_direction_and_keeps_within_an_episode():
    f = LearntFrame()
    delta = np.zeros((4, 2))
    f.refresh(delta, np.zeros(4, dtype=int), L=0.1)
    assert f.T is None and not f.complete               # nothing moved: the sensor's frame
    w = np.array([[0.3, 0.4]])
    assert f.of(w, w[0], delta, 0.1).L == 0.1
    delta[3] = (0.0, 0.1)                                # one direction moved along
    f.refresh(delta, np.array([0, 0, 0, 1]), L=0.1)
    assert f.T is not None and not f.complete           # the other measured in links
    delta[1] = (0.1, 0.0)
    f.refresh(delta, np.array([0, 1, 0, 1]), L=0.1, again=False)   # a new direction
    assert f.complete
    v = f.version
    delta[1] = (0.12, 0.0)                               # drift only: kept in the episode
    f.refresh(delta, np.array([0, 2, 0, 1]), L=0.1, again=False)
    assert f.version == v
    f.refresh(delta, np.array([0, 2, 0, 1]), L=0.1)      # a new episode: re-estimated
    assert f.version == v + 1


@pytest.mark.parametrize("shape", [(4, 2, 2), (2, 2, 2), (3, 3, 3), (3, 3, 2), (6, 4, 4),
                                   (4, 1, 2), (4, 2, 1), (1, 2, 2), (5, 6, 6)])
def test_the_forward_model_in_the_frame_is_numpys_product_to_the_bit(shape):
    """frame.forward_model (kernels.frame_delta where it sums as this machine's BLAS does)
    gives the bits of numpy's ``delta @ T.T``, so that it moves no trajectory; over
    magnitudes where the order of rounding shows."""
    P, dim, k = shape
    rng = np.random.default_rng(7)
    for _ in range(300):
        delta = rng.normal(size=(P, dim)) * 10.0 ** rng.uniform(-3, 2, size=(P, 1))
        T = rng.normal(size=(k, dim))
        np.testing.assert_array_equal(forward_model(delta, T), delta @ T.T)


def test_frames_by_name():
    assert isinstance(make_frame("learnt"), LearntFrame)
    assert isinstance(make_frame("grid"), SensorFrame) and make_frame("none").complete


def run(spec_A, steps=1500, unknown="learnt", seed=3):
    """The actions of a TMGWR agent on the default maze with its sensation x -> A x."""
    maze = Maze.from_file(maze_file())
    world = GridWorld(maze, "G", seed=0, max_episode_steps=400)
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(seed), {"unknown": unknown})
    agent.set_goal(world.goal, spec_A @ world.goal_observation())
    obs, _ = world.reset()
    agent.begin_episode(spec_A @ obs)
    actions = []
    for _ in range(steps):
        a = agent.act()
        actions.append(a)
        obs, _, terminated, truncated, info = world.step(a)
        agent.observe(spec_A @ obs, info)
        if terminated or truncated:
            obs, _ = world.reset()
            agent.begin_episode(spec_A @ obs)
    return actions


@pytest.mark.parametrize("deg", [30, 90])
def test_a_rotated_sensor_gives_the_same_trajectory(deg):
    """Rotation keeps the map's distances, and the learnt frame undoes it for the value of
    the unknown: the same seed takes the same actions (the grid rules, measured on the
    sensor's axes, do not)."""
    same = run(np.eye(2))
    assert run(rotation(deg)) == same
    if deg == 30:
        assert run(rotation(deg), unknown="grid") != run(np.eye(2), unknown="grid")
