"""stuck()'s search (kernels.reaches_source_from): the answer of the reverse breadth-first
search over every node (kernels.reaches_source over the links kernels.contradicted leaves),
searched from one node.

What must hold: on random maps (dead slots, absorbing nodes, links into dead slots,
contradicted links, several sources or none) the search from every node, in any order
and reusing what earlier searches of the same stamp learnt, answers as the full search
marks; a new stamp forgets what was learnt.
"""

from __future__ import annotations

import numpy as np
import pytest

from tmgwr_agent.core import kernels


def random_map(rng: np.random.Generator, n: int, K: int = 4, P: int = 4):
    out = np.where(rng.random((n, K)) < 0.6, rng.integers(0, n, (n, K)), -1)
    E = np.where(out >= 0, rng.uniform(0.05, 1.0, (n, K)), 0.0)
    E[rng.random((n, K)) < 0.05] = 0.0                        # E gone to 0
    alive = rng.random(n) > 0.1
    absorbing = rng.random(n) < 0.05
    succ = np.where(rng.random((n, P)) < 0.5, out[:, rng.integers(0, K, P)], -1)
    bump_t = np.where(rng.random((n, P)) < 0.3, rng.integers(0, 100, (n, P)), -1)
    source = rng.random(n) < rng.choice([0.0, 0.002, 0.02])
    return out, E, alive, absorbing, succ, bump_t, source


@pytest.mark.parametrize("seed", range(12))
def test_search_from_a_node_answers_as_the_full_search(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 400))
    out, E, alive, absorbing, succ, bump_t, source = random_map(rng, n)
    mark = np.zeros(n, dtype=bool)
    kernels.reaches_source(out, kernels.contradicted(out, E, n, bump_t, succ), n, absorbing,
                           alive, source, mark)
    V = rng.random(n + 1)
    known, seen = np.zeros(n, np.int64), np.zeros(n, np.int64)
    stack = np.empty(n, np.int64)
    search = 0
    for stamp in (1, 2):                  # a new stamp: learnt afresh
        for start in rng.permutation(n):
            search += 1
            assert kernels.reaches_source_from(out, E, n, absorbing, alive, source, bump_t,
                                               succ, V, start, known, stamp, seen, search,
                                               stack) == mark[start]
        if stamp == 1:                    # the next stamp's map: other sources
            source = rng.random(n) < 0.01
            kernels.reaches_source(out, kernels.contradicted(out, E, n, bump_t, succ), n,
                                   absorbing, alive, source, mark)
