"""Trace one TMGWR training trial on the PointMaze world, one JSON line per episode.

What issue #26's PointMaze trace needed and the experiments do not print: per training
episode its steps, whether it reached the goal, epsilon, the map's live nodes (and per
free cell), how the agent chose its actions (the random ``walk``, a ``link`` of Eq. 6, an
``option`` of Eq. 5'), bumps and merges, the distinct resting places (to 1 cm) and the
greedy probe after it (its steps, null when it misses the oracle). ``--steps FILE`` also
writes one line per step (action, how chosen, sensation, bump, winner, goal node).

    python tools/pointmaze_trace.py --maze default --episodes 12
    python tools/pointmaze_trace.py --maze blocking:0 --seed 31 --agent tmgwr:none
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np
from pointmaze_check import load

from maze_sim.maze import Maze
from maze_sim.worlds import make_world
from tmgwr_agent.experiments.agent_factory import make_agent
from tmgwr_agent.experiments.runner import Caps, agent_state, run_episode, set_goal
from tmgwr_agent.world_senses import world_senses


def how_chosen(ag) -> str:
    """How the agent's last action was chosen: the random walk, a link or an option."""
    if ag.selector.took_option:
        return "option"
    return "walk" if ag.last_explored else "link"


def episode(world, ag, cap: int, steps_out) -> dict:
    """One training episode (runner.run_episode's loop, with the counts of the module
    doc)."""
    obs, _ = world.reset()
    ag.begin_episode(obs, agent_state(world))
    count: Counter = Counter()
    places = set()
    steps, reached, info = 0, False, None
    while steps < cap:
        a = ag.act(explore=True)
        count[how_chosen(ag)] += 1
        obs, _, terminated, truncated, info = world.step(a)
        ag.observe(obs, info)
        steps += 1
        count["bump"] += info.bumped
        count["merge"] += len(ag.map.merges)
        places.add(tuple(np.round(obs[:2], 2)))
        if steps_out is not None:
            steps_out.write(json.dumps({"t": steps, "a": a, "how": how_chosen(ag),
                                        "x": np.round(obs, 3).tolist(),
                                        "bumped": bool(info.bumped), "winner": ag.winner,
                                        "goal_node": ag.motivation.goal_node}) + "\n")
        if terminated:
            reached = info.reached_goal
            break
        if truncated:
            break
    if not (info is not None and info.terminated):
        world.end_episode()
    return {"steps": steps, "reached": reached, "counts": dict(count), "places": len(places)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maze", default="default", help="default or FAMILY:INDEX")
    ap.add_argument("--agent", default="tmgwr")
    ap.add_argument("--seed", type=int, default=0, help="suite seed and trial seed")
    ap.add_argument("--trial", type=int, default=0)
    ap.add_argument("--episodes", type=int, default=12)
    ap.add_argument("--cap", type=int, default=0, help="steps an episode (0: the "
                    "experiments' cap)")
    ap.add_argument("--steps", default="", help="also write one JSON line per step here")
    a = ap.parse_args(argv)
    if not a.agent.startswith("tmgwr"):
        ap.error(f"--agent must be a tmgwr variant (the trace reads its map), got {a.agent}")
    _, path = load(a.maze, a.seed, Path(tempfile.mkdtemp(prefix="pointmaze_trace_")))
    maze = Maze.from_file(path)
    caps = Caps.for_maze(maze)
    world = make_world("pointmaze", maze, "G", caps.episode_steps, a.seed)
    ss = np.random.SeedSequence(a.seed, spawn_key=(a.trial,))
    ag = make_agent(a.agent, maze, np.random.default_rng(ss), senses=world_senses(world))
    set_goal(world, ag, "G")
    d = world.shortest_path_length()
    free = len(maze.free_cells())
    print(json.dumps({"maze": str(path), "free_cells": free, "oracle": d}), flush=True)
    steps_out = open(a.steps, "w") if a.steps else None
    try:
        for k in range(a.episodes):
            ep = episode(world, ag, a.cap or caps.episode_steps, steps_out)
            nodes = int(ag.map.alive[:ag.map.n].sum())
            probe = run_episode(world, ag, learn=False, explore=False, max_steps=d)
            print(json.dumps({"episode": k, **ep, "epsilon": round(ag.epsilon, 3),
                              "nodes": nodes, "nodes_per_free_cell": round(nodes / free, 2),
                              "greedy_steps": probe.steps if probe.reached_goal else None}),
                  flush=True)
    finally:
        if steps_out is not None:
            steps_out.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
