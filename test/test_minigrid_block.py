"""After a block in MiniGrid (issue 26): remembered walls are doubted while stuck.

Without a lattice (MiniGrid's turns and forward: core/frame.py) a remembered wall had no
option at all (``OptionRules._unplaced_options``), also while the agent's knowledge said
the goal could not be reached (stuck). When the block leaves only a way through a wall
that has opened, the agent then ran out of unknown moves and random-walked until it hit
the opening. Now a remembered wall is doubted while stuck as on a lattice: ``rho`` grows
with the steps since its bump up to the wall prior, and its successor is valued as
unknown space where the local forward model predicts it."""

import statistics

import numpy as np

from maze_sim.maze import Maze
from maze_sim.minigrid_world import MiniGridWorld
from maze_sim.worlds import parse_world
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.experiments.env_change import event_oracle, trial
from tmgwr_agent.experiments.parallel import trial_seeds
from tmgwr_agent.experiments.runner import run_episode
from tmgwr_agent.world_senses import world_senses

#: Event a blocks the right gap of the wall (row 3) and opens the left one (A).
GAPS = ("#########\n"
        "#S......#\n"
        "#.......#\n"
        "#A#####a#\n"
        "#......G#\n"
        "#########\n")


def _episode_after_the_block(maze_text: str, seed: int, trained: int):
    """A world built from ``maze_text`` and an agent trained there for ``trained``
    episodes (its route learnt), event a fired and the next episode begun."""
    world = MiniGridWorld(Maze.from_text(maze_text), "G", max_episode_steps=3000)
    agent = TMGWRAgent(world_senses(world), np.random.default_rng(seed))
    agent.set_goal(world.goal, world.goal_observation())
    for _ in range(trained):
        run_episode(world, agent)
    world.fire_event("a")
    obs, _ = world.reset()
    agent.begin_episode(obs)
    return world, agent


def _stuck_after_the_block(maze_text: str, seed: int):
    """An agent trained on ``maze_text`` until its route is learnt, then walked after
    event a until it is stuck (the known route broke and no link leads to the goal)."""
    world, agent = _episode_after_the_block(maze_text, seed, 6)
    for _ in range(200):
        obs, _, terminated, _, info = world.step(agent.act())
        agent.observe(obs, info)
        if agent.motivation._stuck or terminated:
            break
    assert agent.motivation._stuck
    return agent


def test_while_stuck_a_remembered_wall_has_an_option():
    """Trained, then blocked: once the agent is stuck, walls it bumped into have options
    (rho > 0, a successor worth U > 0; before: none, rho = 0 on every remembered wall)."""
    agent = _stuck_after_the_block(GAPS, 0)
    mo, m = agent.motivation, agent.map
    n = m.n
    walls = m.alive[:n, None] & mo.tried[:n] & (mo.bump_t[:n] >= 0)
    assert walls.any()
    doubted = walls & (mo.rho[:n] > 0.0)
    assert doubted.any()
    assert (mo.U[:n][doubted] > 0.0).all() or (mo.osucc[:n][doubted] >= 0).all()


def test_a_block_that_leaves_only_an_opened_wall_is_passed_in_few_steps():
    """Six trials of the env-change protocol on GAPS: the median first episode after the
    event stays within four times the oracle (before: over six times; the agent found the
    opening only by a random walk)."""
    maze, spec = Maze.from_text(GAPS), parse_world("minigrid")
    oracle = event_oracle(spec, maze, "a", "G")["oracle_steps"]
    steps = [trial("tmgwr", t, s, maze, "a", "G", to_optimal=False, world_spec=spec)["steps"]
             for t, s in enumerate(trial_seeds(0, 6))]
    assert None not in steps, steps
    assert statistics.median(steps) <= 4 * oracle, (steps, oracle)


def test_while_stuck_walls_known_before_the_break_are_doubted_alike():
    """Every remembered wall bumped before the route broke is as doubtful as any other
    (the wall prior; before: less the more recent its bump, so the walls nearest the
    opening, bumped last in training, were re-tested last), and a wall whose cell lies
    beyond the places the map and the goal span (the maze's outer wall) is not doubted
    (before: re-tested as unknown space as near the goal as the opening). Walls that lead
    only back to places the agent reaches: the next tests."""
    agent = _stuck_after_the_block(GAPS, 0)
    mo, m = agent.motivation, agent.map
    n, prior = m.n, mo.wall_prior()
    lo, hi = mo._known_extent(m)
    step = float(np.sqrt(mo.delta_sq.max()))
    reach = mo._reached(m)
    before = beyond = 0
    for i in np.flatnonzero(m.alive[:n]):
        for a in range(mo.n_primitives):
            if not (mo.tried[i, a] and 0 <= mo.bump_t[i, a] < mo.break_t):
                continue
            x = mo._predicted(m, np.array([i]), a)[0]
            if ((x < lo - 0.5 * step) | (x > hi + 0.5 * step)).any():
                beyond += 1
                assert mo.rho[i, a] == 0.0, (i, a, x)
            elif mo._leads_on(m, x[None, :], reach, step)[0]:    # else no way round
                before += 1
                assert mo.rho[i, a] == prior, (i, a, mo.rho[i, a], prior)
    assert before > 0 and beyond > 0


def test_the_place_a_broken_move_led_to_is_closed():
    """The move that broke the route (a move made before that bumps now) led to a node:
    without a lattice that place is what closed, terminal in Eq. 5 (before: only a
    lattice cell closed, and the node before the block kept its potential through the
    broken link, so the agent bumped into the block again)."""
    agent = _stuck_after_the_block(GAPS, 0)
    mo, m = agent.motivation, agent.map
    n = m.n
    broke = np.argwhere(m.alive[:n, None] & (mo.bump_t[:n] == mo.break_t))
    assert len(broke)
    closed = mo.closed_cells(n)
    for i, a in broke:
        assert not mo.lattice[a]
        j = mo.succ[i, a]
        assert j >= 0 and closed[j], (i, a, j)


def test_an_untried_move_into_a_known_linked_place_is_worth_that_place():
    """An untried move whose predicted successor is the place of a live node that the
    map links with the move's node is valued by that node's potential (``osucc``), not
    as unknown space (before: every untried move without a lattice was unknown space,
    and the agent turned through the headings it knew)."""
    agent = _stuck_after_the_block(GAPS, 0)
    mo, m = agent.motivation, agent.map
    n = m.n
    half = 0.5 * np.sqrt(mo.delta_sq[mo.delta_sq > 0.0].min())
    turns = mo._turns(m)                       # a turn needs no link (the test below)
    placed = 0
    for i in np.flatnonzero(m.alive[:n]):
        for a in range(mo.n_primitives):
            q = mo.osucc[i, a]
            if mo.tried[i, a] or q < 0:
                continue
            placed += 1
            x = mo._predicted(m, np.array([i]), a)[0]
            assert np.linalg.norm(x - m.w[q]) < half
            assert a in turns or q in m.out[i] or i in m.out[q]
            assert mo.U[i, a] == 0.0 and mo.rho[i, a] > 0.0
    assert placed > 0


def test_in_a_training_episode_an_untried_move_into_a_known_place_is_unknown_space():
    """Trained, in an episode whose known route has not broken: an untried move whose
    predicted successor is the place of a live node linked with its node is valued as
    unknown space (``U > 0``, no ``osucc``), so the look round that training pays for
    goes on (before: it was worth that place in every episode, and the agent kept the
    first route it found, taking more episodes to learn a shortest one)."""
    world = MiniGridWorld(Maze.from_text(GAPS), "G", max_episode_steps=3000)
    agent = TMGWRAgent(world_senses(world), np.random.default_rng(0))
    agent.set_goal(world.goal, world.goal_observation())
    for _ in range(6):
        run_episode(world, agent)
    obs, _ = world.reset()
    agent.begin_episode(obs)
    mo, m = agent.motivation, agent.map
    n = m.n
    mo.refresh_options(m, n)
    assert not mo.broken
    known = 0
    for i in np.flatnonzero(m.alive[:n]):
        for a in np.flatnonzero(~mo.lattice):
            if mo.tried[i, a] or mo.rho[i, a] <= 0.0:
                continue
            x = mo._predicted(m, np.array([i]), int(a))
            if x is None or mo._known_place(m, x, np.array([i]))[0] < 0:
                continue
            known += 1
            assert mo.osucc[i, a] == -1 and mo.U[i, a] > 0.0, (i, a, mo.osucc[i, a])
    assert known > 0


def test_after_the_break_an_untried_move_is_bounded_one_move_on():
    """Once the known route broke, an untried move into unknown space is worth ``V*
    gamma^h`` with h at least one move more than the distance bound of the successor the
    best primitive from it reaches (``_one_move_on``); some move's h is raised by it (a
    turn: its successor is as far from the goal as its node). Before: h was the distance
    bound alone, and every untried turn was worth the node's own bound, whichever way it
    turned."""
    agent = _stuck_after_the_block(GAPS, 0)
    mo, m = agent.motivation, agent.map
    n = m.n
    assert mo.broken
    mo._options_key = ()                       # a full pass, on the weights of now
    mo.refresh_options(m, n)
    step = _nearer(mo, m)
    tol = mo.goal_tolerance

    def bound(x):
        g = np.linalg.norm(x - mo.goal_x, axis=1)
        return np.where(g <= tol, 0.0, g / step)

    checked = raised = 0
    for i in np.flatnonzero(m.alive[:n]):
        for a in np.flatnonzero(~mo.lattice):
            if mo.tried[i, a] or mo.osucc[i, a] >= 0 or mo.U[i, a] <= 0.0:
                continue
            x = mo._predicted(m, np.array([i]), int(a))
            h0 = bound(x)[0]
            on = 1.0 + min(bound(mo._predicted(m, None, b, at=x))[0]
                           for b in range(mo.n_primitives))
            h = max(h0, on) if h0 > 0.0 else 0.0
            assert np.isclose(mo.U[i, a], mo.v_star * mo.gamma ** h), (i, a, h0, on)
            checked += 1
            raised += on > h0 + 1e-9
    assert checked > 0 and raised > 0


def _nearer(mo, m) -> float:
    """The most one remembered move (last try moved it, both nodes alive) brought the
    agent nearer the goal sensation, at most the longest step."""
    n, longest = m.n, float(np.sqrt(mo.delta_sq.max()))
    dist = np.linalg.norm(m.w[:n] - mo.goal_x, axis=1)
    most = -np.inf
    for k in np.flatnonzero(m.alive[:n]):
        for a in range(mo.n_primitives):
            j = mo.succ[k, a]
            if mo.tried[k, a] and mo.bump_t[k, a] < 0 and 0 <= j < n and j != k \
                    and m.alive[j]:
                most = max(most, dist[k] - dist[j])
    return min(most, longest) if most > 0.0 else longest


def test_after_the_break_the_bound_counts_the_steps_that_lead_on():
    """Once the known route broke, the bound of an untried move's steps divides the
    distance by the most one of the agent's moves brought it nearer the goal
    (``_nearer``), not by the longest step: a turn has the longest step in MiniGrid's
    sensation and brings the goal no nearer. Before: the longest step, and every place
    looked nearer the goal than it is."""
    agent = _stuck_after_the_block(GAPS, 0)
    mo, m = agent.motivation, agent.map
    n = m.n
    mo._options_key = ()
    mo.refresh_options(m, n)
    longest, nearer = float(np.sqrt(mo.delta_sq.max())), _nearer(mo, m)
    assert 0.0 < nearer < longest
    assert np.isclose(mo._nearer(m, longest), nearer)
    checked = 0
    for i in np.flatnonzero(m.alive[:n]):
        for a in np.flatnonzero(~mo.lattice):
            if mo.tried[i, a] or mo.osucc[i, a] >= 0 or mo.U[i, a] <= 0.0:
                continue
            x = mo._predicted(m, np.array([i]), int(a))
            g = np.linalg.norm(x - mo.goal_x, axis=1)[0]
            if g <= mo.goal_tolerance:
                continue
            assert mo.U[i, a] <= mo.v_star * mo.gamma ** (g / nearer) * (1 + 1e-9), (i, a)
            checked += 1
    assert checked > 0


#: GAPS with a pillar in the start's room: once the route broke, the pillar's cell is
#: walled in by places the agent reaches, so opening it would lead nowhere new.
PILLAR = ("#########\n"
          "#S......#\n"
          "#...#...#\n"
          "#.......#\n"
          "#A#####a#\n"
          "#......G#\n"
          "#########\n")


def test_while_stuck_a_wall_that_leads_only_back_has_no_option():
    """Stuck after the block: a remembered wall whose ways on, over places the map does
    not know (the affine forward model's moves), all end at places the agent reaches
    already is no way round and has no option (``_leads_on``); walls whose ways on reach
    a place beyond are doubted. Before: every remembered wall was doubted alike, and the
    agent bumped a pillar inside its own room from each of its sides."""
    agent = _stuck_after_the_block(PILLAR, 0)
    mo, m = agent.motivation, agent.map
    n = m.n
    mo._options_key = ()
    mo.refresh_options(m, n)
    reach = mo._reached(m)
    step = float(np.sqrt(mo.delta_sq.max()))
    lo, hi = mo._known_extent(m)
    closed = doubted = 0
    for i in np.flatnonzero(m.alive[:n]):
        for a in range(mo.n_primitives):
            if not (mo.tried[i, a] and 0 <= mo.bump_t[i, a] < mo.break_t):
                continue
            x = mo._predicted(m, np.array([i]), a)
            if ((x < lo - 0.5 * step) | (x > hi + 0.5 * step)).any():
                continue
            if mo._leads_on(m, x, reach, step)[0]:
                doubted += 1
                assert mo.rho[i, a] > 0.0, (i, a)
            else:
                closed += 1
                assert mo.rho[i, a] == 0.0, (i, a, x)
    assert closed > 0 and doubted > 0


def test_after_the_break_moves_are_predicted_by_the_affine_forward_model():
    """Once the known route broke, a move's successor is predicted by the affine fit over
    the agent's moves (``_affine``), which MiniGrid's moves obey (a forward steps along
    the heading the sensation holds: ``w + (w_3, w_2, 0, 0)`` in its scaled units): the
    forward predicted from every live node lies within a quarter step of where it truly
    leads. Before: the nearest node whose forward moved predicted it, and where that
    node faced another way the prediction went off the heading."""
    from maze_sim.minigrid_world import FORWARD
    agent = _stuck_after_the_block(GAPS, 0)
    mo, m = agent.motivation, agent.map
    n = m.n
    assert mo.broken and mo._affine(m, FORWARD) is not None
    rows = np.flatnonzero(m.alive[:n])
    w = m.w[rows]
    truth = w + np.stack([w[:, 3], w[:, 2], 0 * w[:, 0], 0 * w[:, 0]], axis=1)
    x = mo._predicted(m, rows, FORWARD)
    quarter = 0.25 * np.sqrt(mo.delta_sq[FORWARD])
    assert (np.linalg.norm(x - truth, axis=1) < quarter).all()


#: A long wall (column 4) between the start's corridor and the goal's room: event a
#: blocks its gap at the top and opens one at the bottom (A), so the agent tests the
#: wall cell by cell on its way down, and meets those cells again from below.
LONG_WALL = ("#######\n"
             "#G..a.#\n"
             "#...#.#\n"
             "#...#.#\n"
             "#...#S#\n"
             "#...#.#\n"
             "#...#.#\n"
             "#...A.#\n"
             "#######\n")

#: MiniGrid's headings as (row, col) steps (0 east, 1 south, 2 west, 3 north).
HEADING = ((0, 1), (1, 0), (0, -1), (-1, 0))


def _after_the_block(maze_text: str, seed: int):
    """The post-block episode of an agent trained on ``maze_text``: the cells its
    forwards bumped into (in order, with the heading) and the agent at the end."""
    world, agent = _episode_after_the_block(maze_text, seed, 8)
    bumps = []
    for _ in range(400):
        row, col, h = world.pose
        obs, _, terminated, _, info = world.step(agent.act())
        agent.observe(obs, info)
        if info.bumped:
            bumps.append(((row + HEADING[h][0], col + HEADING[h][1]), h))
        if terminated:
            break
    return bumps, agent


def test_after_the_break_a_cell_bumped_from_one_side_is_shut_from_the_others():
    """Once the route broke, a place the agent bumped into is shut, and so is every place
    the turns (moves that never bumped) join with it (``_shut_places``): no forward
    after the break bumps again into a cell it bumped into from another heading. Before:
    the headings put those places far apart in sensation, and the agent, having tested
    the wall's cells from the side, bumped into one of them again from below after it
    passed the opening."""
    again = 0
    for seed in range(6):
        bumps, agent = _after_the_block(LONG_WALL, seed)
        seen = {}
        for cell, h in bumps:
            again += cell in seen and seen[cell] != h
            seen[cell] = h
        assert agent.motivation.broken
    assert again == 0


def test_after_the_break_an_untried_turn_into_a_known_place_is_worth_it_unlinked():
    """Once the known route broke, an untried turn (a primitive that never bumped and,
    repeated, comes back where it started: ``_turns``) whose predicted successor is the
    place of a live node is valued by that node's potential (``osucc``), whether or not
    the map links the two; some such pair is unlinked. Before: only a linked place
    counted, and an untried turn at a cell whose headings the agent had met by different
    ways was unknown space, so the agent turned a full circle through them."""
    world, agent = _episode_after_the_block(LONG_WALL, 0, 8)
    for _ in range(20):                        # the route broke; the wall is being tested
        obs, _, terminated, _, info = world.step(agent.act())
        agent.observe(obs, info)
        assert not terminated
    mo, m = agent.motivation, agent.map
    n = m.n
    assert mo.broken
    mo._options_key = ()                       # a full pass, on the weights of now
    mo.refresh_options(m, n)
    turns = mo._turns(m)
    assert turns
    half = 0.5 * np.sqrt(mo.delta_sq[mo.delta_sq > 0.0].min())
    unlinked = 0
    for i in np.flatnonzero(m.alive[:n]):
        for a in turns:
            if mo.tried[i, a]:
                continue
            x = mo._predicted(m, np.array([i]), a)[0]
            d = np.linalg.norm(m.w[:n] - x, axis=1)
            d[~m.alive[:n]] = np.inf
            q = int(np.argmin(d))
            if q == i or d[q] >= half:
                continue
            assert mo.osucc[i, a] == q and mo.U[i, a] == 0.0, (i, a, q, mo.osucc[i, a])
            unlinked += not (q in m.out[i] or i in m.out[q])
    assert unlinked > 0
