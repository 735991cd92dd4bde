"""A step's kernel calls, lean: :func:`kernels.map_step` (sensorimotor_map.py,
``SensorimotorMap.step``) takes the map's hyperparameters in one array, writes the rows it
changed into a buffer the map keeps and appends them to the change log itself when they
fit, as ``RowLog.touch`` would; :func:`kernels.sensed_motion` takes the two sensations;
:func:`kernels.eq6_choices` computes each choice's term once. The log, the map and the
motion statistics come out as the Python path makes them."""

import re

import numpy as np

from maze_sim import GridWorld, Maze
from maze_sim.maze import maze_file
from tmgwr_agent.core import kernels
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.core.sensorimotor_map import STEP_PARAMETERS, RowLog
from tmgwr_agent.world_senses import maze_senses

MAP = ("w", "c", "h", "alive", "out", "E", "a", "age", "terminal", "inn", "motion")


class PythonLog(RowLog):
    """A log whose buffer has no room for the kernel: every row goes through touch."""

    def buffer(self):
        return np.empty(0, dtype=np.int64), self._len


def test_the_kernel_logs_the_rows_touch_would_log():
    maze = Maze.from_file(maze_file())
    agents, worlds = [], []
    for log in (RowLog(), PythonLog()):
        agent = TMGWRAgent(maze_senses(), np.random.default_rng(3))
        agent.map.log = log
        world = GridWorld(maze, "G", seed=0, max_episode_steps=300)
        agent.set_goal(world.goal, world.goal_observation())
        agent.begin_episode(world.reset()[0])
        agents.append(agent)
        worlds.append(world)
    for _ in range(1500):
        acts = [agent.act() for agent in agents]
        assert acts[0] == acts[1]
        for agent, world in zip(agents, worlds):
            obs, _, terminated, truncated, info = world.step(acts[0])
            agent.observe(obs, info)
            if terminated or truncated:
                agent.begin_episode(world.reset()[0])
        f, g = (agent.map for agent in agents)
        assert (f.log.pos, f.log._start) == (g.log.pos, g.log._start)
        assert np.array_equal(f.log.since(f.log._start), g.log.since(g.log._start))
        assert f.version == g.version and f.a_place == g.a_place
    for name in MAP:
        assert np.array_equal(getattr(f, name), getattr(g, name)), name


def test_the_step_parameters_are_the_maps():
    m = TMGWRAgent(maze_senses(), np.random.default_rng(0),
                   {"eps_b": 0.25, "max_age": 77, "link_rule": "literal"}).map
    assert m._hp.tolist() == [float(getattr(m, k)) for k in STEP_PARAMETERS] + [0.0]
    assert m._hp[STEP_PARAMETERS.index("eps_b")] == 0.25
    assert m._hp[STEP_PARAMETERS.index("max_age")] == 77.0


def test_sensed_motion_adds_a_finite_displacement_only():
    motion = np.zeros((2, 4))
    x, before = np.array([1.0, 2.0]), np.full(2, np.nan)
    assert kernels.sensed_motion(motion, 0, x, before, 0.95) == (0.95, -1)
    assert not motion.any()
    _, count = kernels.sensed_motion(motion, 1, x, np.array([1.0, 1.0]), 0.95)
    assert count == 1 and motion[1].tolist() == [1.0, 0.0, 1.0, 0.0]
    _, count = kernels.sensed_motion(motion, 1, x, np.array([1.0, 0.0]), 0.95)
    assert count == 2 and motion[1].tolist() == [2.0, 0.0, 1.5, 0.5]


def test_eq6_ranks_each_choice_once():
    """One call of the term per choice (the second pass reads the first's values): the
    compiled kernel has one call site of ``_eq6_term``."""
    from test_kernels_refcount import compiled
    n, K, P = 6, 4, 4
    rng = np.random.default_rng(0)
    out = np.where(rng.random((n, K)) < 0.6, rng.integers(0, n, (n, K)), -1)
    E, A, V = np.where(out >= 0, 0.9, 0.0), rng.random((n, K, 2)), rng.random(n + 1)
    U, rho = rng.random((n, P)), rng.random((n, P))
    osucc, onb, ong = np.full((n, P), -2), np.ones((n, P, P), np.int64), np.full((n, P, P), 0.5)
    slots, acts, took = (np.empty(K + P, t) for t in (np.int64, np.int64, bool))
    fn = compiled("eq6_choices", out[1], E[1], A[1], V, 1, False, 0.1, 0.97, U, rho, osucc,
                  onb, ong, rng.random((P, 2)), slots, acts, took)
    assert len(re.findall(r"call [^\n]*_eq6_term", fn)) == 1


def test_a_converged_update_is_one_kernel_call(monkeypatch):
    """Once the map has converged, the estimator's update of most steps is one kernel call
    (kernels.converged_step: the preparation of the rows that changed and the incremental
    solve, motivation.py's ``_fused_update``), not one per stage."""
    maze = Maze.from_file(maze_file())
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(3))
    world = GridWorld(maze, "G", seed=0, max_episode_steps=300)
    agent.set_goal(world.goal, world.goal_observation())
    agent.begin_episode(world.reset()[0])

    def run(steps):
        for _ in range(steps):
            obs, _, terminated, truncated, info = world.step(agent.act())
            agent.observe(obs, info)
            if terminated or truncated:
                agent.begin_episode(world.reset()[0])
    run(8000)
    calls, per_update = [], []
    for name, kernel in kernels.KERNELS.items():
        def counted(*args, kernel=kernel, name=name):
            calls.append(name)
            return kernel(*args)
        monkeypatch.setattr(kernels, name, counted)
    update = agent.motivation.update

    def counted_update(*args, **kw):
        calls.clear()
        result = update(*args, **kw)
        if agent.motivation.solved:
            per_update.append(tuple(calls))
        return result
    monkeypatch.setattr(agent.motivation, "update", counted_update)
    run(500)
    assert per_update.count(("converged_step",)) > len(per_update) // 2


def test_the_sensed_move_joins_the_step_call(monkeypatch):
    """A move that was not blocked adds its sensed displacement to the primitive's
    statistics once (``SensorimotorMap.motion``), in the step's own kernel call
    (kernels.map_step) when that makes the whole step: kernels.sensed_motion is called
    from Python only on the steps the map finishes in Python (an insertion, a row to
    widen, ...)."""
    calls = []
    sensed_motion = kernels.sensed_motion

    def counted(*args):
        calls.append(args[1])
        return sensed_motion(*args)
    monkeypatch.setattr(kernels, "sensed_motion", counted)
    maze = Maze.from_file(maze_file())
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(3))
    world = GridWorld(maze, "G", seed=0, max_episode_steps=300)
    agent.set_goal(world.goal, world.goal_observation())
    agent.begin_episode(world.reset()[0])
    moves = np.zeros(len(agent.map.motion))
    for _ in range(3000):
        obs, _, terminated, truncated, info = world.step(agent.act())
        agent.observe(obs, info)
        moves[info.action] += not info.bumped
        if terminated or truncated:
            agent.begin_episode(world.reset()[0])
    assert agent.map.motion[:, 0].tolist() == moves.tolist()
    assert 0 < len(calls) < moves.sum() / 4
