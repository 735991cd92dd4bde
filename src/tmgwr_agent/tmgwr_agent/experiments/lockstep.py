"""The in-process twin of the lockstep node graph: the real TMGWRAgent loop, stepped the
way ``maze_sim`` steps the graph, for the reproducibility check and the benchmark.

The graph and this loop produce the same sequence of observations for the same seeds
(``maze_sim``'s ``seed`` -> the world's generator, ``action_selector``'s ``seed`` ->
``numpy.random.default_rng(seed)`` handed to :class:`TMGWRAgent`):

* observation 0 is ``world.reset()`` (``agent.begin_episode``); after each action
  ``world.step`` (``agent.observe``, which decays epsilon when the goal was reached);
  after a terminal observation (goal, previous goal or truncation) the next
  observation is a ``world.reset()`` again. Observation ids count all of them.
* a goal change that the simulator applied at observation ``k`` (its ``SUMMARY`` /
  trajectory file reports ``k``) moves the world's goal right after that observation was
  made and is given to the agent right after it learnt from it (``agent.set_goal``),
  which is what the graph does: the estimator restarts V from 0 for the new goal sensation
  before it solves Eq. 4-5 on the map of step ``k``.

``run_reference`` returns the observed cells ``[(step_id, episode, row, col), ...]``.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from maze_sim.maze import Maze
from maze_sim.world import GridWorld
from maze_sim.worlds import make_world
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.world_senses import maze_senses, world_senses


def run_reference(maze_path: str | Path, steps: int, goal: str | tuple = "G",
                  world_seed: int = 0, agent_seed: int = 0,
                  goal_changes: Sequence[tuple[int, tuple[int, int]]] = (),
                  sensor_noise: float = 0.0, max_episode_steps: int | None = None,
                  params: Mapping[str, Any] | None = None, world_name: str = "grid"):
    """``steps`` observations of the lockstep loop; returns (cells, seconds). ``world_name``:
    the world maze_sim hosts (its ``world`` parameter), the agent told its senses
    (:func:`~tmgwr_agent.world_senses.world_senses`)."""
    maze = Maze.from_file(maze_path)
    if world_name == "grid":
        world = GridWorld(maze, goal, sensor_noise, max_episode_steps, seed=world_seed)
        senses = maze_senses()
    else:
        noise = {"sensor_noise": sensor_noise} if sensor_noise else {}
        world = make_world(world_name, maze, goal, max_episode_steps, seed=world_seed,
                           **noise)
        senses = world_senses(world)
    agent = TMGWRAgent(senses, np.random.default_rng(agent_seed), params)
    changes = {int(k): tuple(c) for k, c in goal_changes}
    cells: list[tuple[int, int, int, int]] = []
    agent.set_goal(world.goal, world.goal_observation())
    t0 = time.perf_counter()
    step, terminal = -1, True
    while step + 1 < steps:
        step += 1
        new_goal = changes.get(step)
        if terminal:
            obs, _ = world.reset()
            if new_goal:
                world.set_goal(new_goal)
            agent.begin_episode(obs, world.cell)
            terminal = False
        else:
            obs, _, terminated, truncated, info = world.step(agent.act(explore=True))
            if new_goal:
                world.set_goal(new_goal)
            agent.observe(obs, info)
            terminal = terminated or truncated
        if new_goal:
            agent.set_goal(world.goal, world.goal_observation())
        cells.append((step, world.episode, *world.cell))
    return cells, time.perf_counter() - t0


def read_trajectory(path: str | Path):
    """(cells, goal_changes) from a maze_sim ``trajectory_path`` file."""
    cells, changes = [], []
    for line in Path(path).read_text().splitlines():
        if not line or line.startswith("#"):
            continue
        parts = line.split()
        if parts[0] == "goal":
            changes.append((int(parts[1]), (int(parts[2]), int(parts[3]))))
        else:
            cells.append(tuple(int(v) for v in parts))
    return cells, changes
