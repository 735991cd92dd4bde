"""The context in primitive steps (core/sensorimotor_map.py, SensorimotorMap._context_metric),
against the real core.

What must hold: an agent whose sensor reads one axis in a five times larger unit learns one
node a place, as it does in the grid's own units (measured in the sensor's units, the
Merge-GNG context told each place apart by the direction it was entered from along that
axis: about two nodes a place); the metric is the sensor's own (none) where the learnt
steps are an isometry of it (one unit, or rotated), and in the scaled sensor it counts a
step along either axis as the shortest step.
"""

from __future__ import annotations

import numpy as np
import pytest

from maze_sim import GridWorld, Maze
from maze_sim.maze import maze_file
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.world_senses import maze_senses

ROT30 = np.array([[np.cos(np.pi / 6), -np.sin(np.pi / 6)],
                  [np.sin(np.pi / 6), np.cos(np.pi / 6)]])


def trained(transform: np.ndarray, steps: int = 3000, seed: int = 1) -> TMGWRAgent:
    """The default agent after ``steps`` learning steps on the paper's maze, sensing
    ``transform @ (row, col)``."""
    world = GridWorld(Maze.from_file(maze_file()), goal="G", seed=seed)
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(seed))
    agent.set_goal(world.goal, transform @ world.goal_observation())
    obs, _ = world.reset()
    agent.begin_episode(transform @ obs, world.cell)
    for _ in range(steps):
        obs, _, terminated, truncated, info = world.step(agent.act())
        agent.observe(transform @ obs, info)
        if terminated or truncated:
            obs, _ = world.reset()
            agent.begin_episode(transform @ obs, world.cell)
    return agent


def test_a_sensor_in_other_units_on_one_axis_learns_one_node_a_place():
    agent = trained(np.diag([1.0, 5.0]))
    m, visited = agent.map, len(Maze.from_file(maze_file()).free_cells())
    assert m.size <= visited, (m.size, visited)
    Sc = m.Sc
    assert Sc.shape == (2, 2)
    steps = Sc @ (np.diag([1.0, 5.0]) * agent.preprocessor.gain)     # one cell each way
    lengths = np.linalg.norm(steps, axis=0)
    np.testing.assert_allclose(lengths, lengths.min(), rtol=1e-6)


@pytest.mark.parametrize("transform", [np.eye(2), 3.0 * ROT30], ids=["identity", "rotate"])
def test_the_sensor_units_stand_where_the_steps_are_an_isometry(transform):
    agent = trained(transform, steps=600)
    assert agent.map.Sc.shape == (0, 0)
