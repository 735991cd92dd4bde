"""Scenario: changing goal state (section 5.2.1, Tables 3-5).

Protocol, per agent and trial (a fresh agent, its generator from the trial's seed):

* the goal is set to the first goal of ``--goals`` (default ``1,2,3,4,1``) and the agent
  runs ``--episodes`` training episodes ("iterations", 1000 in the paper) from S;
* then the goal moves to the next name of the list; the *previous* goal stays a terminal
  cell (``world.set_goal(..., keep_previous=True)``): an episode ends at the current or at
  the previous goal. For the RL agents the previous goal is an ordinary empty cell (reward
  -29 / -18) that happens to end the episode; TMGWR is only told the new goal observation.
  Another ``--episodes`` episodes run, and so on;
* the agents keep learning and exploring throughout (epsilon follows Eq. 7 as trained:
  at its floor of 0.1 after the first phase; only reaching the *current* goal decays it);
* for every transition ``a -> b`` we count, over the ``--episodes`` episodes with goal
  ``b``, the episodes that ended at the previous goal ``a`` and those that ended at the
  current goal ``b``, as percentages of the episodes run ("% number of visits", each
  episode starting from S). An episode truncated by the step cap counts for neither, so
  the two percentages add up to at most 100.

* ``learning_steps`` of a transition ``a -> b``: the mean steps of the last 10 episodes
  with goal ``a`` (:func:`.runner.learning_steps`), what an episode to ``a`` cost once
  learnt, just before the goal moved.

JSON: ``agents[NAME] = {"transitions": [{"from", "to", "previous_pct": STAT,
"current_pct": STAT, "learning_steps": STAT}, ...]}`` plus ``"episodes"`` at the top
level.
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
    learning_steps,
    make_world,
    run_episode,
    scenario_trial,
    set_goal,
    with_overrides,
)
from tmgwr_agent.experiments.stats import stat

DEFAULT_GOALS = ("1", "2", "3", "4", "1")
DEFAULT_EPISODES = 1000


def trial(spec: str, t: int, seed: np.random.SeedSequence, maze_path: str,
          goals: tuple[str, ...], episodes: int,
          overrides: Mapping[str, Any] | None = None, *, sensor: str = IDENTITY,
          world_spec: WorldSpec | None = None) -> list[dict]:
    maze = Maze.from_file(maze_path)
    caps = Caps.for_maze(maze)
    world = make_world(maze, goals[0], caps, sensor, seed, world_spec)
    agent = make_agent(spec, maze, np.random.default_rng(seed), overrides,
                       sensed=not world.identity, senses=world.senses)
    set_goal(world, agent, goals[0])
    out = []
    curve: list[int] = []
    for i, goal in enumerate(goals):
        if i:
            before = learning_steps(curve)        # the last episodes with the old goal
            set_goal(world, agent, goal, keep_previous=True)
        prev = cur = 0
        curve = []
        for _ in range(episodes):
            ep = run_episode(world, agent)
            prev += ep.reached_previous_goal
            cur += ep.reached_goal
            curve.append(ep.steps)
        if i:
            out.append({"from": goals[i - 1], "to": goal,
                        "previous_pct": 100.0 * prev / episodes,
                        "current_pct": 100.0 * cur / episodes,
                        "learning_steps": before})
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
                       (maze_path, tuple(goals), episodes), jobs, "goal-change", progress)
    out = {}
    for a, per_trial in res.items():
        transitions = []
        for k, tr in enumerate(per_trial[0]):
            transitions.append({
                "from": tr["from"], "to": tr["to"],
                "previous_pct": stat(p[k]["previous_pct"] for p in per_trial),
                "current_pct": stat(p[k]["current_pct"] for p in per_trial),
                "learning_steps": stat(p[k]["learning_steps"] for p in per_trial)})
        out[a] = {"transitions": transitions}
    return {"episodes": episodes, "goals": list(goals), "agents": out}
