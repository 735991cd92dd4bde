"""Compile the numba kernels once, into their on-disk cache: ``python -m tmgwr_agent.warmup``.

The kernels (:mod:`tmgwr_agent.core.kernels`) are compiled lazily, for the argument types
of their first call, and cached next to ``kernels.py`` (``__pycache__``, or under
``NUMBA_CACHE_DIR``). ``tools/bootstrap.sh`` runs this module after the colcon build so
that a node's first start loads them from the cache instead of compiling for tens of
seconds. It drives the real agent (the calls the nodes make, with the argument types they
pass) through a few episodes of a small maze, greedy ones included, until every kernel
has a compiled version. With the cache in place it only loads them (about a second).

Exit status 0 when every kernel is compiled, 1 otherwise (the kernels left are named).
"""

from __future__ import annotations

import argparse
import sys
import time


def warm_up(max_steps: int = 3000) -> list[str]:
    """Exercise the kernels through the agent until each one is compiled or cached;
    returns the names of those left."""
    import numpy as np

    from maze_sim.maze import Maze, generate_maze
    from maze_sim.world import GridWorld
    from tmgwr_agent.core import kernels
    from tmgwr_agent.core.agent import TMGWRAgent
    from tmgwr_agent.core.sensorimotor_map import MapSnapshot
    from tmgwr_agent.world_senses import maze_senses

    maze = Maze.from_text(generate_maze(13, 17, np.random.default_rng(0)), "<warm-up maze>")
    world = GridWorld(maze, "G", max_episode_steps=400, seed=0)
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(0))
    agent.set_goal(world.goal, world.goal_observation())
    steps = 0
    while steps < max_steps and kernels.uncached():
        obs, _ = world.reset()
        agent.begin_episode(obs, world.cell)
        explore = bool(world.episode % 2)      # greedy episodes reach Eq. 6
        for _ in range(400):
            obs, _, terminated, truncated, info = world.step(agent.act(explore=explore))
            agent.observe(obs, info)
            steps += 1
            if terminated or truncated:
                break
        # the motivation estimator's node solves Eq. 4-5 on a snapshot of the map
        if hasattr(MapSnapshot, "of"):
            agent.motivation.update(MapSnapshot.of(agent.map))
        # ... and sends the winner's links with its options as virtual links (the
        # in-process agent ranks them unbuilt); the bench's floor ranks links alone
        if agent.winner >= 0:
            links = agent.motivation.links_of(agent.map, agent.winner)
            kernels.best_links(links.targets, links.E, agent.motivation.V)
    # the free-space belief, read after a route broke (never in this static maze)
    agent.motivation.free_space_belief(agent.map, agent.map.n)
    # the map's node index, built from INDEX_MIN slots on (larger than this maze's map)
    from tmgwr_agent.core.node_index import NodeIndex
    NodeIndex().build(agent.map)
    return kernels.uncached()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tmgwr_agent.warmup",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--quiet", action="store_true", help="print nothing when all is cached")
    ap.add_argument("--prefix", default="", help="text put before each line printed")
    args = ap.parse_args(argv)
    from tmgwr_agent.core import kernels

    todo = kernels.uncached()
    if todo:
        print(f"{args.prefix}compiling the numba kernels (once, about "
              f"{kernels.COMPILE_SECONDS} s): {len(todo)} of {len(kernels.KERNELS)} not in "
              f"the cache {kernels.cache_dir()}", flush=True)
    t0 = time.perf_counter()
    kernels.quiet_compilation()                # this is the announced compile
    if todo:
        kernels.clear_cache()                  # all afresh, callees with their callers
    left = warm_up()
    dt = time.perf_counter() - t0
    if left:
        print(f"{args.prefix}numba kernels left uncompiled after the warm-up: "
              f"{', '.join(left)}", file=sys.stderr, flush=True)
        return 1
    if not args.quiet or todo:
        done = f"compiled and cached in {dt:.1f} s" if todo else "already cached"
        print(f"{args.prefix}numba kernels {done} ({kernels.cache_dir()})", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
