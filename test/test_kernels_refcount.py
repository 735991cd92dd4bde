"""The solves' loops take no array reference (kernels.py, "incremental Eq. 4-5'"): numba
passes an inlined helper (node_target, the heap's push) a reference to each of its arrays
(NRT_incref, an atomic add, then NRT_decref), and only LLVM's reference-count pruning
removes those pairs. Where it cannot (a branch around the helper's loops), they run on
every call, several times the cost of the helper's own work. This compiles the kernels
that call those helpers (fresh copies of their Python source, no cache written) and reads
their LLVM code: no NRT_incref may sit in a loop of the kernel's own function."""

import re

import numpy as np
import pytest
from numba import njit

from tmgwr_agent.core import kernels


def own_function(ir: str, name: str) -> str:
    """The LLVM function compiled from kernel ``name`` (not its Python wrappers)."""
    for fn in re.split(r"\ndefine ", ir)[1:]:
        m = re.search(r"@([\w.$]+)\(", fn)
        head = m.group(1) if m else ""
        if "cpython" not in head and "cfunc" not in head and \
                re.search(r"\d" + re.escape(name) + r"B\d", head):
            return fn
    raise AssertionError(f"no LLVM function for {name}")


def increfs_in_loops(fn: str) -> int:
    """NRT_incref calls in the blocks of ``fn`` that lie on a cycle of its control flow
    (strongly connected components of the branch graph, Tarjan's algorithm)."""
    blocks = re.split(r"\n(?=[\w.\-]+:)", fn)
    succ, inc = {}, {}
    for k, b in enumerate(blocks):
        label = "entry" if k == 0 else b.split(":")[0].strip()
        succ[label] = re.findall(r"label %([\w.\-]+)", b)
        inc[label] = b.count("@NRT_incref")
    index, low, stack, on_stack, cyclic = {}, {}, [], set(), set()
    counter = [0]

    def visit(v):   # recursive: a kernel has a few hundred blocks
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in succ.get(v, []):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            members = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                members.append(w)
                if w == v:
                    break
            if len(members) > 1 or v in succ.get(v, []):
                cyclic.update(members)

    for v in succ:
        if v not in index:
            visit(v)
    return sum(inc[v] for v in cyclic)


def solve_inputs(n=6, K=4, P=4, B=4):
    """A small map with the argument types the estimator passes."""
    rng = np.random.default_rng(0)
    out = np.where(rng.random((n, K)) < 0.6, rng.integers(0, n, (n, K)), -1)
    E = np.where(out >= 0, 0.9, 0.0)
    R = np.zeros(n)
    R[0] = 1.0
    V = np.zeros(n + 1)
    absorbing, alive = np.zeros(n, bool), np.ones(n, bool)
    U, rho = np.zeros((n, P)), np.zeros((n, P))
    osucc, onb = np.full((n, P), -1), np.full((n, P, B), -1)
    ong = np.zeros((n, P, B))
    first, pred = kernels.predecessors(out, n, alive, osucc, onb)
    heap, pos, key = np.zeros(n + 1, np.int64), np.full(n + 1, -1), np.zeros(n + 1)
    return (out, E, R, V, n, 0.97, 1e-4, 1e-150, absorbing, alive, U, rho, osucc, onb, ong,
            first, pred, heap, pos, key)


def compiled(name, *args):
    """LLVM function of a fresh, uncached compilation of kernel ``name`` for ``args``."""
    f = njit(getattr(kernels, name).py_func)
    f(*args)
    return own_function(next(iter(f.inspect_llvm().values())), name)


@pytest.mark.parametrize("name", ["_drain", "_queue_seeds", "invalidate", "_ordered_solve"])
def test_the_solves_loops_take_no_array_reference(name):
    (out, E, R, V, n, gamma, tol, floor, absorbing, alive, U, rho, osucc, onb, ong, first,
     pred, heap, pos, key) = solve_inputs()
    eq = (out, E, R, V, gamma, tol, floor, absorbing, alive, U, rho, osucc, onb, ong)
    seeds, target = np.arange(n, dtype=np.int64), np.full(n + 1, np.nan)
    args = {
        "_drain": eq + (first, pred, 10 * n, heap, pos, key, 0, True, target),
        "_queue_seeds": eq + (seeds, n, heap, pos, key, 0, True, target, False),
        "invalidate": (out, E, R, V, n) + eq[4:] + (first, pred, seeds, n,
                                                    np.zeros(n, np.int64),
                                                    np.zeros(n, bool), target),
        "_ordered_solve": (out, E, R, V, n) + eq[4:] + (first, pred, seeds, n, 10 * n,
                                                        heap, pos, key, target, False),
    }[name]
    assert increfs_in_loops(compiled(name, *args)) == 0
