"""Load the numba kernels a node steps with from their on-disk cache before its ready line.

numba loads a cached kernel at the kernel's first call in a process (:mod:`tmgwr_agent.core.
kernels`): in a node, that call is a per-step callback after the ready line, so a restarted
node rejoined the ring only once its first steps had loaded them. :func:`load_cached_kernels`
loads them at start instead. It reads numba's cache index (numba internals, as
``kernels._cached`` does, hence the guards): a kernel it cannot load is left to its first
call, as before.
"""

from __future__ import annotations


def load_cached_kernels(names=None) -> int:
    """Load every compiled version that the on-disk cache's index lists for the kernels
    ``names`` (all of :data:`tmgwr_agent.core.kernels.KERNELS` by default); returns how
    many were loaded. A kernel the index does not list waits for its first call."""
    from tmgwr_agent.core import kernels
    loaded = 0
    for name in (kernels.KERNELS if names is None else names):
        dispatcher = kernels.KERNELS[name]
        try:
            signatures = [key[0] for key in dispatcher._cache._cache_file._load_index()]
        except Exception:  # noqa: BLE001 -- numba internals: leave it to its first call
            continue
        for signature in signatures:
            if signature in dispatcher.overloads:
                continue
            try:
                dispatcher.compile(signature)   # found in the cache: loaded, not compiled
                loaded += 1
            except Exception:  # noqa: BLE001 -- as above
                pass
    return loaded
