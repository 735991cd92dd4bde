"""Episodes, greedy rollouts and the convergence test shared by every scenario.

The loop is the one of :mod:`tmgwr_agent.core.protocol`: a *training episode* starts at S
(``world.reset()``), the agent acts epsilon-greedily and learns from every step, and the
episode ends at the current goal, at the previous goal while one is set (goal-change
scenario), or when the episode step cap truncates it. The Eq. 7 epsilon decay happens in
``observe`` only when the *current* goal is reached.

A *greedy rollout* is the convergence probe: from S, ``learn=False`` and
``explore=False`` (epsilon 0, nothing learnt), at most ``D`` steps where ``D`` is the BFS
shortest-path length of the current layout. The path is *optimal* when it reaches the
goal within those ``D`` steps (it cannot be shorter). A world whose oracle is measured by
a scripted controller (PointMaze) declares a ``probe_tolerance``: the rollout may then
take up to that share of ``D`` more steps (:func:`probe_tolerance`; the JSON records it).
The rollout draws from the agent's generator only to break ties and moves the random
walk's direction, so it is part of the seeded run; it teaches nothing.

*Convergence* (section 5.2.5, "follows the optimal path ten consecutive times"): after
every training episode one greedy rollout is made; the agent has converged once
``streak`` (10) consecutive rollouts were optimal. ``episodes_to_converge`` is the number
of training episodes after which the streak *started* (so an agent whose very first
rollout is optimal and stays so scores 1). We probe with greedy rollouts rather than
counting optimal training episodes because at the epsilon floor of 0.1 a 44-step
epsilon-greedy episode is rarely optimal however well the agent knows the way.

Caps (nothing runs forever). With ``F`` the number of free cells of the maze (99 on the
default maze):

* ``episode_steps = 200 F`` steps per episode (19 800 on the default maze): a random walk
  finds the goal of the default maze in a few thousand steps, so the cap only truncates an
  agent that is stuck (the model-based agent after a block);
* ``max_episodes = max(200, 20 F)`` training episodes per convergence run (1980);
* ``budget_steps = 1000 F`` steps in all per convergence run (99 000; Q-learning, the
  slowest learner that converges, needs some 10 000 - 30 000 on the default maze).

A run that hits a cap is a failed trial (``None`` -> ``null`` in the JSON).

Parameter overrides (``experiment --params``): every scenario's trial function takes the
agent's overrides as its last argument (``None``: the declared defaults);
:func:`with_overrides` hands each agent its own when the trials of several agents run
through one function (:func:`.parallel.agent_trials`, :func:`.parallel.run_items`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import partial
from typing import Any, Callable, Mapping

import numpy as np

from maze_sim.maze import Maze
from maze_sim.sensors import SensorSpec
from maze_sim.world import GridWorld
from maze_sim.worlds import WorldSpec, world_class
from maze_sim.worlds import make_world as make_hosted_world
from tmgwr_agent.core.protocol import Agent
from tmgwr_agent.experiments.sensing import HostedWorld, SensedWorld, noise_rng

#: Consecutive optimal greedy rollouts that count as convergence (section 5.2.5).
STREAK = 10
#: ``learning_steps``: the mean steps of this many training episodes before an event.
LEARNING_EPISODES = 10


@dataclass(frozen=True)
class Caps:
    episode_steps: int
    max_episodes: int
    budget_steps: int

    @classmethod
    def for_maze(cls, maze: Maze, episode_factor: int = 200, episodes_factor: int = 20,
                 budget_factor: int = 1000) -> "Caps":
        free = len(maze.free_cells())
        return cls(episode_steps=episode_factor * free,
                   max_episodes=max(200, episodes_factor * free),
                   budget_steps=budget_factor * free)


@dataclass
class Episode:
    steps: int
    reached_goal: bool
    reached_previous_goal: bool


def with_overrides(fn: Callable,
                   overrides: Mapping[str, Mapping[str, Any]] | None) -> Callable:
    """``fn(spec, *args)`` -> ``fn(spec, *args, overrides=overrides[spec])``: a trial
    function that gives each agent spec its own parameter overrides (none: ``fn`` itself).
    Picklable, for the process pool."""
    if not overrides:
        return fn
    return partial(_call_with, fn, {a: dict(v) for a, v in overrides.items() if v})


def scenario_trial(fn: Callable, sensor: str, world: WorldSpec | None) -> Callable:
    """A scenario's trial function with its ``--sensor`` and ``--world`` bound (only those
    that differ from the defaults, so a plain run calls ``fn`` itself). Picklable."""
    kwargs: dict[str, Any] = {}
    if sensor != "identity":
        kwargs["sensor"] = sensor
    if world is not None and world.name != "grid":
        kwargs["world_spec"] = world
    return partial(fn, **kwargs) if kwargs else fn


def _call_with(fn: Callable, overrides: dict[str, dict[str, Any]], spec: str, *args) -> Any:
    return fn(spec, *args, overrides=overrides.get(spec))


def make_world(maze: Maze, goal: str, caps: Caps, sensor: SensorSpec | str | None = None,
               seed: np.random.SeedSequence | None = None,
               world: WorldSpec | None = None) -> SensedWorld | HostedWorld:
    """The world under ``sensor`` (default identity); ``seed``: the trial's seed, whose
    sensor-noise stream (:func:`.sensing.noise_rng`) drives any noise; ``world``: the
    ``--world`` (None or ``grid``: our grid world; another: :func:`maze_sim.worlds.
    make_world` of it, sensed as it senses, :class:`.sensing.HostedWorld`)."""
    if world is None or world.name == "grid":
        grid = GridWorld(maze, goal=goal, max_episode_steps=caps.episode_steps)
        return SensedWorld(grid, sensor, noise_rng(seed))
    return HostedWorld(make_hosted_world(world, maze, goal, caps.episode_steps))


def agent_state(world: GridWorld | SensedWorld | HostedWorld):
    """What a tabular agent may know of where it is: the discretised sensation of a
    :class:`.sensing.SensedWorld` or a hosted world, the cell of a bare world (identity
    sensing)."""
    return world.state if isinstance(world, (SensedWorld, HostedWorld)) else world.cell


def set_goal(world: GridWorld | SensedWorld, agent: Agent, goal: str,
             keep_previous: bool = False) -> None:
    """Move the goal in the world and tell the agent (its tabular state for the tabular
    agents, the goal *sensation* for TMGWR, which never sees cells)."""
    world.set_goal(goal, keep_previous=keep_previous)
    state = world.goal_state if isinstance(world, (SensedWorld, HostedWorld)) else world.goal
    agent.set_goal(state, world.goal_observation())


def run_episode(world: GridWorld | SensedWorld, agent: Agent, learn: bool = True,
                explore: bool = True, max_steps: int | None = None) -> Episode:
    """One episode from S; ``max_steps`` (default: the world's episode cap) truncates."""
    obs, _ = world.reset()
    agent.begin_episode(obs, agent_state(world), learn=learn)
    cap = max_steps if max_steps is not None else world.max_episode_steps
    steps = 0
    while True:
        action = agent.act(explore=explore)
        obs, _, terminated, truncated, info = world.step(action)
        agent.observe(obs, info, learn=learn)
        steps += 1
        if terminated:
            return Episode(steps, info.reached_goal, info.reached_previous_goal)
        if truncated or (cap is not None and steps >= cap):
            world.end_episode()          # cut here: an event may now wall the cell in
            return Episode(steps, False, False)


def probe_tolerance(world) -> float:
    """The share of the oracle's steps by which a greedy rollout may exceed them and still
    count as optimal: what the world declares (``probe_tolerance``, a world whose oracle
    is a scripted controller rather than a proven shortest path: PointMaze), else 0 (an
    exact oracle: the grid's and MiniGrid's BFS)."""
    return float(getattr(world, "probe_tolerance", 0.0))


def declared_probe_tolerance(world: WorldSpec | None) -> float:
    """:func:`probe_tolerance` of the worlds ``--world`` builds (the JSON's
    ``probe_tolerance``, recorded when not 0)."""
    if world is None or world.name == "grid" or not world.from_maze:
        return 0.0
    return probe_tolerance(world_class(world.name))


def greedy_optimal(world: GridWorld, agent: Agent, optimal: int | None = None) -> bool:
    """Does a greedy rollout (epsilon 0, no learning) take a shortest path to the goal:
    reach it within the oracle's ``D`` steps, and the world's :func:`probe_tolerance` of
    them (an exact oracle: no path is shorter, so exactly ``D``)?"""
    d = world.shortest_path_length() if optimal is None else optimal
    if d < 0:
        return False
    cap = d + math.floor(probe_tolerance(world) * d)
    return run_episode(world, agent, learn=False, explore=False, max_steps=cap).reached_goal


def learning_steps(curve: list[int], n: int = LEARNING_EPISODES) -> float | None:
    """The mean steps of the last ``n`` training episodes of ``curve`` (all of them when
    fewer ran; None when none did): the cost of an episode once learnt, epsilon-greedy
    exploration and any re-testing of walls included (the greedy probes never show it)."""
    tail = curve[-n:]
    return sum(tail) / len(tail) if tail else None


def map_nodes(agent: Any) -> int | None:
    """The nodes of the agent's learnt map (None: an agent without one, a table)."""
    m = getattr(agent, "map", None)
    return None if m is None else m.size


@dataclass
class Convergence:
    episodes: int | None        # training episodes to the start of the streak; None = cap
    trained: int                # training episodes run
    steps: int                  # training steps run
    cpu_s: float                # process CPU seconds of the training episodes only
    curve: list[int]            # steps of every training episode


def train_until_converged(world: GridWorld, agent: Agent, caps: Caps, streak: int = STREAK,
                          min_episodes: int = 0) -> Convergence:
    """Train episode after episode, probing with a greedy rollout after each, until
    ``streak`` consecutive rollouts are optimal (and at least ``min_episodes`` episodes
    ran, for the sample-complexity curves). CPU time counts the training episodes only,
    not the probes (they are the experimenter's measurement, not the agent's work)."""
    d = world.shortest_path_length()
    run = 0
    converged_at: int | None = None
    curve: list[int] = []
    steps = 0
    cpu = 0.0
    while len(curve) < caps.max_episodes and steps < caps.budget_steps:
        t0 = time.process_time()
        ep = run_episode(world, agent, max_steps=min(caps.episode_steps,
                                                     caps.budget_steps - steps))
        cpu += time.process_time() - t0
        curve.append(ep.steps)
        steps += ep.steps
        if converged_at is None:
            run = run + 1 if greedy_optimal(world, agent, d) else 0
            if run >= streak:
                converged_at = len(curve) - streak + 1
        if converged_at is not None and len(curve) >= min_episodes:
            break
    return Convergence(converged_at, len(curve), steps, cpu, curve)
