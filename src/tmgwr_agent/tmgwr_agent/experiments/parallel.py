"""Trials in parallel, with results independent of the number of processes.

Seeds: ``numpy.random.SeedSequence(seed).spawn(trials)`` gives one child sequence per
trial; every agent of trial ``t`` gets a generator from the *same* child (common random
numbers: the agents of one trial start from the same seed, as the paper compares them
trial by trial). Work items are ``(agent, trial)`` pairs; each runs in one process from
its own child seed only, and results are put back in ``(agent, trial)`` order, so the JSON
is byte-identical for ``--jobs 1`` and ``--jobs N`` (only CPU-time measurements differ).

``jobs`` defaults to the number of cores; ``jobs == 1`` runs in-process (no pool).
Workers warm the numba kernels of the TMGWR map (``cache=True``: compiled once, then
loaded from the cache) before any work item, so no compile time lands in a timing.
A tqdm progress bar on stderr counts finished work items.
"""

from __future__ import annotations

import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, Callable, Sequence

import numpy as np
from tqdm import tqdm


def default_jobs() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover -- not Linux
        return os.cpu_count() or 1


def trial_seeds(seed: int, trials: int) -> list[np.random.SeedSequence]:
    return np.random.SeedSequence(seed).spawn(trials)


_warm = False


def warm_up() -> None:
    """Compile (or load from the numba cache) every TMGWR kernel with a short run."""
    global _warm
    if _warm:
        return
    from maze_sim.maze import Maze
    from maze_sim.world import GridWorld
    from tmgwr_agent.experiments.agent_factory import make_agent
    from tmgwr_agent.experiments.runner import run_episode
    maze = Maze.from_text("#####\n#S..#\n#.#.#\n#..G#\n#####\n", source="<warm-up>")
    world = GridWorld(maze, "G", max_episode_steps=200)
    agent = make_agent("tmgwr", maze, np.random.default_rng(0))
    agent.set_goal(world.goal, world.goal_observation())
    for _ in range(3):
        run_episode(world, agent)
    run_episode(world, agent, learn=False, explore=False)
    _warm = True


def _call(fn: Callable, args: tuple) -> Any:
    return fn(*args)


def run_items(fn: Callable, items: Sequence[tuple], jobs: int | None = None,
              desc: str = "trials", progress: bool = True) -> list[Any]:
    """``[fn(*item) for item in items]``, in order, over ``jobs`` processes."""
    jobs = default_jobs() if not jobs or jobs < 1 else jobs
    show = progress and len(items) > 1
    results: list[Any] = [None] * len(items)
    if jobs == 1 or len(items) <= 1:
        warm_up()
        for i, item in enumerate(tqdm(items, desc=desc, file=sys.stderr, disable=not show,
                                      leave=False)):
            results[i] = fn(*item)
        return results
    with ProcessPoolExecutor(max_workers=min(jobs, len(items)), initializer=warm_up) as pool:
        futures = {pool.submit(_call, fn, item): i for i, item in enumerate(items)}
        for fut in tqdm(as_completed(futures), total=len(futures), desc=desc,
                        file=sys.stderr, disable=not show, leave=False):
            results[futures[fut]] = fut.result()
    return results


def agent_trials(fn: Callable, agents: Sequence[str], seed: int, trials: int,
                 extra: tuple = (), jobs: int | None = None, desc: str = "trials",
                 progress: bool = True) -> dict[str, list[Any]]:
    """Run ``fn(agent, trial_index, seed_sequence, *extra)`` for every agent and trial;
    returns ``{agent: [result of trial 0, 1, ...]}``."""
    seeds = trial_seeds(seed, trials)
    items = [(a, t, seeds[t]) + tuple(extra) for a in agents for t in range(trials)]
    flat = run_items(fn, items, jobs, desc, progress)
    return {a: flat[i * trials:(i + 1) * trials] for i, a in enumerate(agents)}
