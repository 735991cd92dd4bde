"""How fast the lockstep graph runs, against the ceiling of its design.

Measured in one run, on the same machine and middleware settings:

(a) **ring ceiling**: an empty ring of 5 rclpy processes (and of 2) relaying a step id
    (:mod:`.ring`) with the graph's per-step QoS, the Fast DDS profile and discovery range
    of tools/env.sh, and the same executor loop as the nodes; in laps/s. One lap = one
    message through every process, exactly what one lockstep step of the graph costs in
    messaging alone.
(b) **graph rate**: the five nodes started as for ``./tmgwr up`` (no recorder), steps/s
    over ``graph_steps`` steps after ``warmup`` steps, timed from the Observation topic by
    an in-process observer; plus each node's own per-step callback time (the nodes print
    it at shutdown), which splits a step into computation and messaging.
(c) **in-process rate**: the same core loop (simulator, preprocessor, map, motivation,
    action selection) in one process with the same seed and step window.

``graph_over_ring`` = (b) / (a, 5 processes): the target is >= 0.6.
"""

from __future__ import annotations

import json
import os
import re
import statistics
import sys
import time
from pathlib import Path

from tmgwr_agent.graph.output import say

CALLBACKS = re.compile(r"(\d+) step callbacks, mean (\d+) us, total ([\d.]+) s")


def _opt(args, name, default):
    value = getattr(args, name, None) if args is not None else None
    return default if value is None else value


# ------------------------------------------------------------------------------ (a) ring
def ring(size: int, laps: int, warmup: int = 100, timeout: float = 120.0) -> dict:
    """Laps/s of an empty ring of ``size`` processes (member 0 times it)."""
    from tmgwr_agent.graph.supervisor import GraphError, GraphSupervisor, NodeSpec

    py = sys.executable
    specs = [NodeSpec("", f"ring_{i}", name=f"ring{size}_{i}", argv=[
        py, "-u", "-m", "tmgwr_agent.graph.ring", "--index", str(i), "--size", str(size),
        "--laps", str(laps), "--warmup", str(warmup), "--timeout", str(timeout)])
        for i in range(size)]
    sup = GraphSupervisor(specs, echo=False)
    try:
        # no wait for 'ready' lines: member 0 waits for the whole ring itself (probes)
        sup.start(wait_ready=False)
        leader = sup.process(f"ring{size}_0")
        try:
            leader.proc.wait(timeout=timeout + 10)
        except Exception:  # noqa: BLE001 -- report below with its output
            pass
        leader._reader.join(timeout=2.0)
        for line in reversed(leader.tail):
            if line.startswith("RING "):
                return json.loads(line[5:])
        raise GraphError(leader.describe(f"ring of {size}: no RING result"))
    finally:
        sup.stop(sigint_timeout=3.0)


# ------------------------------------------------------------------------------ (b) graph
def graph_rate(steps: int, warmup: int = 200, seed: int = 0, maze: str | None = None,
               timeout: float = 300.0) -> dict:
    """Steps/s of the lockstep graph over ``steps`` steps after ``warmup`` steps."""
    from tmgwr_agent.graph.run import GraphRun, describe_exit
    from tmgwr_agent.graph.supervisor import GraphError

    run = GraphRun(maze=maze, seed=seed, record=False, echo=False)
    run.start(ready_timeout=120.0)
    mon = run.monitor
    t_begin = time.monotonic()
    marks: dict[str, float] = {}
    try:
        while mon.last_step_id < warmup + steps:
            run.spin_once(0.1)
            if "t0" not in marks and mon.last_step_id >= warmup:
                marks["t0"], marks["s0"] = mon.last_time, mon.last_step_id
            if run.supervisor.dead():
                raise GraphError("; ".join(describe_exit(p) for p in run.supervisor.dead()))
            if time.monotonic() - t_begin > timeout:
                raise GraphError(f"the graph made only {mon.last_step_id} steps in {timeout} s")
        seconds = mon.last_time - marks["t0"]
        counted = mon.last_step_id - int(marks["s0"])
    finally:
        codes = run.stop()
    callbacks = {}
    for p in run.supervisor.processes:
        for line in reversed(p.tail):
            m = CALLBACKS.search(line)
            if m:
                callbacks[p.label] = {"calls": int(m.group(1)), "mean_us": int(m.group(2)),
                                      "total_s": float(m.group(3))}
                break
    rate = counted / seconds
    step_us = 1e6 / rate
    compute_us = sum(c["mean_us"] for c in callbacks.values())
    return {"steps": counted, "warmup": warmup, "seed": seed, "seconds": round(seconds, 3),
            "steps_per_s": round(rate, 1), "step_us": round(step_us),
            "callbacks": callbacks, "callbacks_us_per_step": compute_us,
            "messaging_us_per_step": round(step_us - compute_us),
            "missed_observations": mon.missed, "exit_codes": codes}


# ------------------------------------------------------------------------------ (c) in-process
def in_process_rate(steps: int, warmup: int = 200, seed: int = 0,
                    maze: str | None = None) -> dict:
    """Steps/s of the same loop in one process (what each node does, in order)."""
    import numpy as np

    from maze_sim.maze import Maze, maze_file
    from maze_sim.world import GridWorld
    from tmgwr_agent.core.agent import TMGWRAgent

    path = maze_file(maze) if maze else maze_file()
    m = Maze.from_file(path)
    world = GridWorld(m, goal="G", seed=seed)
    agent = TMGWRAgent(m, np.random.default_rng(seed))
    agent.set_goal(world.goal, world.goal_observation())
    obs, _ = world.reset()
    agent.begin_episode(obs, world.cell)
    times = []
    t0 = 0.0
    for n in range(warmup + steps):
        if n == warmup:
            t0 = time.perf_counter()
        t = time.perf_counter()
        a = agent.act()
        obs, _, terminated, truncated, info = world.step(a)
        agent.observe(obs, info)
        if terminated or truncated:
            obs, _ = world.reset()
            agent.begin_episode(obs, world.cell)
        if n >= warmup:
            times.append(time.perf_counter() - t)
    seconds = time.perf_counter() - t0
    return {"steps": steps, "warmup": warmup, "seed": seed, "seconds": round(seconds, 3),
            "steps_per_s": round(steps / seconds, 1),
            "step_us_median": round(1e6 * statistics.median(times), 1)}


# ------------------------------------------------------------------------------ all
def run(args=None) -> dict:
    """(a), (b), (c) in one run; ``args`` may carry ``ring_laps``, ``graph_steps``,
    ``graph_seed``, ``maze``. Returns the dict the experiments bench merges."""
    laps = int(_opt(args, "ring_laps", 2000))
    steps = int(_opt(args, "graph_steps", 2000))
    seed = int(_opt(args, "graph_seed", 0))
    maze = _opt(args, "maze", None)
    say(f"graph bench: rings of 5 and 2 processes ({laps} laps), graph and in-process "
          f"({steps} steps, seed {seed})")
    r5 = ring(5, laps)
    say(f"  ring of 5: {r5['laps_per_s']} laps/s ({r5['hop_ms']} ms per hop)")
    r2 = ring(2, laps)
    say(f"  ring of 2: {r2['laps_per_s']} laps/s ({r2['hop_ms']} ms per hop)")
    g = graph_rate(steps, seed=seed, maze=maze)
    say(f"  graph: {g['steps_per_s']} steps/s ({g['step_us']} us a step: "
          f"{g['callbacks_us_per_step']} us in the nodes' callbacks, "
          f"{g['messaging_us_per_step']} us messaging and executors)")
    ip = in_process_rate(steps, seed=seed, maze=maze)
    say(f"  in-process: {ip['steps_per_s']} steps/s ({ip['step_us_median']} us median step)")
    ratio = g["steps_per_s"] / r5["laps_per_s"]
    out = {
        "ring5_laps_per_s": r5["laps_per_s"], "ring2_laps_per_s": r2["laps_per_s"],
        "graph_steps_per_s": g["steps_per_s"], "in_process_steps_per_s": ip["steps_per_s"],
        "graph_over_ring": round(ratio, 3), "target_graph_over_ring": 0.6,
        "ring5": r5, "ring2": r2, "graph": g, "in_process": ip,
        "cpus": os.cpu_count(), "load_avg_1min": round(os.getloadavg()[0], 2),
    }
    ring_lap_us = 1e6 / r5["laps_per_s"]
    say(f"  graph / ring = {ratio:.2f} (target >= 0.6). Per step: ring lap {ring_lap_us:.0f} "
          f"us; graph step {g['step_us']} us = callbacks "
          + ", ".join(f"{k} {v['mean_us']}" for k, v in g["callbacks"].items())
          + f" us + {g['messaging_us_per_step']} us messaging; in-process step "
            f"{ip['step_us_median']} us")
    return out


def main(argv: list[str] | None = None) -> int:
    import argparse
    ap = argparse.ArgumentParser(prog="python -m tmgwr_agent.graph.bench", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ring-laps", type=int, default=2000)
    ap.add_argument("--graph-steps", type=int, default=2000)
    ap.add_argument("--graph-seed", type=int, default=0)
    ap.add_argument("--maze")
    ap.add_argument("--json", help="also write the result here")
    args = ap.parse_args(argv)
    result = run(args)
    text = json.dumps(result, indent=2)
    if args.json:
        Path(args.json).write_text(text + "\n")
    say("BENCH " + json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
