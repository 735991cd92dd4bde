"""The numpy reference of Algorithm 1 / Eq. 4-5 (core/value_iteration.py) and the compiled
solver the agent runs (kernels.value_iteration) reach the same V on random maps, with and
without the options of Eq. 5', and the reference solves a hand case of Eq. 5."""

import numpy as np
import pytest

from tmgwr_agent.core import kernels
from tmgwr_agent.core.value_iteration import Options, solve


def random_map(rng, n, K=4, P=4, options=True):
    out = np.where(rng.random((n, K)) < 0.6, rng.integers(0, n, (n, K)), -1)
    E = rng.random((n, K))
    E[rng.random((n, K)) < 0.1] = 0.0
    R = np.where(rng.random(n) < 0.1, rng.random(n), 0.0)
    absorbing = rng.random(n) < 0.1
    alive = rng.random(n) < 0.9
    V = np.append(rng.random(n) * (rng.random(n) < 0.5), 0.0)    # a warm start
    rho = np.where(rng.random((n, P)) < (0.3 if options else 0.0), rng.random((n, P)), 0.0)
    osucc = rng.choice(np.r_[-2, -1, np.arange(n)], size=(n, P))
    onb = np.where(rng.random((n, P, P)) < 0.5, rng.integers(0, n, (n, P, P)), -1)
    ong = rng.random((n, P, P))
    U = rng.random((n, P)) * 5
    return out, E, R, V, absorbing, alive, Options(U, rho, osucc, onb, ong)


@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("with_options", [False, True])
def test_reference_equals_the_kernel_on_random_maps(seed, with_options):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 120))
    out, E, R, V, absorbing, alive, o = random_map(rng, n, options=with_options)
    args = (0.8, 0.97, 1e-6, 1e-150, 5000)
    Vk = V.copy()
    sweeps = kernels.value_iteration(out, E, R, Vk, n, *args, absorbing, alive, o.U, o.rho,
                                     o.osucc, o.onb, o.ong)
    Vr, sweeps_r = solve(out, E, R, V, *args, absorbing, alive, o)
    np.testing.assert_allclose(Vr, Vk, rtol=1e-12, atol=1e-300)
    assert sweeps_r == sweeps


def test_eq5_on_a_chain_by_hand():
    """0 -> 1 -> 2 (the goal, R = 1): V(2) = 1 / (1 - gamma) is not reached (no link out
    of 2): V(2) = R_2 = 1, V(1) = gamma, V(0) = gamma^2; node 3, linked to nothing, is 0."""
    out = np.array([[1], [2], [-1], [-1]])
    E = np.ones((4, 1))
    R = np.array([0.0, 0.0, 1.0, 0.0])
    no = np.zeros(4, bool)
    V, _ = solve(out, E, R, np.zeros(5), 0.8, 0.9, 1e-12, 1e-150, 100000, no, ~no)
    np.testing.assert_allclose(V, [0.81, 0.9, 1.0, 0.0, 0.0], rtol=1e-9)
