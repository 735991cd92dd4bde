"""Compiled inner loops of the map and the planner (numba, cached on disk).

Each kernel is the loop form of an equation the calling module states in numpy terms; they
exist because a step of the agent is a few dozen tiny array operations, and numpy's
per-call overhead (microseconds) would dominate it. Dead node slots are skipped through the
``alive`` mask; link slots hold -1 when empty. Callers pass the arguments positionally:
numba's dispatcher takes keyword arguments through a slow path (microseconds a call, more
than most kernels' work).

Compilation is lazy (for the argument types of the first call) and cached on disk
(``cache=True``: ``__pycache__`` next to this file, or under ``NUMBA_CACHE_DIR``).
``tools/bootstrap.sh`` fills the cache once (:mod:`tmgwr_agent.warmup`); a process
that finds it empty says so (:func:`announce_compilation`) before compiling (tens of seconds).
"""

from __future__ import annotations

import contextlib
import glob
import math
import os
import sys

import numpy as np
from numba import njit, types
from numba.core.extending import intrinsic


@njit(inline="always")
def context_gap(C, c, i, Sc):
    """``|Sc (C - c_i)|^2``, the context's share of ``d_n`` (sensorimotor_map.py, "The
    context in primitive steps"); ``|C - c_i|^2`` when ``Sc`` has no rows (the sensor's
    own units)."""
    dc = 0.0
    if Sc.shape[0] == 0:
        for k in range(C.shape[0]):
            u = C[k] - c[i, k]
            dc += u * u
        return dc
    for r in range(Sc.shape[0]):
        u = 0.0
        for k in range(C.shape[0]):
            u += Sc[r, k] * (C[k] - c[i, k])
        dc += u * u
    return dc


@njit(cache=True)
def merge_distance_argmin(w, c, alive, n, x, C, alpha_c, Sc):
    """argmin_n d_n, d_n = (1 - alpha_c)|x - w_n|^2 + alpha_c |Sc (C - c_n)|^2; returns
    (b, d_b)."""
    best, best_d = -1, np.inf
    dim = x.shape[0]
    for i in range(n):
        if not alive[i]:
            continue
        dx = 0.0
        for k in range(dim):
            t = x[k] - w[i, k]
            dx += t * t
        d = (1.0 - alpha_c) * dx + alpha_c * context_gap(C, c, i, Sc)
        if d < best_d:
            best, best_d = i, d
    return best, best_d


@njit(inline="always")
def pair_distance(w, c, i, j, alpha_c, Sc):
    """The merge's distance between nodes i and j,
    ``(1 - alpha_c)|w_i - w_j|^2 + alpha_c |Sc (c_i - c_j)|^2`` (sensorimotor_map.py)."""
    dx = 0.0
    for k in range(w.shape[1]):
        t = w[i, k] - w[j, k]
        dx += t * t
    return (1.0 - alpha_c) * dx + alpha_c * context_gap(c[i], c, j, Sc)


@njit(cache=True)
def close_pair(w, c, alive, n, rows, alpha_c, Sc, r2):
    """The nearest pair (i, j), i in ``rows``, of live nodes closer than the GWR's matching
    radius, ``d_ij = (1 - alpha_c)|w_i - w_j|^2 + alpha_c |Sc (c_i - c_j)|^2 < r2``
    (sensorimotor_map.py, the merge); (-1, -1) when none."""
    bi, bj, best = -1, -1, r2
    for i in rows:
        if i < 0 or i >= n or not alive[i]:
            continue
        for j in range(n):
            if j == i or not alive[j]:
                continue
            d = pair_distance(w, c, i, j, alpha_c, Sc)
            if d < best:
                bi, bj, best = i, j, d
    return bi, bj


# ---------------------------------------------------------------- the node index
# A uniform grid over the first one or two coordinates of the weights (place_index.py):
# ``head[cell]`` the first node of a cell's list, ``node[0]`` / ``node[1]`` the next and
# previous node of each node's list, ``node[2]`` its cell (-1: not listed); ``geom`` =
# (origin x, origin y, cell width, 1 / width), ``shape`` = (cells along x, along y,
# coordinates used, valid). A search that finds ``shape[3]`` 0 scans every node instead.


@njit(cache=True)
def index_cell(w, i, geom, shape):
    """The cell of node i's weights (-1: outside the grid)."""
    fx = (w[i, 0] - geom[0]) * geom[3]
    if not (0.0 <= fx < shape[0]):
        return -1
    cy = 0
    if shape[2] > 1:
        fy = (w[i, 1] - geom[1]) * geom[3]
        if not (0.0 <= fy < shape[1]):
            return -1
        cy = int(fy)
    return int(fx) * shape[1] + cy


@njit(cache=True)
def _index_unlink(head, node, i):
    cell = node[2, i]
    if cell < 0:
        return
    nx, pv = node[0, i], node[1, i]
    if pv >= 0:
        node[0, pv] = nx
    else:
        head[cell] = nx
    if nx >= 0:
        node[1, nx] = pv
    node[0, i] = node[1, i] = node[2, i] = -1


@njit(cache=True)
def _index_link(head, node, i, cell):
    nx = head[cell]
    node[0, i], node[1, i], node[2, i] = nx, -1, cell
    if nx >= 0:
        node[1, nx] = i
    head[cell] = i


@njit(cache=True)
def index_build(w, alive, n, head, node, geom, shape):
    """List every live node of ``[0, n)`` in its cell; False (``shape[3]`` set to 0)
    when one lies outside the grid."""
    head[:] = -1
    node[:] = -1
    for i in range(n):
        if alive[i]:
            cell = index_cell(w, i, geom, shape)
            if cell < 0:
                shape[3] = 0
                return False
            _index_link(head, node, i, cell)
    shape[3] = 1
    return True


@njit(cache=True)
def index_move(w, alive, n, rows, k, head, node, geom, shape):
    """Bring the first k ``rows`` (weights or alive flags changed; may repeat) to their
    cells; False (``shape[3]`` set to 0: the caller builds the grid again) when a live
    one left the grid or a row lies beyond the node arrays."""
    if shape[3] == 0:
        return False
    for q in range(k):
        i = rows[q]
        if i < 0:
            continue
        if i >= node.shape[1]:
            shape[3] = 0
            return False
        cell = -1
        if i < n and alive[i]:
            cell = index_cell(w, i, geom, shape)
            if cell < 0:
                shape[3] = 0
                return False
        if cell != node[2, i]:
            _index_unlink(head, node, i)
            if cell >= 0:
                _index_link(head, node, i, cell)
    return True


@njit(cache=True)
def _index_square(geom, shape, x0, x1):
    """The cell (unbounded, clamped one cell outside the grid) of the point (x0, x1) and
    its coordinates in cell widths."""
    fx = (x0 - geom[0]) * geom[3]
    cx = int(min(max(math.floor(fx), -1.0), float(shape[0])))
    fy, cy = 0.0, 0
    if shape[2] > 1:
        fy = (x1 - geom[1]) * geom[3]
        cy = int(min(max(math.floor(fy), -1.0), float(shape[1])))
    return fx, cx, fy, cy


@njit(cache=True)
def _index_clearance(shape, fx, cx, fy, cy, r):
    """The distance (in cell widths, a little under) from the point to the nearest cell
    outside the square of cells within ``r`` of (cx, cy): a lower bound on the distance
    of every node the square does not hold (0 when the point is outside the square)."""
    g = min(fx - (cx - r), (cx + r + 1) - fx)
    if shape[2] > 1:
        g = min(g, fy - (cy - r), (cy + r + 1) - fy)
    return max(g, 0.0) * (1.0 - 1e-9)


@njit(cache=True)
def _index_covers(shape, cx, cy, r):
    """The square of cells within r of (cx, cy) holds the whole grid."""
    if cx - r > 0 or cx + r < shape[0] - 1:
        return False
    return shape[2] < 2 or (cy - r <= 0 and cy + r >= shape[1] - 1)


@njit(cache=True)
def _argmin_in_cell(w, c, alive, n, x, C, alpha_c, Sc, head, node, cell, best, best_d):
    """:func:`merge_distance_argmin` over one cell's list, from (best, best_d)."""
    i = head[cell]
    while i >= 0:
        if i < n and alive[i]:
            dx = 0.0
            for k in range(x.shape[0]):
                t = x[k] - w[i, k]
                dx += t * t
            d = (1.0 - alpha_c) * dx + alpha_c * context_gap(C, c, i, Sc)
            if d < best_d or (d == best_d and i < best):
                best, best_d = i, d
        i = node[0, i]
    return best, best_d


@njit(cache=True)
def indexed_argmin(w, c, alive, n, x, C, alpha_c, Sc, head, node, geom, shape):
    """:func:`merge_distance_argmin` through the node index: the cells in squares of
    growing width around x until no node outside can be as near as the best found
    (``(1 - alpha_c)`` times the squared distance along the indexed coordinates bounds
    ``d_n`` below); ties to the lowest id, as the scan."""
    if shape[3] == 0 or alpha_c >= 1.0:
        return merge_distance_argmin(w, c, alive, n, x, C, alpha_c, Sc)
    best, best_d = -1, np.inf
    fx, cx, fy, cy = _index_square(geom, shape, x[0], x[1] if shape[2] > 1 else 0.0)
    gx, gy = shape[0], shape[1]
    r = 0
    while True:
        for ix in range(max(cx - r, 0), min(cx + r, gx - 1) + 1):
            if ix == cx - r or ix == cx + r:          # a side of the square: every cell
                for iy in range(max(cy - r, 0), min(cy + r, gy - 1) + 1):
                    best, best_d = _argmin_in_cell(w, c, alive, n, x, C, alpha_c, Sc, head,
                                                   node, ix * gy + iy, best, best_d)
                continue
            if 0 <= cy - r < gy:                       # inside: the top and bottom cells
                best, best_d = _argmin_in_cell(w, c, alive, n, x, C, alpha_c, Sc, head, node,
                                               ix * gy + cy - r, best, best_d)
            if r > 0 and 0 <= cy + r < gy:
                best, best_d = _argmin_in_cell(w, c, alive, n, x, C, alpha_c, Sc, head, node,
                                               ix * gy + cy + r, best, best_d)
        if _index_covers(shape, cx, cy, r):
            return best, best_d
        lb = _index_clearance(shape, fx, cx, fy, cy, r) * geom[2]
        if (1.0 - alpha_c) * lb * lb > best_d:
            return best, best_d
        r += 1


@njit(cache=True)
def indexed_close_pair(w, c, alive, n, rows, alpha_c, Sc, r2, head, node, geom, shape):
    """:func:`close_pair` through the node index: for each i of ``rows`` only the cells
    within the radius (``(1 - alpha_c) |w_i - w_j|^2 < r2`` along the indexed
    coordinates); ties to the first row, then the lowest j, as the scan."""
    if shape[3] == 0 or alpha_c >= 1.0:
        return close_pair(w, c, alive, n, rows, alpha_c, Sc, r2)
    bi, bj, bq, best = -1, -1, -1, r2
    reach = math.sqrt(r2 / (1.0 - alpha_c)) * geom[3] * (1.0 + 1e-9)   # in cell widths
    gy = shape[1]
    for q in range(len(rows)):
        i = rows[q]
        if i < 0 or i >= n or not alive[i]:
            continue
        fx = (w[i, 0] - geom[0]) * geom[3]
        x0 = max(int(math.floor(fx - reach)), 0)
        x1 = min(int(math.floor(fx + reach)), shape[0] - 1)
        y0, y1 = 0, 0
        if shape[2] > 1:
            fy = (w[i, 1] - geom[1]) * geom[3]
            y0 = max(int(math.floor(fy - reach)), 0)
            y1 = min(int(math.floor(fy + reach)), gy - 1)
        for ix in range(x0, x1 + 1):
            for iy in range(y0, y1 + 1):
                j = head[ix * gy + iy]
                while j >= 0:
                    if j != i and j < n and alive[j]:
                        d = pair_distance(w, c, i, j, alpha_c, Sc)
                        if d < best or (d == best and (q < bq or (q == bq and j < bj))):
                            bi, bj, bq, best = i, j, q, d
                    j = node[0, j]
    return bi, bj


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
def incident_neighbours(out, inn, n, b):
    """Nodes linked to b in either direction (sorted, unique): its links' targets and the
    sources of the links into it (``inn``, :func:`in_links`)."""
    found = np.empty(out.shape[1] + inn.shape[1], dtype=np.int64)
    c = 0
    for s in range(out.shape[1]):
        if out[b, s] >= 0 and out[b, s] != b:
            found[c] = out[b, s]
            c += 1
    for s in range(inn.shape[1]):
        if inn[b, s] >= 0 and inn[b, s] != b:
            found[c] = inn[b, s]
            c += 1
    found = np.sort(found[:c])
    keep = np.empty(c, dtype=np.int64)
    k = 0
    for q in range(c):
        if k == 0 or found[q] != keep[k - 1]:
            keep[k] = found[q]
            k += 1
    return keep[:k]


@njit(cache=True)
def link_differences(w, out, n, d):
    """``w_i - w_j`` of every link i -> j of the rows ``i < n``, row by row and slot by slot
    (the order of ``np.nonzero(out[:n] >= 0)``), written to the rows of ``d``; returns how
    many (the median link length, motivation.py, takes their norms with numpy as
    before, so that it is the same to the bit)."""
    c = 0
    for i in range(n):
        for s in range(out.shape[1]):
            j = out[i, s]
            if j >= 0:
                for k in range(w.shape[1]):
                    d[c, k] = w[i, k] - w[j, k]
                c += 1
    return c


@njit(cache=True)
def in_links(out, n, inn):
    """The sources of the links into every node: ``inn[j]`` lists each i with a link
    i -> j once (-1: empty slots), the reverse of ``out``; returns False when some row of
    ``inn`` is too narrow (nothing is then to be trusted)."""
    inn[:] = -1
    for i in range(n):
        for s in range(out.shape[1]):
            j = out[i, s]
            if j >= 0 and not _in_link_add(inn, j, i):
                return False
    return True


@njit(cache=True)
def _in_link_add(inn, j, i):
    for s in range(inn.shape[1]):
        if inn[j, s] < 0:
            inn[j, s] = i
            return True
    return False


@njit(cache=True)
def _in_link_remove(inn, j, i):
    for s in range(inn.shape[1]):
        if inn[j, s] == i:
            inn[j, s] = -1
            return


@njit(cache=True)
def goal_reward(w, alive, i, g, inv, cut, floor):
    """Eq. 10 for node i: sim(i, g) = exp(-|w_i - w_g|^2 inv), 0 below ``floor`` (no exp
    beyond ``cut``, where it would be below it) and for dead slots."""
    if not alive[i]:
        return 0.0
    d = 0.0
    for k in range(w.shape[1]):
        t = w[i, k] - w[g, k]
        d += t * t
    if d * inv > cut:
        return 0.0
    r = np.exp(-d * inv)
    return r if r >= floor else 0.0


@njit(cache=True)
def goal_rewards(w, alive, n, g, sigma, floor, R, rows, k):
    """Eq. 10: R_i = sim(i, g) = exp(-|w_i - w_g|^2 / (2 sigma^2)), 0 below ``floor``, for
    every node (``k`` < 0) or for the nodes ``rows[:k]`` only (the others unchanged)."""
    inv = 1.0 / (2.0 * sigma * sigma)
    cut = 1.0 - np.log(floor) if floor > 0.0 else np.inf   # exp(-cut) < floor: no exp
    for q in range(n if k < 0 else k):
        i = q if k < 0 else rows[q]
        R[i] = goal_reward(w, alive, i, g, inv, cut, floor)


@njit(cache=True)
def nearest_weight_among(w, alive, x, best, rows, k):
    """:func:`nearest_weight` when only the nodes ``rows[:k]`` changed since it answered
    ``best`` (which did not): the nearest of ``best`` and those (ties: the lowest id, as
    the scan)."""
    best_d = 0.0
    for c in range(x.shape[0]):
        t = x[c] - w[best, c]
        best_d += t * t
    for q in range(k):
        i = rows[q]
        if not alive[i]:
            continue
        d = 0.0
        for c in range(x.shape[0]):
            t = x[c] - w[i, c]
            d += t * t
        if d < best_d or (d == best_d and i < best):
            best, best_d = i, d
    return best


@intrinsic
def _fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (a fused multiply-add, LLVM's ``llvm.fma``)."""
    def codegen(context, builder, signature, args):
        return builder.fma(*args)
    return types.float64(types.float64, types.float64, types.float64), codegen


@njit(cache=True)
def frame_delta(delta, T, out):
    """The forward model in frame coordinates, ``out = delta T^T`` (frame.py), each sum
    accumulated as a BLAS matrix product whose kernels fuse multiply-adds does it: the
    first product, then one fused multiply-add per further term in order (the bits of
    numpy's ``delta @ T.T`` on such a BLAS, which ``frame.forward_model`` probes before
    it uses this; test_frame.py)."""
    for p in range(delta.shape[0]):
        for r in range(T.shape[0]):
            s = delta[p, 0] * T[r, 0]
            for c in range(1, T.shape[1]):
                s = _fma(delta[p, c], T[r, c], s)
            out[p, r] = s
    return out


@njit(cache=True)
def frame_coords(w, T, rows, k, out):
    """Frame coordinates ``out[i] = T w_i`` (frame.py) of every row of w (``k`` < 0) or
    of the rows ``rows[:k]`` only."""
    for q in range(w.shape[0] if k < 0 else k):
        i = q if k < 0 else rows[q]
        for r in range(T.shape[0]):
            s = 0.0
            for c in range(T.shape[1]):
                s += T[r, c] * w[i, c]
            out[i, r] = s


@njit(cache=True)
def absorbing_flags(terminal, use_terminal, closed, use_closed, R, goal_r, n, rows, k,
                    absorbing, terminal_only, count):
    """The absorbing nodes of Eq. 4-5' (motivation.py): ``absorbing[i]`` = (terminal or
    closed) and ``R_i < goal_r``, and ``terminal_only[i]`` = terminal and ``R_i < goal_r``
    (``use_terminal`` / ``use_closed`` False: no node is), for every node (``k`` < 0,
    ``count`` ignored) or the nodes ``rows[:k]`` only; returns the number of
    ``terminal_only`` nodes (``count``: before the call)."""
    if k < 0:
        count = 0
    for q in range(n if k < 0 else k):
        i = q if k < 0 else rows[q]
        if i >= n:
            continue
        below = R[i] < goal_r
        t = use_terminal and terminal[i] and below
        if k >= 0:
            count -= terminal_only[i]
        count += t
        terminal_only[i] = t
        absorbing[i] = t or (use_closed and closed[i] and below)
    return count


@njit(cache=True)
def link_adjacency(out, E, n, alive, absorbing, reverse):
    """The links with E > 0 as adjacency lists (CSR): node j's are ``adj[deg[j]:deg[j +
    1]]``, its successors, or with ``reverse`` its predecessors. An absorbing node has no
    successor; dead slots have none either way."""
    K = out.shape[1]
    deg = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        if not alive[i] or absorbing[i]:
            continue
        for s in range(K):
            j = out[i, s]
            if j >= 0 and j < n and E[i, s] > 0.0:
                deg[(j if reverse else i) + 1] += 1
    for j in range(n):
        deg[j + 1] += deg[j]
    adj = np.empty(deg[n], dtype=np.int64)
    fill = deg[:n].copy()
    for i in range(n):
        if not alive[i] or absorbing[i]:
            continue
        for s in range(K):
            j = out[i, s]
            if j >= 0 and j < n and E[i, s] > 0.0:
                a, b = (j, i) if reverse else (i, j)
                adj[fill[a]] = b
                fill[a] += 1
    return deg, adj


@njit(cache=True)
def reaches_source(out, E, n, absorbing, alive, source, mark):
    """``mark[i]``: some link path with E > 0 leads from node i to a source node
    (``source[i]``: R_i > 0 or an option of the value of the unknown). A reverse
    breadth-first search from the sources over the links (an absorbing node has no
    successor, a dead slot is never marked). Returns the number of marked nodes.

    Eq. 4-5 have no source in an unmarked node, whose potential is then exactly 0; value
    iteration alone only approaches 0 geometrically, leaving numerical dust that Eq. 6
    would follow."""
    deg, pred = link_adjacency(out, E, n, alive, absorbing, True)   # j <- i
    queue = np.empty(n, dtype=np.int64)
    head, tail = 0, 0
    for i in range(n):
        mark[i] = alive[i] and source[i]
        if mark[i]:
            queue[tail] = i
            tail += 1
    while head < tail:
        j = queue[head]
        head += 1
        for p in range(deg[j], deg[j + 1]):
            i = pred[p]
            if not mark[i]:
                mark[i] = True
                queue[tail] = i
                tail += 1
    return tail


@njit(cache=True)
def _believed(out, E, bump_t, succ, i, s):
    """Link slot s of node i has E > 0 and is not contradicted (:func:`contradicted`)."""
    j = out[i, s]
    if j < 0 or E[i, s] <= 0.0:
        return False
    for a in range(bump_t.shape[1]):
        if bump_t[i, a] >= 0 and succ[i, a] == j:
            return False
    return True


@njit(cache=True)
def reaches_source_from(out, E, n, absorbing, alive, source, bump_t, succ, V, start, known,
                        stamp, seen, search, stack):
    """:func:`reaches_source`'s mark of node ``start`` over the links the outcome memory
    does not contradict (:func:`contradicted`), by a depth-first search from it that
    stops at the first source, or node known to reach one; the successor of largest V
    first, so that on a map whose potentials lead to a source the search mostly walks
    that way alone. ``known[i]`` is ``stamp`` for a node known to reach a source,
    ``-stamp`` for one known not to (a new stamp forgets both): a search that finds one
    marks the nodes of its path, one that finds none every node it visited (all that
    they lead to was visited). ``seen`` (``search``: this search's mark) and ``stack``:
    work arrays of n entries."""
    if not alive[start]:
        return False
    if known[start] == stamp or source[start]:
        known[start] = stamp
        return True
    if known[start] == -stamp:
        return False
    K = out.shape[1]
    depth = 0
    stack[0] = start
    seen[start] = search
    while depth >= 0:
        i = stack[depth]
        nxt = -1
        if not absorbing[i]:
            best = -1.0
            for s in range(K):                       # the untried successor of largest V
                j = out[i, s]
                if j < 0 or j >= n or not alive[j] or seen[j] == search or \
                        known[j] == -stamp or not _believed(out, E, bump_t, succ, i, s):
                    continue
                if V[j] > best:
                    best, nxt = V[j], j
        if nxt < 0:
            depth -= 1                               # nothing left from i
            continue
        if source[nxt] or known[nxt] == stamp:
            for q in range(depth + 1):
                known[stack[q]] = stamp
            known[nxt] = stamp
            return True
        seen[nxt] = search
        depth += 1
        stack[depth] = nxt
    for i in range(n):                               # every node it visited: none reaches
        if seen[i] == search:
            known[i] = -stamp
    return False


@njit(cache=True)
def link_steps(out, E, n, alive, absorbing, root, reverse, dist):
    """``dist[i]``: the fewest links with E > 0 from node ``root`` to i (``reverse``: from
    i to ``root``), -1 where no link path leads; an absorbing node has no successor, a
    dead slot is never reached. Breadth-first search over the links (their steps, not
    their reliabilities: the route as the agent would walk it)."""
    deg, adj = link_adjacency(out, E, n, alive, absorbing, reverse)
    dist[:n] = -1
    if root < 0 or root >= n or not alive[root]:
        return
    queue = np.empty(n, dtype=np.int64)
    queue[0] = root
    dist[root] = 0
    head, tail = 0, 1
    while head < tail:
        j = queue[head]
        head += 1
        for p in range(deg[j], deg[j + 1]):
            i = adj[p]
            if dist[i] < 0:
                dist[i] = dist[j] + 1
                queue[tail] = i
                tail += 1


@njit(cache=True)
def stale(bump_e, i, a, episode, trust):
    """Pair (i, a) is a stale wall: its last outcome was a bump, ``trust`` episodes (> 0)
    or more ago (motivation.py, Eq. 5')."""
    return trust > 0 and bump_e[i, a] >= 0 and episode - bump_e[i, a] >= trust


@njit(cache=True)
def at_cell(w, alive, j, x, L):
    """Node j is alive and within L / 2 of position x (where a move once led is still
    the node at the cell it predicts)."""
    gap = 0.0
    for k in range(w.shape[1]):
        gap += (w[j, k] - x[k]) ** 2
    return alive[j] and gap <= 0.25 * L * L


@njit(cache=True)
def stale_savings(w, alive, n, delta, L, gamma, grid, origin, tried, bump_e, succ, episode,
                  trust, ds, dg, route, onb, ong, res_i, res_a, res_s):
    """The steps each stale remembered wall would save on the known route if it opened
    (motivation.py, Eq. 5'): for a pair (i, a) stale (``trust`` episodes since its last
    bump), the way ``ds[i]`` steps from the episode's start to i, the step into the wall
    cell, and on to the goal, ``dg`` steps, through the cell's known node (a move made
    before) or its best exit (:func:`wall_exits`, ``k`` cells along its run then one step
    out: ``k + 2``), against ``route`` steps. The pairs with a saving go to ``res_i``,
    ``res_a``, ``res_s``; returns how many. ``onb`` / ``ong``: scratch. A way through a
    wall of i takes at least ``ds[i] + 1`` steps, so the walls of the nodes with ``ds[i] +
    1 >= route`` are not looked at (they cannot save a step)."""
    x, y, z = np.empty(w.shape[1]), np.empty(w.shape[1]), np.empty(w.shape[1])
    Vd = np.zeros(n + 1)                       # gamma^dg: wall_exits then picks min k + dg
    for q in range(n):
        if dg[q] >= 0:
            Vd[q] = gamma ** dg[q]
    c = 0
    for i in range(n):
        if not alive[i] or ds[i] < 0 or ds[i] + 1 >= route:
            continue
        for a in range(tried.shape[1]):
            if not tried[i, a] or not stale(bump_e, i, a, episode, trust):
                continue
            for k in range(w.shape[1]):
                x[k] = w[i, k] + delta[a, k]
            best = -1
            j = succ[i, a]
            if j >= 0:
                if j < n and at_cell(w, alive, j, x, L) and dg[j] >= 0:
                    best = ds[i] + 1 + dg[j]
            else:
                for b in range(onb.shape[2]):
                    onb[i, a, b] = -1
                    ong[i, a, b] = 0.0
                if wall_exits_into(w, i, a, x, delta, L, grid, origin, Vd, gamma, onb, ong,
                                   y, z):
                    for b in range(onb.shape[2]):
                        q = onb[i, a, b]
                        if q >= 0 and dg[q] >= 0:
                            k = int(np.round(np.log(ong[i, a, b]) / np.log(gamma)))
                            p = ds[i] + k + 2 + dg[q]
                            if best < 0 or p < best:
                                best = p
            if best >= 0 and best < route:
                res_i[c], res_a[c], res_s[c] = i, a, route - best
                c += 1
    return c


@njit(cache=True)
def successor_value(V, j, U_o, nb, ng, k, gamma):
    """S of Eq. 5' for an option whose successor is ``j``: V of a known node (j >= 0),
    gamma max ``ng[k, b] V(nb[k, b])`` over the known exits ``nb[k]`` of a remembered
    wall cell (j = -2; ``ng`` discounts the unknown cells of the run between,
    :func:`wall_exits`), or the optimistic U of unknown space (j = -1, ``U_o``)."""
    if j >= 0:
        return V[j]
    if j == -2:
        best = 0.0
        for b in range(nb.shape[1]):
            q = nb[k, b]
            if q >= 0 and ng[k, b] * V[q] > best:
                best = ng[k, b] * V[q]
        return gamma * best
    return U_o


@njit(cache=True)
def option_successor(V, U, osucc, onb, ong, i, a, gamma):
    """The value of option (i, a)'s successor: :func:`successor_value` read off the
    (node, primitive) tables in place (no view of node i's rows: the solves call this for
    every option of every node they update)."""
    j = osucc[i, a]
    if j >= 0:
        return V[j]
    if j == -2:
        best = 0.0
        for b in range(onb.shape[2]):
            q = onb[i, a, b]
            if q >= 0 and ong[i, a, b] * V[q] > best:
                best = ong[i, a, b] * V[q]
        return gamma * best
    return U[i, a]


@njit(cache=True)
def contradicted(out, E, n, bump_t, succ):
    """E with the links zeroed whose pair's last outcome was a bump (the move from i with
    primitive a once led to ``succ[i, a]``, and bumped since): what the outcome memory
    still believes traversable."""
    Eb = E[:n].copy()
    for i in range(n):
        for a in range(bump_t.shape[1]):
            j = succ[i, a]
            if bump_t[i, a] >= 0 and j >= 0:
                for s in range(out.shape[1]):
                    if out[i, s] == j:
                        Eb[i, s] = 0.0
    return Eb


@njit(cache=True)
def option_lists(n, absorbing, rho, U, osucc, onb, ong):
    """The options of Eq. 5' (``rho[i, a] > 0``) as flat lists, node by node (CSR: node
    i's are ``[first[i], first[i + 1])``, primitives in order): rho, the successor
    ``osucc``, U, and a wall cell's known exits ``onb`` with their discounts ``ong``.
    Absorbing nodes have none.
    (The sweeps read these lists: a few times faster than the (node, primitive) tables.)"""
    A = rho.shape[1]
    first = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        first[i + 1] = first[i]
        if not absorbing[i]:
            for a in range(A):
                if rho[i, a] > 0.0:
                    first[i + 1] += 1
    m = first[n]
    o_rho = np.empty(m)
    o_succ = np.empty(m, dtype=np.int64)
    o_U = np.empty(m)
    o_nb = np.empty((m, onb.shape[2]), dtype=np.int64)
    o_ng = np.empty((m, onb.shape[2]))
    c = 0
    for i in range(n):
        if not absorbing[i]:
            for a in range(A):
                if rho[i, a] > 0.0:
                    o_rho[c], o_succ[c], o_U[c] = rho[i, a], osucc[i, a], U[i, a]
                    o_nb[c] = onb[i, a]
                    o_ng[c] = ong[i, a]
                    c += 1
    return first, o_rho, o_succ, o_U, o_nb, o_ng


@njit(cache=True)
def value_iteration(out, E, R, V, n, beta, gamma, tol, v_floor, max_sweeps, absorbing,
                    alive, U, rho, osucc, onb, ong):
    """Synchronous sweeps of Eq. 4-5 (with the options of the value of the unknown) until
    every |beta Delta_V(i)| <= tol V(i) + v_floor.

    ``V`` has n + 1 entries, ``V[n] == 0`` (the target of empty link slots). A node with
    ``absorbing[i]`` has no successor (a terminal state: Delta_V(i) = R_i - V(i)). Node i's
    option for primitive a (``rho[i, a] > 0``) is a virtual successor worth
    ``rho S + (1 - rho) (R_i + gamma max_k E[i, k] V(k))`` with ``S = V(osucc[i, a])``
    for a known successor, else ``U[i, a]`` (motivation.py, Eq. 5';
    :func:`successor_value`, here over :func:`option_lists`).
    Nodes from which no link path leads to a source (R > 0 or an option) get exactly
    V = 0 (:func:`reaches_source`), as do dead slots. Returns the number of sweeps.
    """
    K = out.shape[1]
    first, o_rho, o_succ, o_U, o_nb, o_ng = option_lists(n, absorbing, rho, U, osucc, onb,
                                                         ong)
    source = np.empty(n, dtype=np.bool_)
    for i in range(n):
        source[i] = R[i] > 0.0 or first[i + 1] > first[i]
    live = np.empty(n, dtype=np.bool_)
    reaches_source(out, E, n, absorbing, alive, source, live)
    for i in range(n):
        if not live[i]:
            V[i] = 0.0
    new = np.empty(n)
    sweeps = 0
    for sweeps in range(1, max_sweeps + 1):
        done = True
        for i in range(n):
            if not live[i]:
                new[i] = 0.0
                continue
            best = 0.0
            if not absorbing[i]:
                for s in range(K):                      # max_k E[i, k] V(k)
                    j = out[i, s]
                    if j >= 0:
                        ev = E[i, s] * V[j]
                        if ev > best:
                            best = ev
                stay = R[i] + gamma * best      # where a failed test leaves the agent
                opt = 0.0
                for c in range(first[i], first[i + 1]):   # max_a O(i, a), Eq. 5'
                    sv = successor_value(V, o_succ[c], o_U[c], o_nb, o_ng, c, gamma)  # S
                    r = o_rho[c]
                    ov = r * sv + (1.0 - r) * stay
                    if ov > opt:
                        opt = ov
                if opt > best:
                    best = opt
            step = beta * (R[i] + gamma * best - V[i])      # beta * Delta_V(i), Eq. 4
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


# ---------------------------------------------------------------- incremental Eq. 4-5'
# node_target and the heap's helpers are inlined into their callers at numba's IR level
# (``inline="always"``): the solves call them once per node update and per reader of it,
# and a call that is not inlined passes each of its arrays as a struct of several words,
# which costs more than the few link and option slots the body reads. The same operations
# in the same order: the same V to the bit.
# An inlined body takes a reference to each array it is passed (numba's NRT_incref, an
# atomic add, and NRT_decref after), and LLVM's reference-count pruning removes those
# pairs only when the body has no branch around its loops: no early return, no ``break``.
# Left in, they cost several times the body itself, on every call. So these helpers are
# written without either (test_kernels_refcount.py checks their callers' loops).
@njit(inline="always")
def node_target(i, out, E, R, V, gamma, absorbing, alive, U, rho, osucc, onb, ong):
    """The right-hand side of Eq. 4-5' at node i, ``R_i + gamma max(max_k E[i, k] V(k),
    max_a O(i, a))`` (:func:`value_iteration`'s update with beta = 1): the value V(i) has
    at the fixed point given its successors' values. Dead slots: 0; absorbing nodes: R_i
    (no loop turns for them: ``live`` = 0; their R_i + gamma 0, times ``alive``)."""
    live = np.int64(alive[i]) * (1 - np.int64(absorbing[i]))
    best = 0.0
    for s in range(out.shape[1] * live):                # max_k E[i, k] V(k)
        j = out[i, s]
        if j >= 0:
            ev = E[i, s] * V[j]
            if ev > best:
                best = ev
    stay = R[i] + gamma * best
    opt = 0.0
    for a in range(rho.shape[1] * live):                # max_a O(i, a), Eq. 5'
        r = rho[i, a]
        if r > 0.0:
            # S (:func:`option_successor`), written out: the solves spend most of their
            # time here, and the call is not inlined
            j = osucc[i, a]
            if j >= 0:
                sv = V[j]
            elif j == -2:
                sv = 0.0
                for b in range(onb.shape[2]):
                    q = onb[i, a, b]
                    if q >= 0 and ong[i, a, b] * V[q] > sv:
                        sv = ong[i, a, b] * V[q]
                sv *= gamma
            else:
                sv = U[i, a]
            ov = r * sv + (1.0 - r) * stay
            if ov > opt:
                opt = ov
    if opt > best:
        best = opt
    return alive[i] * (R[i] + gamma * best)


@njit(cache=True)
def predecessors(out, n, alive, osucc, onb):
    """Who reads whose value in Eq. 4-5' (CSR, ``pred[first[j]:first[j + 1]]``: the nodes i
    whose target reads V(j)): links i -> j, option successors ``osucc[i, a] == j`` and wall
    exits ``onb[i, a, b] == j`` of every option slot, whatever its rho (a superset: a rho
    that changes needs no rebuild, nor a link or successor that goes: the solves compute
    the target of a reader too many in vain, and miss none)."""
    K, P, B = out.shape[1], osucc.shape[1], onb.shape[2]
    first = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        if alive[i]:
            for s in range(K):
                j = out[i, s]
                if 0 <= j < n:
                    first[j + 1] += 1
            for a in range(P):
                j = osucc[i, a]
                if 0 <= j < n:
                    first[j + 1] += 1
                for b in range(B):
                    j = onb[i, a, b]
                    if 0 <= j < n:
                        first[j + 1] += 1
    for j in range(n):
        first[j + 1] += first[j]
    pred = np.empty(first[n], dtype=np.int64)
    fill = first[:n].copy()
    for i in range(n):
        if alive[i]:
            for s in range(K):
                j = out[i, s]
                if 0 <= j < n:
                    pred[fill[j]] = i
                    fill[j] += 1
            for a in range(P):
                j = osucc[i, a]
                if 0 <= j < n:
                    pred[fill[j]] = i
                    fill[j] += 1
                for b in range(B):
                    j = onb[i, a, b]
                    if 0 <= j < n:
                        pred[fill[j]] = i
                        fill[j] += 1
    return first, pred


@njit(inline="always")
def _heap_down(heap, pos, key, k, size):
    x = heap[k]
    while True:
        c = 2 * k + 1
        if c >= size:
            break
        if c + 1 < size and key[heap[c + 1]] > key[heap[c]]:
            c += 1
        if key[heap[c]] <= key[x]:
            break
        heap[k] = heap[c]
        pos[heap[k]] = k
        k = c
    heap[k] = x
    pos[x] = k


@njit(inline="always")
def _heap_push(heap, pos, key, size, i, priority):
    """Push node i with ``priority`` (or raise its priority if queued); returns the size."""
    k = pos[i]
    grow = k < 0
    if grow:
        k = size
    if grow or priority > key[i]:
        key[i] = priority
    ki = key[i]
    p = (k - 1) >> 1
    while k > 0 and key[heap[p]] < ki:                  # sift up
        heap[k] = heap[p]
        pos[heap[k]] = k
        k = p
        p = (k - 1) >> 1
    heap[k] = i
    pos[i] = k
    return size + grow


@njit(cache=True)
def _queue_seeds(out, E, R, V, gamma, tol, v_floor, absorbing, alive, U, rho, osucc, onb,
                 ong, seeds, n_seeds, heap, pos, key, size, by_value, target, reuse):
    """Push every node of ``seeds[:n_seeds]`` whose target (:func:`node_target`) differs
    from its V by more than ``tol`` times the target plus ``v_floor``, keyed by that
    change, or with ``by_value`` by the target itself; returns the queue's size. Every
    target computed is kept in ``target`` (:func:`_drain`); with ``reuse``, a seed's
    target already there (not NaN: computed since the last change of what it reads) is
    taken as it is."""
    for k in range(n_seeds):
        i = seeds[k]
        t = target[i]
        if not reuse or t != t:
            t = node_target(i, out, E, R, V, gamma, absorbing, alive, U, rho, osucc, onb,
                            ong)
            target[i] = t
        d = abs(t - V[i])
        if d > tol * t + v_floor:
            size = _heap_push(heap, pos, key, size, i, t if by_value else d)
    return size


@njit(cache=True)
def _drain(out, E, R, V, gamma, tol, v_floor, absorbing, alive, U, rho, osucc, onb, ong,
           first, pred, max_updates, heap, pos, key, size, by_value, target):
    """The loop of :func:`prioritized_sweep` and :func:`ordered_solve`: pop the node of
    the largest key, set its V to its target, queue the nodes that read it whose own
    change would exceed ``tol`` (keyed as :func:`_queue_seeds`); until the queue is empty
    (returns the updates) or ``max_updates`` were made (returns -1, ``pos`` left all
    -1). A queued node's target is the one last computed for it (``target``): within a
    call only V changes, and every change of V(j) computes again the target of every
    node that reads it (``pred``), so that one is still its target when it is popped."""
    updates = 0
    while size > 0:
        i = heap[0]
        pos[i] = -1
        size -= 1
        if size > 0:
            heap[0] = heap[size]
            pos[heap[0]] = 0
            _heap_down(heap, pos, key, 0, size)
        if updates >= max_updates:
            while size > 0:                          # leave pos clean for the next call
                size -= 1
                pos[heap[size]] = -1
            return -1
        V[i] = target[i]
        updates += 1
        for c in range(first[i], first[i + 1]):
            p = pred[c]
            t = node_target(p, out, E, R, V, gamma, absorbing, alive, U, rho, osucc, onb,
                            ong)
            target[p] = t
            d = abs(t - V[p])
            if d > tol * t + v_floor:
                size = _heap_push(heap, pos, key, size, p, t if by_value else d)
    return updates


@njit(cache=True)
def prioritized_sweep(out, E, R, V, n, gamma, tol, v_floor, absorbing, alive, U, rho, osucc,
                      onb, ong, first, pred, seeds, n_seeds, max_updates, heap, pos, key):
    """Eq. 4-5' solved incrementally by prioritized sweeping (Moore & Atkeson 1993) from a
    solution of a map that differs from this one in the rows ``seeds[:n_seeds]`` only
    (their links, rewards, options or absorbing flag changed): each queued node's value is
    set to its target (:func:`node_target`), largest change first, and the nodes that read
    it (``pred``, :func:`predecessors`) are queued when their own change would exceed
    ``tol V + v_floor``; it stops when the queue holds nothing above that. Returns the
    updates made, or -1 after ``max_updates`` (the caller then solves in full: a change
    that cuts a region off its sources decays only geometrically). ``heap``, ``pos``
    (-1 = not queued) and ``key`` are work arrays of n entries; ``pos`` is left all -1."""
    target = np.empty(len(V))
    size = _queue_seeds(out, E, R, V, gamma, tol, v_floor, absorbing, alive, U, rho, osucc,
                        onb, ong, seeds, n_seeds, heap, pos, key, 0, False, target, False)
    return _drain(out, E, R, V, gamma, tol, v_floor, absorbing, alive, U, rho, osucc, onb,
                  ong, first, pred, max_updates, heap, pos, key, size, False, target)


@njit(cache=True)
def ordered_solve(out, E, R, V, n, gamma, tol, v_floor, absorbing, alive, U, rho, osucc,
                  onb, ong, first, pred, seeds, n_seeds, max_updates, heap, pos, key):
    """:func:`_ordered_solve` computing every seed's target."""
    return _ordered_solve(out, E, R, V, n, gamma, tol, v_floor, absorbing, alive, U, rho,
                          osucc, onb, ong, first, pred, seeds, n_seeds, max_updates, heap,
                          pos, key, np.empty(len(V)), False)


@njit(cache=True)
def _ordered_solve(out, E, R, V, n, gamma, tol, v_floor, absorbing, alive, U, rho, osucc,
                   onb, ong, first, pred, seeds, n_seeds, max_updates, heap, pos, key, target,
                   reuse):
    """Eq. 4-5' on the nodes ``seeds[:n_seeds]`` from values at or below their fixed point
    (V = 0 after a goal change, or after :func:`invalidate`), largest value first, as
    Dijkstra's algorithm settles a shortest path: with ``R`` = 0 a node is worth at most
    gamma times its best successor (E <= 1, rho <= 1), so a node popped after every
    larger one mostly has its final value at its first update. Two things break that,
    and are dealt with: the nodes with R > 0 among the seeds (the goal and its
    neighbours) feed each other, a goal and its neighbour converging by gamma^2 a round,
    so they are first solved among themselves by Gauss-Seidel rounds until they change
    by less than ``tol / 100`` of their value (the others at their current values); and
    an option mixes two successors (``rho S + (1 - rho) stay``), so a node may rise again
    when a smaller successor is settled: it is queued again, as by
    :func:`prioritized_sweep`, whose stopping rule this shares. Returns the updates made
    (the rounds of the first part not counted), or -1 after ``max_updates``.
    ``target``, ``reuse``: the targets already known (:func:`_queue_seeds`)."""
    m = 0
    for k in range(n_seeds):
        if R[seeds[k]] > 0.0 and alive[seeds[k]]:
            m += 1
    cluster = np.empty(m, dtype=np.int64)          # the seeds with R > 0
    m = 0
    for k in range(n_seeds):
        if R[seeds[k]] > 0.0 and alive[seeds[k]]:
            cluster[m] = seeds[k]
            m += 1
    for _ in range(100000):                        # solved among themselves
        change = 0.0
        for i in cluster:
            t = node_target(i, out, E, R, V, gamma, absorbing, alive, U, rho, osucc, onb,
                            ong)
            d = abs(t - V[i]) - 0.01 * tol * t
            if d > change:
                change = d
            V[i] = t
        if change <= v_floor:
            break
    size = 0
    for j in cluster:                              # then who reads them, and the seeds
        for c in range(first[j], first[j + 1]):
            p = pred[c]
            t = node_target(p, out, E, R, V, gamma, absorbing, alive, U, rho, osucc, onb,
                            ong)
            target[p] = t
            if abs(t - V[p]) > tol * t + v_floor:
                size = _heap_push(heap, pos, key, size, p, t)
    size = _queue_seeds(out, E, R, V, gamma, tol, v_floor, absorbing, alive, U, rho, osucc,
                        onb, ong, seeds, n_seeds, heap, pos, key, size, True, target,
                        reuse)
    return _drain(out, E, R, V, gamma, tol, v_floor, absorbing, alive, U, rho, osucc, onb,
                  ong, first, pred, max_updates, heap, pos, key, size, True, target)


@njit(cache=True)
def invalidate_solve(out, E, R, V, n, gamma, tol, v_floor, absorbing, alive, U, rho, osucc,
                     onb, ong, first, pred, seeds, n_seeds, found, mark, max_updates, heap,
                     pos, key):
    """:func:`invalidate`, then :func:`ordered_solve` from the seeds and the nodes it
    found, in one call; returns (found, the ordered solve's result). When it found none,
    V is as it was and the targets it computed for the seeds are still theirs: the
    ordered solve takes them instead of computing them again."""
    target = np.full(len(V), np.nan)
    k = invalidate(out, E, R, V, n, gamma, tol, v_floor, absorbing, alive, U, rho, osucc,
                   onb, ong, first, pred, seeds, n_seeds, found, mark, target)
    both = seeds[:n_seeds]
    if k > 0:
        both = np.concatenate((seeds[:n_seeds], found[:k]))
    done = _ordered_solve(out, E, R, V, n, gamma, tol, v_floor, absorbing, alive, U, rho,
                          osucc, onb, ong, first, pred, both, len(both), max_updates, heap,
                          pos, key, target, k == 0)
    return k, done


@njit(cache=True)
def invalidate(out, E, R, V, n, gamma, tol, v_floor, absorbing, alive, U, rho, osucc, onb,
               ong, first, pred, seeds, n_seeds, found, mark, target):
    """Before an incremental solve of a change that may lower values (a link removed, an
    E, R or option gone, a node made absorbing or dead): the nodes whose value rested on
    it, with V set to 0 (LPA*'s under-consistent nodes, Koenig & Likhachev). A seed whose
    target (:func:`node_target`) fell below its V by more than ``tol V + v_floor`` is
    one; so is every node that reads one of them (``pred``) whose target then falls so.
    Lowering those values by sweeping would take geometrically many rounds where two
    nodes held each other up (a region cut off from its sources); from 0 they rise to the
    fixed point in one ordered pass (:func:`ordered_solve`). Writes them to ``found``
    (n entries) and returns how many; ``mark`` (n booleans, all False) is left so; the
    targets of the seeds it looked at, to ``target``."""
    c = 0
    for k in range(n_seeds):
        i = seeds[k]
        if mark[i] or V[i] <= 0.0:
            continue
        t = node_target(i, out, E, R, V, gamma, absorbing, alive, U, rho, osucc, onb, ong)
        target[i] = t
        if t < V[i] - tol * V[i] - v_floor:
            mark[i] = True
            V[i] = 0.0
            found[c] = i
            c += 1
    h = 0
    while h < c:
        j = found[h]
        h += 1
        for q in range(first[j], first[j + 1]):
            p = pred[q]
            if mark[p] or V[p] <= 0.0:
                continue
            t = node_target(p, out, E, R, V, gamma, absorbing, alive, U, rho, osucc, onb,
                            ong)
            if t < V[p] - tol * V[p] - v_floor:
                mark[p] = True
                V[p] = 0.0
                found[c] = p
                c += 1
    for k in range(c):
        mark[found[k]] = False
    return c


@njit(cache=True)
def changed_rows(out, E, R, absorbing, out0, E0, R0, absorbing0, n, seeds, rows, k):
    """The rows whose links, reliabilities, reward or absorbing flag differ from the copy
    (``out0`` ...) of the last solve, written into ``seeds``, and the copy brought up to
    date; every row (``k`` < 0), or only the rows ``rows[:k]`` (the only ones that may
    have changed: the map's change log; repeats are seeded once, in ascending order as
    by the scan, so that the sweep that follows is the same). Returns (count, lost,
    relinked): ``lost`` when a change may cut a node off its sources (a link removed or
    retargeted or its E gone to 0, a node made absorbing, a reward gone to 0), which
    prioritized sweeping only follows geometrically; ``relinked`` when a link got a new
    target (:func:`predecessors` must be rebuilt; one removed leaves a reader too many
    there, which costs a target computed in vain but misses none)."""
    K = out.shape[1]
    c = 0
    lost = False
    relinked = False
    for q in range(n if k < 0 else k):
        i = q if k < 0 else rows[q]
        if i >= n:
            continue
        diff = R[i] != R0[i] or absorbing[i] != absorbing0[i]
        if R0[i] > 0.0 and R[i] <= 0.0:
            lost = True
        if absorbing[i] and not absorbing0[i]:
            lost = True
        for s in range(K):
            if out[i, s] != out0[i, s]:
                diff = True
                if out[i, s] >= 0:
                    relinked = True
                if out0[i, s] >= 0:
                    lost = True
            elif E[i, s] != E0[i, s]:
                diff = True
                if E0[i, s] > 0.0 and E[i, s] <= 0.0:
                    lost = True
        if diff:
            seeds[c] = i
            c += 1
            R0[i] = R[i]
            absorbing0[i] = absorbing[i]
            for s in range(K):
                out0[i, s] = out[i, s]
                E0[i, s] = E[i, s]
    if k >= 0:              # ascending, as a scan of every row seeds them (insertion sort)
        for q in range(1, c):
            v = seeds[q]
            p = q - 1
            while p >= 0 and seeds[p] > v:
                seeds[p + 1] = seeds[p]
                p -= 1
            seeds[p + 1] = v
    return c, lost, relinked


@njit(cache=True)
def changed_options(rows, n_rows, rho, U, osucc, onb, ong, rho0, U0, osucc0, onb0, ong0,
                    seeds, c):
    """:func:`changed_rows` for the options of Eq. 5' of the nodes ``rows[:n_rows]`` (those
    recomputed since the last solve): the rows that differ from the copy are appended to
    ``seeds`` from ``c`` and the copy brought up to date. Returns (count, lost, relinked):
    ``lost`` when an option may be worth less than in the copy (its rho, U or a wall
    exit's discount lowered, its successor or an exit changed, a row's last option gone:
    the nodes whose value rested on it would be swept down only geometrically where two
    of them hold each other up), ``relinked`` when an option's successor or a wall exit
    became a node it was not (the predecessors must be rebuilt, :func:`predecessors`; a
    successor gone, or now unknown space, leaves a reader too many there, which misses
    none)."""
    P, B = rho.shape[1], onb.shape[2]
    lost = False
    relinked = False
    for k in range(n_rows):
        i = rows[k]
        diff = False
        for a in range(P):
            if rho[i, a] != rho0[i, a] or U[i, a] != U0[i, a]:
                diff = True
                if rho[i, a] < rho0[i, a] or (rho[i, a] > 0.0 and U[i, a] < U0[i, a]):
                    lost = True
            if osucc[i, a] != osucc0[i, a]:
                diff = True
                if osucc[i, a] >= 0:
                    relinked = True
                if rho[i, a] > 0.0:
                    lost = True
            for b in range(B):
                if onb[i, a, b] != onb0[i, a, b]:
                    diff = True
                    if onb[i, a, b] >= 0:
                        relinked = True
                    if rho[i, a] > 0.0:
                        lost = True
                elif ong[i, a, b] != ong0[i, a, b]:
                    diff = True
                    if rho[i, a] > 0.0 and ong[i, a, b] < ong0[i, a, b]:
                        lost = True
        if diff:
            seeds[c] = i
            c += 1
            for a in range(P):
                rho0[i, a], U0[i, a], osucc0[i, a] = rho[i, a], U[i, a], osucc[i, a]
                for b in range(B):
                    onb0[i, a, b], ong0[i, a, b] = onb[i, a, b], ong[i, a, b]
    return c, lost, relinked


@njit(cache=True)
def cell_grid(w, alive, n, L):
    """A lookup table of the nodes by position (2-D sensations): ``grid[r, c]`` = the node
    whose weight rounds to cell (r, c) of side L from ``origin`` (-1 = none). Other
    dimensions get an empty table (no lookup: options keep their optimistic value)."""
    origin = np.zeros(2)
    if w.shape[1] != 2 or n == 0:
        return np.full((0, 0), -1, dtype=np.int64), origin
    lo = np.full(2, np.inf)
    hi = np.full(2, -np.inf)
    for i in range(n):
        if alive[i]:
            for k in range(2):
                lo[k] = min(lo[k], w[i, k])
                hi[k] = max(hi[k], w[i, k])
    if lo[0] > hi[0]:
        return np.full((0, 0), -1, dtype=np.int64), origin
    origin[:] = lo - L
    rows = int((hi[0] - origin[0]) / L + 0.5) + 2
    cols = int((hi[1] - origin[1]) / L + 0.5) + 2
    grid = np.full((rows, cols), -1, dtype=np.int64)
    for i in range(n):
        if alive[i]:
            grid[int((w[i, 0] - origin[0]) / L + 0.5), int((w[i, 1] - origin[1]) / L + 0.5)] = i
    return grid, origin


@njit(cache=True)
def belief_steps(w, alive, n, tried, bump_t, closed, delta, lattice, L, goal):
    """The free-space belief's steps to the goal (unknown.py, *the free-space belief after a
    break*): ``dist[r, c]`` = the fewest lattice moves (the primitives of ``lattice``, as
    whole cells) from cell (r, c) (side L, from ``origin``) to the goal sensation's cell
    over the cells not believed closed; -1 where no such way exists, -2 a cell believed
    closed: the cell of a node in ``closed`` (its cell closed), or a cell a remembered wall
    (a lattice primitive's pair whose last try bumped) predicts and no live node lies in.
    The cells are those of the box the live nodes and the goal span and the ring of cells
    just beyond it; each lattice primitive's move, rounded to whole cells, is one step of
    the search (the caller checks that the cells hold the places:
    ``OptionRules.cells_hold``). An empty table (the options keep their L1 value) in other
    dimensions."""
    origin = np.zeros(2)
    empty = np.full((0, 0), -1, dtype=np.int64)
    if w.shape[1] != 2 or n == 0:
        return empty, origin
    # the moves as whole cells ((0, 0): a primitive that never moved)
    dr = np.zeros(tried.shape[1], dtype=np.int64)
    dc = np.zeros(tried.shape[1], dtype=np.int64)
    for a in range(tried.shape[1]):
        if lattice[a]:
            dr[a] = int(np.floor(delta[a, 0] / L + 0.5))
            dc[a] = int(np.floor(delta[a, 1] / L + 0.5))
    lo = goal[:2].copy()
    hi = goal[:2].copy()
    for i in range(n):
        if alive[i]:
            for k in range(2):
                lo[k] = min(lo[k], w[i, k])
                hi[k] = max(hi[k], w[i, k])
    origin[:] = lo - L
    rows = int(np.floor((hi[0] - origin[0]) / L + 0.5)) + 2
    cols = int(np.floor((hi[1] - origin[1]) / L + 0.5)) + 2
    dist = np.full((rows, cols), -1, dtype=np.int64)
    for i in range(n):
        if not alive[i]:
            continue
        for a in range(tried.shape[1]):
            if lattice[a] and tried[i, a] and bump_t[i, a] >= 0:
                r = int(np.floor((w[i, 0] + delta[a, 0] - origin[0]) / L + 0.5))
                c = int(np.floor((w[i, 1] + delta[a, 1] - origin[1]) / L + 0.5))
                if 0 <= r < rows and 0 <= c < cols:
                    dist[r, c] = -2
    for i in range(n):
        if alive[i]:
            r = int(np.floor((w[i, 0] - origin[0]) / L + 0.5))
            c = int(np.floor((w[i, 1] - origin[1]) / L + 0.5))
            dist[r, c] = -2 if closed[i] else -1
    # breadth first from the goal (a predecessor of cell y is y less a move)
    gr = int(np.floor((goal[0] - origin[0]) / L + 0.5))
    gc = int(np.floor((goal[1] - origin[1]) / L + 0.5))
    queue = np.empty(rows * cols, dtype=np.int64)
    dist[gr, gc] = 0
    queue[0] = gr * cols + gc
    head, tail = 0, 1
    while head < tail:
        r, c = divmod(queue[head], cols)
        head += 1
        for a in range(tried.shape[1]):
            if dr[a] == 0 and dc[a] == 0:
                continue
            pr, pc = r - dr[a], c - dc[a]
            if 0 <= pr < rows and 0 <= pc < cols and dist[pr, pc] == -1:
                dist[pr, pc] = dist[r, c] + 1
                queue[tail] = pr * cols + pc
                tail += 1
    return dist, origin


@njit(cache=True)
def belief_h(dist, origin, L, x, delta, lattice):
    """Steps from position x to the goal in the belief of :func:`belief_steps`: its cell's
    distance; for a cell believed closed (an option supposes it open), one more than its
    best neighbour's; -1 when the belief knows no way; -3 when x lies beyond the table."""
    r = int(np.floor((x[0] - origin[0]) / L + 0.5))
    c = int(np.floor((x[1] - origin[1]) / L + 0.5))
    if r < 0 or c < 0 or r >= dist.shape[0] or c >= dist.shape[1]:
        return -3
    d = dist[r, c]
    if d != -2:
        return d
    best = -1
    for a in range(delta.shape[0]):
        if not lattice[a]:
            continue
        nr = r + int(np.floor(delta[a, 0] / L + 0.5))
        nc = c + int(np.floor(delta[a, 1] / L + 0.5))
        if 0 <= nr < dist.shape[0] and 0 <= nc < dist.shape[1] and dist[nr, nc] >= 0:
            if best < 0 or dist[nr, nc] + 1 < best:
                best = dist[nr, nc] + 1
    return best


@njit(cache=True)
def in_extent(grid, origin, L, x):
    """Whether position x lies within the known extent of the world: the rows and
    columns of :func:`cell_grid` that its nodes span (not its one-cell margin)."""
    r = int(np.floor((x[0] - origin[0]) / L + 0.5))
    c = int(np.floor((x[1] - origin[1]) / L + 0.5))
    return 1 <= r < grid.shape[0] - 1 and 1 <= c < grid.shape[1] - 1


@njit(cache=True)
def node_at(grid, origin, L, w, x):
    """The node within L / 2 of position x (-1 if none), from :func:`cell_grid`."""
    if grid.shape[0] == 0:
        return -1
    r = int(np.floor((x[0] - origin[0]) / L + 0.5))
    c = int(np.floor((x[1] - origin[1]) / L + 0.5))
    if r < 0 or c < 0 or r >= grid.shape[0] or c >= grid.shape[1]:
        return -1
    j = grid[r, c]
    if j >= 0 and (w[j, 0] - x[0]) ** 2 + (w[j, 1] - x[1]) ** 2 <= 0.25 * L * L:
        return j
    return -1


@njit(cache=True)
def untried_chain(out, E, n, alive, absorbing, w, delta, L, grid, origin, tried, start, goal,
                  route, chain):
    """The shortest way from node ``start`` to node ``goal`` over the links with E > 0
    and the untried moves between known places (primitive a never taken from i, a known
    node j within L / 2 of its predicted cell ``w_i + delta_a``, :func:`node_at`), one
    step each; when it is shorter than ``route`` (the known route's link steps) its
    untried moves are marked in ``chain`` (motivation.py, Eq. 5'). Returns its steps (-1:
    none). Breadth-first from ``start``, links before untried moves, so that of equally
    short ways the one the agent knows more of is kept; an absorbing node has no
    successor, a dead slot is never reached."""
    if start < 0 or goal < 0 or start >= n or goal >= n or not alive[start]:
        return -1
    K, P = out.shape[1], tried.shape[1]
    dist = np.full(n, -1, dtype=np.int64)
    parent = np.full(n, -1, dtype=np.int64)
    hop = np.full(n, -1, dtype=np.int64)          # the untried primitive into j, or -1
    queue = np.empty(n, dtype=np.int64)
    x = np.empty(w.shape[1])
    queue[0] = start
    dist[start] = 0
    head, tail = 0, 1
    while head < tail and dist[goal] < 0:
        i = queue[head]
        head += 1
        if absorbing[i] and i != start:
            continue
        for s in range(K + P):
            if s < K:
                j = out[i, s]
                if j < 0 or E[i, s] <= 0.0:
                    continue
            else:
                if i >= tried.shape[0] or tried[i, s - K]:
                    continue
                for d in range(w.shape[1]):
                    x[d] = w[i, d] + delta[s - K, d]
                j = node_at(grid, origin, L, w, x)
                if j < 0 or j == i:
                    continue
            if alive[j] and dist[j] < 0:
                dist[j] = dist[i] + 1
                parent[j] = i
                hop[j] = s - K if s >= K else -1
                queue[tail] = j
                tail += 1
    d_goal = dist[goal]
    if 0 < d_goal < route:
        j = goal
        while j != start:
            if hop[j] >= 0:
                chain[parent[j], hop[j]] = True
            j = parent[j]
    return d_goal


@njit(cache=True)
def wall_exits(w, i, a, x, delta, L, grid, origin, V, gamma, onb, ong):
    """:func:`wall_exits_into` with its own scratch."""
    return wall_exits_into(w, i, a, x, delta, L, grid, origin, V, gamma, onb, ong,
                           np.empty(w.shape[1]), np.empty(w.shape[1]))


@njit(cache=True)
def wall_exits_into(w, i, a, x, delta, L, grid, origin, V, gamma, onb, ong, y, z):
    """Where the remembered wall cell x (primitive a from node i bumped into it) leads if
    it opened (motivation.py, Eq. 5'): a wall opens along its run, so the cells opened
    with it may be a straight run of unknown cells from x in any direction but back to i
    (straight on through a thick wall, or sideways along it), ``k`` cells from x, and
    the way on is any known node next to x or to a cell of such a run, reached ``k + 1``
    steps after x: an exit ``q`` worth ``gamma^k V(q)`` (times the gamma of the step out
    of x). A run goes on only through cells with no known node beside them: it ends
    after the first cell next to known space (its exits counted; beyond it the way
    leads through known space anyway), at a known node, or where it would leave the
    known extent of the world (the rows and columns its nodes span: nothing was ever
    sensed beyond). Without these stops a run along the maze's outer wall reached the
    goal's side over any wall between (a generated braided maze: every re-test went to
    the outer wall, the opened wall waited for ever; the default maze: the outer wall
    re-tested on the way to the block). The ``P`` exits of most ``gamma^k V(q)`` by
    the last solve's V go to ``onb[i, a]`` / ``ong[i, a]`` (ties: the nearest); the
    sweep takes the max over them with the V it iterates. Returns whether there is any
    exit. A primitive that never moved the agent (``|delta_a| <= L / 2``) has no cell
    to open. ``y``, ``z``: scratch of the sensation's size (this runs for every stale
    wall at an episode's start)."""
    P = delta.shape[0]
    step2 = 0.0
    for k in range(w.shape[1]):
        step2 += delta[a, k] * delta[a, k]
    if step2 <= 0.25 * L * L:
        return False
    found = False
    for b in range(-1, P):
        back = False
        if b >= 0:                                   # not the way back to i
            dot = 0.0
            for k in range(w.shape[1]):
                dot += delta[b, k] * delta[a, k]
            back = dot < -0.5 * step2
            nb2 = 0.0
            for k in range(w.shape[1]):
                nb2 += delta[b, k] * delta[b, k]
            if back or nb2 <= 0.25 * L * L:
                continue
        # b = -1: the exits of x itself; else the run from x along b
        limit = 1 if b < 0 else grid.shape[0] + grid.shape[1] + 1
        for m in range(0 if b < 0 else 1, limit):
            for k in range(w.shape[1]):
                y[k] = x[k] + (m * delta[b, k] if b >= 0 else 0.0)
            if m > 0:
                if not in_extent(grid, origin, L, y) or node_at(grid, origin, L, w, y) >= 0:
                    break                            # the run ends
            g = gamma ** m
            touched = False
            for c in range(P):
                for k in range(w.shape[1]):
                    z[k] = y[k] + delta[c, k]
                q = node_at(grid, origin, L, w, z)
                touched |= q >= 0
                if q < 0 or q == i:
                    continue
                found = True
                # keep the P best exits (by g V(q), then fewer steps); a node once
                val = g * V[q]
                slot = -1
                for s in range(P):
                    if onb[i, a, s] == q:
                        slot = -2 if ong[i, a, s] >= g else s
                        break
                if slot == -2:
                    continue
                if slot < 0:
                    worst, wv = -1, np.inf
                    for s in range(P):
                        if onb[i, a, s] < 0:
                            worst = s
                            break
                        sv = ong[i, a, s] * V[onb[i, a, s]]
                        if sv < wv or (sv == wv and ong[i, a, s] < ong[i, a, worst]):
                            worst, wv = s, sv
                    if onb[i, a, worst] >= 0 and \
                            (val < wv or (val == wv and g <= ong[i, a, worst])):
                        continue
                    slot = worst
                onb[i, a, slot] = q
                ong[i, a, slot] = g
            if touched and m > 0:
                break                                # known space beside: the run ends
    return found


@njit(cache=True)
def _linked(out, i, j):
    for s in range(out.shape[1]):
        if out[i, s] == j:
            return True
    return False


@njit(cache=True)
def option_values(w, out, alive, n, rows, goal, delta, L, v_star, gamma, tried, bump_t,
                  closed_t, bump_e, succ, clock, horizon, episode, trust, rho_max, rho_new,
                  stuck, grid, origin, V, sel, chain, U, rho, osucc, onb, ong,
                  bdist, borigin, lattice):
    """The options of the value of the unknown (motivation.py, Eq. 5') of the nodes
    ``rows`` (none for dead slots; rows >= n are skipped), per node i and primitive a:
    ``rho[i, a]`` = ``rho_new`` for a primitive never taken from i (the chance a move opens,
    ``MotivationEstimator.open_prior``), 1 if it is a move of this episode's untried chain
    (``chain[i, a]``, :func:`untried_chain`); 1 for one whose move's link (to ``succ[i,
    a]``) the map has since deleted; for one whose last outcome was a bump (a remembered
    wall): when ``stuck``, ``rho_max (1 - exp(-tau / (horizon + e)))``, ``tau`` the steps
    since the bump and ``e`` those it had been known closed before it (``bump_t -
    closed_t``: failed re-tests stretch the horizon); else ``rho_max`` once ``trust``
    episodes (``trust`` > 0) have started since its bump (``bump_e``) and the pair is one of
    this episode's re-tests (``sel[i, a]``), 0 otherwise; 0 otherwise (known: no option).
    The option's successor ``osucc[i, a]``: a known node (where the move once led, if that
    node is still alive and there, else a node at the predicted position ``w_i + delta_a``),
    whose V the sweep reads; -1 when none, and then ``U[i, a] = v_star gamma^h``, ``h = |w_i
    + delta_a - x_g|_1 / L`` (the fewest steps from the predicted successor to the goal
    sensation); -2 for a remembered wall cell (not ``stuck``), whose value if it opened is
    gamma times the best ``gamma^k V(q)`` of its exits ``onb[i, a]`` (discounts ``ong[i,
    a]``): the known nodes next to it, or next to a cell of a run of unknown cells from it,
    ``k`` cells along (straight on or sideways: a wall that opens opens along its run,
    :func:`wall_exits`); no exit: no option. ``stuck``: the optimistic U, as for unknown
    space. ``V``: the last solve's potentials (they pick the exits). ``bdist`` (with
    ``borigin``; empty: none): the free-space belief after a break (:func:`belief_steps`),
    which, for a ``lattice`` primitive, replaces the L1 count ``h`` by the belief's steps
    (:func:`belief_h`; no way: U = 0) and drops an option that is not a remembered wall
    chosen for a re-test when its cell is no nearer the goal than its node's, by the
    belief. (One loop over the rows and pairs: a call per row cost more than its work.)"""
    x = np.empty(w.shape[1])
    for i in rows:
        if i >= n:
            continue
        if not alive[i]:
            for a in range(U.shape[1]):
                rho[i, a] = 0.0
                U[i, a] = 0.0
                osucc[i, a] = -1
            continue
        # the node's own steps to the goal in the free-space belief (-3: no belief)
        h_i = belief_h(bdist, borigin, L, w[i], delta, lattice) if bdist.shape[0] > 0 else -3
        for a in range(U.shape[1]):
            j = -1
            wall = False
            if not tried[i, a]:
                r = 1.0 if chain[i, a] else rho_new
            elif stuck and 0 <= bump_t[i, a] < clock and horizon > 0.0:
                tau = clock - bump_t[i, a]
                e = bump_t[i, a] - closed_t[i, a] if closed_t[i, a] >= 0 else 0
                r = rho_max * (1.0 - np.exp(-tau / (horizon + e)))
                j = succ[i, a]
            elif not stuck and stale(bump_e, i, a, episode, trust):
                r = rho_max if sel[i, a] else 0.0
                j = succ[i, a]
                wall = j < 0
            elif bump_t[i, a] < 0 and succ[i, a] >= 0 and not _linked(out, i, succ[i, a]):
                r = 1.0
                j = succ[i, a]
            else:
                r = 0.0
            if r == 0.0:                    # no option (most pairs): nothing to look up
                for b in range(U.shape[1]):
                    onb[i, a, b] = -1
                    ong[i, a, b] = 0.0
                rho[i, a] = 0.0
                U[i, a] = 0.0
                osucc[i, a] = -1
                continue
            d = 0.0
            for k in range(w.shape[1]):
                x[k] = w[i, k] + delta[a, k]
                d += abs(x[k] - goal[k])
            if j >= 0 and not at_cell(w, alive, j, x, L):
                j = -1          # where the move led, a node since removed (its slot maybe
                #                 reused elsewhere): the cell is looked up as for any move
            for b in range(U.shape[1]):
                onb[i, a, b] = -1
                ong[i, a, b] = 0.0
            u = v_star * gamma ** (d / L)
            if bdist.shape[0] > 0 and lattice[a]:
                h = belief_h(bdist, borigin, L, x, delta, lattice)
                if h_i >= 0 and not wall and (h == -1 or h >= h_i):
                    r = 0.0         # off every shortest believed way from i
                elif h == -1:
                    u = 0.0
                elif h >= 0:
                    u = v_star * gamma ** h
            if r > 0.0 and wall:
                # a remembered wall: if it opened, the cell leads on to known nodes
                j = -2
                u = 1.0
                if not wall_exits(w, i, a, x, delta, L, grid, origin, V, gamma, onb, ong):
                    r = 0.0
            elif r > 0.0 and j < 0:
                j = node_at(grid, origin, L, w, x)
            if r == 0.0:
                rho[i, a] = 0.0
                U[i, a] = 0.0
                osucc[i, a] = -1
                continue
            rho[i, a] = r
            U[i, a] = u
            osucc[i, a] = j if j != i else -1


@njit(cache=True)
def option_rows_changed(w, alive, n, touched, delta, L, grid_was, grid, origin, tried, bump_e,
                        succ, sel, episode, trust, stuck, untried, rows):
    """The rows ``i < n`` whose options (:func:`option_values`) may read something the map changed
    (unknown.py, an incremental refresh of Eq. 5'), given the map rows it ``touched`` (a
    mask of n: weights, alive, links) and the node lookup before (``grid_was``) and after
    (``grid``) with the same shape and ``origin`` (:func:`cell_grid`): row i itself
    (its weight, liveness, links); a pair whose remembered successor ``succ[i, a]`` was
    touched (:func:`at_cell` reads its weight and liveness); a pair whose predicted cell
    ``w_i + delta_a`` changed its node, or holds a touched node (:func:`node_at` reads
    its weight); a stale wall this episode may re-test whose successor is unknown
    (:func:`wall_exits` looks up cells along runs and reads V); with ``untried`` every
    pair never tried (rho_new changed). Writes them, ascending, to ``rows``; returns how
    many."""
    changed = np.zeros(grid.shape, dtype=np.bool_)
    for r in range(grid.shape[0]):
        for c in range(grid.shape[1]):
            q = grid[r, c]
            changed[r, c] = q != grid_was[r, c] or (0 <= q < n and touched[q])
    look = grid.shape[0] > 0 and w.shape[1] == 2
    count = 0
    for i in range(n):
        hit = touched[i]
        if alive[i] and not hit:
            for a in range(tried.shape[1]):
                j = succ[i, a]
                if 0 <= j < n and touched[j]:
                    hit = True
                elif not tried[i, a]:
                    hit = untried
                elif not stuck and j < 0 and sel[i, a] and stale(bump_e, i, a, episode, trust):
                    hit = True
                if not hit and look:
                    r = int(np.floor((w[i, 0] + delta[a, 0] - origin[0]) / L + 0.5))
                    c = int(np.floor((w[i, 1] + delta[a, 1] - origin[1]) / L + 0.5))
                    hit = 0 <= r < grid.shape[0] and 0 <= c < grid.shape[1] and changed[r, c]
                if hit:
                    break
        if hit:
            rows[count] = i
            count += 1
    return count


@njit(cache=True)
def untried_rho(alive, n, tried, chain, lattice, rho_new, rho, rows):
    """``rho_new`` (the open prior, unknown.py) on every pair of a live node never tried,
    except a lattice primitive's move of this episode's untried chain (rho 1): while the
    prior stays above 0 the only value of those options that follows it
    (:func:`option_values`; a primitive off the lattice: ``OptionRules._unplaced_options``).
    Writes the rows holding such a pair, ascending, to ``rows``; returns how many."""
    count = 0
    for i in range(n):
        if not alive[i]:
            continue
        hit = False
        for a in range(tried.shape[1]):
            if not tried[i, a] and not (lattice[a] and chain[i, a]):
                rho[i, a] = rho_new
                hit = True
        if hit:
            rows[count] = i
            count += 1
    return count


@njit(cache=True)
def record_outcome(tried, bump_t, closed_t, bump_e, succ, delta, delta_sq, moves, w, node,
                   winner, inserted, a, bumped, clock, episode):
    """The outcome memory of Eq. 5' after primitive a taken from ``node`` (unknown.py):
    a new winner starts untried; the pair (node, a) is tried, with the step and the
    episode of a bump or -1 after a move (``closed_t``: the step of the first bump of the
    current run of bumps, since when the pair is known closed), whose successor ``succ``
    is remembered; a move updates the mean displacement ``delta[a]`` and the mean of its
    squared length ``delta_sq[a]`` (the spread, frame.py). Returns whether the pair's
    option changed."""
    if inserted and winner >= 0:
        for b in range(tried.shape[1]):
            tried[winner, b] = False
            bump_t[winner, b] = -1
            closed_t[winner, b] = -1
            bump_e[winner, b] = -1
            succ[winner, b] = -1
    if node < 0:
        return False
    changed = (not tried[node, a]) or bumped or bump_t[node, a] >= 0 or succ[node, a] != winner
    tried[node, a] = True
    if bumped:
        if bump_t[node, a] < 0:          # closed since this bump (the first of a run)
            closed_t[node, a] = clock
        bump_t[node, a] = clock
        bump_e[node, a] = episode
        return changed
    bump_t[node, a] = -1
    closed_t[node, a] = -1
    bump_e[node, a] = -1
    succ[node, a] = winner
    if winner >= 0 and winner != node:
        moves[a] += 1
        dd = 0.0
        for k in range(delta.shape[1]):
            d = w[winner, k] - w[node, k]
            delta[a, k] += (d - delta[a, k]) / moves[a]
            dd += d * d
        delta_sq[a] += (dd - delta_sq[a]) / moves[a]
    return changed


@njit(cache=True)
def best_link_value(out_i, E_i, V):
    """max_k E[i, k] V(k) over node i's links (Eq. 5-6), 0 without any."""
    best = 0.0
    for s in range(out_i.shape[0]):
        j = out_i[s]
        if j >= 0:
            ev = E_i[s] * V[j]
            if ev > best:
                best = ev
    return best


@njit(cache=True)
def option_links(out_i, E_i, A_i, V, i, U, rho, osucc, onb, ong, R_i, gamma, primitives):
    """Node i's links followed by one virtual link per option (motivation.py): targets,
    reliabilities and action vectors, where an option's target is i itself and its
    reliability makes E V(target) the option's successor value, so Eq. 6 ranks links and
    options alike."""
    K = out_i.shape[0]
    P = primitives.shape[0]
    stay = R_i + gamma * best_link_value(out_i, E_i, V)
    targets = np.full(K + P, -1, dtype=np.int64)
    E = np.zeros(K + P)
    A = np.empty((K + P, A_i.shape[1]))
    targets[:K] = out_i
    E[:K] = E_i
    A[:K] = A_i
    A[K:] = primitives
    if V[i] > 0.0:
        for a in range(P):
            r = rho[i, a]
            if r > 0.0:
                sv = option_successor(V, U, osucc, onb, ong, i, a, gamma)
                targets[K + a] = i
                E[K + a] = (r * sv + (1.0 - r) * stay) / V[i]
    return targets, E, A


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
    top = best_link_value(out_i, E_i, V)
    if top <= 0.0:
        return np.empty(0, dtype=np.int64)
    res = []
    for s in range(out_i.shape[0]):
        j = out_i[s]
        if j >= 0 and E_i[s] * V[j] == top:
            res.append(s)
    return np.array(res, dtype=np.int64)


@njit(cache=True)
def eq6_choices(out_i, E_i, A_i, V, i, exclude_self, R_i, gamma, U, rho, osucc, onb, ong,
                primitives, slots, acts, took):
    """Eq. 6 at node i in one pass (action_selector.py): the choices attaining
    max E V(target) > 0 over i's links and, with options (``U`` holding row i), i's options
    ranked as the virtual links :func:`option_links` makes of them (the same arithmetic,
    hence the same ties as :func:`option_links` then :func:`best_links`), targets equal
    to i ignored with ``exclude_self``. Writes for each choice, links first: its slot
    (K + a for option a), the nearest motor primitive of its action vector
    (:func:`nearest_row`) and whether it is an option (target i); returns their count."""
    K = out_i.shape[0]
    P = rho.shape[1] if U.shape[0] > i else 0
    stay = R_i + gamma * best_link_value(out_i, E_i, V) if P else 0.0
    with_options = P > 0 and V[i] > 0.0 and not exclude_self
    ev = np.empty(K + (P if with_options else 0))
    top = 0.0
    for s in range(len(ev)):
        ev[s] = _eq6_term(out_i, E_i, V, i, exclude_self, stay, gamma, U, rho, osucc, onb,
                          ong, K, s)
        if ev[s] > top:
            top = ev[s]
    c = 0
    if top <= 0.0:
        return c
    for s in range(len(ev)):
        if ev[s] == top:
            slots[c] = s
            acts[c] = nearest_row(primitives, A_i[s] if s < K else primitives[s - K])
            took[c] = s >= K or out_i[s] == i
            c += 1
    return c


@njit(cache=True)
def _eq6_term(out_i, E_i, V, i, exclude_self, stay, gamma, U, rho, osucc, onb, ong, K, s):
    """E V(target) of choice s of :func:`eq6_choices` (0: none)."""
    if s < K:
        j = out_i[s]
        if j < 0 or (exclude_self and j == i):
            return 0.0
        return E_i[s] * V[j]
    a = s - K
    r = rho[i, a]
    if r <= 0.0:
        return 0.0
    sv = option_successor(V, U, osucc, onb, ong, i, a, gamma)
    return ((r * sv + (1.0 - r) * stay) / V[i]) * V[i]


@njit(cache=True)
def habituate(h, i, tau, kappa):
    """GWR habituation: h_i += tau (kappa (1 - h_i) - 1)."""
    h[i] += tau * (kappa * (1.0 - h[i]) - 1.0)


@njit(cache=True)
def adapt(w, c, h, won, mean, out, inn, n, b, x, C, eps_b, eps_n, tau_b, tau_n, kappa):
    """Move the winner and its linked neighbours towards (x, C), then habituate them;
    returns the nodes moved (b first). ``won``: the samples each node won; with ``mean``
    the winner moves at least at ``1 / won``, the running mean of its samples
    (sensorimotor_map.py, "The mean of a place's samples")."""
    rate = eps_b * h[b]
    won[b] += 1.0
    if mean and 1.0 / won[b] > rate:
        rate = 1.0 / won[b]
    for k in range(x.shape[0]):
        w[b, k] += rate * (x[k] - w[b, k])
        c[b, k] += rate * (C[k] - c[b, k])
    habituate(h, b, tau_b, kappa)
    nbs = incident_neighbours(out, inn, n, b)
    moved = np.empty(len(nbs) + 1, dtype=np.int64)
    moved[0] = b
    for q in range(len(nbs)):
        nb = nbs[q]
        moved[q + 1] = nb
        rate = eps_n * h[nb]
        for k in range(x.shape[0]):
            w[nb, k] += rate * (x[k] - w[nb, k])
            c[nb, k] += rate * (C[k] - c[nb, k])
        habituate(h, nb, tau_n, kappa)
    return moved


@njit(cache=True)
def sim_action(a_ij, a, sigma_a):
    """Eq. 2: sim(a_ij, a) = exp(-|a_ij - a|^2 / (2 sigma_a^2))."""
    d = 0.0
    for k in range(a.shape[0]):
        t = a_ij[k] - a[k]
        d += t * t
    return np.exp(-d / (2.0 * sigma_a * sigma_a))


@njit(cache=True)
def needs_wider_rows(out, inn, i, j):
    """Whether i -> j would be a new link (i != j) while row i, or row j of the links in
    (``inn``), has no free slot, so the caller must widen the link rows before
    :func:`update_links` (a numpy test of the row costs more than the rest of the link
    update)."""
    if i == j:
        return False
    free = False
    for s in range(out.shape[1]):
        t = out[i, s]
        if t == j:
            return False
        if t < 0:
            free = True
    if not free:
        return True
    for s in range(inn.shape[1]):
        if inn[j, s] < 0:
            return False
    return True


@njit(cache=True)
def reinforce_link(out, E, A, age, inn, i, j, a, alpha, sigma_a, eta_a, E_init):
    """Eq. 1-2 on the traversed link i -> j (i != j), then a_ij follows the action a.

    A transition never seen before creates the link (labelled a, reliability ``E_init``)
    in the first free slot of row i, which the caller guarantees. Returns
    ``(slot, created)``: the link's slot in row i and whether it was created.
    """
    K = out.shape[1]
    slot = -1
    created = False
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
        _in_link_add(inn, j, i)
        created = True
    # Eq. 1-2 with I{i != j} = 1: E[i, j] += alpha (sim(a_ij, a) - E[i, j])
    E[i, slot] += alpha * (sim_action(A[i, slot], a, sigma_a) - E[i, slot])
    # a_ij += eta_a (a - a_ij): the label stays the action that leads from i to j
    for k in range(a.shape[0]):
        A[i, slot, k] += eta_a * (a[k] - A[i, slot, k])
    return slot, created


@njit(cache=True)
def credit_other_links(out, E, A, i, slot, a, alpha, sigma_a):
    """The credit rule: action a did not lead along the other links i -> k (every slot
    but ``slot``), so each is blamed as far as its action matches a:
    E[i, k] += alpha sim(a_ik, a) (0 - E[i, k])."""
    for s in range(out.shape[1]):
        if s != slot and out[i, s] >= 0:
            E[i, s] -= alpha * sim_action(A[i, s], a, sigma_a) * E[i, s]


@njit(cache=True)
def age_links(out, E, age, inn, n, i, slot, E_min, max_age):
    """GWR ageing: every link incident to i (in or out) ages by one, the traversed link
    (row i, ``slot``; -1 for none) restarts at 0. Links older than ``max_age`` and links
    out of i less reliable than ``E_min`` are deleted.

    Returns the end nodes of the deleted links as a flat array: they may now be isolated,
    which the caller checks (GWR removes nodes without links).
    """
    ends = []
    rows = np.empty(inn.shape[1] + 1, dtype=np.int64)     # i and the sources into it
    rows[0] = i
    c = 1
    for s in range(inn.shape[1]):
        if inn[i, s] >= 0 and inn[i, s] != i:
            rows[c] = inn[i, s]
            c += 1
    for src in np.sort(rows[:c]):                          # in row order, as a scan
        for s in range(out.shape[1]):
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
                _in_link_remove(inn, t, src)
                ends.append(src)
                ends.append(t)
    return np.array(ends, dtype=np.int64)


@njit(cache=True)
def update_links(out, E, A, age, inn, n, i, j, a, alpha, sigma_a, eta_a, E_init, E_min,
                 max_age, credit):
    """The link update of one transition i -> j under action a: Eq. 1-2 on the traversed
    link, the credit rule on the other links out of i (``credit``), then GWR ageing.

    A self transition (i == j, a bump) only ages: Eq. 1-2 would drive E[i, i] to 0, so it
    is not stored. Returns ``(created, ends)``: whether a link was created, and the end
    nodes of every deleted link (:func:`age_links`).
    """
    slot = -1
    created = False
    if i != j:
        slot, created = reinforce_link(out, E, A, age, inn, i, j, a, alpha, sigma_a, eta_a,
                                       E_init)
    if credit:
        credit_other_links(out, E, A, i, slot, a, alpha, sigma_a)
    return created, age_links(out, E, age, inn, n, i, slot, E_min, max_age)


@njit(cache=True)
def match(w, c, h, won, mean, alive, out, inn, n, prev, x, C, alpha_c, Sc, beta_c, a_T, h_T,
          learn, eps_b, eps_n, tau_b, tau_n, kappa, prior, head, node, geom, shape):
    """The matching and adaptation of one input x (sensorimotor_map.py, one call a step):
    writes its Merge-GNG context ``C_t = (1 - beta_c) w_prev + beta_c c_prev`` into C (x
    itself at an episode start, ``prev`` < 0), finds the winner b = argmin d_n and, when
    learning, applies the GWR test: returns ``(b, True)`` when a node must be inserted (an
    empty map, or activity ``exp(-sqrt(d_b)) < a_T`` with ``h_b <= h_T``: the caller
    inserts), else adapts b and its neighbours towards (x, C) and returns ``(b, False)``;
    a third value lists the nodes whose weights moved (empty when none did). ``prior``:
    the node the links predict, the winner when x lies within its place (-1: none);
    ``head`` ... ``shape``: the node index (node_index.py) the winner is searched
    through."""
    none = np.empty(0, dtype=np.int64)
    if prev >= 0:
        for k in range(C.shape[0]):
            C[k] = (1.0 - beta_c) * w[prev, k] + beta_c * c[prev, k]
    else:
        C[:] = x
    b, d_b = indexed_argmin(w, c, alive, n, x, C, alpha_c, Sc, head, node, geom, shape)
    if 0 <= prior < n and prior != b and alive[prior]:     # the place the links predict
        d_p = 0.0
        if Sc.shape[0] == 0:
            for k in range(x.shape[0]):
                d_p += (1.0 - alpha_c) * (x[k] - w[prior, k]) ** 2 \
                    + alpha_c * (C[k] - c[prior, k]) ** 2
        else:
            for k in range(x.shape[0]):
                d_p += (1.0 - alpha_c) * (x[k] - w[prior, k]) ** 2
            d_p += alpha_c * context_gap(C, c, prior, Sc)
        if d_p < np.log(a_T) ** 2:
            b, d_b = prior, d_p
    if not learn:
        return b, False, none
    if b < 0 or (np.exp(-np.sqrt(d_b)) < a_T and h[b] <= h_T):
        return b, True, none
    return b, False, adapt(w, c, h, won, mean, out, inn, n, b, x, C, eps_b, eps_n, tau_b,
                           tau_n, kappa)


@njit(cache=True)
def link_step(out, E, A, age, inn, alive, terminal, n, i, j, a, alpha, sigma_a, eta_a,
              E_init, E_min, max_age, credit, keep1, keep2):
    """The link stage of one transition i -> j (sensorimotor_map.py): returns -1, having
    changed nothing, when i -> j would be a new link and row i (or row j of the links in,
    ``inn``, :func:`in_links`, kept up to date) has no free slot (the caller widens the
    rows and calls again); else :func:`update_links`, then GWR's removal
    of the end nodes of deleted links that are left without any link (never ``keep1`` or
    ``keep2``, nor a node flagged ``terminal``), and returns the number of structural
    changes: 1 when a link was created or deleted, plus one per node removed; and the rows
    it changed besides row i (the ends of deleted links, the nodes removed)."""
    if needs_wider_rows(out, inn, i, j):
        return -1, np.empty(0, dtype=np.int64)
    created, ends = update_links(out, E, A, age, inn, n, i, j, a, alpha, sigma_a, eta_a,
                                 E_init, E_min, max_age, credit)
    changes = 1 if created or len(ends) else 0
    for k in ends:
        if k == keep1 or k == keep2 or not alive[k] or terminal[k]:
            continue
        linked = False
        for s in range(out.shape[1]):
            if out[k, s] >= 0:
                linked = True
        for s in range(inn.shape[1]):
            if inn[k, s] >= 0:
                linked = True
        if not linked:
            alive[k] = False
            changes += 1
    return changes, ends


@njit(cache=True)
def place_activity(motion, a_T):
    """The activity threshold of one place (sensorimotor_map, One node a place): GWR's
    ``a_T``, or ``exp(-sqrt(2 s))`` where that radius is wider, ``s`` the least spread of a
    primitive (rows of ``motion``: count, mean displacement, sum of squared deviations)
    whose moves stand out of their scatter, ``|m|^2 > 4 s``."""
    k = motion.shape[1] - 2
    smin = np.inf
    for p in range(motion.shape[0]):
        count = motion[p, 0]
        if count < 2:
            continue
        s = motion[p, k + 1] / count
        m2 = 0.0
        for j in range(k):
            m2 += motion[p, 1 + j] ** 2
        if m2 > 4.0 * s and s < smin:
            smin = s
    if smin == np.inf:
        return a_T
    return min(a_T, math.exp(-math.sqrt(2.0 * smin)))


@njit(cache=True)
def sensed_motion(motion, a, x, x_prev, a_T):
    """Add the sensed displacement ``d = x - x_prev`` of a move by primitive ``a`` to its
    running moments in ``motion`` (Welford: count, mean, sum of squared deviations);
    returns the activity threshold of one place after it (:func:`place_activity`) and the
    primitive's count of moves; ``(a_T, -1)``, nothing added, when ``d`` is not finite
    (no sensation before it)."""
    k = motion.shape[1] - 2
    for j in range(k):
        if not math.isfinite(x[j] - x_prev[j]):
            return a_T, -1
    motion[a, 0] += 1.0
    m2 = 0.0
    for j in range(k):
        d = x[j] - x_prev[j]
        dev = d - motion[a, 1 + j]
        motion[a, 1 + j] += dev / motion[a, 0]
        m2 += dev * (d - motion[a, 1 + j])
    motion[a, k + 1] += m2
    return place_activity(motion, a_T), int(motion[a, 0])


@njit(cache=True)
def stray_move(w, i, j, step, step_r2):
    """Whether node j lies farther than ``sqrt(step_r2)`` from ``w_i + step`` (``step_r2``
    < 0: never): a move from i's place by ``step`` does not reach j's place
    (sensorimotor_map.py, "A move between other places")."""
    if step_r2 < 0.0 or i < 0 or j < 0:
        return False
    d2 = 0.0
    for q in range(w.shape[1]):
        e = w[j, q] - w[i, q] - step[q]
        d2 += e * e
    return d2 > step_r2


@njit(cache=True)
def map_step(w, c, h, won, mean, alive, out, inn, n, prev, x, C, Sc, a_T, learn, hp, E, A,
             age, terminal, a, has_action, unblocked, step, step_r2, keep, r2, prior, head,
             node, geom, shape, moves, k, changed, log_rows, log_len, motion, sensed, x_prev,
             a_T_gwr):
    """One learning step of the map in one call (sensorimotor_map.py) when nothing needs
    Python: :func:`match`, then, reached by action ``a`` (``has_action``) from ``prev``,
    :func:`link_step` on prev -> winner (``keep1`` prev, ``keep2`` ``keep``; none when
    ``unblocked``, the action was not blocked, and the winner is ``prev``: a move within
    one node, or, with ``step_r2`` >= 0, lies farther than ``sqrt(step_r2)`` from where
    the action's mean move ``step`` leads from it: a move between other places,
    sensorimotor_map.py), then, with ``r2`` >= 0, :func:`close_pair` over the
    nodes moved (the merge's first pair). Returns
    ``(b, insert, n_moved, done, changes, n_ends, i, j, linked, logged)``: the nodes the match
    moved, then the end nodes of the links deleted, are written to ``changed``
    (``[:n_moved]``, ``[n_moved:n_moved + n_ends]``; room for ``1 + 6 K`` ids, ``K`` the
    slots of a row: an array the caller keeps, as returned arrays cost more to hand to
    Python than the step's own work); ``done`` False when the
    step needs the caller (not learning, a node to insert, a terminal ``prev``, link rows
    to widen: then only the match was made, and the caller goes on from there), else
    ``linked`` says whether the link stage ran (``changes`` and the ends its result) and
    ``(i, j)`` is the close pair ((-1, -1): none, or ``r2`` < 0). The node index
    (``head`` ... ``shape``, node_index.py) first follows the rows ``moves[:k]`` (changed
    since it last did), then the nodes the match moved. ``hp``: the map's hyperparameters
    the step reads, in the order of ``sensorimotor_map.STEP_PARAMETERS`` (one array: a
    call costs per argument). When ``done``, the rows the step changed (the nodes moved,
    then with the link stage ``prev`` and the ends) are appended to the map's change log
    (``log_rows``, holding ``log_len`` entries: ``RowLog.buffer``) when they fit in it,
    as ``RowLog.touch`` would append them, and ``logged`` is the log's new length; else
    -1 (the caller logs them). With ``sensed`` >= 0 (a move by that primitive, not
    blocked) and ``done``, its sensed displacement ``x - x_prev`` then joins its statistics
    (:func:`sensed_motion` with GWR's ``a_T_gwr``), and two more values are returned,
    ``(a_place, count)``, :func:`sensed_motion`'s; ``(a_T_gwr, -2)`` when it was not
    called (the caller calls it after its part of the step)."""
    alpha_c, beta_c, h_T, eps_b, eps_n = hp[0], hp[1], hp[2], hp[3], hp[4]
    tau_b, tau_n, kappa, alpha, sigma_a = hp[5], hp[6], hp[7], hp[8], hp[9]
    eta_a, E_init, E_min, max_age, credit = hp[10], hp[11], hp[12], int(hp[13]), hp[14] != 0.0
    index_move(w, alive, n, moves, k, head, node, geom, shape)
    b, insert, moved = match(w, c, h, won, mean, alive, out, inn, n, prev, x, C, alpha_c, Sc,
                             beta_c, a_T, h_T, learn, eps_b, eps_n, tau_b, tau_n, kappa, prior,
                             head, node, geom, shape)
    nm = len(moved)
    changed[:nm] = moved
    changes, linked = 0, False
    if not learn or insert:
        return b, insert, nm, False, changes, 0, -1, -1, linked, -1, a_T_gwr, -2
    ne = 0
    if prev >= 0 and has_action and not (unblocked and (
            b == prev or stray_move(w, prev, b, step, step_r2))):
        if terminal[prev]:
            return b, insert, nm, False, changes, 0, -1, -1, linked, -1, a_T_gwr, -2
        changes, ends = link_step(out, E, A, age, inn, alive, terminal, n, prev, b, a, alpha,
                                  sigma_a, eta_a, E_init, E_min, max_age, credit, prev, keep)
        if changes < 0:
            return b, insert, nm, False, 0, 0, -1, -1, linked, -1, a_T_gwr, -2
        linked = True
        ne = len(ends)
        changed[nm:nm + ne] = ends
    i, j = -1, -1
    if r2 >= 0.0 and nm:
        index_move(w, alive, n, moved, nm, head, node, geom, shape)
        i, j = indexed_close_pair(w, c, alive, n, moved, alpha_c, Sc, r2, head, node, geom,
                                  shape)
    logged = -1
    size = nm + (1 + ne if linked else 0)
    if log_len + size <= log_rows.shape[0]:
        log_rows[log_len:log_len + nm] = moved
        if linked:
            log_rows[log_len + nm] = prev
            log_rows[log_len + nm + 1:log_len + size] = changed[nm:nm + ne]
        logged = log_len + size
    a_place, count = a_T_gwr, -2
    if sensed >= 0:
        a_place, count = sensed_motion(motion, sensed, x, x_prev, a_T_gwr)
    return b, insert, nm, True, changes, ne, i, j, linked, logged, a_place, count


@njit(cache=True)
def changed_rows_sweep(out, E, R, absorbing, out0, E0, R0, absorbing0, n, seeds, rows, k,
                       sweep, V, gamma, tol, v_floor, alive, U, rho, osucc, onb, ong, first,
                       pred, max_updates, heap, pos, key):
    """:func:`changed_rows`, then, with ``sweep`` when they raise nothing that needs more
    (no value may be lost, no link target changed) and some changed,
    :func:`prioritized_sweep` from them, in one call (motivation.py's incremental solve).
    Returns ``(c, lost, relinked, swept, done)``: ``swept`` says whether the sweep ran,
    ``done`` its result."""
    c, lost, relinked = changed_rows(out, E, R, absorbing, out0, E0, R0, absorbing0, n, seeds,
                                     rows, k)
    if not sweep or c == 0 or lost or relinked:
        return c, lost, relinked, False, 0
    done = prioritized_sweep(out, E, R, V, n, gamma, tol, v_floor, absorbing, alive, U, rho,
                             osucc, onb, ong, first, pred, seeds, c, max_updates, heap, pos,
                             key)
    return c, lost, relinked, True, done


@njit(cache=True)
def prepare_rows(w, alive, T, x, delta, frame_delta_out, rows, k, goal_x, g0, sigma, floor,
                 R, terminal, use_terminal, closed, use_closed, goal_r, n, abs_rows, abs_k,
                 absorbing, terminal_only, count):
    """The estimator's preparation of a converged step in one call (motivation.py,
    ``MotivationEstimator._prepare_rows``), used when only the rows ``rows[:k]`` of the
    map changed since the last one and the goal node, frame, sizes and keys held: the
    frame coordinates of those rows (:func:`frame_coords` into ``x``), the forward model
    in the frame (:func:`frame_delta`), the node nearest the goal among the last one
    ``g0`` and those rows (:func:`nearest_weight_among`), and, when that is still ``g0``,
    Eq. 10 on those rows (:func:`goal_rewards`) and the absorbing flags of ``abs_rows[:
    abs_k]`` (:func:`absorbing_flags`; none when ``abs_k`` < 0). The general path is
    ``MotivationEstimator._prepare`` and ``_absorbing``, which call the same kernels one
    by one. Returns ``(g, count)``: the nearest node and the terminal-only count (as
    given when the flags were not brought up to date)."""
    if k > 0:
        frame_coords(w, T, rows, k, x)
    frame_delta(delta, T, frame_delta_out)
    g = nearest_weight_among(w, alive, goal_x, g0, rows, k)
    if g != g0:
        return g, count
    goal_rewards(x, alive, n, g, sigma, floor, R, rows, k)
    if abs_k >= 0:
        count = absorbing_flags(terminal, use_terminal, closed, use_closed, R, goal_r, n,
                                abs_rows, abs_k, absorbing, terminal_only, count)
    return g, count


@njit(cache=True)
def converged_step(w, alive, T, x, delta, frame_delta_out, rows, k, goal_x, g0, sigma, floor,
                   R, terminal, use_terminal, closed, use_closed, goal_r, n, abs_rows, abs_k,
                   absorbing, terminal_only, count, out, E, R_, absorbing_, out0, E0, R0,
                   absorbing0, n_, seeds, logged, k_logged, sweep, V, gamma, tol, v_floor,
                   alive_, U, rho, osucc, onb, ong, first, pred, max_updates, heap, pos, key):
    """The motivation estimator's update of a converged step in one call (motivation.py,
    ``MotivationEstimator._fused_update``), :func:`prepare_rows`'s arguments followed by
    :func:`changed_rows_sweep`'s: the preparation of the changed rows (Eq. 10 on them,
    their absorbing flags), then, when the goal's node ``g0`` and the terminal-only
    ``count`` held (else the caller's general path goes on from the preparation), Eq.
    4-5' from the rows that changed since the last solve. The general path calls the two
    kernels one by one. Returns ``(g, count, c, lost, relinked, swept, done)``, ``c`` -1
    when the solve was left to the caller."""
    g, count_now = prepare_rows(w, alive, T, x, delta, frame_delta_out, rows, k, goal_x, g0,
                                sigma, floor, R, terminal, use_terminal, closed, use_closed,
                                goal_r, n, abs_rows, abs_k, absorbing, terminal_only, count)
    if g != g0 or count_now != count:
        return g, count_now, -1, False, False, False, 0
    c, lost, relinked, swept, done = changed_rows_sweep(                  # Eq. 4-5'
        out, E, R_, absorbing_, out0, E0, R0, absorbing0, n_, seeds, logged, k_logged, sweep,
        V, gamma, tol, v_floor, alive_, U, rho, osucc, onb, ong, first, pred, max_updates,
        heap, pos, key)
    return g, count_now, c, lost, relinked, swept, done


# ---------------------------------------------------------------- the on-disk cache
#: Every kernel, by name (what the warm-up must compile); those numba inlines into their
#: callers (``inline="always"``) are never compiled on their own, and keep no cache of their
#: own: a test that calls one from Python would otherwise add a cache file after the
#: warm-up, and the bootstrap would read the cache as changed (tools/bootstrap.sh).
KERNELS = {name: obj for name, obj in list(globals().items())
           if hasattr(obj, "py_func") and hasattr(obj, "signatures")
           and obj.targetoptions.get("inline", "never") != "always"}
#: About how long compiling all of them takes on one free core (seconds).
COMPILE_SECONDS = 15
_announced = False


def cache_dir() -> str:
    """Where the compiled kernels are cached."""
    try:
        return str(next(iter(KERNELS.values()))._cache._cache_path)
    except Exception:  # numba internals: informative only
        return "numba's cache directory"


def _cached(dispatcher) -> bool:
    """Whether the cache holds a compiled version of this kernel for the current source
    (numba's index, keyed by the source file's stamp; numba internals, hence the guard)."""
    try:
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:
        return True     # cannot tell: say nothing rather than something wrong


def clear_cache() -> None:
    """Remove every cached kernel of this module. A warm-up after the source changed
    starts from here: a kernel called only from other kernels is compiled, and cached,
    only while a caller compiles, so a caller cached by an earlier process left its
    callees stale for ever and the warm-up could not tell the cache complete."""
    d = cache_dir()
    for f in glob.glob(os.path.join(glob.escape(d), "kernels.*.nb[ic]")):
        with contextlib.suppress(OSError):
            os.remove(f)


def uncached() -> list[str]:
    """The kernels neither compiled in this process nor in the cache: those a first call
    will have to compile (kernels called only from other kernels are compiled, and
    cached, with their callers)."""
    return [name for name, d in KERNELS.items() if not d.signatures and not _cached(d)]


def quiet_compilation() -> None:
    """The caller announces the compilation itself (the bootstrap's warm-up)."""
    global _announced
    _announced = True


def announce_compilation() -> None:
    """Once per process, before the first kernel call: when the cache lacks kernels, say
    on stderr that the first steps will wait for numba (the agent's core objects call
    this when they are made)."""
    global _announced
    if _announced:
        return
    _announced = True
    todo = uncached()
    if todo:
        print(f"tmgwr_agent: compiling numba kernels, first start only (about "
              f"{COMPILE_SECONDS} s; {len(todo)} of {len(KERNELS)} not cached in "
              f"{cache_dir()}; tools/bootstrap.sh compiles them ahead)",
              file=sys.stderr, flush=True)
