"""The incremental solution of Eq. 4-5' (prioritized sweeping, kernels.prioritized_sweep)
equals a full solve within vi_tol after random sequences of map edits, and the agent's
estimator, solving incrementally, keeps V equal to a full solve of each step's map."""

import numpy as np
import pytest

from tmgwr_agent.core import kernels
from tmgwr_agent.core.value_iteration import Options, solve

NONE = np.zeros(0, dtype=np.int64)    # no row list: changed_rows compares every row

GAMMA, BETA, TOL, FLOOR = 0.97, 0.8, 1e-4, 1e-150


def trained_on_default_maze(episodes):
    """(world, agent): the default agent on the default maze, goal G, trained for
    ``episodes`` episodes (seed 0)."""
    from maze_sim.maze import Maze
    from tmgwr_agent.experiments.agent_factory import make_agent
    from tmgwr_agent.experiments.runner import Caps, make_world, run_episode, set_goal
    from tmgwr_agent.experiments.scenarios import DEFAULT_MAZE

    maze = Maze.from_file(DEFAULT_MAZE)
    world = make_world(maze, "G", Caps.for_maze(maze))
    agent = make_agent("tmgwr", maze, np.random.default_rng(0))
    set_goal(world, agent, "G")
    for _ in range(episodes):
        run_episode(world, agent, max_steps=3000)
    return world, agent


def random_map(rng, n, K=4, P=4):
    out = np.where(rng.random((n, K)) < 0.6, rng.integers(0, n, (n, K)), -1)
    E = np.where(out >= 0, rng.uniform(0.3, 1.0, (n, K)), 0.0)
    R = np.where(rng.random(n) < 0.1, rng.random(n), 0.0)
    absorbing = rng.random(n) < 0.05
    alive = np.ones(n, bool)
    rho = np.where(rng.random((n, P)) < 0.2, rng.random((n, P)), 0.0)
    osucc = rng.choice(np.r_[-2, -1, np.arange(n)], size=(n, P))
    onb = np.where(rng.random((n, P, P)) < 0.5, rng.integers(0, n, (n, P, P)), -1)
    ong = rng.random((n, P, P))
    U = rng.random((n, P)) * 5
    return out, E, R, absorbing, alive, Options(U, rho, osucc, onb, ong)


def exact(out, E, R, absorbing, alive, o):
    """The fixed point of Eq. 4-5' (the numpy reference at a tolerance far below vi_tol)."""
    n = len(R)
    V, _ = solve(out, E, R, np.zeros(n + 1), BETA, GAMMA, 1e-13, FLOOR, 10**6, absorbing,
                 alive, o)
    return V


def edit(rng, out, E, R, o, n):
    """One random edit that keeps every node's sources (what the estimator sweeps
    incrementally; a removal makes it solve in full): a link added or its reliability
    changed up or down, a reward raised, an option's rho, U or successor changed.
    Returns the rows it touched."""
    i = int(rng.integers(n))
    kind = rng.integers(5)
    if kind == 0:
        free = np.flatnonzero(out[i] < 0)
        if len(free):
            out[i, free[0]] = rng.integers(n)
            E[i, free[0]] = rng.uniform(0.3, 1.0)
    elif kind == 1:
        s = np.flatnonzero(out[i] >= 0)
        if len(s):
            E[i, s[0]] = np.clip(E[i, s[0]] * rng.uniform(0.7, 1.3), 0.05, 1.0)
    elif kind == 2:
        R[i] = R[i] + rng.uniform(0.0, 0.5)
    else:
        a = int(rng.integers(o.rho.shape[1]))
        if o.rho[i, a] > 0.0:
            o.rho[i, a] = rng.uniform(0.05, 1.0)
        o.U[i, a] = rng.random() * 5
        if kind == 4:
            o.osucc[i, a] = rng.choice(np.r_[-2, -1, np.arange(n)])
    return [i]


@pytest.mark.parametrize("seed", range(10))
def test_incremental_equals_a_full_solve_after_random_edits(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 150))
    out, E, R, absorbing, alive, o = random_map(rng, n)
    V = exact(out, E, R, absorbing, alive, o)
    heap, pos, key = np.empty(n, np.int64), np.full(n, -1, np.int64), np.zeros(n)
    updates = 0
    for _ in range(40):
        seeds = np.array(sorted({i for _ in range(int(rng.integers(1, 4)))
                                 for i in edit(rng, out, E, R, o, n)}), dtype=np.int64)
        first, pred = kernels.predecessors(out, n, alive, o.osucc, o.onb)
        done = kernels.prioritized_sweep(out, E, R, V, n, GAMMA, TOL * (1 - GAMMA), FLOOR,
                                         absorbing, alive, o.U, o.rho, o.osucc, o.onb,
                                         o.ong, first, pred, seeds, len(seeds), 100 * n,
                                         heap, pos, key)
        assert done >= 0
        updates += done
        ref = exact(out, E, R, absorbing, alive, o)
        np.testing.assert_allclose(V[:n], ref[:n], rtol=TOL, atol=1e-12)
        assert (pos == -1).all()
    assert updates > 0


def removal(rng, out, E, R, absorbing, o, n):
    """One random edit that may lower values (what kernels.invalidate prepares for): a
    link removed or its E lowered or zeroed, a reward gone, a node made absorbing, an
    option gone. Returns the rows it touched."""
    i = int(rng.integers(n))
    kind = rng.integers(5)
    s = np.flatnonzero(out[i] >= 0)
    if kind == 0 and len(s):
        out[i, s[0]] = -1
        E[i, s[0]] = 0.0
    elif kind == 1 and len(s):
        E[i, s[0]] = 0.0 if rng.random() < 0.5 else E[i, s[0]] * rng.uniform(0.1, 0.9)
    elif kind == 2:
        R[i] = 0.0
    elif kind == 3:
        absorbing[i] = True
    else:
        o.rho[i] = 0.0
    return [i]


def full_ordered(out, E, R, absorbing, alive, o, n):
    """kernels.ordered_solve from V = 0 over every node; (V, updates)."""
    V = np.zeros(n + 1)
    first, pred = kernels.predecessors(out, n, alive, o.osucc, o.onb)
    heap, pos, key = np.empty(n, np.int64), np.full(n, -1, np.int64), np.zeros(n)
    done = kernels.ordered_solve(out, E, R, V, n, GAMMA, TOL * (1 - GAMMA), FLOOR, absorbing,
                                 alive, o.U, o.rho, o.osucc, o.onb, o.ong, first, pred,
                                 np.arange(n, dtype=np.int64), n, 100 * n, heap, pos, key)
    assert (pos == -1).all()
    return V, done


@pytest.mark.parametrize("seed", range(10))
def test_an_ordered_solve_from_zero_equals_a_full_solve(seed):
    """The goal-change solve (kernels.ordered_solve from V = 0, largest values first):
    V within vi_tol of the exact fixed point, nodes off every route exactly 0, on random
    maps with cycles, options and a goal whose neighbours hold rewards too."""
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(20, 200))
    out, E, R, absorbing, alive, o = random_map(rng, n)
    g = int(rng.integers(n))                      # a goal and its 2-cycle neighbour
    R[g], absorbing[g] = 1.0, False
    out[g, 0], E[g, 0] = (g + 1) % n, 1.0
    nb = (g + 1) % n
    R[nb], absorbing[nb] = 0.01, False
    out[nb, 0], E[nb, 0] = g, 1.0
    V, done = full_ordered(out, E, R, absorbing, alive, o, n)
    assert done > 0
    ref = exact(out, E, R, absorbing, alive, o)
    np.testing.assert_allclose(V[:n], ref[:n], rtol=TOL, atol=1e-12)
    assert (V[:n][ref[:n] == 0.0] == 0.0).all()


def test_an_ordered_solve_settles_a_chain_in_one_update_a_node():
    """On a corridor to a goal that returns to its neighbour (the 2-cycle that makes a
    synchronous solve from V = 0 converge by gamma^2 a round) every node but the goal's
    cluster is updated once: the Dijkstra order."""
    n = 400
    out = np.full((n, 2), -1, dtype=np.int64)
    out[1:, 0] = np.arange(n - 1)                 # i -> i - 1, towards the goal 0
    out[0, 0] = 1
    E = np.where(out >= 0, 1.0, 0.0)
    R = np.zeros(n)
    R[0], R[1] = 1.0, 0.01
    P = 4
    o = Options(np.zeros((n, P)), np.zeros((n, P)), np.full((n, P), -1),
                np.full((n, P, P), -1), np.zeros((n, P, P)))
    absorbing, alive = np.zeros(n, bool), np.ones(n, bool)
    V, done = full_ordered(out, E, R, absorbing, alive, o, n)
    assert done <= n
    ref = exact(out, E, R, absorbing, alive, o)
    np.testing.assert_allclose(V[:n], ref[:n], rtol=TOL, atol=1e-12)


@pytest.mark.parametrize("seed", range(10))
def test_invalidating_what_a_removal_held_up_then_an_ordered_solve_is_exact(seed):
    """Edits that lower values (links removed, E, R or options gone, nodes made
    absorbing): kernels.invalidate sets to 0 the nodes whose value rested on them, an
    ordered solve of those and the edited rows brings V within vi_tol of the exact fixed
    point again, every time, including regions cut off their sources (exactly 0)."""
    rng = np.random.default_rng(200 + seed)
    n = int(rng.integers(20, 150))
    out, E, R, absorbing, alive, o = random_map(rng, n)
    V = exact(out, E, R, absorbing, alive, o)
    heap, pos, key = np.empty(n, np.int64), np.full(n, -1, np.int64), np.zeros(n)
    found, mark = np.empty(n, np.int64), np.zeros(n, bool)
    invalidated = 0
    for _ in range(30):
        rows = set()
        for _ in range(int(rng.integers(1, 4))):
            rows.update(removal(rng, out, E, R, absorbing, o, n) if rng.random() < 0.6
                        else edit(rng, out, E, R, o, n))
        seeds = np.array(sorted(rows), dtype=np.int64)
        first, pred = kernels.predecessors(out, n, alive, o.osucc, o.onb)
        args = (out, E, R, V, n, GAMMA, TOL * (1 - GAMMA), FLOOR, absorbing, alive, o.U,
                o.rho, o.osucc, o.onb, o.ong, first, pred)
        V2 = V.copy()                 # the same in one call, for the bits below
        k = kernels.invalidate(*args, seeds, len(seeds), found, mark, np.empty(n + 1))
        assert not mark.any()
        invalidated += k
        both = np.concatenate((seeds, found[:k]))
        assert kernels.ordered_solve(*args, both, len(both), 100 * n, heap, pos, key) >= 0
        args2 = args[:3] + (V2,) + args[4:]
        assert kernels.invalidate_solve(*args2, seeds, len(seeds), found, mark, 100 * n, heap,
                                        pos, key)[0] == k
        np.testing.assert_array_equal(V2, V)   # invalidate's targets reused: same bits
        ref = exact(out, E, R, absorbing, alive, o)
        np.testing.assert_allclose(V[:n], ref[:n], rtol=TOL, atol=1e-12)
        assert (V[:n][ref[:n] == 0.0] == 0.0).all()
        assert (pos == -1).all()
    assert invalidated > 0


def test_a_budget_exceeded_says_so_and_leaves_the_queue_clean():
    rng = np.random.default_rng(3)
    n = 60
    out, E, R, absorbing, alive, o = random_map(rng, n)
    V = np.zeros(n + 1)                       # far from the solution: many updates
    first, pred = kernels.predecessors(out, n, alive, o.osucc, o.onb)
    seeds = np.arange(n, dtype=np.int64)
    heap, pos, key = np.empty(n, np.int64), np.full(n, -1, np.int64), np.zeros(n)
    assert kernels.prioritized_sweep(out, E, R, V, n, GAMMA, 1e-8, FLOOR, absorbing, alive,
                                     o.U, o.rho, o.osucc, o.onb, o.ong, first, pred, seeds,
                                     n, 3, heap, pos, key) == -1
    assert (pos == -1).all()


@pytest.mark.parametrize("seed", range(10))
def test_a_sweep_over_budget_continued_from_its_v_equals_a_full_solve(seed):
    """An incremental solve that outgrows its budget goes on from the V it left
    (MotivationEstimator._continued: an ordered solve over every node from that V), not
    from V = 0: after random sequences of edits, raising and lowering values, each cut
    off after a few updates (or none), V ends within vi_tol of the exact fixed point, and
    nodes off every route exactly 0. Eq. 4-5' is a contraction, so its one fixed point is
    reached from any V; the stopping rule is the same."""
    rng = np.random.default_rng(300 + seed)
    n = int(rng.integers(20, 150))
    out, E, R, absorbing, alive, o = random_map(rng, n)
    V = exact(out, E, R, absorbing, alive, o)
    heap, pos, key = np.empty(n, np.int64), np.full(n, -1, np.int64), np.zeros(n)
    found, mark = np.empty(n, np.int64), np.zeros(n, bool)
    cut = 0
    for _ in range(30):
        rows = set()
        for _ in range(int(rng.integers(1, 4))):
            rows.update(removal(rng, out, E, R, absorbing, o, n) if rng.random() < 0.4
                        else edit(rng, out, E, R, o, n))
        seeds = np.array(sorted(rows), dtype=np.int64)
        first, pred = kernels.predecessors(out, n, alive, o.osucc, o.onb)
        args = (out, E, R, V, n, GAMMA, TOL * (1 - GAMMA), FLOOR, absorbing, alive, o.U,
                o.rho, o.osucc, o.onb, o.ong, first, pred)
        budget = int(rng.integers(0, 4))
        if rng.random() < 0.5:                       # as motivation._incremental does
            k = kernels.invalidate(*args, seeds, len(seeds), found, mark,
                                   np.empty(n + 1))
            both = np.concatenate((seeds, found[:k]))
            done = kernels.ordered_solve(*args, both, len(both), budget, heap, pos, key)
        else:
            done = kernels.prioritized_sweep(*args, seeds, len(seeds), budget, heap, pos,
                                             key)
        assert (pos == -1).all()
        if done < 0:
            cut += 1
            everyone = np.arange(n, dtype=np.int64)
            assert kernels.ordered_solve(*args, everyone, n, 100 * n, heap, pos, key) >= 0
        ref = exact(out, E, R, absorbing, alive, o)
        np.testing.assert_allclose(V[:n], ref[:n], rtol=TOL, atol=1e-12)
        assert (V[:n][ref[:n] == 0.0] == 0.0).all()
    assert cut > 0


def test_changed_rows_finds_the_edits_and_flags_a_removal():
    rng = np.random.default_rng(0)
    n = 30
    out, E, R, absorbing, alive, o = random_map(rng, n)
    out0, E0, R0, a0 = out.copy(), E.copy(), R.copy(), absorbing.copy()
    seeds = np.empty(n, np.int64)
    s = np.flatnonzero(out[4] >= 0)[0]
    E[4, s] *= 0.5
    R[9] += 0.1
    c, lost, relinked = kernels.changed_rows(out, E, R, absorbing, out0, E0, R0, a0, n, seeds,
                                             NONE, -1)
    assert sorted(seeds[:c]) == [4, 9] and not lost and not relinked
    assert np.array_equal(E0, E)
    s = np.flatnonzero(out[7] >= 0)[0]
    out[7, s] = -1                  # removed: the predecessors keep a reader too many
    c, lost, relinked = kernels.changed_rows(out, E, R, absorbing, out0, E0, R0, a0, n, seeds,
                                             NONE, -1)
    assert list(seeds[:c]) == [7] and lost and not relinked
    out[7, s] = 3                   # added: node 7 reads node 3, which they must list
    c, lost, relinked = kernels.changed_rows(out, E, R, absorbing, out0, E0, R0, a0, n, seeds,
                                             NONE, -1)
    assert list(seeds[:c]) == [7] and not lost and relinked


def test_changed_rows_of_the_logged_rows_only():
    """Given the rows the map's log lists, only those are compared (a repeat is seeded
    once, in ascending order as by a scan); an edit elsewhere is not seen, which is why
    every writer of the map must log."""
    rng = np.random.default_rng(1)
    n = 30
    out, E, R, absorbing, alive, o = random_map(rng, n)
    out0, E0, R0, a0 = out.copy(), E.copy(), R.copy(), absorbing.copy()
    seeds = np.empty(2 * n, np.int64)
    R[[3, 5, 9]] += 0.1
    rows = np.array([9, 5, 9], dtype=np.int64)
    c, lost, relinked = kernels.changed_rows(out, E, R, absorbing, out0, E0, R0, a0, n, seeds,
                                             rows, len(rows))
    assert list(seeds[:c]) == [5, 9] and not lost and not relinked
    assert R0[9] == R[9] and R0[3] != R[3]


def test_the_agent_solving_incrementally_meets_the_full_solves_stopping_rule(monkeypatch):
    solves = _run_checked(monkeypatch)
    assert solves["incremental"] > 3 * (solves["full"] + solves["ordered"])
    assert solves["ordered"] > 0 and solves.get("invalidated", 0) > 0


def test_every_incremental_solve_over_budget_continued_meets_the_stopping_rule(monkeypatch):
    """With no budget at all every incremental solve that has something to update is
    cut at once and continued from its V (MotivationEstimator._continued): the same
    checks as above hold on every solve of the training run."""
    from tmgwr_agent.core import motivation
    monkeypatch.setattr(motivation, "INCREMENTAL_BUDGET", 0)
    solves = _run_checked(monkeypatch)
    assert solves.get("continued", 0) > 10 and solves.get("budget", 0) == 0


def _run_checked(monkeypatch) -> dict:
    """Every solve of a training run on the default maze (a goal change and a block
    included): the rows brought up to date from the map's change log (the solve's copy of
    its inputs, the frame coordinates, the rewards, the goal node) equal a recompute of
    every row; incremental or in full, the solve leaves every node with |beta (T(i) - V(i))| <=
    vi_tol V(i) (T: the right-hand side of Eq. 4-5', kernels.node_target), the stopping
    rule of the synchronous solve; and V within vi_tol / (beta (1 - gamma)) of the exact
    fixed point, the bound that rule gives."""
    from maze_sim.maze import Maze
    from tmgwr_agent.core.motivation import V_FLOOR, MotivationEstimator
    from tmgwr_agent.experiments.agent_factory import make_agent
    from tmgwr_agent.experiments.runner import Caps, make_world, run_episode, set_goal
    from tmgwr_agent.experiments.scenarios import DEFAULT_MAZE

    original = MotivationEstimator._solve
    seen = {"incremental": 0, "full": 0}     # solved without sweeps, or with
    worst = {"rule": 0.0, "exact": 0.0}

    def checked(self, m, n, R, absorbing):
        sweeps = original(self, m, n, R, absorbing)
        seen["incremental" if sweeps == 0 else "full"] += 1
        # what was brought up to date from the map's change log alone equals a recompute
        inc = self._inc
        assert np.array_equal(inc.out0, m.out[:n]) and np.array_equal(inc.E0, m.E[:n])
        assert np.array_equal(inc.R0, R[:n]) and np.array_equal(inc.abs0, absorbing[:n])
        F = self.frame.of(m.w, self.goal_x, self.delta, self._F.L, cache=False)
        assert np.array_equal(F.w[:n], self._F.w[:n])
        assert self._g_raw == m.nearest_by_weight(self.goal_x)
        if self.goal_node >= 0:
            R_full = np.empty(n)
            kernels.goal_rewards(F.w, m.alive, n, self.goal_node, self.goal_sigma * F.L,
                                 self.goal_sim_floor, R_full, NONE, -1)
            assert np.array_equal(R_full, self.R[:n])
        T = np.array([kernels.node_target(i, m.out, m.E, R, self.V, self.gamma, absorbing,
                                          m.alive, self.U, self.rho, self.osucc, self.onb,
                                          self.ong) for i in range(n)])
        V = self.V[:n]
        rule = np.abs(self.beta * (T - V)) / (self.vi_tol * V + V_FLOOR)
        ref = self.V.copy()
        kernels.value_iteration(m.out, m.E, R, ref, n, self.beta, self.gamma, 1e-13,
                                V_FLOOR, 10**6, absorbing, m.alive, self.U[:n],
                                self.rho[:n], self.osucc[:n], self.onb[:n], self.ong[:n])
        exact = np.abs(V - ref[:n]) / (ref[:n] + 1e-12)
        live = T > 1e-100          # (a node off every route: T = V = 0)
        worst["rule"] = max(worst["rule"], float(rule[live].max(initial=0.0)))
        worst["exact"] = max(worst["exact"], float(exact.max()))
        return sweeps

    monkeypatch.setattr(MotivationEstimator, "_solve", checked)
    maze = Maze.from_file(DEFAULT_MAZE)
    caps = Caps.for_maze(maze)
    world = make_world(maze, "G", caps)
    agent = make_agent("tmgwr", maze, np.random.default_rng(0))
    set_goal(world, agent, "G")
    for k in range(11):
        if k == 7:
            set_goal(world, agent, "3")
        if k == 9:
            world.fire_event("a")
        run_episode(world, agent, max_steps=3000)
    solves = agent.motivation.solves
    print(seen, worst, solves)
    assert worst["rule"] <= 1.0
    mot = agent.motivation
    assert worst["exact"] <= mot.vi_tol / (mot.beta * (1.0 - mot.gamma))
    return solves


def test_the_greedy_probes_potentials_after_a_goal_change_are_exact():
    """After a goal change V0 (Eq. 5 without options, the greedy probe's potentials and
    the route reading) restarts from 0 and is solved in order of value
    (kernels.ordered_solve): within vi_tol of the exact fixed point, as the synchronous
    solve it replaces there."""
    from tmgwr_agent.core.motivation import V_FLOOR
    from tmgwr_agent.experiments.runner import run_episode, set_goal

    world, agent = trained_on_default_maze(4)
    mot, m = agent.motivation, agent.map
    for goal in ("3", "G"):
        set_goal(world, agent, goal)
        assert mot._v0_zero
        V0 = mot.exploit(m)
        assert not mot._v0_zero                       # solved in order, not by sweeps
        n = m.n
        ref = np.zeros(n + 1)
        kernels.value_iteration(m.out, m.E, mot.R, ref, n, mot.beta, mot.gamma, 1e-13,
                                V_FLOOR, 10**6, mot._absorbing(m, n), m.alive, mot.U[:n],
                                np.zeros((n, mot.n_primitives)), mot.osucc[:n], mot.onb[:n],
                                mot.ong[:n])
        assert (ref[:n] > 0.0).sum() > n // 2            # a route to most nodes
        np.testing.assert_allclose(V0[:n], ref[:n], rtol=mot.vi_tol, atol=1e-12)
        run_episode(world, agent, max_steps=3000)


def test_a_goal_change_writes_over_the_retired_copy_and_solves_the_same():
    """The ordered solve after a goal change writes its copy of the inputs over the state
    the goal change retired (no fresh arrays), and solves to the same bits as an estimator
    that starts from fresh ones, at the change and in the episode after it."""
    import copy

    from tmgwr_agent.experiments.runner import run_episode, set_goal

    world, agent = trained_on_default_maze(4)
    world2, agent2 = copy.deepcopy((world, agent))
    fresh = agent2.motivation
    fresh._retire_incremental = lambda: setattr(fresh, "_inc", None)   # nothing kept
    for goal in ("3", "G"):
        inc = agent.motivation._inc
        assert inc is not None
        set_goal(world, agent, goal)
        set_goal(world2, agent2, goal)
        for a in (agent, agent2):
            if not a.motivation.solved:
                a.motivation.update(a.map)
        assert agent.motivation._inc is inc and agent2.motivation._inc is not inc
        np.testing.assert_array_equal(agent.motivation.V, agent2.motivation.V)
        e1 = run_episode(world, agent, max_steps=3000)
        e2 = run_episode(world2, agent2, max_steps=3000)
        assert e1 == e2
        np.testing.assert_array_equal(agent.motivation.V, agent2.motivation.V)


@pytest.mark.parametrize("dim", [2, 3, 4])
def test_the_median_link_length_is_numpys_to_the_bit(dim):
    """MotivationEstimator.link_scale gathers the links' differences in a kernel
    (kernels.link_differences) and takes their norms and median with numpy as the
    indexing it replaces did: the same value to the bit (a summation in another order
    would move the frame's L by an ulp and every trajectory after it)."""
    from types import SimpleNamespace

    from tmgwr_agent.core.motivation import MotivationEstimator

    rng = np.random.default_rng(dim)
    n = 300
    out = np.where(rng.random((n + 20, 5)) < 0.6, rng.integers(0, n, (n + 20, 5)), -1)
    m = SimpleNamespace(n=n, out=out, w=rng.normal(size=(n + 20, dim)) * 0.37)
    src, tgt = np.nonzero(out[:n] >= 0)
    d = m.w[src] - m.w[out[src, tgt]]
    assert MotivationEstimator.link_scale(m) == float(np.median(np.sqrt(
        np.einsum("ij,ij->i", d, d))))
    m.out = np.full_like(out, -1)
    assert MotivationEstimator.link_scale(m) == 0.0


def test_a_change_below_the_stopping_rule_moves_no_value():
    """On the default maze, trained and solved to the fixed point, a link's E lowered by a
    fraction of the stopping rule (motivation.sweep_tolerance) is not propagated: the
    incremental solve leaves every V as it was, and every node still meets the rule."""
    from tmgwr_agent.core.motivation import V_FLOOR, sweep_tolerance

    world, agent = trained_on_default_maze(3)
    m, mot = agent.map, agent.motivation
    mot.update(m)
    n, R, absorbing = m.n, mot.R, mot._absorbing(m, m.n)
    assert mot._inc is not None and mot.goal_node >= 0
    kernels.value_iteration(m.out, m.E, R, mot.V, n, mot.beta, mot.gamma, 1e-13, V_FLOOR,
                            10**6, absorbing, m.alive, mot.U[:n], mot.rho[:n],
                            mot.osucc[:n], mot.onb[:n], mot.ong[:n])

    def target(i):
        return kernels.node_target(i, m.out, m.E, R, mot.V, mot.gamma, absorbing, m.alive,
                                   mot.U, mot.rho, mot.osucc, mot.onb, mot.ong)

    s = sweep_tolerance(mot.vi_tol, mot.beta)
    # the node of the largest value whose target rests on one of its links
    for i in np.argsort(-mot.V[:n]):
        if absorbing[i] or R[i] > 0.0 or not m.alive[i]:
            continue
        ev = np.where(m.out[i] >= 0, m.E[i] * mot.V[m.out[i]], 0.0)
        k = int(np.argmax(ev))
        if np.isclose(R[i] + mot.gamma * ev[k], target(i), rtol=1e-12):
            break
    before = target(i)
    m.E[i, k] *= 1.0 - 0.25 * s
    m.log.touch(int(i))
    change = (before - target(i)) / before
    assert 0.1 * s < change < 0.5 * s        # above the old sweep's vi_tol (1 - gamma)
    V = mot.V.copy()
    incremental = mot.solves["incremental"]
    mot.update(m)
    assert mot.solves["incremental"] == incremental + 1
    assert np.array_equal(mot.V, V)
    T = np.array([target(j) for j in range(n)])
    assert (np.abs(mot.beta * (T - mot.V[:n])) <= mot.vi_tol * mot.V[:n] + V_FLOOR).all()


def test_an_option_worth_less_is_invalidated():
    """kernels.changed_options flags ``lost`` (invalidate, then an ordered solve) when an
    option's rho or U is lowered though the row keeps options, not when they rise."""
    rng = np.random.default_rng(2)
    n = 20
    *_, o = random_map(rng, n)
    o.rho[5] = [0.5, 0.5, 0.0, 0.0]
    copy = [a.copy() for a in o]
    seeds = np.empty(n, np.int64)
    rows = np.array([5], dtype=np.int64)

    def changed():
        return kernels.changed_options(rows, 1, o.rho, o.U, o.osucc, o.onb, o.ong,
                                       copy[1], copy[0], copy[2], copy[3], copy[4], seeds, 0)

    o.rho[5, 0] = 0.6
    c, lost, _ = changed()
    assert c == 1 and not lost
    o.rho[5, 0] = 0.2
    c, lost, _ = changed()
    assert c == 1 and lost
    o.U[5, 1] *= 0.5
    c, lost, _ = changed()
    assert c == 1 and lost
    o.U[5, 1] *= 3.0
    c, lost, _ = changed()
    assert c == 1 and not lost
