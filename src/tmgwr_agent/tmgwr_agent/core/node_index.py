"""The node index of the sensorimotor map: a uniform grid over its weights, so that a step
finds the winner and the merge's close pairs among the nodes near the input, not among
all of them.

Both searches minimise ``d_n = (1 - alpha_c) |x - w_n|^2 + alpha_c |Sc (C_t - c_n)|^2``
(sensorimotor_map.py), which is at least ``(1 - alpha_c)`` times the squared distance
along any of w's coordinates. The grid lists every live node in the cell of its first one
or two weight coordinates; the winner is searched in squares of cells of growing width
around the input until no node outside the square can be as near as the best found
(:func:`kernels.indexed_argmin`), a close pair within the cells the merge's radius reaches
(:func:`kernels.indexed_close_pair`). Both return what a scan of every node returns, ties
included (the lowest id, the first row), so the index changes no trajectory.

The grid follows the map's change log (:class:`~tmgwr_agent.core.sensorimotor_map.RowLog`:
every write of weights or alive flags lists its rows, the map's contract): before a search
the rows listed since the last one are moved to their cells (the step's own adaptation in
the same kernel call, :func:`kernels.map_step`). It is built again, its cell width the
side of a square that holds one live node on average over their bounding box (and a
margin around it), when the log cannot list the rows, a node leaves the grid, or the map
has twice the slots it had at the last build. Below ``INDEX_MIN`` slots the searches scan
every node (a scan of a small map costs less than keeping the grid).
"""

from __future__ import annotations

import math

import numpy as np

from tmgwr_agent.core import kernels

_NO_ROWS = np.zeros(0, dtype=np.int64)
#: Slots from which the map searches through the index.
INDEX_MIN = 256
#: Margin of the grid around the nodes' bounding box, as a share of its side.
MARGIN = 0.25
#: At most this many cells a live node.
MAX_CELLS_PER_NODE = 4


class NodeIndex:
    """The grid's arrays (the layout is :mod:`tmgwr_agent.core.kernels`', section "the node
    index") and the position of the map's change log it follows."""

    def __init__(self):
        self.head = np.full(1, -1, dtype=np.int64)
        self.node = np.full((3, 0), -1, dtype=np.int64)
        self.geom = np.array([0.0, 0.0, 1.0, 1.0])
        self.shape = np.array([1, 1, 1, 0], dtype=np.int64)     # not valid: scan
        self._log = None
        self._pos = -1
        self._built_n = 0

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """What the kernels' searches take: head, node, geom, shape."""
        return self.head, self.node, self.geom, self.shape

    def sync(self, m) -> None:
        """Bring the grid up to date with map m's weights and alive flags: the rows its
        change log lists since the last call moved to their cells (:meth:`pending`), or
        the grid built again when one left it."""
        rows = self.pending(m)
        if len(rows) and not kernels.index_move(m.w, m.alive, m.n, rows, len(rows),
                                                *self.arrays):
            self.pending(m)                 # a node left the grid: built again

    def pending(self, m) -> np.ndarray:
        """The rows of map m to move to their cells before the next search, those its
        change log lists since the last call (the caller moves them:
        :func:`kernels.index_move`, or :func:`kernels.map_step` in the same call as the
        step), after building the grid again when due; below ``INDEX_MIN`` slots none,
        the grid marked not valid (the searches scan)."""
        log, n = m.log, m.n
        if self.shape[3] and log is self._log and n <= 2 * self._built_n:
            rows = log.since(self._pos)
            if rows is not None:
                self._pos = log.pos
                return rows
        self._log, self._pos = log, log.pos
        self.shape[3] = 0
        if n >= INDEX_MIN:
            self.build(m)
        return _NO_ROWS

    def build(self, m) -> None:
        """Build the grid around map m's live nodes (valid unless a weight is not
        finite), whatever its size."""
        n = m.n
        k = min(m.w.shape[1], 2)
        live = np.flatnonzero(m.alive[:n])
        if not len(live):
            return
        p = m.w[live, :k]
        if not np.isfinite(p).all():      # (not valid: the searches scan)
            return
        lo, span = p.min(axis=0), np.ptp(p, axis=0)
        margin = MARGIN * span
        side = span + 2.0 * margin
        width = float(np.prod(side)) ** (1.0 / k) / len(live) ** (1.0 / k)
        if not math.isfinite(width) or width <= 0.0:     # all on a line or a point
            width = float(side.max()) / len(live) if side.max() > 0.0 else 1.0
        while True:
            cells = np.floor(side / width).astype(np.int64) + 1
            if int(np.prod(cells)) <= MAX_CELLS_PER_NODE * len(live) + 16:
                break
            width *= 1.5
        origin = lo - margin
        self.geom[:] = (origin[0], origin[1] if k > 1 else 0.0, width, 1.0 / width)
        self.shape[:] = (cells[0], cells[1] if k > 1 else 1, k, 0)
        size = int(cells[0]) * int(self.shape[1])
        if len(self.head) < size:
            self.head = np.full(size, -1, dtype=np.int64)
        if self.node.shape[1] < len(m.w):
            self.node = np.full((3, len(m.w)), -1, dtype=np.int64)
        self._built_n = n
        kernels.index_build(m.w, m.alive, n, *self.arrays)
