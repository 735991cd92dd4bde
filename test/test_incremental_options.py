"""The incremental refresh of the options of Eq. 5' (kernels.option_rows_changed, the rows
core/unknown.py re-values when only the map's structure changed) gives the same options as
a full pass (kernels.option_values over every row) after random sequences of map edits:
weights moved within and across cells, nodes removed and placed, links made and deleted,
with the same forward model, outcome memory and potentials; a new open prior either
re-values the rows of the untried pairs or is written on them (kernels.untried_rho)."""

import numpy as np
import pytest

from tmgwr_agent.core import kernels
from tmgwr_agent.core.unknown import NO_BELIEF

P, K = 4, 4
STEPS = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])   # the lattice moves
GAMMA, V_STAR = 0.97, 1.0
JITTER = 0.45                           # how far from its cell's centre a weight may lie


class World:
    """A lattice of ``rows`` x ``cols`` cells of side 1, a node on some of the inner ones
    (weights anywhere in their cell, so a lookup within half a cell finds them or not;
    sometimes two a cell), the two corner nodes fixed so the node lookup's extent stays
    the same (the incremental path's condition), and an outcome memory of random moves,
    bumps and walls."""

    def __init__(self, rng, rows=9, cols=11, cap=120):
        self.rng, self.rows, self.cols = rng, rows, cols
        self.w = np.zeros((cap, 2))
        self.alive = np.zeros(cap, dtype=bool)
        self.inner = [(r, c) for r in range(1, rows - 1) for c in range(1, cols - 1)]
        order = rng.permutation(len(self.inner))
        chosen = [(0, 0), (rows - 1, cols - 1)] + [self.inner[k] for k in order][:50]
        self.n = len(chosen) + 10                       # spare dead slots to place nodes in
        for i, (r, c) in enumerate(chosen):
            self.place(i, r, c, jitter=i >= 2)
        self.out = np.full((cap, K), -1, dtype=np.int64)
        for i in range(self.n):
            for s in range(K):
                if rng.random() < 0.5:
                    self.out[i, s] = rng.integers(self.n)
        self.delta = STEPS + rng.uniform(-0.02, 0.02, STEPS.shape)
        self.goal = np.array([rows - 1.0, cols - 1.0])
        self.tried = rng.random((cap, P)) < 0.6
        self.bump_t = np.where(self.tried & (rng.random((cap, P)) < 0.4),
                               rng.integers(0, 50, (cap, P)), -1)
        self.closed_t = np.where(self.bump_t >= 0, self.bump_t - rng.integers(0, 5, (cap, P)), -1)
        self.bump_e = np.where(self.bump_t >= 0, rng.integers(0, 10, (cap, P)), -1)
        self.succ = np.where(self.tried & (rng.random((cap, P)) < 0.7),
                             rng.integers(0, self.n, (cap, P)), -1)
        self.sel = rng.random((cap, P)) < 0.5
        self.chain = rng.random((cap, P)) < 0.05
        self.V = rng.uniform(0.1, 1.0, cap + 1)

    def place(self, i, r, c, jitter=True):
        self.w[i] = np.array([r, c], dtype=float) + \
            (self.rng.uniform(-JITTER, JITTER, 2) if jitter else 0.0)
        self.alive[i] = True

    def cell(self):
        """An inner cell, taken or free."""
        return self.inner[self.rng.integers(len(self.inner))]

    def edit(self):
        """One random map edit (never of the corner nodes 0 and 1); returns the rows it
        touched, as the map's change log lists them."""
        rng = self.rng
        i = int(rng.integers(2, self.n))
        kind = rng.integers(5)
        if kind == 0 and self.alive[i]:              # a weight drifts within its cell
            centre = np.floor(self.w[i] + 0.5)
            self.w[i] = centre + np.clip(self.w[i] + rng.uniform(-0.2, 0.2, 2) - centre,
                                         -JITTER, JITTER)
        elif kind == 1 and self.alive[i]:            # a node removed
            self.alive[i] = False
            self.out[i] = -1
        elif kind == 2:                              # a node placed (a slot reused)
            self.place(i, *self.cell())
        elif kind == 3:                              # a link made
            self.out[i, rng.integers(K)] = rng.integers(self.n)
        else:                                        # a link deleted
            self.out[i, rng.integers(K)] = -1
        return [i]

    def options(self, rows, rho_new, stuck, U, rho, osucc, onb, ong, grid, origin):
        kernels.option_values(self.w, self.out, self.alive, self.n, rows, self.goal,
                              self.delta, 1.0, V_STAR, GAMMA, self.tried, self.bump_t,
                              self.closed_t, self.bump_e, self.succ, 60, 40.0, 12, 3.0, 0.5,
                              rho_new, stuck, grid, origin, self.V, self.sel, self.chain,
                              U, rho, osucc, onb, ong, *NO_BELIEF, np.ones(P, dtype=bool))

    def full(self, rho_new, stuck):
        cap = len(self.w)
        o = (np.zeros((cap, P)), np.zeros((cap, P)), np.full((cap, P), -1, np.int64),
             np.full((cap, P, P), -1, np.int64), np.zeros((cap, P, P)))
        grid, origin = kernels.cell_grid(self.w, self.alive, self.n, 1.0)
        self.options(np.arange(self.n), rho_new, stuck, *o, grid, origin)
        return o


def check_equal(world, got, want):
    alive = world.alive[: world.n]
    for name, g, e in zip(("U", "rho", "osucc", "onb", "ong"), got, want):
        np.testing.assert_array_equal(g[: world.n][alive], e[: world.n][alive], err_msg=name)


@pytest.mark.parametrize("stuck", [False, True])
@pytest.mark.parametrize("seed", range(8))
def test_incremental_options_equal_a_full_pass_after_random_edits(seed, stuck):
    rng = np.random.default_rng(seed)
    world = World(rng)
    rho_new = 0.4
    opts = world.full(rho_new, stuck)
    grid, origin = kernels.cell_grid(world.w, world.alive, world.n, 1.0)
    rows = np.empty(world.n, dtype=np.int64)
    partial = 0
    for _ in range(60):
        touched = np.zeros(world.n, dtype=bool)
        for _ in range(int(rng.integers(1, 4))):
            touched[world.edit()] = True
        untried = rng.random() < 0.2                   # the open prior re-estimated
        if untried:
            rho_new = float(rng.uniform(0.1, 0.9))
            if rng.random() < 0.5:                     # written on the untried pairs
                k = kernels.untried_rho(world.alive, world.n, world.tried, world.chain,
                                        np.ones(P, dtype=bool), rho_new, opts[1], rows)
                assert k > 0
                untried = False
        grid_was = grid
        grid, new_origin = kernels.cell_grid(world.w, world.alive, world.n, 1.0)
        assert grid.shape == grid_was.shape and np.array_equal(new_origin, origin)
        c = kernels.option_rows_changed(world.w, world.alive, world.n, touched, world.delta,
                                        1.0, grid_was, grid, origin, world.tried,
                                        world.bump_e, world.succ, world.sel, 12, 3.0, stuck,
                                        untried, rows)
        assert np.all(np.diff(rows[:c]) > 0)
        partial += c < world.n
        world.options(rows[:c], rho_new, stuck, *opts, grid, origin)
        check_equal(world, opts, world.full(rho_new, stuck))
    assert partial > 30                   # the refresh was incremental, not a full pass


def test_a_changed_rows_list_misses_nothing_a_full_pass_would_change():
    """Without the rows option_rows_changed adds beyond the touched ones (the readers of a
    changed node or cell), the options go wrong: the test above can fail."""
    rng = np.random.default_rng(3)
    world = World(rng)
    opts = world.full(0.4, False)
    grid, origin = kernels.cell_grid(world.w, world.alive, world.n, 1.0)
    wrong = 0
    for _ in range(60):
        touched = [i for _ in range(2) for i in world.edit()]
        grid, origin = kernels.cell_grid(world.w, world.alive, world.n, 1.0)
        world.options(np.array(sorted(set(touched)), dtype=np.int64), 0.4, False, *opts,
                      grid, origin)
        want = world.full(0.4, False)
        alive = world.alive[: world.n]
        wrong += not np.array_equal(opts[2][: world.n][alive], want[2][: world.n][alive])
        opts = want
    assert wrong > 0


def test_the_union_of_option_rows_is_numpys():
    """unknown.union_rows (a mask, where the option rows can be every row of a large map)
    gives what np.union1d gives: the sorted rows of either list, the same dtype."""
    from tmgwr_agent.core.unknown import union_rows

    rng = np.random.default_rng(0)
    for _ in range(500):
        a, b = (rng.integers(0, rng.integers(1, 300), size=rng.integers(0, 40))
                for _ in range(2))
        u, r = np.union1d(a, b), union_rows(a, b)
        assert u.dtype == r.dtype and np.array_equal(u, r)
