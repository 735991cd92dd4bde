"""Measure agents on the PointMaze world (maze_sim.pointmaze_world): issue #26, part 2.

Per maze, agent and trial (a fresh agent, its generator from the trial's seed), the
protocol of the env-change scenario (experiments/env_change.py, steps 1-3) on PointMaze:
train to convergence (runner.train_until_converged: ten consecutive greedy rollouts that
reach the goal within the oracle's primitive steps and the world's probe_tolerance), fire
the block event, count the steps of the next episode (``steps``, null when the episode cap
runs out). TMGWR also reports its map's nodes per free cell after training. The JSON
keeps the env-change contract (``oracle_steps``, ``agents[NAME].steps``, ...) and gains
``"world": "pointmaze"`` and the probe's ``probe_tolerance``.

    python tools/pointmaze_check.py --mazes default,braided:0,open:0 --trials 3 \\
        --agents tmgwr,q_learning,dyna_q_plus --out results/pointmaze_check.json
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from maze_sim.maze import Maze, maze_file
from maze_sim.suite import generate
from maze_sim.worlds import make_world, world_class
from tmgwr_agent.experiments.agent_factory import make_agent
from tmgwr_agent.experiments.runner import (
    Caps,
    probe_tolerance,
    run_episode,
    set_goal,
    train_until_converged,
)
from tmgwr_agent.experiments.stats import stat
from tmgwr_agent.world_senses import world_senses


def load(spec: str, seed: int, tmp: Path) -> tuple[str, Path]:
    if spec == "default":
        return "default", maze_file()
    family, _, index = spec.partition(":")
    sm = generate(family, int(index or 0), seed)
    return f"{family}:{index}", sm.write(tmp)


def trial(agent: str, path: str, t: int, seed: int, event: str, budget: int) -> dict:
    maze = Maze.from_file(path)
    caps = Caps.for_maze(maze, budget_factor=budget)
    ss = np.random.SeedSequence(seed, spawn_key=(t,))
    world = make_world("pointmaze", maze, "G", caps.episode_steps, seed)
    ag = make_agent(agent, maze, np.random.default_rng(ss), senses=world_senses(world))
    set_goal(world, ag, "G")
    t0 = time.process_time()
    conv = train_until_converged(world, ag, caps)
    out = {"train_episodes": conv.episodes, "train_steps": conv.steps,
           "cpu_s": time.process_time() - t0}
    out["last_train_steps"] = conv.curve[-1] if conv.curve else None
    if agent.startswith("tmgwr"):
        out["nodes_per_free_cell"] = int(ag.map.alive[:ag.map.n].sum()) / len(maze.free_cells())
    world.fire_event(event)
    ep = run_episode(world, ag)
    out["steps"] = ep.steps if ep.reached_goal else None
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mazes", default="default")
    ap.add_argument("--agents", default="tmgwr,q_learning,dyna_q_plus")
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--event", default="a")
    ap.add_argument("--budget", type=int, default=1000, help="training steps in all per "
                    "convergence run, per free cell (the experiments' 1000)")
    ap.add_argument("--out", default="")
    a = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="pointmaze_check_"))
    result = {"world": "pointmaze", "seed": a.seed, "trials": a.trials,
              "budget_per_free_cell": a.budget,
              "probe_tolerance": probe_tolerance(world_class("pointmaze")), "mazes": {}}
    with ProcessPoolExecutor(a.jobs) as pool:
        for spec in a.mazes.split(","):
            name, path = load(spec, a.seed, tmp)
            maze = Maze.from_file(path)
            world = make_world("pointmaze", maze, "G")
            entry = {"file": str(path), "free_cells": len(maze.free_cells()),
                     "k_push": world.k_push, "k_brake": world.k_brake,
                     "oracle_before": world.shortest_path_length(),
                     "bfs_before": maze.shortest_path_length(maze.start, maze.goals["G"]),
                     "oracle_steps": world.event_oracle_steps(a.event), "agents": {}}
            futs = {ag: [pool.submit(trial, ag, str(path), t, a.seed, a.event, a.budget)
                         for t in range(a.trials)] for ag in a.agents.split(",")}
            for ag, fs in futs.items():
                rs = [f.result() for f in fs]
                entry["agents"][ag] = {k: stat(r.get(k) for r in rs) for k in rs[0]}
                entry["agents"][ag]["raw"] = rs
                print(name, ag, json.dumps(rs), file=sys.stderr, flush=True)
            result["mazes"][name] = entry
    text = json.dumps(result, indent=1)
    if a.out:
        Path(a.out).write_text(text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
