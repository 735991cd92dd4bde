"""The node index (core/node_index.py): the map's searches through its grid return what a
scan of every node returns, ties included, and a map that learns through it follows the
same trajectory as one that scans.

What must hold: :func:`kernels.indexed_argmin` equals :func:`kernels.merge_distance_argmin`
and :func:`kernels.indexed_close_pair` equals :func:`kernels.close_pair` on maps with
duplicate weights (ties), dead slots, queries outside the grid, in one, two and three
dimensions; after nodes move (:func:`kernels.index_move`) the grid lists every live node
in its cell; a map stepped through the index (noisy inputs, so nodes move and merge) wins
the same nodes, makes the same merges and ends with the same arrays as one that scans.
"""

from __future__ import annotations

from itertools import product

import numpy as np
import pytest

from tmgwr_agent.core import kernels, sensorimotor_map
from tmgwr_agent.core.node_index import INDEX_MIN, NodeIndex
from tmgwr_agent.core.outcome import EPISODE_START, Outcome
from tmgwr_agent.core.sensorimotor_map import SensorimotorMap


class Nodes:
    """Weights, contexts and alive flags of a map, with the change log the index reads."""

    def __init__(self, w: np.ndarray, alive: np.ndarray):
        self.w, self.alive, self.n = w, alive, len(w)
        self.log = sensorimotor_map.RowLog()


def lattice_nodes(rng: np.random.Generator, side: int, dim: int) -> tuple[np.ndarray, ...]:
    """A jittered lattice of side^2 nodes (the first two coordinates; the rest noise),
    some exact duplicates (ties) and some dead slots."""
    g = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2) * 1.0
    w = np.zeros((len(g), dim))
    w[:, :min(dim, 2)] = g[:, :min(dim, 2)]
    w += rng.normal(0.0, 0.1, w.shape)
    dup = rng.choice(len(w), len(w) // 10, replace=False)
    w[dup] = w[rng.choice(len(w), len(dup))]           # exact ties
    c = w + rng.normal(0.0, 0.05, w.shape)
    c[dup] = c[rng.choice(len(w), len(dup))]
    alive = rng.random(len(w)) > 0.1
    return w, c, alive


def listed(index: NodeIndex, n: int) -> dict[int, int]:
    """Node -> cell, read off the grid's lists."""
    out = {}
    for cell in range(int(index.shape[0] * index.shape[1])):
        i = index.head[cell]
        while i >= 0:
            assert i not in out
            out[int(i)] = cell
            i = index.node[0, i]
    return out


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_indexed_searches_equal_the_scans(dim):
    rng = np.random.default_rng(dim)
    side = 25 if dim > 1 else 400
    w, c, alive = lattice_nodes(rng, side, dim) if dim > 1 else (
        np.sort(rng.normal(0.0, 100.0, (side, 1)), axis=0), rng.normal(0.0, 1.0, (side, 1)),
        rng.random(side) > 0.1)
    if dim == 1:
        w[1::7] = w[::7][:len(w[1::7])]                  # ties in one dimension too
    m = Nodes(w, alive)
    index = NodeIndex()
    index.sync(m)
    assert index.shape[3] == 1
    n = len(w)
    lo, hi = w.min(0), w.max(0)
    # the context in the sensor's units, and in a learnt metric (sensorimotor_map.py)
    metrics = (np.zeros((0, 0)), np.ascontiguousarray(rng.normal(0.0, 2.0, (dim, dim))))
    for q in range(400):
        if q % 4 == 0:
            x = w[rng.integers(n)].copy()                       # on a node (and its ties)
        else:
            x = rng.uniform(lo - 0.5 * (hi - lo), hi + 0.5 * (hi - lo))  # also outside
        C = x + rng.normal(0.0, 0.05, dim)
        for alpha_c, SC in product((0.0, 0.01, 0.5), metrics):
            assert kernels.indexed_argmin(w, c, alive, n, x, C, alpha_c, SC, *index.arrays) == \
                kernels.merge_distance_argmin(w, c, alive, n, x, C, alpha_c, SC)
    for q in range(200):
        rows = rng.integers(-1, n, 6)
        rows[3] = rows[1]                                        # a row twice
        for (alpha_c, r2), SC in product(((0.0, 0.3), (0.01, 0.05), (0.5, 2.0)), metrics):
            assert kernels.indexed_close_pair(w, c, alive, n, rows, alpha_c, SC, r2,
                                              *index.arrays) == \
                kernels.close_pair(w, c, alive, n, rows, alpha_c, SC, r2)


def test_moved_nodes_are_listed_in_their_cells_or_the_grid_is_built_again():
    rng = np.random.default_rng(5)
    w, _, alive = lattice_nodes(rng, 20, 2)
    m = Nodes(w, alive)
    index = NodeIndex()
    index.sync(m)
    for _ in range(50):
        rows = rng.choice(len(w), 8)
        w[rows] += rng.normal(0.0, 0.7, (8, 2))
        alive[rows[:2]] = ~alive[rows[:2]]
        m.log.touch(rows)
        index.sync(m)
        expected = {int(i): kernels.index_cell(w, i, index.geom, index.shape)
                    for i in np.flatnonzero(alive)}
        assert listed(index, len(w)) == expected
    w[0] = w.max(0) + 100.0                                  # out of the grid: built again
    m.log.touch(0)
    index.sync(m)
    assert index.shape[3] == 1 and listed(index, len(w))[0] >= 0


def noisy_walk(m: SensorimotorMap, rng: np.random.Generator, steps: int) -> list:
    """A walk on a 24 x 24 lattice (a tenth of a unit a cell) sensed with noise of 0.2
    cell, bumps at its border; the winner and the merges of each step."""
    moves = np.array([[1, 0], [-1, 0], [0, 1], [0, -1]])
    p = np.array([0, 0])
    trace = []
    for t in range(steps):
        if t % 500 == 0:
            outcome = EPISODE_START
        else:
            a = int(rng.integers(4))
            q = p + moves[a]
            bumped = not ((0 <= q) & (q < 24)).all()
            p = p if bumped else q
            outcome = Outcome(action=a, bumped=bumped)
        winner = m.experience(0.1 * p + rng.normal(0.0, 0.02, 2), outcome)
        trace.append((winner, tuple(m.merges)))
    return trace


def test_a_map_learns_the_same_through_the_index(monkeypatch):
    def run(scan: bool):
        if scan:
            monkeypatch.setattr(sensorimotor_map, "INDEX_MIN", 10 ** 9)
        m = SensorimotorMap(dim=2, primitives=np.array(
            [[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]]))
        trace = noisy_walk(m, np.random.default_rng(3), 6000)
        monkeypatch.undo()
        return m, trace

    m1, t1 = run(scan=False)
    m0, t0 = run(scan=True)
    assert m1.n >= INDEX_MIN and m1.index.shape[3] == 1 and m0.index.shape[3] == 0
    assert any(merges for _, merges in t1)               # nodes merged on the way
    assert t1 == t0
    for name in ("w", "c", "h", "alive", "out", "E"):
        np.testing.assert_array_equal(getattr(m1, name)[:m1.n], getattr(m0, name)[:m0.n])
