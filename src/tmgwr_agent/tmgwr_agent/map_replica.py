"""The map that travels: exact per-step changes of the map arrays, and replicas of them.

Eq. 4-5 read five arrays of the sensorimotor map, one row per node slot ``[0, n)``: the
alive mask, the terminal flags, the weights ``w`` (n x dim), the link targets ``out`` and
their reliabilities ``E`` (n x K) (:class:`~tmgwr_agent.core.sensorimotor_map.MapSnapshot`).
A step changes a few rows of them (the winner and its neighbours adapt, the previous
winner's links follow Eq. 1-2, a node is inserted or removed), so the map learner sends
only those rows, and every consumer keeps an exact copy, a :class:`Replica`:

* :class:`ChangeEncoder` (the learner) compares the map with what it last sent, row by
  row and bit for bit (float rows as their int64 bit patterns), and returns a
  :class:`MapChange`: the slot ids whose row differs, their rows, the new ``n`` and ``K``.
  Slots the map added (``n`` grew) and link columns it added (``K`` grew) start empty
  (alive 0, terminal 0, weight 0, targets -1, E 0), as the core allocates them, and are
  listed only when they differ from empty; the encoder applies each change to its own
  replica, so what it compares with is exactly what the consumers hold.
* Each change belongs to one map (``map_id``, chosen when the learner creates or loads a
  map) and turns its state ``base`` into state ``sequence`` (consecutive numbers). A
  change with ``base`` :data:`FULL` lists every slot: the whole map (the first change of a
  map, and the latched snapshots), which replaces any replica.
* :meth:`Replica.apply` applies a change when it follows the replica's state, and says so:
  :data:`APPLIED`, :data:`CURRENT` (the replica is already at that state: a resent
  step), :data:`STALE` (an older whole map, ignored) or :data:`GAP` (a change of another
  map, or one that does not start where the replica is: a message was missed, or the
  consumer joined late). After a gap the replica waits for a whole map (the latched
  snapshot, or one it asks for) and goes on from there.

ROS-free: the nodes and the bag tools convert messages (any object with the fields of
``tmgwr_interfaces/MapChange``: rclpy's arrays or rosbags' numpy arrays) with
:meth:`MapChange.of_fields`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tmgwr_agent.core.sensorimotor_map import MapSnapshot, RowLog

FULL = 0                 # base of a change that holds the whole map

APPLIED, CURRENT, STALE, GAP = "applied", "current", "stale", "gap"

#: The arrays of a replica, their dtypes and the value of an empty slot.
ROWS = {"alive": (np.bool_, False), "terminal": (np.bool_, False),
        "w": (np.float64, 0.0), "out": (np.int64, -1), "E": (np.float64, 0.0)}


@dataclass
class MapChange:
    """Rows ``slots`` of the map arrays after the change, turning state ``base`` of map
    ``map_id`` into state ``sequence``; ``n``, ``degree``, ``dim``, ``version`` are the
    map's after it, and ``(run_id, step_id)`` the step that made it."""

    map_id: int
    base: int
    sequence: int
    n: int
    degree: int
    dim: int
    version: int
    slots: np.ndarray        # int64, ascending
    alive: np.ndarray        # bool, one per slot
    terminal: np.ndarray     # bool
    w: np.ndarray            # float64, len(slots) x dim
    out: np.ndarray          # int64, len(slots) x degree
    E: np.ndarray            # float64, len(slots) x degree
    run_id: int = 0
    step_id: int = -1
    #: pairs (keep, gone) the map merged in this change, in order (SensorimotorMap.merges):
    #: what a consumer's per-node memory applies (the rows above already hold the result)
    merges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))

    @property
    def full(self) -> bool:
        return self.base == FULL

    @classmethod
    def of_fields(cls, m, version: int, run_id: int = 0, step_id: int = -1) -> MapChange:
        """The change carried by a ``tmgwr_interfaces/MapChange`` message ``m`` (rclpy's
        array.array fields or rosbags' numpy arrays)."""
        k = len(m.slots)
        dim, degree = int(m.dim), int(m.degree)
        return cls(map_id=int(m.map_id), base=int(m.base_sequence), sequence=int(m.sequence),
                   n=int(m.n_slots), degree=degree, dim=dim, version=int(version),
                   slots=_array(m.slots, np.int32).astype(np.int64),
                   alive=_array(m.alive, np.uint8).astype(bool),
                   terminal=_array(m.terminal_nodes, np.uint8).astype(bool),
                   w=_array(m.weights, np.float64).reshape(k, dim),
                   out=_array(m.link_targets, np.int32).astype(np.int64).reshape(k, degree),
                   E=_array(m.link_reliability, np.float64).reshape(k, degree),
                   run_id=int(run_id), step_id=int(step_id),
                   merges=_array(getattr(m, "merges", ()), np.int32).astype(np.int64)
                   .reshape(-1, 2))

    def problem(self) -> str | None:
        """Why this change cannot be of a learner (a stray message), or None."""
        k = len(self.slots)
        if self.map_id <= 0:
            return f"map id {self.map_id} (a learner's map ids are positive)"
        if min(self.n, self.degree, self.dim) < 0 or self.sequence < 0:
            return f"{self.n} slots, degree {self.degree}, dim {self.dim}, state {self.sequence}"
        if len(self.alive) != k or len(self.terminal) != k:
            return f"{k} slots but {len(self.alive)} alive and {len(self.terminal)} terminal flags"
        if k and (self.slots.min() < 0 or self.slots.max() >= self.n):
            return f"a slot outside [0, {self.n})"
        if self.out.size and (self.out.min() < -1 or self.out.max() >= self.n):
            return f"a link target outside [-1, {self.n})"
        if self.merges.size and (self.merges.min() < 0 or self.merges.max() >= self.n):
            return f"a merged node outside [0, {self.n})"
        return None

    def nbytes(self) -> int:
        """Bytes of its arrays as a message carries them (slot ids and targets int32)."""
        k = len(self.slots)
        return k * (4 + 2 + 8 * self.dim + 12 * self.degree) + 4 * self.merges.size


def _array(a, dtype) -> np.ndarray:
    """A message array as a numpy array of ``dtype`` (a copy: replicas keep their rows)."""
    if isinstance(a, np.ndarray):
        return a.astype(dtype, copy=True)
    return np.frombuffer(a, dtype=dtype).copy() if len(a) else np.zeros(0, dtype)


class Replica:
    """The map arrays Eq. 4-5 read, kept up to date from :class:`MapChange` s.

    Rows ``[0, n)`` are the map's; storage grows by doubling like the core's, and
    :meth:`snapshot` hands the estimator views of rows ``[0, n)`` (no copy).
    """

    def __init__(self):
        self.map_id = 0
        self.sequence = -1          # state held (-1: none, waiting for a whole map)
        self.run_id, self.step_id = 0, -1     # the step of the last change applied
        self.version = 0
        self.n, self.degree, self.dim = 0, 0, 0
        self.arrays = {name: np.zeros((0,), dtype) for name, (dtype, _) in ROWS.items()}
        self.log = RowLog()         # the slots each change wrote (the estimator's input)
        self.merges = np.zeros((0, 2), dtype=np.int64)   # applied, not yet taken

    @property
    def synced(self) -> bool:
        return self.sequence >= 0

    def __getattr__(self, name):    # replica.w etc.: rows [0, n) of the arrays
        arrays = self.__dict__.get("arrays")
        if arrays is not None and name in arrays:
            return arrays[name][: self.n]
        raise AttributeError(name)

    # ------------------------------------------------------------------ changes
    def status(self, c: MapChange) -> str:
        """What :meth:`apply` would do with ``c``."""
        same = self.synced and c.map_id == self.map_id
        if c.full:
            return STALE if same and c.sequence < self.sequence else (
                CURRENT if same and c.sequence == self.sequence else APPLIED)
        if same and c.sequence == self.sequence:
            return CURRENT
        return APPLIED if same and c.base == self.sequence else GAP

    def apply(self, c: MapChange) -> str:
        """Apply ``c`` if it follows this replica's state (or holds a newer whole map);
        returns :data:`APPLIED`, :data:`CURRENT`, :data:`STALE` or :data:`GAP`."""
        status = self.status(c)
        if status != APPLIED:
            return status
        if c.full or c.dim != self.dim:
            self.log.invalidate()
            self.dim, self.n = c.dim, 0
            self.arrays = {name: np.zeros((0, c.dim) if name == "w" else
                                          (0, c.degree) if name in ("out", "E") else (0,),
                                          dtype) for name, (dtype, _) in ROWS.items()}
            self.degree = c.degree
        self.resize(c.n, c.degree)
        for name in ROWS:
            self.arrays[name][c.slots] = getattr(c, name)
        if not c.full:
            self.log.touch(c.slots)
        self.merges = np.concatenate([self.merges, c.merges]) \
            if len(self.merges) and not c.full else c.merges
        self.map_id, self.sequence, self.version = c.map_id, c.sequence, c.version
        self.run_id, self.step_id = c.run_id, c.step_id
        return APPLIED

    def take_merges(self) -> np.ndarray:
        """The merges of the changes applied since the last call (pairs ``(keep, gone)``,
        in order): what the consumer's per-node memory has yet to apply."""
        merges, self.merges = self.merges, np.zeros((0, 2), dtype=np.int64)
        return merges

    def resize(self, n: int, degree: int) -> None:
        """``n`` slots of ``degree`` link columns; new slots and columns are empty, rows
        beyond a smaller ``n`` are dropped (emptied)."""
        if n == self.n and degree == self.degree:
            return                          # most steps: nothing to do
        a = self.arrays
        if degree > self.degree:
            cap = len(a["alive"])
            a["out"] = np.concatenate([a["out"], np.full((cap, degree - self.degree), -1,
                                                         np.int64)], axis=1)
            a["E"] = np.concatenate([a["E"], np.zeros((cap, degree - self.degree))], axis=1)
        elif degree < self.degree:
            a["out"] = np.ascontiguousarray(a["out"][:, :degree])
            a["E"] = np.ascontiguousarray(a["E"][:, :degree])
        self.degree = degree
        cap = len(a["alive"])
        if n > cap:
            new_cap = max(64, cap)
            while new_cap < n:
                new_cap *= 2
            for name, (dtype, empty) in ROWS.items():
                old = a[name]
                grown = np.full((new_cap, *old.shape[1:]), empty, dtype)
                grown[:cap] = old
                a[name] = grown
        for name, (_, empty) in ROWS.items():
            a[name][n: max(self.n, n)] = empty
        self.n = n

    def snapshot(self) -> MapSnapshot:
        """The replica as the estimator reads a map (views of rows ``[0, n)``)."""
        n = self.n
        a = self.arrays
        return MapSnapshot(w=a["w"][:n], alive=a["alive"][:n], out=a["out"][:n],
                           E=a["E"][:n], terminal=a["terminal"][:n], version=self.version,
                           log=self.log)

    def full_change(self) -> MapChange:
        """The whole replica as a change (:data:`FULL`): what a snapshot carries."""
        n = self.n
        return MapChange(map_id=self.map_id, base=FULL, sequence=self.sequence, n=n,
                         degree=self.degree, dim=self.dim, version=self.version,
                         slots=np.arange(n, dtype=np.int64),
                         **{name: self.arrays[name][:n].copy() for name in ROWS},
                         run_id=self.run_id, step_id=self.step_id)

    def equals(self, m) -> bool:
        """Whether rows ``[0, n)`` equal those of ``m`` (a map or replica) bit for bit."""
        if (self.n, self.degree, self.dim) != (m.n, m.out.shape[1], m.w.shape[1]):
            return False
        return all(np.array_equal(_bits(getattr(self, name)), _bits(getattr(m, name)[: m.n]))
                   for name in ROWS) and self.version == m.version


def _bits(a: np.ndarray) -> np.ndarray:
    """Float arrays as their bit patterns (so -0.0 != 0.0 and NaN == NaN), others as is."""
    return a.view(np.int64) if a.dtype == np.float64 else a


class ChangeEncoder:
    """The learner's side: :meth:`encode` the change of a map since the last call.

    ``m`` is anything with the map's attributes (``n``, ``w``, ``alive``, ``out``, ``E``,
    ``terminal``, ``version``; storage may be longer than ``n``): a
    :class:`~tmgwr_agent.core.sensorimotor_map.SensorimotorMap`. One encoder per map
    instance: a new map (created, loaded) gets a new encoder with a new ``map_id``.
    """

    def __init__(self, map_id: int):
        if map_id <= 0:
            raise ValueError(f"map_id must be positive, got {map_id}")
        self.map_id = map_id
        self.sent = Replica()       # exactly what consumers that applied every change hold

    @property
    def sequence(self) -> int:
        return self.sent.sequence

    def encode(self, m, run_id: int = 0, step_id: int = -1) -> MapChange:
        """The rows of ``m`` that differ from the last change sent (all of them the first
        time, or when the map shrank or changed dimension); the encoder's replica
        applies it."""
        n, degree, dim = int(m.n), int(m.out.shape[1]), int(m.w.shape[1])
        sent = self.sent
        full = (not sent.synced or n < sent.n or degree < sent.degree or dim != sent.dim)
        if full:
            slots = np.arange(n, dtype=np.int64)
        else:
            sent.resize(n, degree)          # new slots / columns empty, as the core's
            slots = changed_rows(sent, m, n)
        change = MapChange(
            map_id=self.map_id, base=FULL if full else sent.sequence,
            sequence=sent.sequence + 1 if sent.synced else 1, n=n, degree=degree, dim=dim,
            version=int(m.version), slots=slots,
            **{name: getattr(m, name)[slots].astype(ROWS[name][0], copy=False)
               for name in ROWS},
            run_id=int(run_id), step_id=int(step_id),
            merges=np.asarray(getattr(m, "merges", ()), dtype=np.int64).reshape(-1, 2))
        status = sent.apply(change)
        assert status == APPLIED, status
        sent.take_merges()                  # (no memory of its own to move)
        return change

    def snapshot(self) -> MapChange | None:
        """The whole map as last encoded (None before the first :meth:`encode`)."""
        return self.sent.full_change() if self.sent.synced else None


def changed_rows(old: Replica, m, n: int) -> np.ndarray:
    """Slot ids in ``[0, n)`` whose row of any array differs between ``old`` (resized to
    ``n`` slots) and ``m``, bit for bit.

    Each array is compared flat and the few differing elements are mapped to their rows:
    a step changes a handful of rows, and numpy's ``any(axis=1)`` over rows of 2-8 values
    costs far more on a large map."""
    a = old.arrays
    found = []
    for name in ROWS:
        x, y = _bits(a[name][:n]), _bits(getattr(m, name)[:n])
        diff = np.flatnonzero(x != y)
        if len(diff):
            found.append(diff // max(x.size // max(n, 1), 1))
    if not found:
        return np.zeros(0, dtype=np.int64)
    return np.unique(np.concatenate(found)).astype(np.int64)
