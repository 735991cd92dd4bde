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
  same. What it still assumes, and has learnt rather than been told: each primitive
  displaces the sensation by about the same vector wherever it is taken (a lattice),
  and the primitives come in opposite pairs (then the L1 norm in these coordinates is the
  fewest primitive steps that cover a gap). Until the agent has moved along every
  direction its moves span, the sensor frame stands in. The basis is chosen at an
  episode's start and kept for the episode (the potentials are not re-solved for a drift
  of the mean displacement every step).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tmgwr_agent.core import kernels

_NO_ROWS = np.zeros(0, dtype=np.int64)


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
                again: bool = True) -> None:
        """Nothing to learn."""

    def of(self, w: np.ndarray, goal: np.ndarray, delta: np.ndarray, L: float,
           rows: np.ndarray | None = None, cache: bool = True) -> Frame:
        return Frame(w, goal, delta, L)


class LearntFrame:
    """The coordinates of the learnt forward model (``learnt``); :meth:`refresh` picks the
    basis, :meth:`of` maps sensations into it."""

    name = "learnt"

    #: A primitive joins the basis when the part of its displacement outside the span of
    #: those chosen is at least this share of its length (it is a new direction).
    INDEPENDENT = 0.5

    def __init__(self):
        self.T: np.ndarray | None = None     # None: the sensor frame stands in
        self.chosen: tuple[int, ...] = ()    # the primitives of the basis
        self.version = 0                     # bumped whenever T changes
        self._w = np.zeros((0, 0))           # the last coordinates of the map's weights
        self._w_version = -1                 # the basis they were computed in
        self._goal_key: tuple = ()           # (basis, goal) of the goal's coordinates
        self._goal = np.zeros(0)

    def refresh(self, delta: np.ndarray, moves: np.ndarray, L: float,
                again: bool = True) -> None:
        """Choose the basis from the forward model ``delta`` (one row per primitive),
        the most used primitives first (``moves``), ``L`` the median link length. With
        ``again`` False the basis is re-estimated only when it gains a primitive (a new
        direction moved along), not for the drift of the mean displacements."""
        dim = delta.shape[1]
        basis: list[np.ndarray] = []
        chosen: list[int] = []
        for a in np.argsort(-moves, kind="stable"):
            d = delta[a]
            length = float(np.linalg.norm(d))
            if moves[a] == 0 or length == 0.0 or len(basis) == dim:    # never moved
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
        return Frame(x, self._goal,
                     np.ascontiguousarray(delta @ T.T), 1.0)


def make_frame(unknown: str) -> SensorFrame | LearntFrame:
    """The frame of the value of the unknown ``unknown`` (``grid`` or ``learnt``)."""
    return LearntFrame() if unknown == "learnt" else SensorFrame()
