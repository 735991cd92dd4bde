"""Compiled inner loops of the map and the planner (numba, cached on disk).

Each kernel is the loop form of an equation the calling module states in numpy terms; they
exist because a step of the agent is a few dozen tiny array operations, and numpy's
per-call overhead (microseconds) would dominate it. Dead node slots are skipped through the
``alive`` mask; link slots hold -1 when empty.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def merge_distance_argmin(w, c, alive, n, x, C, alpha_c):
    """argmin_n d_n, d_n = (1 - alpha_c)|x - w_n|^2 + alpha_c |C - c_n|^2; returns (b, d_b)."""
    best, best_d = -1, np.inf
    dim = x.shape[0]
    for i in range(n):
        if not alive[i]:
            continue
        dx = 0.0
        dc = 0.0
        for k in range(dim):
            t = x[k] - w[i, k]
            dx += t * t
            u = C[k] - c[i, k]
            dc += u * u
        d = (1.0 - alpha_c) * dx + alpha_c * dc
        if d < best_d:
            best, best_d = i, d
    return best, best_d


@njit(cache=True)
def nearest_weight(w, alive, n, x):
    """argmin_n |x - w_n|^2 over live nodes (-1 if none)."""
    best, best_d = -1, np.inf
    for i in range(n):
        if not alive[i]:
            continue
        d = 0.0
        for k in range(x.shape[0]):
            t = x[k] - w[i, k]
            d += t * t
        if d < best_d:
            best, best_d = i, d
    return best


@njit(cache=True)
def incident_neighbours(out, n, b):
    """Nodes linked to b in either direction (sorted, unique)."""
    mark = np.zeros(n, dtype=np.bool_)
    for s in range(out.shape[1]):
        t = out[b, s]
        if t >= 0:
            mark[t] = True
    for i in range(n):
        for s in range(out.shape[1]):
            if out[i, s] == b:
                mark[i] = True
                break
    mark[b] = False
    return np.flatnonzero(mark)


@njit(cache=True)
def goal_rewards(w, alive, n, g, sigma, floor, R):
    """Eq. 10: R_i = sim(i, g) = exp(-|w_i - w_g|^2 / (2 sigma^2)), 0 below ``floor``."""
    inv = 1.0 / (2.0 * sigma * sigma)
    for i in range(n):
        if not alive[i]:
            R[i] = 0.0
            continue
        d = 0.0
        for k in range(w.shape[1]):
            t = w[i, k] - w[g, k]
            d += t * t
        r = np.exp(-d * inv)
        R[i] = r if r >= floor else 0.0


@njit(cache=True)
def value_iteration(out, E, R, V, n, beta, gamma, tol, v_floor, max_sweeps, absorbing,
                    alive):
    """Synchronous sweeps of Eq. 4-5 until every |beta Delta_V(i)| <= tol V(i) + v_floor.

    ``V`` has n + 1 entries, ``V[n] == 0`` (the target of empty link slots). A node with
    ``absorbing[i]`` has no successor (a terminal state: Delta_V(i) = R_i - V(i)); a dead
    slot (``alive[i]`` false) has V = 0. Returns the number of sweeps. Potentials below
    ``v_floor`` are set to exactly 0 at the end.
    """
    K = out.shape[1]
    for i in range(n):
        if not alive[i]:
            V[i] = 0.0
    new = np.empty(n)
    sweeps = 0
    for sweeps in range(1, max_sweeps + 1):
        done = True
        for i in range(n):
            best = 0.0
            for s in range(K if not absorbing[i] else 0):
                j = out[i, s]
                if j >= 0:
                    ev = E[i, s] * V[j]
                    if ev > best:
                        best = ev
            step = beta * (R[i] + gamma * best - V[i])      # beta * Delta_V(i)
            new[i] = V[i] + step
            if abs(step) > tol * new[i] + v_floor:
                done = False
        V[:n] = new
        if done:
            break
    for i in range(n):
        if V[i] < v_floor:
            V[i] = 0.0
    return sweeps


@njit(cache=True)
def nearest_row(table, a):
    """argmin_r |table[r] - a|^2 (first on ties)."""
    best, best_d = 0, np.inf
    for r in range(table.shape[0]):
        d = 0.0
        for k in range(a.shape[0]):
            t = table[r, k] - a[k]
            d += t * t
        if d < best_d:
            best, best_d = r, d
    return best


@njit(cache=True)
def best_links(out_i, E_i, V):
    """Slots of node i's links attaining max_k E[i, k] V(k) > 0 (Eq. 6); empty if none."""
    top = 0.0
    for s in range(out_i.shape[0]):
        j = out_i[s]
        if j >= 0:
            ev = E_i[s] * V[j]
            if ev > top:
                top = ev
    if top <= 0.0:
        return np.empty(0, dtype=np.int64)
    res = []
    for s in range(out_i.shape[0]):
        j = out_i[s]
        if j >= 0 and E_i[s] * V[j] == top:
            res.append(s)
    return np.array(res, dtype=np.int64)


@njit(cache=True)
def habituate(h, i, tau, kappa):
    """GWR habituation: h_i += tau (kappa (1 - h_i) - 1)."""
    h[i] += tau * (kappa * (1.0 - h[i]) - 1.0)


@njit(cache=True)
def adapt(w, c, h, out, n, b, x, C, eps_b, eps_n, tau_b, tau_n, kappa):
    """Move the winner and its linked neighbours towards (x, C), then habituate them."""
    rate = eps_b * h[b]
    for k in range(x.shape[0]):
        w[b, k] += rate * (x[k] - w[b, k])
        c[b, k] += rate * (C[k] - c[b, k])
    habituate(h, b, tau_b, kappa)
    for nb in incident_neighbours(out, n, b):
        rate = eps_n * h[nb]
        for k in range(x.shape[0]):
            w[nb, k] += rate * (x[k] - w[nb, k])
            c[nb, k] += rate * (C[k] - c[nb, k])
        habituate(h, nb, tau_n, kappa)


@njit(cache=True)
def sim_action(a_ij, a, sigma_a):
    """Eq. 2: sim(a_ij, a) = exp(-|a_ij - a|^2 / (2 sigma_a^2))."""
    d = 0.0
    for k in range(a.shape[0]):
        t = a_ij[k] - a[k]
        d += t * t
    return np.exp(-d / (2.0 * sigma_a * sigma_a))


@njit(cache=True)
def update_links(out, E, A, age, n, i, j, a, alpha, sigma_a, eta_a, E_init, E_min,
                 max_age, credit):
    """Eq. 1-2 on the transition i -> j under action a, the credit option, then ageing.

    The caller guarantees a free slot in row i when i -> j is new. Returns
    ``(created, ends)``: whether a link was created, and the end nodes of every link this
    call deleted (for the isolated-node check), as a flat array.
    """
    K = out.shape[1]
    slot = -1
    created = False
    if i != j:
        for s in range(K):
            if out[i, s] == j:
                slot = s
                break
        if slot < 0:
            for s in range(K):
                if out[i, s] < 0:
                    slot = s
                    break
            out[i, slot] = j
            A[i, slot, :] = a
            E[i, slot] = E_init
            age[i, slot] = 0
            created = True
        # Eq. 1-2 on the traversed link, I{i != j} = 1
        E[i, slot] += alpha * (sim_action(A[i, slot], a, sigma_a) - E[i, slot])
        for k in range(a.shape[0]):
            A[i, slot, k] += eta_a * (a[k] - A[i, slot, k])
    if credit:
        # blame the other links out of i as far as their action matches a
        for s in range(K):
            if s != slot and out[i, s] >= 0:
                E[i, s] -= alpha * sim_action(A[i, s], a, sigma_a) * E[i, s]
    # GWR ageing of every link incident to i; deletion of stale and unreliable links
    ends = []
    for src in range(n):
        for s in range(K):
            t = out[src, s]
            if t < 0 or (src != i and t != i):
                continue
            if src == i and s == slot:
                age[src, s] = 0
            else:
                age[src, s] += 1
            if age[src, s] > max_age or (src == i and E[src, s] < E_min):
                out[src, s] = -1
                E[src, s] = 0.0
                ends.append(src)
                ends.append(t)
    return created, np.array(ends, dtype=np.int64)
