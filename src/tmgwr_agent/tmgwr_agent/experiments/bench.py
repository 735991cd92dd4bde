"""``./tmgwr bench``: how fast the TMGWR core is, and CPU seconds to convergence.

* ``step_default`` / ``step_large``: wall-clock time of one core step of the TMGWR agent,
  ``act()`` + ``observe()`` (Eq. 6 selection, the map update with Eq. 1-2, Eq. 4-5
  re-planning warm-started), measured with ``time.perf_counter_ns`` around those two calls
  only (the simulator's ``step`` is not counted), over ``--steps`` consecutive steps of
  ordinary training episodes (learning and epsilon-greedy exploration on, epsilon at its
  floor) *after* training: on the default maze the agent is first trained to convergence
  (ten consecutive optimal greedy paths); on the large maze (``generate_maze(51, 51)``,
  about 1300 free cells) training runs until one greedy rollout is optimal (at most 20
  episodes; the first episode, a random walk over the whole maze, takes about a minute).
  Reported: median (its targets: docs, Benchmarks),
  mean, p10, p90, p99, max, and the map's node count.
* ``worlds``: per world (grid, pointmaze; :func:`bench_worlds`), the CPU per step of the
  TMGWR agent and of the world's own ``step`` (PointMaze: the MuJoCo physics), apart.
* ``cpu_to_convergence``: per agent, CPU seconds (``time.process_time``) of the training
  episodes from scratch to convergence on goal G of the default maze, STAT over
  ``--trials`` trials with the seeds of :mod:`.parallel` (the same for every agent), run
  in one process by default (``--jobs 1``) so the agents are measured under the same load.
* the graph and bag benchmarks (``tmgwr_agent.graph.bench.run(args)``,
  ``tmgwr_agent.bag.bench.run(args)``, written by their own packages) are called when
  present and their dicts merged under ``graph`` and ``bag``, so every figure comes from
  one run. Output: ``results/bench.json`` (``--json``), the figures of issue 11 as ratios
  in one table (:func:`ratio_table`: graph / ring on the default and the large mazes,
  composed / ring, two hosts, bytes per step, CPU to convergence per agent), then every
  figure (``report.bench_table``).
* nothing fails silently: a part that failed is named on stderr, kept in the JSON
  (``error`` / ``errors``) and in the table, and the command exits 1.
"""

from __future__ import annotations

import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

from maze_sim.maze import Maze, bfs_distances, generate_maze, move
from tmgwr_agent.core import kernels
from tmgwr_agent.experiments.agent_factory import AGENT_NAMES, make_agent
from tmgwr_agent.experiments.parallel import agent_trials, default_jobs, warm_up
from tmgwr_agent.experiments.runner import (
    Caps,
    greedy_optimal,
    make_world,
    run_episode,
    set_goal,
    train_until_converged,
)
from tmgwr_agent.experiments.scenarios import DEFAULT_MAZE
from tmgwr_agent.experiments.stats import stat


def timed_steps(world, agent, n: int, clock=time.perf_counter_ns,
                starts: list | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` steps of training episodes, timed by ``clock`` (nanoseconds): the agent's
    (``act`` + ``observe``) and the world's (``step``) apart, and the winner each step
    acted from. The agent's ``begin_episode`` (the episode's first solve: its route, its
    re-tests, its options) is not a step; with ``starts`` its nanoseconds are appended
    there."""
    agent_ns = np.empty(n, dtype=np.int64)
    world_ns = np.empty(n, dtype=np.int64)
    win = np.empty(n, dtype=np.int64)
    i = 0
    while i < n:
        obs, _ = world.reset()
        t0 = clock()
        agent.begin_episode(obs, world.cell)
        if starts is not None:
            starts.append(clock() - t0)
        while i < n:
            win[i] = agent.winner
            t0 = clock()
            a = agent.act()
            t1 = clock()
            obs, _, term, trunc, info = world.step(a)
            t2 = clock()
            agent.observe(obs, info)
            t3 = clock()
            agent_ns[i], world_ns[i] = (t1 - t0) + (t3 - t2), t2 - t1
            i += 1
            if term or trunc:
                break
    return agent_ns, world_ns, win


def time_steps(world, agent, n: int) -> np.ndarray:
    """Nanoseconds of ``act`` + ``observe`` for ``n`` steps of training episodes."""
    return timed_steps(world, agent, n)[0]


def step_stats(ns: np.ndarray, agent, maze: Maze, trained_episodes: int | None) -> dict:
    us = ns / 1e3
    return {"free_cells": len(maze.free_cells()), "nodes": int(agent.map.size),
            "trained_episodes": trained_episodes, "steps": int(len(us)),
            "median_us": float(np.median(us)), "mean_us": float(us.mean()),
            "p10_us": float(np.percentile(us, 10)), "p90_us": float(np.percentile(us, 90)),
            "p99_us": float(np.percentile(us, 99)), "max_us": float(us.max())}


def bench_default(seed: int, steps: int, clock=time.perf_counter_ns) -> dict:
    """The default maze's converged core step, ``steps`` of them timed by ``clock``."""
    maze = Maze.from_file(DEFAULT_MAZE)
    caps = Caps.for_maze(maze)
    world = make_world(maze, "G", caps)
    agent = make_agent("tmgwr", maze, np.random.default_rng(seed))
    set_goal(world, agent, "G")
    conv = train_until_converged(world, agent, caps)
    out = step_stats(timed_steps(world, agent, steps, clock)[0], agent, maze, conv.episodes)
    out["target_median_us"] = 50.0
    return out


def bench_large(seed: int, steps: int, max_episodes: int = 20) -> dict:
    maze = Maze.from_text(generate_maze(51, 51, np.random.default_rng(seed)),
                          source=f"generate_maze(51, 51, seed {seed})")
    caps = Caps.for_maze(maze)
    world = make_world(maze, "G", caps)
    agent = make_agent("tmgwr", maze, np.random.default_rng(seed))
    set_goal(world, agent, "G")
    trained = None
    for k in range(1, max_episodes + 1):
        run_episode(world, agent)
        if greedy_optimal(world, agent):
            trained = k
            break
    out = step_stats(time_steps(world, agent, steps), agent, maze, trained)
    out["maze"] = maze.source
    out["target_median_us"] = 1000.0
    return out


def time_split(world, agent, n: int) -> tuple[np.ndarray, np.ndarray]:
    """CPU nanoseconds (``time.thread_time_ns``) of the agent (``act`` + ``observe``) and
    of the world (``step``), apart, over ``n`` steps of training episodes."""
    return timed_steps(world, agent, n, time.thread_time_ns)[:2]


#: The worlds whose agent and world CPU per step ``bench_worlds`` measures.
BENCH_WORLDS = ("grid", "minigrid", "pointmaze")


def bench_worlds(seed: int, steps: int, warmup: int = 2000) -> dict:
    """Per world (:data:`BENCH_WORLDS`, built from the default maze): CPU per step of the
    TMGWR agent and of the world, apart, over ``steps`` steps of training episodes after
    ``warmup`` steps of them (the map built, epsilon falling). ``agent_over_world``: the
    agent's median over the world's (below 1: the world, not the agent, is the
    bottleneck). A world this build cannot load is recorded as ``error``."""
    from maze_sim.worlds import make_world as make_named_world
    from tmgwr_agent.world_senses import world_senses
    maze = Maze.from_file(DEFAULT_MAZE)
    caps = Caps.for_maze(maze)
    out: dict = {}
    for name in BENCH_WORLDS:
        try:
            world = make_named_world(name, maze, "G", caps.episode_steps, seed)
        except Exception as exc:  # noqa: BLE001 -- recorded, the others still run
            out[name] = {"error": repr(exc)}
            continue
        agent = make_agent("tmgwr", maze, np.random.default_rng(seed),
                           senses=world_senses(world))
        set_goal(world, agent, "G")
        time_split(world, agent, warmup)
        a_ns, w_ns = time_split(world, agent, steps)
        a_us, w_us = np.median(a_ns) / 1e3, np.median(w_ns) / 1e3
        out[name] = {"steps": steps, "warmup": warmup, "nodes": int(agent.map.size),
                     "agent_cpu_median_us": float(a_us), "agent_cpu_mean_us":
                     float(a_ns.mean() / 1e3), "world_cpu_median_us": float(w_us),
                     "world_cpu_mean_us": float(w_ns.mean() / 1e3),
                     "agent_over_world": float(a_us / w_us) if w_us else None}
    return out


def _convergence_trial(spec, t, seed, maze_path):
    maze = Maze.from_file(maze_path)
    caps = Caps.for_maze(maze)
    world = make_world(maze, "G", caps)
    agent = make_agent(spec, maze, np.random.default_rng(seed))
    set_goal(world, agent, "G")
    conv = train_until_converged(world, agent, caps)
    return (conv.cpu_s if conv.episodes is not None else None, conv.episodes)


def cpu_to_convergence(trials: int, seed: int, jobs: int) -> dict:
    res = agent_trials(_convergence_trial, AGENT_NAMES, seed, trials, (str(DEFAULT_MAZE),),
                       jobs, "cpu to convergence")
    return {a: {"cpu_s": stat(r[0] for r in rs), "episodes": stat(r[1] for r in rs)}
            for a, rs in res.items()}


def _optional(key: str, args) -> dict:
    """``tmgwr_agent.<key>.bench.run(args)`` for key ``graph`` or ``bag`` (imported here:
    they load rclpy / rosbags); a failure is recorded, not fatal, so the figures measured
    so far are still written."""
    try:
        if key == "graph":
            from tmgwr_agent.graph.bench import run as bench_run
        else:
            from tmgwr_agent.bag.bench import run as bench_run
        return bench_run(args)
    except Exception as exc:  # noqa: BLE001 -- keep the core figures
        print(f"bench: tmgwr_agent.{key}.bench failed: {exc!r}", file=sys.stderr)
        return {"error": repr(exc)}


def run(args) -> int:
    from tmgwr_agent.experiments.output import write_json
    from tmgwr_agent.experiments.report import bench_table
    if args.trials < 1 or args.steps < 1:
        print("tmgwr: error: --trials and --steps must be >= 1", file=sys.stderr)
        return 2
    warm_up()
    result: dict = {"machine": {"python": platform.python_version(),
                                "processor": platform.processor() or platform.machine(),
                                "cores": default_jobs()}}
    print("bench: TMGWR step time on the default maze ...", file=sys.stderr)
    result["step_default"] = bench_default(args.seed, args.steps)
    print("bench: TMGWR step time on a ~1300-cell maze (about a minute of training) ...",
          file=sys.stderr)
    result["step_large"] = bench_large(args.seed, args.steps)
    t0 = time.perf_counter()
    result.update(scaling(args.seed))
    result["scaling_wall_s"] = round(time.perf_counter() - t0, 1)
    print("bench: agent and world CPU per step in each world ...", file=sys.stderr)
    result["worlds"] = bench_worlds(args.seed, args.steps)
    print("bench: CPU seconds to convergence ...", file=sys.stderr)
    result["cpu_to_convergence"] = cpu_to_convergence(args.trials, args.seed, args.jobs)
    if not getattr(args, "no_graph", False):
        for key in ("graph", "bag"):
            result[key] = _optional(key, args)
    failed = failures(result)
    path = Path(args.json) if args.json else Path("results") / "bench.json"
    write_json(result, path)
    print(ratio_table(result))
    print()
    print(scaling_table(result))
    print()
    print(bench_table(result))
    print(f"written: {path}")
    for where, why in failed.items():
        print(f"bench: FAILED: {where}: {why.splitlines()[0] if why else why}",
              file=sys.stderr)
    return 1 if failed else 0


def failures(result: dict) -> dict[str, str]:
    """``part -> error`` for every part of the bench that failed."""
    out = {}
    for key in ("graph", "bag"):
        part = result.get(key) or {}
        if part.get("error"):
            out[key] = part["error"]
        for sub, why in (part.get("errors") or {}).items():
            out[f"{key}.{sub}"] = why
    return out


def _median(s: dict | None) -> float | None:
    vals = [v for v in (s or {}).get("values", []) if v is not None]
    return float(np.median(vals)) if vals else None


def ratio_table(result: dict) -> str:
    """Issue 11's figures from one run: rates as ratios to the empty ring of 5 rclpy
    processes measured in the same run, bytes per step, CPU to convergence per agent."""
    from tmgwr_agent.experiments.report import _table
    g = result.get("graph") or {}
    return (f"bench summary (ratios to the ring of 5 in this run; load "
            f"{g.get('load_avg_1min')}, {g.get('cpus')} cpus)\n"
            + _table(list(RATIO_HEADER), ratio_rows(result)))


RATIO_HEADER = ("measure", "value", "ratio", "target")


def ratio_rows(result: dict) -> list[list[str]]:
    """The rows of :func:`ratio_table` (also the docs' table, ``./tmgwr results``)."""

    def num(v, digits=2):
        return "-" if v is None else f"{v:.{digits}f}" if isinstance(v, float) else str(v)

    g = result.get("graph") or {}
    ratios = g.get("ratios") or {}
    rows: list[list[str]] = []

    def rate_row(what: str, key: str, ratio: str, target: str = "") -> None:
        part = g.get(key) or {}
        if "skipped" in part:
            rows.append([what, f"skipped: {part['skipped']}", "", target])
        elif key in (g.get("errors") or {}):
            rows.append([what, "FAILED (see errors)", "", target])
        else:
            rows.append([what, f"{num(part.get('steps_per_s'), 1)} steps/s",
                         num(ratios.get(ratio)), target])

    ring = g.get("ring5") or {}
    rows.append(["empty ring of 5 processes", f"{num(ring.get('laps_per_s'), 1)} laps/s",
                 "1.00", ""])
    rate_row("graph, 5 processes, default maze", "graph", "graph_over_ring", ">= 0.6")
    for key, what in (("graph_large", "graph, generated 51x51 maze (~1300 cells)"),
                      ("graph_open200", "graph, 200x200 open maze")):
        rate_row(what, key, key.replace("graph_", "") + "_graph_over_ring", ">= 0.6")
        part = g.get(key) or {}
        if part.get("last_quarter_steps_per_s"):
            rows.append([f"  last quarter of the window (to step {part.get('last_step')})",
                         f"{num(part['last_quarter_steps_per_s'], 1)} steps/s",
                         num(ratios.get(key.replace("graph_", "") + "_last_quarter_over_ring")),
                         ">= 0.6"])
    rate_row("graph, 5 processes, PointMaze (default maze)", "graph_pointmaze",
             "pointmaze_graph_over_ring")
    ws = (g.get("graph_pointmaze") or {}).get("world_step") or {}
    if ws:
        rows.append(["  PointMaze physics in maze_sim, per step",
                     f"mean {ws.get('mean_us')} us (cpu {ws.get('cpu_mean_us')} us)", "", ""])
    rate_row("composed graph, 1 process", "composed", "composed_over_ring", ">= 1.5")
    rate_row("two hosts (netns + veth), 5 processes", "two_hosts", "two_hosts_over_ring")
    for key, what in (("graph", "default maze"), ("graph_large", "generated 51x51"),
                      ("graph_open200", "200x200 open")):
        b = (g.get(key) or {}).get("bytes")
        if b:
            rows.append([f"bytes per step, {what}", f"{b['bytes_per_step']} B",
                         f"({b['per_topic'].get('/sensorimotor_state', 0)} B state)",
                         "flat once the map is built"])
    h = g.get("two_hosts") or {}
    if h.get("link_bytes_per_step"):
        rows.append(["bytes per step over the link (two hosts)",
                     f"{h['link_bytes_per_step']} B", "", ""])
    cpu = result.get("cpu_to_convergence") or {}
    q = (cpu.get("q_learning") or {}).get("cpu_s") or {}
    for agent, d in cpu.items():
        s = d.get("cpu_s") or {}
        vs_q = (s["mean"] / q["mean"]) if s.get("mean") and q.get("mean") else None
        med_q = _median(q)
        med = _median(s)
        rows.append([f"CPU s to convergence, {agent}",
                     f"mean {num(s.get('mean'))}, median {num(med)}",
                     f"{num(vs_q)} x Q (median {num(med / med_q if med and med_q else None)})",
                     "TMGWR < Q" if agent == "tmgwr" else ""])
    bag = result.get("bag") or {}
    if bag:
        rows.append(["recorder, lossless", "FAILED: " + bag["error"].splitlines()[0]
                     if bag.get("error") else f"{num(bag.get('recorder_lossless_msg_per_s'))} "
                     "msg/s", "", ""])
    for name, w in (result.get("worlds") or {}).items():
        if w.get("error"):
            rows.append([f"agent / world CPU per step, {name}", "FAILED: " + w["error"], "",
                         ""])
            continue
        rows.append([f"agent / world CPU per step, {name} ({w.get('nodes')} nodes)",
                     f"agent {num(w.get('agent_cpu_median_us'), 1)} us, world "
                     f"{num(w.get('world_cpu_median_us'), 1)} us (medians)",
                     num(w.get("agent_over_world")),
                     "agent < world" if name == "pointmaze" else ""])
    for key, what in (("step_default", "default maze"), ("step_large", "generated 51x51")):
        st = result.get(key) or {}
        if st.get("median_us") is not None:
            target = st.get("target_median_us")
            rows.append([f"core step, {what} ({st.get('nodes')} nodes)",
                         f"median {num(st['median_us'], 1)} us, "
                         f"mean {num(st.get('mean_us'), 1)} us", "",
                         f"median <= {target:g} us" if target else ""])
    return rows


# ---------------------------------------------------------------------------- scaling
#: Free cells of the scaling benchmark's maps (issue 27), per family.
SCALING_CELLS = (300, 1400, 3200, 10000)
SCALING_FAMILIES = ("open", "braided")
#: Steps timed per map for the scaling rows.
SCALING_STEPS = 2000
#: Ordinary learning episodes at most after the tours (:func:`tour_train`); a greedy
#: optimal rollout ends training earlier.
SCALING_EPISODES = 12
#: Learning tours of the maze before them.
SCALING_TOURS = 3
#: What the scaling rows may be timed by: wall-clock time (``make bench``), or the
#: benchmarking thread's CPU time (comparisons on a machine shared with other work).
CLOCKS = {"wall": time.perf_counter_ns, "cpu": time.thread_time_ns}


def scaling_open_field(cells: int, rng: np.random.Generator, density: float = 0.08) -> str:
    """An open square field of about ``cells`` free cells with sparse random obstacles (bars
    of 1 to 3 cells covering about ``density`` of it), pockets walled up, S and G in opposite
    corners."""
    side = int(round(math.sqrt(cells / (1.0 - density))))
    walls = np.ones((side + 2, side + 2), dtype=bool)
    walls[1:-1, 1:-1] = False
    keep = {(1, 1), (side, side)}
    while walls[1:-1, 1:-1].sum() < density * side * side:
        h, w = 1, int(rng.integers(1, 4))
        if rng.random() < 0.5:
            h, w = w, h
        r, c = int(rng.integers(1, side + 1)), int(rng.integers(1, side + 1))
        cut = {(rr, cc) for rr in range(r, min(r + h, side + 1))
               for cc in range(c, min(c + w, side + 1))}
        if not cut & keep:
            for cell in cut:
                walls[cell] = True
    walls |= bfs_distances(walls, (1, 1)) < 0              # wall up cut-off pockets
    chars = np.where(walls, "#", ".").astype("<U1")
    chars[1, 1], chars[side, side] = "S", "G"
    return "\n".join("".join(row) for row in chars) + "\n"


def scaling_braided(cells: int, rng: np.random.Generator, loops: float = 0.2) -> str:
    """A braided maze of about ``cells`` free cells: a recursive-backtracker perfect maze
    with a share ``loops`` of its inner walls knocked out (:func:`maze_sim.maze.
    generate_maze`), S top left, G bottom right."""
    side = int(round(math.sqrt(2.0 * cells / (1.0 + loops / 2.0)))) + 1
    side += 1 - side % 2                                   # odd
    return generate_maze(side, side, rng, loop_fraction=loops)


def scaling_maze(family: str, cells: int, seed: int) -> Maze:
    rng = np.random.default_rng([seed, cells, SCALING_FAMILIES.index(family)])
    text = (scaling_open_field if family == "open" else scaling_braided)(cells, rng)
    return Maze.from_text(text, source=f"scaling {family} ~{cells} cells, seed {seed}")


#: The move that undoes each action (up/down, left/right: maze_sim's numbering).
_BACK = (1, 0, 3, 2)


def tour_actions(walls: np.ndarray, start) -> list[int]:
    """A depth-first tour of every free cell from ``start`` that, on entering a cell, also
    takes each move into a wall there once (a bump), and walks back along the tree: the
    actions of a systematic explorer (:func:`maze_sim.maze.move`'s numbering)."""
    seen = np.zeros_like(walls)
    seen[start] = True
    acts: list[int] = []
    stack: list[tuple[tuple[int, int], int, int]] = [(start, 0, -1)]   # cell, next a, came
    while stack:
        cell, k, came = stack.pop()
        if k == 0:
            acts.extend(a for a in range(4) if move(walls, cell, a)[1])
        for a in range(k, 4):
            nxt, bumped = move(walls, cell, a)
            if not bumped and not seen[nxt]:
                seen[nxt] = True
                stack.append((cell, a + 1, came))
                stack.append((nxt, 0, a))
                acts.append(a)
                break
        else:
            if came >= 0:
                acts.append(_BACK[came])
    return acts


def tour_train(world, agent, tours: int = SCALING_TOURS,
               max_episodes: int = SCALING_EPISODES) -> dict:
    """The cheaper route to a converged agent on a large map (the first episode of a random
    walk over 10,000 cells would take hours): ``tours`` learning episodes that follow
    :func:`tour_actions` from S (the agent observes every step but does not choose; the
    world's goal G ends an episode, which then resumes from G), which give the map a node
    per cell, the links of every move and the bumps of every wall; the goal then told to
    the agent, Eq. 7's epsilon set to its floor (as after ten goals); then ordinary
    learning episodes from S until a greedy rollout takes a shortest path (at most
    ``max_episodes``). Returns those episodes and whether the last probe was optimal."""
    acts = tour_actions(world.walls, world.maze.start)
    for _ in range(tours):
        obs, _ = world.reset()
        agent.begin_episode(obs, world.cell)
        for a in acts:
            obs, _, term, trunc, info = world.step(a)
            agent.observe(obs, info)
            if term or trunc:
                obs, _ = world.reset(start=world.cell)
                agent.begin_episode(obs, world.cell)
        world.end_episode()
    set_goal(world, agent, "G")
    agent.selector.attained = True
    schedule = agent.selector.policy.schedule
    schedule.eps = schedule.eps_min
    d = world.shortest_path_length()
    for k in range(1, max_episodes + 1):
        run_episode(world, agent)
        if greedy_optimal(world, agent, d):
            return {"episodes": k, "optimal": True}
    return {"episodes": max_episodes, "optimal": False}


def lookup_floor_ns(agent, winners: np.ndarray, clock=time.perf_counter_ns) -> np.ndarray:
    """Nanoseconds of a pure lookup of the winner's best link (its links' ``E V`` argmax,
    :func:`kernels.best_links`) for each of ``winners`` on the agent's map: the floor of a
    step that changes nothing."""
    m, V = agent.map, agent.motivation.V
    out = np.empty(len(winners), dtype=np.int64)
    for k, i in enumerate(winners):
        t0 = clock()
        kernels.best_links(m.out[i], m.E[i], V)
        out[k] = clock() - t0
    return out


def time_steps_winners(world, agent, n: int, clock=time.perf_counter_ns,
                       starts: list | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`time_steps`, with the winner each step acted from (and ``starts``, as
    :func:`timed_steps`)."""
    agent_ns, _, win = timed_steps(world, agent, n, clock, starts)
    return agent_ns, win


def goal_change_first_ms(world, agent, goal_cell, clock=time.perf_counter_ns) -> float:
    """Milliseconds of the agent's part of a goal change (``set_goal``, which re-solves
    Eq. 4-5 from V = 0) and of its first step after it, mid-episode."""
    obs, _ = world.reset()
    agent.begin_episode(obs, world.cell)
    for _ in range(3):                       # a few steps into the episode
        obs, _, term, trunc, info = world.step(agent.act())
        agent.observe(obs, info)
    world.set_goal(goal_cell)
    goal_obs = world.goal_observation()
    state = world.goal_state
    t0 = clock()
    agent.set_goal(state, goal_obs)
    a = agent.act()
    t1 = clock()
    obs, _, term, trunc, info = world.step(a)
    t2 = clock()
    agent.observe(obs, info)
    t3 = clock()
    world.end_episode()
    return ((t1 - t0) + (t3 - t2)) / 1e6


def block_episode_ms(world, agent, seed: int, clock=time.perf_counter_ns) -> dict:
    """A cell of the agent's route is blocked (the first one from the route's middle on that
    leaves the goal reachable), then one learning episode from S is timed (``act`` +
    ``observe``, milliseconds) with its steps."""
    d = world.shortest_path_length()
    path = _greedy_cells(world, agent, d)
    blocked = None
    for cell in path[len(path) // 2:-1]:
        try:
            world.set_cell(cell[0], cell[1], True)
        except Exception:  # noqa: BLE001 -- refused: it would cut the last route
            continue
        blocked = cell
        break
    obs, _ = world.reset()
    agent.begin_episode(obs, world.cell)
    total, steps = 0, 0
    while True:
        t0 = clock()
        a = agent.act()
        t1 = clock()
        obs, _, term, trunc, info = world.step(a)
        t2 = clock()
        agent.observe(obs, info)
        total += (t1 - t0) + (clock() - t2)
        steps += 1
        if term or trunc:
            break
    return {"block_episode_ms": total / 1e6, "block_episode_steps": steps,
            "blocked_cell": list(blocked) if blocked else None,
            "shortest_after": world.shortest_path_length()}


def _greedy_cells(world, agent, d: int) -> list[tuple[int, int]]:
    """The cells of a greedy rollout (no learning) of at most ``d`` steps from S."""
    obs, _ = world.reset()
    agent.begin_episode(obs, world.cell, learn=False)
    cells = [world.cell]
    for _ in range(d):
        obs, _, term, trunc, info = world.step(agent.act(explore=False))
        agent.observe(obs, info, learn=False)
        cells.append(world.cell)
        if term or trunc:
            break
    world.end_episode()
    return cells


def scaling_row(family: str, cells: int, seed: int, steps: int = SCALING_STEPS,
                overrides: dict | None = None, clock=time.perf_counter_ns) -> dict:
    """One row of the scaling benchmark (issue 27): the default TMGWR agent trained on
    :func:`scaling_maze` by :func:`tour_train`, then ``steps`` converged learning steps
    timed (median, p99, mean; ``solves``: how many the estimator solved incrementally), the
    lookup floor on the same winners, as many more steps with the incremental solve off
    (``full_solve_step_median_us``: the same map solved in full every step, an A/B in one
    run), the episode starts among those steps (``begin_episode``, not counted as steps:
    median and max), the first step after a goal change (to the free cell nearest the
    maze's centre, and back to G), and the episode after a block on the route; every time
    by ``clock``
    (nanoseconds; :data:`CLOCKS`)."""
    maze = scaling_maze(family, cells, seed)
    caps = Caps.for_maze(maze)
    world = make_world(maze, "G", caps)
    world.set_goal("G")
    agent = make_agent("tmgwr", maze, np.random.default_rng(seed), overrides)
    t0 = time.perf_counter()
    trained = tour_train(world, agent)
    train_s = time.perf_counter() - t0
    before = dict(getattr(agent.motivation, "solves", {}))
    starts: list[int] = []
    ns, winners = time_steps_winners(world, agent, steps, clock, starts)
    solves = {k: v - before.get(k, 0)
              for k, v in getattr(agent.motivation, "solves", {}).items()}
    full = None
    if getattr(agent.motivation, "vi_incremental", False):   # the same map, solved in full
        agent.motivation.vi_incremental = False
        full = float(np.median(time_steps_winners(world, agent, steps, clock)[0])) / 1e3
        agent.motivation.vi_incremental = True
    us = ns / 1e3
    floor = lookup_floor_ns(agent, winners, clock) / 1e3
    free = maze.free_cells()
    centre = np.array(maze.walls.shape) / 2.0
    mid = min(free, key=lambda c: (abs(c[0] - centre[0]) + abs(c[1] - centre[1]), c))
    goal_ms = goal_change_first_ms(world, agent, mid, clock)
    world.set_goal("G")
    back_ms = goal_change_first_ms(world, agent, maze.goal_cell("G"), clock)
    block = block_episode_ms(world, agent, seed, clock)
    med = float(np.median(us))
    return {"family": family, "cells": len(free), "nodes": int(agent.map.size),
            "maze": maze.source, "train_s": round(train_s, 2), "trained": trained,
            "step_median_us": med, "step_p99_us": float(np.percentile(us, 99)),
            "step_mean_us": float(us.mean()), "step_max_us": float(us.max()),
            "floor_median_us": float(np.median(floor)),
            "median_over_floor": med / float(np.median(floor)),
            "solves": solves, "full_solve_step_median_us": full,
            "episode_starts": len(starts),
            "episode_start_median_ms": float(np.median(starts)) / 1e6,
            "episode_start_max_ms": float(np.max(starts)) / 1e6,
            "goal_change_first_ms": goal_ms, "goal_back_first_ms": back_ms,
            **block}


def scaling(seed: int, steps: int = SCALING_STEPS, cells=SCALING_CELLS,
            families=SCALING_FAMILIES, clock: str = "wall") -> dict:
    """``scaling``: every row of :func:`scaling_row`; ``scaling_slopes``: per family, the
    log-log slope of the step's median against the node count from about 1,400 cells
    on (:func:`scaling_slopes`); ``clock``: a key of :data:`CLOCKS`."""
    rows = []
    for family in families:
        for c in cells:
            print(f"bench: scaling, {family} ~{c} cells ...", file=sys.stderr)
            rows.append(scaling_row(family, c, seed, steps, clock=CLOCKS[clock]))
    return {"scaling": rows, "scaling_slopes": scaling_slopes(rows), "scaling_clock": clock}


SCALING_HEADER = ("family", "cells", "nodes", "median us", "p99 us", "mean us",
                  "median / floor", "episode start ms (max)", "goal change ms",
                  "block episode ms (steps)", "incremental solves")


def scaling_rows(result: dict) -> list[list[str]]:
    """The scaling rows as text cells under :data:`SCALING_HEADER`."""
    rows = []
    for r in result.get("scaling") or []:
        sv = r.get("solves") or {}
        total = sum(v for k, v in sv.items()
                    if k in ("incremental", "continued", "ordered", "full"))
        rows.append([r["family"], str(r["cells"]), str(r["nodes"]),
                     f"{r['step_median_us']:.1f}", f"{r['step_p99_us']:.0f}",
                     f"{r['step_mean_us']:.0f}", f"{r['median_over_floor']:.0f}",
                     _episode_start(r), f"{r['goal_change_first_ms']:.1f}",
                     f"{r['block_episode_ms']:.1f} ({r['block_episode_steps']})",
                     f"{sv.get('incremental', 0)} / {total}" if total else "-"])
    return rows


def _episode_start(r: dict) -> str:
    """A row's episode start, median (max) in ms; '-' in rows recorded before it was."""
    if "episode_start_median_ms" not in r:
        return "-"
    return f"{r['episode_start_median_ms']:.1f} ({r['episode_start_max_ms']:.1f})"


def scaling_table(result: dict) -> str:
    """The scaling rows (issue 27) as a table, with the slopes."""
    from tmgwr_agent.experiments.report import _table
    rows = scaling_rows(result)
    slopes = ", ".join(f"{f} {v:.2f}" for f, v in (result.get("scaling_slopes") or {}).items())
    return ("scaling (issue 27): converged core step against map size; log-log slope of the "
            f"median from ~1,400 cells: {slopes or '-'}\n" + _table(list(SCALING_HEADER), rows))


def scaling_slopes(rows: list[dict]) -> dict:
    """Per family, d log(step median) / d log(nodes) between its rows of about 1,400 cells
    and over (the least-squares slope)."""
    out = {}
    for family in {r["family"] for r in rows}:
        rs = [r for r in rows if r["family"] == family and r["cells"] >= 1000]
        if len(rs) >= 2:
            x = np.log([r["nodes"] for r in rs])
            y = np.log([r["step_median_us"] for r in rs])
            out[family] = float(np.polyfit(x, y, 1)[0])
    return out


def scaling_main(argv: list[str] | None = None) -> int:
    """``python -m tmgwr_agent.experiments.bench``: the scaling rows alone (issue 27), for
    measuring a change of the core step without the rest of ``./tmgwr bench``."""
    import argparse
    import json
    p = argparse.ArgumentParser(prog="python -m tmgwr_agent.experiments.bench",
                                description=scaling_main.__doc__)
    p.add_argument("--cells", default=",".join(map(str, SCALING_CELLS)),
                   help="comma-separated free cells per map (default %(default)s; empty: "
                   "no scaling rows)")
    p.add_argument("--default", type=int, default=0, metavar="STEPS",
                   help="also time STEPS converged core steps on the default maze, by "
                   "--clock (JSON step_default; default 0: not)")
    p.add_argument("--families", default=",".join(SCALING_FAMILIES),
                   help="comma-separated families (default %(default)s)")
    p.add_argument("--steps", type=int, default=SCALING_STEPS,
                   help="converged steps timed per map (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="maze and agent seed (default 0)")
    p.add_argument("--json", default=None, metavar="OUT", help="also write the rows here")
    p.add_argument("--clock", default="wall", choices=tuple(CLOCKS),
                   help="wall: time.perf_counter_ns (default); cpu: this thread's CPU time "
                   "(time.thread_time_ns), less hurt by other processes on a loaded "
                   "machine")
    args = p.parse_args(argv)
    try:
        cells = tuple(int(c) for c in args.cells.split(",") if c.strip())
    except ValueError:
        p.error(f"--cells: not a comma-separated list of integers: {args.cells!r}")
    families = tuple(args.families.split(","))
    bad = [f for f in families if f not in SCALING_FAMILIES]
    if bad or args.steps < 1 or min(cells, default=1) < 1 or args.default < 0:
        p.error(f"--families must be among {', '.join(SCALING_FAMILIES)} (got "
                f"{args.families!r}), --steps and --cells >= 1, --default >= 0")
    if not cells and not args.default:
        p.error("--cells is empty and --default 0: nothing to time")
    warm_up()
    result: dict = {}
    if args.default:
        d = result["step_default"] = bench_default(args.seed, args.default,
                                                   CLOCKS[args.clock])
        d["clock"] = args.clock
        print(f"default maze ({args.clock} clock, {d['steps']} converged steps): core step "
              f"median {d['median_us']:.1f} us, p90 {d['p90_us']:.1f}, p99 {d['p99_us']:.1f}")
    if cells:
        result.update(scaling(args.seed, args.steps, cells, families, args.clock))
        print(scaling_table(result))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(scaling_main())
