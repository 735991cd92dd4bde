"""The frame in which the value of the unknown measures places (Eq. 5', motivation.py).

The rules of the value of the unknown look places up (the node at a move's predicted
successor), count steps to the goal and follow a wall along its run. They need a frame: a
way to turn a sensation into coordinates where one primitive step is one unit. Two frames
are offered, chosen by the estimator's ``unknown`` parameter:

* :class:`SensorFrame` (``grid``): the sensation's own axes, one step = ``L``, the median
  length of the map's links. Its assumptions: the primitives move along the sensor's
  axes by the same length on every axis (so the L1 distance over ``L`` counts steps and an
  axis-aligned cell of side ``L`` holds one place). True of the grid world sensed as
  (row, col) in one unit; false as soon as the axes are scaled differently, rotated or
  noisy.
* :class:`LearntFrame` (``learnt``, the default): the coordinates of the agent's own
  forward model. ``delta_a``, the mean sensed displacement of primitive ``a`` over the
  agent's moves, is learnt from experience (motivation.py); the displacements of
  linearly independent primitives (the most used first) form a basis ``B``, and a
  sensation ``x`` has the coordinates ``T x``, ``T = B^-1``: primitive steps. Directions
  no primitive has moved along are completed by an orthonormal complement measured in
  link lengths. In these coordinates a sensation that is any invertible linear transform
  of another (units, rotation, shear) gives the same numbers, so the rules below work the
  same. What it still assumes, and checks rather than is told: each primitive
  displaces the sensation by about the same vector wherever it is taken (a lattice),
  and the primitives come in opposite pairs (then the L1 norm in these coordinates is the
  fewest primitive steps that cover a gap). Until the agent has moved along every
  direction its moves span, the sensor frame stands in. The basis is chosen at an
  episode's start and kept for the episode (the potentials are not re-solved for a drift
  of the mean displacement every step).

**Is the forward model a lattice?** (:meth:`LearntFrame.refresh`, ``lattice``.) Beside
the mean displacement ``delta_a`` the agent keeps its spread ``s_a``, the root mean square
of ``|d - delta_a|`` over the moves ``d`` made with ``a`` (motivation.py). The rules that
need a lattice find a move's successor as the place within half a step of ``w_i +
delta_a`` (the cells of :func:`kernels.cell_grid`, the closed-cell test). So a primitive
is *consistent* while ``s_a <= CONSISTENT |delta_a|``, ``CONSISTENT`` = 1/2: its moves
land, in the root mean square, within half of its own step of the place the mean
predicts. A primitive never moved with counts as consistent (nothing contradicts it yet).
An inconsistent primitive (a move that depends on where it is taken: a forward step that
follows a heading, a turn that rotates it) joins no basis, and no rule that places its
successor is used for it: a pair of it never tried is unknown space at a distance bounded
without a lattice (``OptionRules._unplaced_options`` in unknown.py), a tried one has no option.
When no primitive is consistent, the goal is represented by the nodes where the agent
sensed it (``OptionRules.sensed_goal``, unknown.py). With :class:`SensorFrame` (``grid``)
the lattice is declared, not checked.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tmgwr_agent.core import kernels

_NO_ROWS = np.zeros(0, dtype=np.int64)
#: Sensations of at most this many values have their forward model mapped by a kernel
#: (:func:`forward_model`), where it sums as numpy's product does (probed: :func:`_same_sums`).
KERNEL_DIM = 4
_same: bool | None = None


def _same_sums() -> bool:
    """Whether :func:`kernels.frame_delta` gives the bits of numpy's matrix product on this
    machine (its BLAS sums a product's terms in order with fused multiply-adds): checked
    once, on random matrices of 2 to 8 rows and 2 to ``KERNEL_DIM`` columns, where sums
    rounded otherwise differ."""
    global _same
    if _same is None:
        rng = np.random.default_rng(0)
        _same = True
        for P in range(2, 9):
            for dim in range(2, KERNEL_DIM + 1):
                for k in range(2, dim + 1):
                    d, T = rng.normal(size=(P, dim)), rng.normal(size=(k, dim))
                    _same &= np.array_equal(kernels.frame_delta(d, T, np.empty((P, k))),
                                            d @ T.T)
    return _same


def forward_model(delta: np.ndarray, T: np.ndarray) -> np.ndarray:
    """``delta T^T``, the forward model in frame coordinates: numpy's product, by a kernel
    of the same bits where one is known (a BLAS call for a few products costs more than
    most kernels of a step); a vector product (one row or one basis vector) is numpy's."""
    if 1 < len(delta) and 1 < len(T) and delta.shape[1] <= KERNEL_DIM and _same_sums():
        return kernels.frame_delta(delta, T, np.empty((len(delta), len(T))))
    return np.ascontiguousarray(delta @ T.T)


class Frame(NamedTuple):
    """Sensations, goal and forward model in frame coordinates, and the frame's step
    length ``L`` (what the kernels of Eq. 5' take)."""

    w: np.ndarray
    goal: np.ndarray
    delta: np.ndarray
    L: float


class SensorFrame:
    """The sensor's own axes, one step = the median link length (``grid``)."""

    name = "grid"
    version = 0          # the frame never changes (only with L, a key of its own)

    complete = True

    def refresh(self, delta: np.ndarray, moves: np.ndarray, L: float,
                again: bool = True, spread: np.ndarray | None = None) -> None:
        """Nothing to learn."""

    @staticmethod
    def lattice(n_primitives: int) -> np.ndarray:
        """Every primitive: the grid rules declare the lattice."""
        return np.ones(n_primitives, dtype=bool)

    def of(self, w: np.ndarray, goal: np.ndarray, delta: np.ndarray, L: float,
           rows: np.ndarray | None = None, cache: bool = True) -> Frame:
        return Frame(w, goal, delta, L)

    @staticmethod
    def cached(w: np.ndarray, goal: np.ndarray, delta: np.ndarray) -> None:
        """Nothing to map: the estimator's general path (:meth:`LearntFrame.cached`)."""
        return None


class LearntFrame:
    """The coordinates of the learnt forward model (``learnt``); :meth:`refresh` picks the
    basis, :meth:`of` maps sensations into it."""

    name = "learnt"

    #: A primitive joins the basis when the part of its displacement outside the span of
    #: those chosen is at least this share of its length (it is a new direction).
    INDEPENDENT = 0.5
    #: A primitive is consistent while the spread of its displacements is at most this
    #: share of its mean displacement's length (the module docstring: half a step).
    CONSISTENT = 0.5

    def __init__(self):
        self.T: np.ndarray | None = None     # None: the sensor frame stands in
        self._lattice = np.ones(0, dtype=bool)   # the consistent primitives (refresh)
        self.chosen: tuple[int, ...] = ()    # the primitives of the basis
        self.version = 0                     # bumped whenever T changes
        self._w = np.zeros((0, 0))           # the last coordinates of the map's weights
        self._w_version = -1                 # the basis they were computed in
        self._goal_key: tuple = ()           # (basis, goal) of the goal's coordinates
        self._goal = np.zeros(0)

    def refresh(self, delta: np.ndarray, moves: np.ndarray, L: float,
                again: bool = True, spread: np.ndarray | None = None) -> None:
        """Choose the basis from the forward model ``delta`` (one row per primitive),
        the most used primitives first (``moves``), ``L`` the median link length, among
        the consistent primitives (``spread``: the spread of each one's displacements,
        :meth:`consistent`; None: every primitive). With ``again`` False the basis is
        re-estimated only when it gains a primitive (a new direction moved along), not
        for the drift of the mean displacements."""
        dim = delta.shape[1]
        self._lattice = self.consistent(delta, moves, spread)
        basis: list[np.ndarray] = []
        chosen: list[int] = []
        for a in np.argsort(-moves, kind="stable"):
            d = delta[a]
            length = float(np.linalg.norm(d))
            if moves[a] == 0 or length == 0.0 or len(basis) == dim \
                    or not self._lattice[a]:          # never moved, or no lattice step
                continue
            if basis:
                Q, _ = np.linalg.qr(np.array(basis).T)
                rest = d - Q @ (Q.T @ d)
                if np.linalg.norm(rest) < self.INDEPENDENT * length:
                    continue
            basis.append(d)
            chosen.append(int(a))
        if not again and len(chosen) <= len(self.chosen):
            return
        self.chosen = tuple(chosen)
        if not basis:
            T = None
        else:
            B = np.array(basis).T                                  # dim x r
            if B.shape[1] < dim:                                   # complete the span
                Q, _ = np.linalg.qr(np.hstack([B, np.eye(dim)]))
                B = np.hstack([B, L * Q[:, B.shape[1]:dim]])
            T = np.linalg.inv(B)
        if (T is None) != (self.T is None) or \
                (T is not None and not np.array_equal(T, self.T)):
            self.T = T
            self.version += 1

    @classmethod
    def consistent(cls, delta: np.ndarray, moves: np.ndarray,
                   spread: np.ndarray | None, share: float | None = None) -> np.ndarray:
        """Per primitive: its displacements are consistent, ``spread <= share |delta|``
        (``share`` default :attr:`CONSISTENT`), or it never moved (the module docstring);
        every one without ``spread``."""
        if spread is None:
            return np.ones(len(delta), dtype=bool)
        length = np.sqrt(np.einsum("ij,ij->i", delta, delta))
        return (moves == 0) | (spread <= (cls.CONSISTENT if share is None else share) * length)

    def lattice(self, n_primitives: int) -> np.ndarray:
        """The primitives found consistent at the last :meth:`refresh` (every one
        before it)."""
        if len(self._lattice) != n_primitives:
            return np.ones(n_primitives, dtype=bool)
        return self._lattice

    @property
    def complete(self) -> bool:
        """The basis spans the sensation (no direction measured in link lengths)."""
        return self.T is not None and len(self.chosen) == len(self.T)

    def of(self, w: np.ndarray, goal: np.ndarray, delta: np.ndarray, L: float,
           rows: np.ndarray | None = None, cache: bool = True) -> Frame:
        """Weights ``w``, the goal and the forward model in frame coordinates. With
        ``cache`` the coordinates of w are kept (in one array, rewritten by the next
        call) and ``rows``, when given, are the only rows of w that changed since the last
        call (the map's change log): the others are kept when the basis and the size of w
        are the same. ``cache`` False: w's coordinates in a fresh array."""
        if self.T is None:
            return Frame(w, goal, delta, L)
        T = self.T
        if not cache:
            x = np.empty((len(w), len(T)))
            kernels.frame_coords(w, T, _NO_ROWS, -1, x)
        else:
            x = self._w
            if rows is None or x.shape != (len(w), len(T)) or self._w_version != self.version:
                if x.shape != (len(w), len(T)):
                    x = self._w = np.empty((len(w), len(T)))
                kernels.frame_coords(w, T, _NO_ROWS, -1, x)
                self._w_version = self.version
            elif len(rows):
                kernels.frame_coords(w, T, rows, len(rows), x)
        if self._goal_key != (self.version, goal.tobytes()):
            self._goal_key = (self.version, goal.tobytes())
            self._goal = np.ascontiguousarray(T @ goal)
        return Frame(x, self._goal, forward_model(delta, T), 1.0)

    def cached(self, w: np.ndarray, goal: np.ndarray, delta: np.ndarray) -> tuple | None:
        """``(T, x, goal, delta_out)`` when :meth:`of` with ``rows`` would only map those
        rows into the cached coordinates ``x``, the goal's coordinates are cached and the
        forward model is mapped by the kernel (``delta_out``: a new array for it): what
        the estimator's fused preparation (``kernels.prepare_rows``) needs to do the
        same; else None (:meth:`of` is the general path)."""
        T, x = self.T, self._w
        if T is None or x.shape != (len(w), len(T)) or self._w_version != self.version \
                or self._goal_key != (self.version, goal.tobytes()) \
                or not (1 < len(delta) and 1 < len(T) and delta.shape[1] <= KERNEL_DIM
                        and _same_sums()):
            return None
        return T, x, self._goal, np.empty((len(delta), len(T)))


def make_frame(unknown: str) -> SensorFrame | LearntFrame:
    """The frame of the value of the unknown ``unknown`` (``grid`` or ``learnt``)."""
    return LearntFrame() if unknown == "learnt" else SensorFrame()
