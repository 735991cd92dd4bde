"""Scenario: time-based comparison (section 5.2.5, Fig. 7).

CPU seconds (``time.process_time`` of the worker process; the numba kernels are compiled
or loaded from the cache before any measurement, :func:`.parallel.warm_up`). Only the
agent's training episodes are timed; the greedy convergence probes are the experimenter's
and are excluded. Per agent and trial:

* ``train_s``: a fresh agent, goal ``G`` of the maze (the environment of Fig. 2): from the
  start of training to convergence (ten consecutive optimal greedy rollouts, counted to
  the end of the streak). ``null`` when the caps run out;
* ``goal_adapt_s``: a second fresh agent trained to convergence on goal ``4``; the goal
  moves to ``3`` (``--goals 4,3``) and we time the training until it has converged on the
  new goal (ten consecutive optimal greedy rollouts again). ``null`` when either
  convergence fails;
* ``event_recover_s``: the agent of ``train_s``, after convergence, meets the event
  (``--event``, default ``a``); we time the episode until the goal is first reached (the
  ``steps`` of the env-change scenario). ``null`` when the episode cap runs out (the
  model-based agent never recovers, Fig. 7c).

CPU times depend on the machine and on what else runs on it: compare agents within one
run (same seeds, same load), not across runs.
"""

from __future__ import annotations

import time
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
    run_episode,
    scenario_trial,
    set_goal,
    train_until_converged,
    with_overrides,
)
from tmgwr_agent.experiments.stats import stat

DEFAULT_GOALS = ("4", "3")


def trial(spec: str, t: int, seed: np.random.SeedSequence, maze_path: str,
          goals: tuple[str, str], event: str, goal: str = "G",
          overrides: Mapping[str, Any] | None = None, *, sensor: str = IDENTITY,
          world_spec: WorldSpec | None = None) -> dict:
    maze = Maze.from_file(maze_path)
    caps = Caps.for_maze(maze)
    s_train, s_adapt = seed.spawn(2)
    # training on G, then the event
    world = make_world(maze, goal, caps, sensor, s_train, world_spec)
    agent = make_agent(spec, maze, np.random.default_rng(s_train), overrides,
                       sensed=not world.identity, senses=world.senses)
    set_goal(world, agent, goal)
    conv = train_until_converged(world, agent, caps)
    train_s = conv.cpu_s if conv.episodes is not None else None
    world.fire_event(event)
    t0 = time.process_time()
    ep = run_episode(world, agent)
    event_s = time.process_time() - t0 if ep.reached_goal else None
    # training on goals[0], then the goal moves to goals[1]
    world = make_world(maze, goals[0], caps, sensor, s_adapt, world_spec)
    agent = make_agent(spec, maze, np.random.default_rng(s_adapt), overrides,
                       sensed=not world.identity, senses=world.senses)
    set_goal(world, agent, goals[0])
    adapt_s = None
    if train_until_converged(world, agent, caps).episodes is not None:
        set_goal(world, agent, goals[1])
        conv2 = train_until_converged(world, agent, caps)
        adapt_s = conv2.cpu_s if conv2.episodes is not None else None
    return {"train_s": train_s, "goal_adapt_s": adapt_s, "event_recover_s": event_s,
            "train_episodes": conv.episodes}


def run(maze_path: str, agents: list[str], trials: int, seed: int,
        goals: tuple[str, ...] = DEFAULT_GOALS, event: str = "a", goal: str = "G",
        jobs: int | None = None, progress: bool = True,
        overrides: Mapping[str, Mapping[str, Any]] | None = None,
        sensor: str = IDENTITY, world: WorldSpec | None = None) -> dict:
    """``overrides``: parameter overrides per agent spec (absent: the defaults);
    ``sensor``: the normalised ``--sensor`` spec."""
    if len(goals) != 2:
        raise ValueError(f"timing takes two goals FROM,TO (got {','.join(goals)})")
    fn = scenario_trial(trial, sensor, world)
    res = agent_trials(with_overrides(fn, overrides), agents, seed, trials,
                       (maze_path, tuple(goals), event, goal), jobs, "timing", progress)
    out = {a: {k: stat(r[k] for r in rs)
               for k in ("train_s", "goal_adapt_s", "event_recover_s", "train_episodes")}
           for a, rs in res.items()}
    return {"goals": list(goals), "event": event, "goal": goal, "agents": out}
