"""Scenario: changing environment (section 5.2.2, Table 6, Fig. 5).

Protocol, per agent and trial (a fresh agent, its generator from the trial's seed):

1. goal ``--goal`` (default ``G``); train to convergence (:func:`.runner.train_until_converged`:
   ten consecutive optimal greedy rollouts). An agent that does not converge within the
   caps still goes on to step 2 (it is as trained as the budget allows); its
   ``train_episodes`` value is ``null``;
2. fire the event (``--event``, default ``a``): its cells become walls. Nobody tells the
   agent; the model-based agent keeps its hard-coded model (Eq. 11);
3. ``steps``: one episode from S with learning and exploration on (epsilon as left by
   training, i.e. at its floor), counting the steps until the goal is first reached;
   ``null`` when the episode step cap (200 x free cells) runs out first;
4. ``episodes_to_optimal``: the number of episodes after the event (the episode of step 3
   is episode 1) until a greedy rollout (epsilon 0, no learning) takes a shortest path of
   the *new* maze; more training episodes run until then, up to the caps. ``null`` when the
   caps run out, and also when step 3 failed (an agent stuck at the block would only burn
   the budget).

``learning_steps``: the mean steps of the last 10 training episodes of step 1
(:func:`.runner.learning_steps`): what an episode costs once learnt, exploration and any
re-testing included, against ``shortest_before``.

``oracle_steps`` (top level): the lower bound of an agent that knows the old maze
perfectly: it walks a shortest path of the old maze, bumps once into the first blocked
cell on it, then walks a shortest path of the new maze from where it stands. Over all
shortest paths of the old maze that run into a blocked cell, the smallest such total
(:func:`oracle_steps`). When some old shortest path avoids every blocked cell the bound is
the (unchanged) shortest path length.

Link rules: the TMGWR agent is run under both readings of Eq. 1-2 (docs/interpretation.md):
the default agent list of this scenario is ``tmgwr,tmgwr:literal,tmgwr:credit,q_learning,
model_based,dyna_q_plus`` (plain ``tmgwr`` is the default rule of ``MapConfig.link_rule``;
with the same seeds it repeats one of the two named runs exactly).

Parameters: ``overrides`` (``experiment --params``) change an agent's declared defaults;
``./tmgwr tune`` scores its runs with steps 1-3 of this same :func:`trial`
(``to_optimal=False``).
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from maze_sim.maze import Maze, bfs_distances
from maze_sim.sensors import IDENTITY
from maze_sim.worlds import WorldSpec
from maze_sim.worlds import make_world as make_hosted_world
from tmgwr_agent.experiments.agent_factory import make_agent
from tmgwr_agent.experiments.parallel import agent_trials
from tmgwr_agent.experiments.runner import (
    Caps,
    greedy_optimal,
    learning_steps,
    make_world,
    run_episode,
    scenario_trial,
    set_goal,
    train_until_converged,
    with_overrides,
)
from tmgwr_agent.experiments.stats import stat

#: Per-trial results, each a STAT per agent in the JSON.
RESULTS = ("steps", "episodes_to_optimal", "train_episodes", "learning_steps")

DEFAULT_AGENTS = ("tmgwr", "tmgwr:literal", "tmgwr:credit", "q_learning", "model_based",
                  "dyna_q_plus")


def oracle_steps(maze: Maze, event: str, goal: str = "G") -> int:
    """Old optimal path up to the first blocked cell, one bump, new shortest path."""
    start, target = maze.start, maze.goal_cell(goal)
    old = maze.walls
    new = maze.walls_after([event])
    ds, dg = bfs_distances(old, start), bfs_distances(old, target)
    dnew = bfs_distances(new, target)
    d = int(ds[target])
    blocked = new & ~old

    def on_path(c):
        return ds[c] >= 0 and dg[c] >= 0 and ds[c] + dg[c] == d

    # Cells reachable from S along old shortest paths through unblocked cells only,
    # layer by layer (ds increases by one along a shortest path).
    frontier = {start}
    best = None
    rows, cols = old.shape
    for _ in range(d + 1):
        nxt = set()
        for c in frontier:
            if c == target:                      # an old shortest path avoids the block
                return d
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                n = (c[0] + dr, c[1] + dc)
                if not (0 <= n[0] < rows and 0 <= n[1] < cols) or not on_path(n) \
                        or ds[n] != ds[c] + 1:
                    continue
                if blocked[n]:
                    if dnew[c] >= 0:
                        total = int(ds[c]) + 1 + int(dnew[c])
                        best = total if best is None else min(best, total)
                else:
                    nxt.add(n)
        frontier = nxt
    if best is None:
        raise ValueError(f"event {event!r}: the goal cannot be reached after it")
    return best


def event_oracle(world: WorldSpec | None, maze: Maze, event: str, goal: str) -> dict:
    """``oracle_steps``, ``shortest_before``, ``shortest_after`` of an event in the
    primitive steps of ``world`` (the grid's: BFS cells; another: its own oracle,
    ``event_oracle_steps`` and ``shortest_steps`` of the world)."""
    if world is None or world.name == "grid":
        start, target = maze.start, maze.goal_cell(goal)
        return {"oracle_steps": oracle_steps(maze, event, goal),
                "shortest_before": maze.shortest_path_length(start, target),
                "shortest_after": maze.shortest_path_length(
                    start, target, walls=maze.walls_after([event]))}
    w = make_hosted_world(world, maze, goal)
    return {"oracle_steps": w.event_oracle_steps(event, goal),
            "shortest_before": w.shortest_steps(maze.walls, goal),
            "shortest_after": w.shortest_steps(maze.walls_after([event]), goal)}


def trial(spec: str, t: int, seed: np.random.SeedSequence, maze: str | Maze, event: str,
          goal: str, overrides: Mapping[str, Any] | None = None, *,
          to_optimal: bool = True, within: int | None = None,
          sensor: str = IDENTITY, world_spec: WorldSpec | None = None) -> dict:
    """Steps 1-4 for one agent and trial (``maze``: a file or a Maze); ``to_optimal``
    False stops after step 3 (``episodes_to_optimal`` is then ``None``); ``within`` caps
    step 4 at that many episodes (``None`` beyond them; default the caps of
    :class:`.runner.Caps`); ``sensor``: the ``--sensor`` spec (:mod:`.sensing`)."""
    maze = maze if isinstance(maze, Maze) else Maze.from_file(maze)
    caps = Caps.for_maze(maze)
    world = make_world(maze, goal, caps, sensor, seed, world_spec)
    agent = make_agent(spec, maze, np.random.default_rng(seed), overrides,
                       sensed=not world.identity, senses=world.senses)
    set_goal(world, agent, goal)
    conv = train_until_converged(world, agent, caps)
    world.fire_event(event)
    d_new = world.shortest_path_length()
    ep = run_episode(world, agent)
    steps = ep.steps if ep.reached_goal else None
    episodes = None
    if steps is not None and to_optimal:
        n, used = 1, ep.steps
        while True:
            if greedy_optimal(world, agent, d_new):
                episodes = n
                break
            if n >= min(caps.max_episodes, within or caps.max_episodes) \
                    or used >= caps.budget_steps:
                break
            e = run_episode(world, agent)
            n += 1
            used += e.steps
    return {"steps": steps, "episodes_to_optimal": episodes,
            "train_episodes": conv.episodes, "learning_steps": learning_steps(conv.curve)}


def run(maze_path: str, agents: list[str], trials: int, seed: int, event: str = "a",
        goal: str = "G", jobs: int | None = None, progress: bool = True,
        overrides: Mapping[str, Mapping[str, Any]] | None = None,
        sensor: str = IDENTITY, world: WorldSpec | None = None) -> dict:
    """``overrides``: parameter overrides per agent spec (absent: the defaults);
    ``sensor``: the normalised ``--sensor`` spec."""
    maze = Maze.from_file(maze_path)
    fn = scenario_trial(trial, sensor, world)
    res = agent_trials(with_overrides(fn, overrides), agents, seed, trials,
                       (maze_path, event, goal), jobs, f"env-change {event}", progress)
    out = {a: {k: stat(r[k] for r in rs) for k in RESULTS}
           for a, rs in res.items()}
    return {"event": event, "goal": goal, **event_oracle(world, maze, event, goal),
            "agents": out}
