"""The baseline agents against hand-computed cases of their equations (Eq. 8, Eq. 9 + 11,
the Dyna-Q+ bonus) and their behaviour on small mazes: Q-learning and Dyna-Q+ learn a
shortest path (they are real baselines), the model-based agent keeps bumping into a block
its hard-coded model does not know."""

import numpy as np
import pytest
from small_mazes import CORRIDOR, SMALL

from maze_sim import GridWorld, Maze
from maze_sim.world import StepInfo
from tmgwr_agent.baselines.dyna_q_plus import DynaQPlusAgent
from tmgwr_agent.baselines.model_based import ModelBasedAgent
from tmgwr_agent.baselines.q_learning import QLearningAgent
from tmgwr_agent.experiments.runner import (
    Caps,
    make_world,
    run_episode,
    set_goal,
    train_until_converged,
)

UP, DOWN, LEFT, RIGHT = range(4)



def info(cell, action, bumped=False, goal=False, step=1):
    return StepInfo(cell=cell, action=action, bumped=bumped, reached_goal=goal,
                    reached_previous_goal=False, step=step, episode=1)


def obs(cell):
    return np.array(cell, dtype=float)


# ------------------------------------------------------------------ Q-learning (Eq. 8)
def test_q_learning_one_update_per_reward_of_eq8():
    maze = Maze.from_text(CORRIDOR)
    ag = QLearningAgent(maze, np.random.default_rng(0))
    ag.set_goal((1, 5))
    ag.begin_episode(obs((1, 1)), (1, 1))
    # empty cell: Q = 0 + 0.39 * (-29 + 0.86 * 0 - 0) = -11.31
    ag.observe(obs((1, 2)), info((1, 2), RIGHT))
    assert ag.Q[1 * 7 + 1][RIGHT] == pytest.approx(-11.31)
    # wall: Q((1,2), up) = 0.39 * (-131 + 0.86 * max Q((1,2)) = 0) = -51.09
    ag.observe(obs((1, 2)), info((1, 2), UP, bumped=True))
    assert ag.Q[1 * 7 + 2][UP] == pytest.approx(-51.09)
    # bootstrapping from a non-zero successor: move left back to S, where
    # max Q(S) = 0 (three untried actions at 0): Q = 0.39 * (-29) again
    ag.observe(obs((1, 1)), info((1, 1), LEFT))
    assert ag.Q[1 * 7 + 2][LEFT] == pytest.approx(-11.31)
    # S -> (1,2) a second time: target -29 + 0.86 * max Q((1,2)) = -29 + 0.86 * 0
    ag.observe(obs((1, 2)), info((1, 2), RIGHT))
    assert ag.Q[1 * 7 + 1][RIGHT] == pytest.approx(-11.31 + 0.39 * (-29 - -11.31))
    # goal (terminal, bootstraps 0): from (1,4) right into G
    ag.begin_episode(obs((1, 4)), (1, 4))
    ag.observe(obs((1, 5)), info((1, 5), RIGHT, goal=True))
    assert ag.Q[1 * 7 + 4][RIGHT] == pytest.approx(0.39 * 88)


# ------------------------------------------------------------------ model-based (Eq. 9, 11)
def test_model_based_fixed_point_on_a_corridor():
    maze = Maze.from_text(CORRIDOR)
    ag = ModelBasedAgent(maze, np.random.default_rng(0))
    ag.set_goal((1, 5))
    for k in range(5):                       # cell k steps from the goal
        expected = -300.0 + 375.0 * 0.94 ** k    # -18 / (1 - 0.94) = -300; 75 + 300 = 375
        assert ag.value((1, 5 - k)) == pytest.approx(expected, abs=1e-6)
    # the greedy one-step look-ahead walks towards the goal
    ag.begin_episode(obs((1, 1)), (1, 1))
    assert ag.act(explore=False) == RIGHT


# ------------------------------------------------------------------ Dyna-Q+ bonus
def test_dyna_q_plus_planning_update_adds_kappa_sqrt_tau():
    maze = Maze.from_text(CORRIDOR)
    ag = DynaQPlusAgent(maze, np.random.default_rng(0), {"n_planning": 0, "kappa": 10.0})
    ag.set_goal((1, 5))
    ag.begin_episode(obs((1, 1)), (1, 1))
    ag.observe(obs((1, 2)), info((1, 2), RIGHT))          # t = 1: (S, right) tried
    for _ in range(8):                                     # t = 2..9: bumps at (1,2)
        ag.observe(obs((1, 2)), info((1, 2), UP, bumped=True))
    assert ag.t == 9
    q_before = ag.Q[1 * 7 + 1][RIGHT]
    assert q_before == pytest.approx(-11.31)
    # planning draws k = int(u * 8) over visited states [S, (1,2)] x 4 actions;
    # k = 3 is (S, right). Find a generator whose first draw selects it.
    seed = next(s for s in range(1000)
                if int(np.random.default_rng(s).random(1)[0] * 8) == 3)
    ag.rng = np.random.default_rng(seed)
    ag.plan(1)
    # model (S, right) -> (1,2), r = -29, tried at t = 1: tau = 9 - 1 = 8;
    # max Q((1,2)) = 0 (up is negative, the rest untried at 0)
    target = -29.0 + 10.0 * np.sqrt(8.0) + 0.86 * 0.0
    assert ag.Q[1 * 7 + 1][RIGHT] == pytest.approx(q_before + 0.39 * (target - q_before))
    assert ag.Q[1 * 7 + 1][RIGHT] == pytest.approx(-7.178234, abs=1e-6)
    # the bonus-free twin Q0 (read by the greedy probe) got the same update without it
    q0 = -11.31 + 0.39 * (-29.0 + 0.86 * 0.0 + 11.31)
    assert ag.Q0[1 * 7 + 1][RIGHT] == pytest.approx(q0)
    ag.Q[1 * 7 + 1] = [-100.0, -100.0, -100.0, 50.0]      # bonus-inflated: right
    ag.Q0[1 * 7 + 1] = [-1.0, -100.0, -100.0, -100.0]     # what it knows: up
    ag.begin_episode(obs((1, 1)), (1, 1))
    assert ag.act(explore=False) == UP                     # the probe reads Q0


# ------------------------------------------------------------------ behaviour
@pytest.mark.parametrize("cls", [QLearningAgent, DynaQPlusAgent])
def test_q_learning_and_dyna_q_plus_learn_a_shortest_path(cls):
    maze = Maze.from_text(SMALL)
    caps = Caps.for_maze(maze)
    world = make_world(maze, "G", caps)
    ag = cls(maze, np.random.default_rng(3))
    set_goal(world, ag, "G")
    conv = train_until_converged(world, ag, caps)
    assert conv.episodes is not None, f"{cls.__name__} did not converge in {conv.trained}"
    ep = run_episode(world, ag, learn=False, explore=False, max_steps=50)
    assert ep.reached_goal and ep.steps == 10


def test_model_based_keeps_bumping_after_a_block():
    maze = Maze.from_text(SMALL)
    world = GridWorld(maze, "G")
    ag = ModelBasedAgent(maze, np.random.default_rng(0))
    set_goal(world, ag, "G")
    assert run_episode(world, ag, learn=False, explore=False, max_steps=10).reached_goal
    world.fire_event("a")                     # (5, 3) becomes a wall
    o, _ = world.reset()
    ag.begin_episode(o, world.cell)
    bumps = 0
    for _ in range(60):
        o, _, term, _, inf = world.step(ag.act(explore=False))
        ag.observe(o, inf)
        bumps += inf.bumped
        assert not term
    assert world.cell == (5, 2) and bumps == 60 - 5   # 5 steps to (5,2), then bumps
