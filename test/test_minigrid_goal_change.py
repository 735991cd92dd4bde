"""Goal changes in MiniGrid (issue 26): the sensation is (row, col, cos h, sin h), no
primitive makes a lattice step (core/frame.py), and a goal is a region of the four poses
of its cell. The world declares its goal radius halfway between the goal cell's
sensations and the nearest others; the agent counts a node whose weights lie in that
region as a goal node (``OptionRules.sensed_goal``), so a goal moved to a place the map
knows is planned for at once; a move whose link aged out keeps an option into the node it
led to (``OptionRules._unplaced_options``). The region of an earlier goal where an episode
ended is terminal as a whole (``OptionRules._terminal_regions``), and an untried move is
valued from the successor a local forward model predicts (``OptionRules._predicted``)."""

import math

import numpy as np
from small_mazes import SMALL

from maze_sim.maze import Maze
from maze_sim.minigrid_world import FORWARD, HEADING_STEP, MiniGridWorld, PoseSensation
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.core.outcome import Outcome
from tmgwr_agent.experiments.runner import run_episode
from tmgwr_agent.world_senses import world_senses


def trained(goal: str = "G", episodes: int = 12, seed: int = 0):
    """A default agent trained on ``goal`` of SMALL in MiniGrid, and its world."""
    world = MiniGridWorld(Maze.from_text(SMALL), goal, max_episode_steps=3000)
    agent = TMGWRAgent(world_senses(world), np.random.default_rng(seed))
    agent.set_goal(world.goal, world.goal_observation())
    for _ in range(episodes):
        run_episode(world, agent)
    return world, agent


def cell_of(agent, i):
    """The maze cell of node i's weights."""
    w = agent.map.w[i] / agent.preprocessor.gain
    return int(round(w[0])), int(round(w[1]))


def test_the_goal_radius_tells_the_goal_cell_apart_halfway():
    """Every pose at the goal cell lies within the radius of the goal sensation, every pose
    elsewhere beyond it, and the radius lies as far from the first (1) as from the nearest
    of the others (sqrt 2)."""
    world = MiniGridWorld(Maze.from_text(SMALL), "G")
    tol, goal = world.goal_tolerance, world.goal_observation()
    assert world_senses(world).goal_tolerance == tol == PoseSensation.GOAL_TOLERANCE
    assert math.isclose(tol - 1.0, math.sqrt(2.0) - tol)
    rows, cols = world.walls.shape
    for r in range(rows):
        for c in range(cols):
            for h in range(len(HEADING_STEP)):
                d = np.linalg.norm(PoseSensation.sensation(r, c, h) - goal)
                assert (d <= tol) == ((r, c) == world.goal), (r, c, h, d)


def test_a_goal_moved_to_a_place_the_map_knows_is_represented_at_once():
    """Trained on G, the map holds nodes at goal 1's cell; when the goal moves there they
    are the goal nodes from the first solve (R = 1 on them alone), before any episode
    ends there (before: R = 0 everywhere until one did, and the agent random-walked)."""
    world, agent = trained()
    m = agent.map
    target = world.check_goal("1")
    there = [i for i in np.flatnonzero(m.alive[: m.n]) if cell_of(agent, i) == target]
    assert there, "the training never visited goal 1's cell"
    world.set_goal("1", keep_previous=True)
    agent.set_goal(world.goal, world.goal_observation())
    obs, _ = world.reset()
    agent.begin_episode(obs)
    mo = agent.motivation
    assert not mo.lattice.any()                      # the goal without a lattice
    goal_nodes = np.flatnonzero(mo.R[: m.n] > 0)
    assert mo.goal_node in goal_nodes.tolist()
    assert sorted(goal_nodes.tolist()) == sorted(there)
    np.testing.assert_array_equal(mo.R[goal_nodes], 1.0)
    assert mo.V[agent.winner] > 0.0                  # a route is planned from S


def test_after_goal_changes_no_episode_ends_at_the_previous_goal():
    """Goals G -> 1 -> 2 (the previous goal stays terminal; neither shortest path passes
    it), three trained agents: every episode after each change ends at the current goal,
    the first within twice the world's oracle (before: the moved goal was unknown to the
    map until an episode happened to end there)."""
    for seed in range(3):
        world, agent = trained(episodes=10, seed=seed)
        for goal in ("1", "2"):
            world.set_goal(goal, keep_previous=True)
            agent.set_goal(world.goal, world.goal_observation())
            oracle = world.shortest_path_length()
            for k in range(4):
                ep = run_episode(world, agent)
                assert ep.reached_goal and not ep.reached_previous_goal, (seed, goal, k, ep)
                if k == 0:
                    assert ep.steps <= 2 * oracle, (seed, goal, ep.steps, oracle)


def test_a_move_whose_link_aged_out_keeps_an_option_into_where_it_led():
    """A move from i to j whose link the map deletes (by age) is neither known (no link)
    nor untried: it keeps an option into j with rho 1, as on a lattice; while the link
    stands it has none."""
    world, agent = trained(episodes=6)
    m, mo = agent.map, agent.motivation
    n = m.n
    pairs = [(i, a, int(mo.succ[i, a])) for i in range(n) for a in range(mo.n_primitives)
             if m.alive[i] and mo.tried[i, a] and mo.bump_t[i, a] < 0
             and mo.succ[i, a] not in (-1, i) and i != agent.winner
             and (m.out[i] == mo.succ[i, a]).any()]
    assert pairs
    i, a, j = pairs[len(pairs) // 2]
    mo.update(m)
    assert mo.rho[i, a] == 0.0 and mo.osucc[i, a] == -1      # known: its link
    s = int(np.flatnonzero(m.out[i] == j)[0])
    m.out[i, s], m.E[i, s] = -1, 0.0                          # the link ages out
    m.rebuild_in_links()
    m.version += 1
    m.log.touch(np.array([i, j]))
    mo.update(m)
    assert mo.rho[i, a] == 1.0 and mo.osucc[i, a] == j


def moved_twice(seed: int = 0):
    """Trained on G, then 5 episodes to goal 1, then the goal moved to 2 (goal 1, the
    previous goal, stays terminal): the world, the agent at the start of an episode and
    goal 1's sensation in the map's units."""
    world, agent = trained(episodes=10, seed=seed)
    world.set_goal("1", keep_previous=True)
    agent.set_goal(world.goal, world.goal_observation())
    for _ in range(5):
        run_episode(world, agent)
    old = agent.preprocessor.goal_features(world.goal_observation())
    world.set_goal("2", keep_previous=True)
    agent.set_goal(world.goal, world.goal_observation())
    obs, _ = world.reset()
    agent.begin_episode(obs)
    return world, agent, old


def region_nodes(agent, x):
    """The live nodes within the goal radius of sensation x (map units)."""
    m, mo = agent.map, agent.motivation
    d = m.w[: m.n] - x
    return np.flatnonzero(m.alive[: m.n] & (np.einsum("ij,ij->i", d, d)
                                             <= mo.goal_tolerance ** 2))


def forget_move(agent, i, a):
    """The outcome memory as if primitive a had never been taken from node i, and the map
    without the link that move made (a known place linked with i would value the move by
    that place, ``OptionRules._known_place``)."""
    mo, m = agent.motivation, agent.map
    j = mo.succ[i, a]
    mo.tried[i, a], mo.succ[i, a], mo.bump_t[i, a] = False, -1, -1
    mo._dirty.add(int(i))
    s = np.flatnonzero(m.out[i] == j) if j >= 0 else []
    if len(s):
        m.out[i, s], m.E[i, s] = -1, 0.0
        m.rebuild_in_links()
        m.version += 1
        m.log.touch(np.array([i]))


def test_an_old_goal_ends_episodes_in_its_whole_region():
    """After the goal moved on, every node in the previous goal's region is terminal
    (absorbing in Eq. 5), also those of headings no episode ended at (before: only the
    flagged node, and a link into another heading's node led into the old goal)."""
    for seed in range(2):
        world, agent, old = moved_twice(seed)
        m, mo = agent.map, agent.motivation
        inside = region_nodes(agent, old)
        assert m.terminal[inside].any() and not m.terminal[inside].all(), seed
        absorbing = mo._absorbing(m, m.n)
        assert absorbing[inside].all(), (seed, inside, absorbing[inside])
        assert not absorbing[region_nodes(agent, mo.goal_x)].any()      # the goal's own


def test_an_untried_move_into_an_old_goal_has_no_option():
    """A forward move the outcome memory forgets, predicted by the local forward model into
    the previous goal's region, has no option (before: the optimistic U of unknown space,
    rho > 0, and the agent walked into the old goal); one into an ordinary place keeps
    its option."""
    world, agent, old = moved_twice(0)
    m, mo = agent.map, agent.motivation
    inside = set(region_nodes(agent, old).tolist())
    into = [i for i in np.flatnonzero(m.alive[: m.n])
            if mo.tried[i, FORWARD] and mo.bump_t[i, FORWARD] < 0
            and int(mo.succ[i, FORWARD]) in inside]
    other = [i for i in np.flatnonzero(m.alive[: m.n])
             if mo.tried[i, FORWARD] and mo.bump_t[i, FORWARD] < 0
             and int(mo.succ[i, FORWARD]) not in inside | {-1, i}
             and mo.R[mo.succ[i, FORWARD]] == 0.0 and not m.terminal[i]]
    assert into and other
    for i in (into[0], other[len(other) // 2]):
        forget_move(agent, i, FORWARD)
    mo.update(m)
    assert mo.rho[into[0], FORWARD] == 0.0 and mo.U[into[0], FORWARD] == 0.0
    assert mo.rho[other[len(other) // 2], FORWARD] > 0.0


def test_an_untried_move_is_valued_from_where_it_leads():
    """Untried forward moves next to the goal: the one the local forward model predicts
    into the goal region is worth a represented goal (h = 0, U = V*), one predicted
    elsewhere less (before: both were valued from the node itself, one step short of the
    goal, and looked alike)."""
    world, agent, _ = moved_twice(0)
    m, mo = agent.map, agent.motivation
    goal = set(region_nodes(agent, mo.goal_x).tolist())
    movers = [i for i in np.flatnonzero(m.alive[: m.n])
              if mo.tried[i, FORWARD] and mo.bump_t[i, FORWARD] < 0 and i not in goal]
    into = [i for i in movers if int(mo.succ[i, FORWARD]) in goal]
    assert into
    gain = agent.preprocessor.gain
    away = [i for i in movers if i not in into                 # a cell next to the goal's
            and abs(np.linalg.norm(m.w[i, :2] - mo.goal_x[:2]) - gain) < 0.01 * gain]
    assert away
    forget_move(agent, into[0], FORWARD)
    forget_move(agent, away[0], FORWARD)
    mo.update(m)
    assert mo.U[into[0], FORWARD] == mo.v_star
    assert 0.0 < mo.U[away[0], FORWARD] < mo.v_star


def test_a_region_the_agent_walks_on_from_is_forgotten():
    """An old goal's region stops being terminal once the agent acts from a node in it
    within an episode (the episode did not end there); its unflagged nodes are then
    ordinary again, the flagged ones stay flagged until the map clears them."""
    world, agent, old = moved_twice(1)
    m, mo = agent.map, agent.motivation
    inside = region_nodes(agent, old)
    loose = inside[~m.terminal[inside]]
    assert len(loose) and mo._absorbing(m, m.n)[loose].all()
    i = int(loose[0])
    mo.record(i, i, False, Outcome(action=0), m.w)         # a turn taken from i
    mo.update(m)
    absorbing = mo._absorbing(m, m.n)
    assert not absorbing[loose].any()
    assert (absorbing[inside] == m.terminal[inside]).all()
