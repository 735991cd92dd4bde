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

Event delay (``--event-delay K[,K...]``, default 0): between steps 1 and 2 every agent
runs ``K`` more learning episodes from S (learning and exploration on, as in training),
so the event falls ``K`` episodes after convergence instead of right at it. An agent whose
behaviour runs in a cycle of episodes (R-max forgetting its walls every ``forget_after``
episodes) meets the event in another phase of it at each ``K``. The training up to
convergence is the same for every ``K`` (the same trial seed), so the delays compare the
same trained agent. With ``K > 0`` each trial also reports ``settled_steps``: the mean
steps of those ``K`` episodes, the cost of an episode once converged (the re-test tax,
against ``shortest_before``), which ``learning_steps`` misses when training converges in
fewer episodes than it averages over. With several delays the JSON holds one body per
delay (:func:`delay_views` reads either layout):

    {..header.., "event_delays": [K, ...],
     "delays": [{"event_delay": K, ..the body of a single-K run..}, ...]}

A single ``K > 0`` keeps the single-run layout and adds ``"event_delay": K``; ``K = 0``
adds nothing (today's JSON).

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

import re
from functools import partial
from typing import Any, Mapping, Sequence

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
    map_nodes,
    run_episode,
    scenario_trial,
    set_goal,
    train_until_converged,
    with_overrides,
)
from tmgwr_agent.experiments.stats import stat

#: Per-trial results, each a STAT per agent in the JSON.
RESULTS = ("steps", "episodes_to_optimal", "train_episodes", "learning_steps")
#: With an event delay K > 0, also: the mean steps of the K settled episodes.
DELAYED_RESULTS = RESULTS + ("settled_steps",)
#: Of an agent with a learnt map only: its nodes when the event fires.
MAP_RESULTS = ("nodes",)

DEFAULT_AGENTS = ("tmgwr", "tmgwr:literal", "tmgwr:credit", "q_learning", "model_based",
                  "dyna_q_plus")


class DelayError(ValueError):
    """An ``--event-delay`` that is not a list of distinct whole numbers >= 0."""


def parse_delays(text: str | int | Sequence[int] | None) -> tuple[int, ...]:
    """``--event-delay``: ``"0,4,8"`` (or ints) -> ``(0, 4, 8)``; None -> ``(0,)``.
    Raises :class:`DelayError` naming the part that is not a whole number >= 0, or a
    delay given twice."""
    if text is None:
        return (0,)
    parts = ([p.strip() for p in text.split(",")] if isinstance(text, str)
             else [str(text)] if isinstance(text, int) else [str(p) for p in text])
    out: list[int] = []
    for part in parts:
        if not re.fullmatch(r"[0-9]+", part):
            raise DelayError(f"{part!r} is not a whole number of episodes >= 0 "
                             f"(expected K or K,K,... such as 0,4,8)")
        if int(part) in out:
            raise DelayError(f"delay {int(part)} given twice")
        out.append(int(part))
    return tuple(out)


def results_keys(delay: int) -> tuple[str, ...]:
    """The per-trial results of a run at event delay ``delay``."""
    return DELAYED_RESULTS if delay else RESULTS


def agent_keys(trials: Sequence[Mapping[str, Any]], delay: int) -> tuple[str, ...]:
    """The results of one agent's ``trials``: :func:`results_keys`, and those of
    ``MAP_RESULTS`` that every trial has (an agent with a map)."""
    return results_keys(delay) + tuple(k for k in MAP_RESULTS
                                       if trials and all(k in r for r in trials))


def delay_views(result: dict) -> list[tuple[int, dict]]:
    """``[(K, result at K)]`` of an env-change JSON in either layout (see the module
    docstring): each view has the single-run layout, the header fields included."""
    if "delays" not in result:
        return [(int(result.get("event_delay", 0)), result)]
    head = {k: v for k, v in result.items() if k not in ("delays", "event_delays")}
    return [(d["event_delay"], {**head, **{k: v for k, v in d.items() if k != "event_delay"}})
            for d in result["delays"]]


#: The fields of a run that differ between delays; the others are the same at every K.
DELAY_BODY = ("agents", "suite")


def with_delays(views: Sequence[tuple[int, dict]]) -> dict:
    """Runs at each delay -> the JSON: a single ``K`` keeps its run's layout (with
    ``event_delay`` before ``agents`` when ``K > 0``); several keep the fields the same
    at every ``K`` once at the top and the :data:`DELAY_BODY` of each under ``delays``."""
    if len(views) == 1:
        k, body = views[0]
        if not k:
            return body
        out = {}
        for key, v in body.items():
            if key == "agents":
                out["event_delay"] = k
            out[key] = v
        return out
    head = {key: v for key, v in views[0][1].items() if key not in DELAY_BODY}
    out = {**head, "event_delays": [k for k, _ in views]}
    out["delays"] = [{"event_delay": k, **{key: body[key] for key in DELAY_BODY
                                          if key in body}} for k, body in views]
    return out


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
          sensor: str = IDENTITY, world_spec: WorldSpec | None = None,
          delay: int = 0) -> dict:
    """Steps 1-4 for one agent and trial (``maze``: a file or a Maze); ``to_optimal``
    False stops after step 3 (``episodes_to_optimal`` is then ``None``); ``within`` caps
    step 4 at that many episodes (``None`` beyond them; default the caps of
    :class:`.runner.Caps`); ``sensor``: the ``--sensor`` spec (:mod:`.sensing`);
    ``delay``: the learning episodes between convergence and the event (with
    ``settled_steps``, their mean steps, when > 0)."""
    maze = maze if isinstance(maze, Maze) else Maze.from_file(maze)
    caps = Caps.for_maze(maze)
    world = make_world(maze, goal, caps, sensor, seed, world_spec)
    agent = make_agent(spec, maze, np.random.default_rng(seed), overrides,
                       sensed=not world.identity, senses=world.senses)
    set_goal(world, agent, goal)
    conv = train_until_converged(world, agent, caps)
    settled = [run_episode(world, agent).steps for _ in range(delay)]
    nodes = map_nodes(agent)
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
    out = {"steps": steps, "episodes_to_optimal": episodes,
           "train_episodes": conv.episodes, "learning_steps": learning_steps(conv.curve)}
    if delay:
        out["settled_steps"] = sum(settled) / delay
    if nodes is not None:
        out["nodes"] = nodes
    return out


def trial_at_delay(fn, spec: str, *args, **kwargs) -> dict:
    """``fn(spec, *args[:-1], delay=args[-1], **kwargs)``: a trial whose delay is its
    last positional argument (one item of a pool over several delays). Picklable with
    :func:`functools.partial`."""
    *args, delay = args
    return fn(spec, *args, delay=delay, **kwargs)


def run(maze_path: str, agents: list[str], trials: int, seed: int, event: str = "a",
        goal: str = "G", jobs: int | None = None, progress: bool = True,
        overrides: Mapping[str, Mapping[str, Any]] | None = None,
        sensor: str = IDENTITY, world: WorldSpec | None = None,
        delays: Sequence[int] = (0,)) -> dict:
    """``overrides``: parameter overrides per agent spec (absent: the defaults);
    ``sensor``: the normalised ``--sensor`` spec; ``delays``: the event delays, each run
    in full (the JSON layout of :func:`with_delays`)."""
    maze = Maze.from_file(maze_path)
    head = {"event": event, "goal": goal, **event_oracle(world, maze, event, goal)}
    views = []
    for k in delays:
        fn = scenario_trial(trial, sensor, world)
        fn = partial(fn, delay=k) if k else fn
        what = f"env-change {event}" + (f" delay {k}" if k else "")
        res = agent_trials(with_overrides(fn, overrides), agents, seed, trials,
                           (maze_path, event, goal), jobs, what, progress)
        views.append((k, {**head, "agents": {a: {key: stat(r[key] for r in rs)
                                                 for key in agent_keys(rs, k)}
                                             for a, rs in res.items()}}))
    return with_delays(views)
