"""Exploration with purpose (motivation.py, Eq. 5'): the agent plans to what its map does
not know. Behaviour on small mazes (a block whose detour was never walked, a shortcut that
opens, a goal moved into space never visited), the paper's agent unchanged by it, and the
exploration state as plain data that continues a run exactly."""

import numpy as np
import pytest

from maze_sim import GridWorld, Maze
from maze_sim.maze import ACTION_VECTORS
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.experiments.agent_factory import make_agent
from tmgwr_agent.experiments.runner import (
    Caps,
    greedy_optimal,
    make_world,
    run_episode,
    set_goal,
    train_until_converged,
)
from tmgwr_agent.world_senses import maze_senses

# A block on the only short way; the detour over the top (14 steps against 10).
BLOCK = ("#########\n"
         "#S..#...#\n"
         "#.#.#.#.#\n"
         "#.#...#.#\n"
         "#.#####.#\n"
         "#...a..G#\n"
         "#########\n")
# A long corridor to G; a far side room (goal 1) behind a door never needed for G.
FAR = ("#####################\n"
       "#S.................G#\n"
       "#.###################\n"
       "#...................#\n"
       "###################.#\n"
       "#1..................#\n"
       "#####################\n")
# The way round (10 steps) and a wall that opens (event a) for a 6-step shortcut.
SHORTCUT = ("#######\n"
            "#S....#\n"
            "###A#.#\n"
            "#G....#\n"
            "#######\n")


def trained(text, goal="G", seed=0, spec="tmgwr", **overrides):
    maze = Maze.from_text(text)
    caps = Caps.for_maze(maze)
    world = make_world(maze, goal, caps)
    agent = make_agent(spec, maze, np.random.default_rng(seed), overrides)
    set_goal(world, agent, goal)
    conv = train_until_converged(world, agent, caps)
    assert conv.episodes is not None
    return world, agent


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_block_finds_the_detour_at_once(seed):
    world, agent = trained(BLOCK, seed=seed)
    world.fire_event("a")
    ep = run_episode(world, agent)
    # walk 7 to the block, bump, 1 back, detour of 14 from there at best: 22; the agent
    # may bump a few times while the blocked link's E falls, and maps what it never saw:
    # within twice the oracle (over seeds 0-7 the steps are 15-56, mean 35; before the
    # stale rule of Eq. 5' counted episodes, 28-56, mean 37)
    assert ep.reached_goal and ep.steps <= 2 * 22, ep.steps
    for _ in range(3):
        run_episode(world, agent)
    assert greedy_optimal(world, agent)


def test_goal_moved_into_unvisited_space_is_found_in_the_first_episode():
    """The goal node exists only once the goal is sensed; before that the options lead
    the agent, by the nearest plausible unknown, towards the goal sensation (no
    oscillation on the node most like the goal), and the next greedy path is shortest.
    Seeds whose training walk visited goal 1 do not test this and are passed over."""
    tested = 0
    for seed in range(40):
        if tested == 3:
            break
        world, agent = trained(FAR, seed=seed)
        x1 = agent.preprocessor.goal_features(
            np.array(world.maze.goal_cell("1"), dtype=float))
        if np.linalg.norm(agent.map.w[agent.map.nearest_by_weight(x1)] - x1) < 0.05:
            continue
        set_goal(world, agent, "1")
        assert agent.motivation.goal_node == -1         # not sensed yet: no goal node
        ep = run_episode(world, agent)
        assert ep.reached_goal and ep.steps <= 6 * world.shortest_path_length(), ep.steps
        run_episode(world, agent)
        assert greedy_optimal(world, agent)
        tested += 1
    assert tested == 3


def test_shortcut_is_found_when_the_remembered_wall_goes_stale():
    """A remembered wall whose other side is known and closer to the goal is trusted for
    ``stale_horizon`` episodes, then re-tested (Eq. 5', within the re-test budget): the
    shortcut is in the greedy path within 10 episodes in every trial (seeds 0-9: 1-6
    episodes). With no re-test budget the wall is never re-tested."""
    for seed in range(5):
        for budget, found_within in ((0.1, 10), (0.0, None)):
            world, agent = trained(SHORTCUT, seed=seed, stale_budget=budget)
            world.fire_event("a")
            assert world.shortest_path_length() == 6
            found = None
            for n in range(1, 16):
                run_episode(world, agent)
                if greedy_optimal(world, agent):
                    found = n
                    break
            if found_within is None:
                assert found is None, (seed, found)
            else:
                assert found is not None and found <= found_within, (seed, found)


def test_paper_agent_has_no_value_of_the_unknown():
    """``+paper`` is Eq. 1-7 as printed: no options in Eq. 5 or Eq. 6, the goal node is the
    node most like the goal even when the goal was never sensed, potentials only where a
    link path leads to the goal."""
    maze = Maze.from_text(FAR)
    world = GridWorld(maze, "G")
    agent = make_agent("tmgwr:paper", maze, np.random.default_rng(0))
    assert not (agent.motivation.value_unknown or agent.selector.try_untried
                or agent.selector.goal_search or agent.motivation.absorbing_terminals)
    agent.set_goal(world.goal, world.goal_observation())
    obs, _ = world.reset()
    agent.begin_episode(obs, world.cell)
    for _ in range(30):                                  # a few steps: most pairs untried
        obs, _, term, _, info = world.step(agent.act())
        agent.observe(obs, info)
        if term:
            break
    m, mo = agent.map, agent.motivation
    mo.update(m)                # at epsilon 1 the agent's steps did not solve Eq. 4-5
    assert mo.goal_node == m.nearest_by_weight(mo.goal_x)
    assert not mo.rho[: m.n].any()
    links = mo.links_of(m, agent.winner)
    assert len(links.targets) == m.out.shape[1]          # no virtual links
    np.testing.assert_array_equal(mo.V, mo.exploit(m))


def test_state_dict_continues_a_run_exactly():
    maze = Maze.from_text(BLOCK)
    a = TMGWRAgent(maze_senses(), np.random.default_rng(5))
    wa = GridWorld(maze, "G")
    a.set_goal(wa.goal, wa.goal_observation())
    for _ in range(3):
        run_episode(wa, a)
    st = a.state_dict()
    for part in st.values():
        assert all(isinstance(v, (np.ndarray, int, float)) for v in part.values())
    b = TMGWRAgent(maze_senses(), np.random.default_rng(0))
    b.map.load_state_dict(a.map.state_dict())
    b.load_state_dict(st)
    b.selector.rng.bit_generator.state = a.selector.rng.bit_generator.state
    b.winner = a.winner
    wb = GridWorld(maze, "G")
    b.set_goal(wb.goal, wb.goal_observation())
    a.set_goal(wa.goal, wa.goal_observation())
    assert [run_episode(wa, a).steps for _ in range(3)] == \
        [run_episode(wb, b).steps for _ in range(3)]


# ------------------------------------------------------------------ walk_while_novel
def test_walk_is_held_once_the_last_n_steps_found_nothing_new():
    """Hand-computed: with epsilon 1 the walk acts while each of the last N steps (N nodes
    acted from) could have found a new node; after N steps over known nodes only it is held
    (Eq. 6 acts), a new node or N held steps without one end the hold, and after the first
    goal the paper's Eq. 7 runs (never held)."""
    from tmgwr_agent.core.action_selector import ActionSelector, SelectorConfig
    from tmgwr_agent.core.outcome import Outcome
    sel = ActionSelector(np.random.default_rng(0), SelectorConfig(),
                         primitives=ACTION_VECTORS)   # eps_start 1
    move = Outcome(action=0)
    for node in (0, 1, 2):                  # three new nodes: N = 3, last new at step 3
        sel.record(node, move)
    assert (sel.n_acted, sel.steps, sel.last_new) == (3, 3, 3)
    assert sel.policy.explores()            # epsilon 1 and not stalled: the walk
    for k, node in enumerate((1, 2, 1)):    # steps 4-6 from known nodes
        assert not sel.walk_stalled(), k    # 0, 1, 2 steps without a new node
        sel.record(node, move)
    assert sel.walk_stalled()               # 3 = N steps found nothing new: held
    assert not sel.policy.explores()        # the draw is made and ignored: Eq. 6 acts
    sel.record(7, move)                     # a new node: N = 4, the walk again
    assert not sel.walk_stalled() and sel.policy.explores()
    for node in (0, 1, 2, 7):
        sel.record(node, move)
    assert sel.walk_stalled()
    for node in (0, 1, 2, 7):               # held N = 4 steps that found nothing either:
        sel.record(node, move)
    assert not sel.walk_stalled()           # the walk again, until a new node
    sel.record(9, move)
    for node in (0, 1, 2, 7, 9):
        sel.record(node, move)
    assert sel.walk_stalled()               # N = 5 steps without a new node: held
    sel.record(0, Outcome(action=0, goal_reached=True, episode_over=True))
    assert not sel.walk_stalled()           # after the first goal: Eq. 7 as printed
    paper = ActionSelector(np.random.default_rng(0), SelectorConfig(walk_while_novel=False),
                           primitives=ACTION_VECTORS)
    for node in (0, 0, 0, 0):
        paper.record(node, move)
    assert paper.policy.hold is None and paper.policy.explores()


def test_a_held_step_is_fixed_with_its_draw_made_ahead():
    """The draw made ahead (the graph's walk_next) and its use agree even when the hold
    changes in between (a new node recorded after the draw)."""
    from tmgwr_agent.core.action_selector import ActionSelector, SelectorConfig
    from tmgwr_agent.core.outcome import Outcome
    sel = ActionSelector(np.random.default_rng(0), SelectorConfig(), primitives=ACTION_VECTORS)
    move = Outcome(action=0)
    for node in (0, 1, 1, 0):               # N = 2, two steps without a new node
        sel.record(node, move)
    assert sel.walk_stalled()
    assert sel.policy.draw_ahead() is False     # held: the next step will not walk
    sel.record(5, move)                         # the hold ends after the draw ...
    assert not sel.walk_stalled()
    assert sel.policy.explores() is False       # ... but that step keeps its draw's hold
    assert sel.policy.explores() is True        # the next draw is not held


def test_large_maze_first_episode_is_not_a_blind_walk():
    """On a 116-cell braided maze whose goal the blind walk takes 4,000-28,000 steps to hit
    (seeds 0-5), the held walk reaches it in the first episode in a third of the steps or
    fewer, summed over four seeds (measured: 312-1348 a seed)."""
    from maze_sim.suite import suite
    maze = Maze.from_text(suite("braided:1", seed=3)[0].text)
    totals = {}
    for flag in (True, False):
        steps = 0
        for seed in range(4):
            world = GridWorld(maze, "G")
            agent = make_agent("tmgwr", maze, np.random.default_rng(seed),
                               {"walk_while_novel": flag})
            set_goal(world, agent, "G")
            ep = run_episode(world, agent, max_steps=200_000)
            assert ep.reached_goal
            steps += ep.steps
        totals[flag] = steps
    assert 3 * totals[True] < totals[False], totals
