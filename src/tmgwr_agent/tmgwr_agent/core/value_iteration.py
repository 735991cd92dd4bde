"""Algorithm 1 (Eq. 4-5) in numpy, to be read top to bottom.

This is the reference of the motivation estimator's solver: the same fixed point as
:func:`tmgwr_agent.core.kernels.value_iteration` (the compiled loop the agent runs, a
few dozen times faster on small maps), and tested equal to it (test_value_iteration.py).
The paper's Eq. 5 is the case without options; the options are the value of the
unknown's virtual successors (Eq. 5', motivation.py), passed in as arrays.

For every node ``i`` of the map, with ``R_i = sim(i, g)`` (Eq. 10) and its outgoing
sensorimotor links ``i -> k`` of reliability ``E[i, k]``::

    V(i) <- V(i) + beta * Delta_V(i)                                   (Eq. 4)
    Delta_V(i) = R_i + gamma * max_k E[i, k] V(k) - V(i)               (Eq. 5)

swept synchronously until every ``|beta Delta_V(i)| <= tol V(i) + v_floor``. An absorbing
(terminal) node has no successor. A node from which no link path with ``E > 0`` leads
to a source (``R > 0``, or an option) has ``V = 0`` exactly: its fixed point.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class Options(NamedTuple):
    """The options of Eq. 5' per (node, primitive): probability ``rho`` that the move
    leads on (0: no option), successor ``osucc`` (a node; -1: unknown space worth ``U``;
    -2: a remembered wall cell worth gamma times its best exit ``ong * V(onb)``)."""

    U: np.ndarray
    rho: np.ndarray
    osucc: np.ndarray
    onb: np.ndarray
    ong: np.ndarray


def reaching(out: np.ndarray, E: np.ndarray, alive: np.ndarray, absorbing: np.ndarray,
             source: np.ndarray) -> np.ndarray:
    """The nodes from which some link path with E > 0 leads to a source (absorbing nodes
    have no successor; dead slots none)."""
    n = len(alive)
    mark = alive & source
    frontier = np.flatnonzero(mark)
    linked = (out[:n] >= 0) & (E[:n] > 0.0) & (alive & ~absorbing)[:, None]
    while len(frontier):
        into = linked & np.isin(out[:n], frontier)         # links i -> frontier
        new = into.any(axis=1) & ~mark
        mark |= new
        frontier = np.flatnonzero(new)
    return mark


def successor_values(V: np.ndarray, o: Options, gamma: float) -> np.ndarray:
    """S(i, a) of every option (Eq. 5'): V of a known node, the best exit of a wall cell,
    or U of unknown space. ``V`` has n + 1 entries, ``V[n] = 0`` (index -1)."""
    wall = gamma * (o.ong * V[o.onb]).max(axis=2)
    return np.where(o.osucc >= 0, V[o.osucc], np.where(o.osucc == -2, wall, o.U))


def solve(out: np.ndarray, E: np.ndarray, R: np.ndarray, V: np.ndarray, beta: float,
          gamma: float, tol: float, v_floor: float, max_sweeps: int,
          absorbing: np.ndarray, alive: np.ndarray, options: Options | None = None
          ) -> tuple[np.ndarray, int]:
    """Eq. 4-5 (with ``options``: Eq. 5') from the warm start ``V`` (n + 1 entries);
    returns (V, sweeps)."""
    n = len(R)
    V = V.copy()
    has_option = np.zeros(n, bool) if options is None else \
        (options.rho[:n] > 0.0).any(axis=1) & ~absorbing
    live = reaching(out, E, alive, absorbing, (R > 0.0) | has_option)
    V[:n][~live] = 0.0
    links = out[:n] >= 0
    for sweep in range(1, max_sweeps + 1):
        EV = np.where(links, E[:n] * V[out[:n]], 0.0)          # E[i, k] V(k)
        best = np.maximum(EV.max(axis=1), 0.0)                 # max_k, Eq. 5
        if options is not None:                                # max_a O(i, a), Eq. 5'
            rho = options.rho[:n]
            stay = (R + gamma * best)[:, None]                 # a failed test stays
            opt = np.where(rho > 0.0, rho * successor_values(V, options, gamma)[:n]
                         + (1.0 - rho) * stay, 0.0)
            best = np.maximum(best, opt.max(axis=1))
        best[absorbing] = 0.0                                  # a terminal state
        step = beta * (R + gamma * best - V[:n])               # beta Delta_V(i), Eq. 4
        new = np.where(live, V[:n] + step, 0.0)
        done = np.all(np.where(live, np.abs(step) <= tol * new + v_floor, True))
        V[:n] = new
        if done:
            break
    V[:n][V[:n] < v_floor] = 0.0
    return V, sweep
