"""The learnt frame checks its own lattice assumption (core/frame.py, "Is the forward model
a lattice?"): a primitive whose sensed displacement depends on where it is taken (MiniGrid's
forward and turns) is found inconsistent from the spread the forward model keeps; no rule
that places its successor is used for it (an untried pair of it is unknown space at a
distance no lattice measures), and with no consistent primitive the goal is where the agent
sensed it; on the grid the check never trips."""

import numpy as np
from small_mazes import SMALL

from maze_sim import GridWorld, Maze
from maze_sim.minigrid_world import MiniGridWorld
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.core.frame import LearntFrame, SensorFrame
from tmgwr_agent.core.motivation import MotivationConfig, MotivationEstimator
from tmgwr_agent.core.outcome import EPISODE_START, Outcome
from tmgwr_agent.core.sensorimotor_map import SensorimotorMap
from tmgwr_agent.world_senses import maze_senses, world_senses


def test_consistency_is_the_spread_against_half_the_mean_step():
    delta = np.array([[0.0, 1.0], [0.0, 0.0], [1.0, 0.0], [0.0, 0.0]])
    moves = np.array([5, 5, 5, 0])
    spread = np.array([0.2, 1.0, 0.5, 0.0])
    # a steady step, a step whose mean is 0 (a heading-dependent move), a spread of exactly
    # half the step (still consistent), a primitive never moved (nothing contradicts it)
    np.testing.assert_array_equal(LearntFrame.consistent(delta, moves, spread),
                                  [True, False, True, True])
    np.testing.assert_array_equal(LearntFrame.consistent(delta, moves, None), [True] * 4)
    np.testing.assert_array_equal(SensorFrame.lattice(4), [True] * 4)


def test_an_inconsistent_primitive_joins_no_basis():
    f = LearntFrame()
    delta = np.array([[0.0, 0.1], [0.1, 0.0], [0.001, 0.001]])
    moves = np.array([3, 3, 9])          # the inconsistent one is the most used
    f.refresh(delta, moves, L=0.1, spread=np.array([0.0, 0.0, 0.1]))
    assert f.chosen == (0, 1) and f.complete
    np.testing.assert_array_equal(f.lattice(3), [True, True, False])
    np.testing.assert_array_equal(LearntFrame().lattice(3), [True] * 3)   # before refresh


def moves_of(mo, w, steps):
    """Record ``steps`` (node, action, winner) moves on weights w, from an episode start."""
    mo.record(-1, steps[0][0], False, EPISODE_START, w)
    for node, a, winner in steps:
        mo.record(node, winner, False, Outcome(a), w)


def link_moves(m, steps):
    """The links of the moves ``steps`` (node, action, winner) in map m, as the map
    learns them (the outcome memory and the map agree)."""
    for node, _, winner in steps:
        if not (m.out[node] == winner).any():
            s = int(np.flatnonzero(m.out[node] < 0)[0])
            m.out[node, s], m.E[node, s] = winner, 1.0
    m.rebuild_in_links()
    m.version += 1
    m.log.invalidate()


def test_the_estimator_keeps_the_spread_and_drops_the_options_it_cannot_place():
    # a ring of four places; primitive 0 always steps +col (a lattice step), primitive 1
    # steps along the ring whichever way it faces (heading-dependent)
    w = 0.1 * np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 2.0]])
    mo = MotivationEstimator(MotivationConfig(), primitives=np.eye(2))
    mo.set_goal(w[4])
    ring = [(0, 0, 1), (1, 1, 2), (2, 1, 3), (3, 1, 0), (0, 1, 1)]
    moves_of(mo, w, ring)
    np.testing.assert_allclose(mo.spread()[0], 0.0, atol=1e-12)
    d = np.array([w[2] - w[1], w[3] - w[2], w[0] - w[3], w[1] - w[0]])
    np.testing.assert_allclose(mo.delta[1], d.mean(axis=0), atol=1e-12)
    np.testing.assert_allclose(mo.spread()[1], np.sqrt(((d - d.mean(axis=0)) ** 2).sum(1)
                                                       .mean()))
    m = SensorimotorMap(dim=2, action_dim=2)
    for x in w[:4]:
        m.step(x, None)
    link_moves(m, ring)
    mo.update(m)
    np.testing.assert_array_equal(mo.lattice, [True, False])
    assert mo.value_unknown
    # primitive 1 was taken from nodes 0-3: no option (its successor cannot be placed)
    assert not mo.rho[:4, 1].any() and mo.rho[:4, 0].any()
    # every primitive inconsistent: only untried pairs have options, into unknown space
    moves_of(mo, w, [(1, 0, 3), (3, 0, 1)])
    link_moves(m, [(1, 0, 3), (3, 0, 1)])
    mo.record(-1, 1, False, EPISODE_START, w)
    m.step(w[4], None)                     # a fifth node, nothing tried from it
    mo.update(m)
    np.testing.assert_array_equal(mo.lattice, [False, False])
    assert not mo.rho[:4][mo.tried[:4, :2]].any()
    # node 4 is the goal sensation itself: its moves lead off it, h counted from the
    # successor the local forward model predicts (the move of the nearest node that made it)
    np.testing.assert_allclose(mo.rho[4, :2], mo.rho_new)
    step = np.sqrt(mo.delta_sq.max())
    for a in range(2):
        x = mo._predicted(m, np.array([4]), a)[0]
        assert np.linalg.norm(x - w[4]) > 0.0
        np.testing.assert_allclose(mo.U[4, a],
                                   mo.v_star * mo.gamma ** (np.linalg.norm(x - w[4]) / step))
    assert (mo.osucc[: m.n, :2] == -1).all()
    # no episode ended at the goal, but node 4's weights lie in the goal region (the
    # goal sensation itself, tolerance 0): it represents the goal, R = 1 there alone
    assert mo.goal_node == 4
    np.testing.assert_array_equal(mo.R[: m.n], [0.0, 0.0, 0.0, 0.0, 1.0])
    # the spread travels with the outcome memory
    mo2 = MotivationEstimator(MotivationConfig(), primitives=np.eye(2))
    mo2.load_state_dict(mo.state_dict())
    np.testing.assert_array_equal(mo2.spread(), mo.spread())


def drive(world, agent, steps):
    agent.set_goal(world.goal, world.goal_observation())
    obs, _ = world.reset()
    agent.begin_episode(obs)
    for _ in range(steps):
        obs, _, terminated, truncated, info = world.step(agent.act())
        agent.observe(obs, info)
        if terminated or truncated:
            obs, _ = world.reset()
            agent.begin_episode(obs)


def test_minigrid_turns_and_forward_are_found_inconsistent():
    """Forward follows the heading and turns rotate it: no lattice. The goal nodes are the
    poses where the goal was sensed (R = 1 there, 0 elsewhere), and a tried pair has no
    option."""
    world = MiniGridWorld(Maze.from_text(SMALL), "G", max_episode_steps=500)
    agent = TMGWRAgent(world_senses(world), np.random.default_rng(0))
    drive(world, agent, 1500)
    mo, m = agent.motivation, agent.map
    assert (mo.moves > 0).all()
    np.testing.assert_array_equal(mo.lattice, [False, False, False])
    n = m.n
    seen = mo.goal_seen[:n] & m.alive[:n]
    assert seen.any() and mo.goal_node in np.flatnonzero(seen).tolist()
    goal = np.array(world.goal_observation()) * agent.preprocessor.gain
    assert np.abs(m.w[:n][seen][:, :2] - goal[:2]).max() < 0.05   # all at the goal cell
    np.testing.assert_array_equal(mo.R[:n], seen.astype(float))
    assert not mo.rho[:n][mo.tried[:n]].any()


def test_grid_moves_stay_a_lattice():
    world = GridWorld(Maze.from_text(SMALL), "G", seed=0, max_episode_steps=500)
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(0))
    drive(world, agent, 400)
    mo = agent.motivation
    assert (mo.moves > 0).all() and mo.lattice.all() and mo.value_unknown
    assert (mo.spread() < 0.1 * np.linalg.norm(mo.delta, axis=1)).all()
