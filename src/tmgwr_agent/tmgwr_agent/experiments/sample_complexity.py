"""Scenario: sample complexity (sections 5.2.4, 6.2.2, Fig. 6).

Protocol, per agent, goal of ``--goals`` (default ``1,2,3,4``) and trial: a fresh agent
(its generator from the trial's seed) starts fully exploratory (epsilon 1, Eq. 7) and runs training
episodes from S to the goal; after each episode a greedy rollout probes convergence
(:mod:`.runner`). It runs at least ``--episodes`` episodes (default 100) for the curve and
on until convergence or the caps.

* ``curve``: the steps of episodes 5, 10, 15, ... ``--episodes`` ("recorded at every 5th
  iteration"), mean over the trials; a truncated episode counts with the steps it took;
* ``episodes_to_converge``: STAT of the training episodes to the start of ten consecutive
  optimal greedy rollouts, ``null`` when the caps ran out first;
* ``shortest_steps``: the world's oracle from S to the goal, in its own primitive steps
  (the length a greedy rollout is held to).
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from maze_sim.maze import Maze
from maze_sim.sensors import IDENTITY
from maze_sim.worlds import WorldSpec
from tmgwr_agent.experiments.agent_factory import make_agent
from tmgwr_agent.experiments.parallel import agent_trials
from tmgwr_agent.experiments.runner import (
    Caps,
    make_world,
    scenario_trial,
    set_goal,
    train_until_converged,
    with_overrides,
)
from tmgwr_agent.experiments.stats import mean_curve, stat

DEFAULT_GOALS = ("1", "2", "3", "4")
DEFAULT_EPISODES = 100
EVERY = 5


def trial(spec: str, t: int, seed: np.random.SeedSequence, maze_path: str,
          goals: tuple[str, ...], episodes: int,
          overrides: Mapping[str, Any] | None = None, *, sensor: str = IDENTITY,
          world_spec: WorldSpec | None = None) -> dict:
    maze = Maze.from_file(maze_path)
    caps = Caps.for_maze(maze)
    out = {}
    for g, child in zip(goals, seed.spawn(len(goals))):
        world = make_world(maze, g, caps, sensor, child, world_spec)
        agent = make_agent(spec, maze, np.random.default_rng(child), overrides,
                           sensed=not world.identity, senses=world.senses)
        set_goal(world, agent, g)
        conv = train_until_converged(world, agent, caps, min_episodes=episodes)
        out[g] = {"curve": conv.curve[EVERY - 1:episodes:EVERY],
                  "episodes_to_converge": conv.episodes,
                  "shortest_steps": world.shortest_path_length()}
    return out


def run(maze_path: str, agents: list[str], trials: int, seed: int,
        goals: tuple[str, ...] = DEFAULT_GOALS, episodes: int = DEFAULT_EPISODES,
        jobs: int | None = None, progress: bool = True,
        overrides: Mapping[str, Mapping[str, Any]] | None = None,
        sensor: str = IDENTITY, world: WorldSpec | None = None) -> dict:
    """``overrides``: parameter overrides per agent spec (absent: the defaults);
    ``sensor``: the normalised ``--sensor`` spec."""
    fn = scenario_trial(trial, sensor, world)
    res = agent_trials(with_overrides(fn, overrides), agents, seed, trials,
                       (maze_path, tuple(goals), episodes), jobs, "sample-complexity",
                       progress)
    out = {}
    for a, rs in res.items():
        out[a] = {"goals": {g: {"curve": mean_curve([r[g]["curve"] for r in rs]),
                                "episodes_to_converge": stat(r[g]["episodes_to_converge"]
                                                             for r in rs),
                                "shortest_steps": rs[0][g]["shortest_steps"]}
                            for g in goals}}
    return {"episodes": episodes, "every": EVERY, "goals": list(goals), "agents": out}
