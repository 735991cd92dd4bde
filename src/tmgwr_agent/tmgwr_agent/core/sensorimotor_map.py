"""The TMGWR sensorimotor map (section 3.1, Fig. 1b, Eq. 1-2).

Growth and adaptation follow GWR (Marsland et al. 2002) with the temporal context of
Merge-GNG (Strickert & Hammer 2005; docs/interpretation.md), as the 2019 TMGWR
paper is not public:

* context of the input    ``C_t = (1 - beta_c) w_{prev} + beta_c c_{prev}``
* distance                ``d_n = (1 - alpha_c) |x - w_n|^2 + alpha_c |Sc (C_t - c_n)|^2``
                          (``Sc``: below, "The context in primitive steps")
* activity                ``a = exp(-sqrt(d_b))`` of the winner ``b``
* insertion               when ``a < a_T`` and ``h_b <= h_T``: a node at ``insert_at`` of
                          the way from the winner to the input (weight and context; GWR:
                          halfway), habituation 1
* adaptation otherwise    ``w_b += eps_b h_b (x - w_b)``, ``w_n += eps_n h_n (x - w_n)``
                          (same for the contexts) for the winner and its neighbours
* habituation             ``h += tau (kappa (1 - h) - 1)`` (tau_b winner, tau_n neighbours)

Links are the *sensorimotor links* of Fig. 1b: directed ``i -> j`` between consecutive
winners, labelled with the action vector ``a_ij`` that was active, and carrying the
reliability ``E[i, j]`` updated by Eq. 1-2::

    E[i, j] <- E[i, j] + alpha * Delta_E,   Delta_E = sim(a_ij, a) I{i != j} - E[i, j]

with ``sim`` a Gaussian of width ``sigma_a`` (0.3 unit moves: two orthogonal unit moves,
``|a - b|^2 = 2``, match by ``exp(-2 / (2 * 0.09)) = 1.5e-5``, so under the credit rule
below an action blames only the links labelled with that action; with 0.5 each action
blamed the links of the orthogonal ones by about a hundredth a step, and the links out of a
junction the agent passes often wore down, E 0.86 after a training, which Eq. 5-6 read
as several steps of detour). A new link starts at ``E_init`` (1: the
binary link of the original TMGWR, "E[i, j] = 1 if a possible transition"; with 0 a
shortcut seen once is worth half a known detour and is ignored until explored again by
chance). After the update the link's action vector
moves towards the action that traversed it, ``a_ij += eta_a (a - a_ij)`` (the map "learns
the possible action vectors linking" nodes, section 3.1): a node that drifted while the map
formed would otherwise keep a link labelled with an action that no longer leads there.
Link rules (an open question; docs/interpretation.md):

* ``literal``: Eq. 1-2 as written; only the traversed link ``i -> j`` is updated (a self
  transition ``i -> i``, a bump, drives ``E[i, i]`` to 0 and is not stored).
* ``credit``: additionally every other link ``i -> k`` is blamed in proportion to how well
  its action matches the action just taken, since that action did not lead to ``k``:
  ``E[i, k] <- E[i, k] + alpha sim(a_ik, a) (0 - E[i, k])``.

As in GWR, every link incident to the previous winner (in or out) ages by one per step
and the traversed link's age restarts at 0; links older than ``max_age``, and links whose
reliability fell below ``E_min``, are deleted; nodes left with no link (in or out) are
removed, which clears nodes that stopped winning; except a node flagged terminal (an
episode ended there, :meth:`SensorimotorMap.mark_terminal`): that the cell ends episodes is
knowledge the agent can only regain by losing an episode there, and a goal that moved away
keeps ending them in the goal-change scenario while the agent stops visiting it, so its
links age out (without the exception the old goal's node went, the cell looked like
unknown space, and Eq. 5' sent the agent into it: one episode lost in 4 of 5 trials of a
suite maze). Neighbours for adaptation are the nodes linked to the winner in either
direction.

**One node a place** (``merge``, our addition, on by default; off under ``paper``). GWR
inserts a node only where no node matches within its radius, ``sqrt(d) < -ln a_T``; that
invariant should hold afterwards too, but adaptation breaks it: a node habituated to its
place (its own rate frozen near ``eps_b / kappa``) is still pulled by its neighbours'
wins (``eps_n``), a noisy sample beyond the radius then inserts a second node for the
place, and the two come within the radius of each other. Their wins then alternate with
the noise, so the links of one action into the place split their reliability between
them, and Eq. 5's ``max_k E V(k)`` undervalues the move (a route then detours round a
cell it knows). So after each learning step, two live nodes of which one moved and that
lie within the matching radius of each other (the ``d`` above, context included: nodes
of one sensation told apart by their contexts stay apart) are merged
(:meth:`SensorimotorMap._merge`): the more habituated one stays (``keep``), at the
midpoint of the two weights and contexts, with the fresher habituation (it re-centres on
its samples); the other's links, in and out, become ``keep``'s, and a link ``s -> k``
that both had is one link: under the credit rule the reliabilities of one action's
links out of a node are running means of the indicator that the action reached each
target, so the indicator of reaching either of two targets that are one place is their
sum, ``E = min(1, E_1 + E_2)`` (links of different actions: the more reliable one);
a link between the two goes (a move within a place is not stored, as a bump); terminal
flags are or-ed. The pairs ``(keep, gone)`` of the last step are in :attr:`merges`, for
the consumers that keep memory per node (the motivation estimator's outcome memory; over
the graph, :class:`~tmgwr_agent.map_replica.MapChange` carries them). A node inserted
by the step and merged into a known place is that place, not a new node
(:attr:`inserted` False: the estimator keeps the place's outcome memory).

Noise spreads a place's samples beyond the matching radius, so duplicates also arise that
never come within the radius. **The radius of a place** is therefore the wider of GWR's
``-ln a_T`` and the sensing scatter, ``-ln a_place`` (:meth:`SensorimotorMap.
_place_radius`), which the insertion test and the merges above use: the map keeps each
primitive's sensed displacement ``x_t - x_{t-1}`` over its moves (not its bumps), their
mean ``m`` and spread ``s`` (mean squared deviation from ``m``; :attr:`motion`). Where a
primitive moves by the same vector wherever it is taken, ``s`` is the scatter of two
samples, twice that of one sample about its place, and ``sqrt(2 s)`` is twice the root
mean square scatter of a sample: a sample that near its winner is taken as noise on the
winner's place, not as a new place. Only primitives whose moves stand out of their
scatter, ``|m| > 2 sqrt(s)``, count (the radius then stays below a step, so neighbouring
places are not taken for one), the least ``s`` among them. Without noise ``s`` is 0 (a
grid) or far below the matching radius (PointMaze's physics): GWR's radius stands.

The touch sensor tells of one more case: a *bump* (the primitive was blocked) leaves the
agent where it was, so its two samples are of one place; its two winners are not merged
all the same. The second sample wins another node than the one stood on only from beyond
the radius of that node's place, and under noise that far out the scatters of
neighbouring places meet: the node is as likely a neighbour's place as a duplicate, and
one sample cannot tell which (a merge of two places cuts every route through them).
Duplicates are merged by their weights, which the samples they win draw into one place's
radius (the merge of close nodes above): many samples, not one, tell that two nodes are
one place. Without noise a bump in a grid senses no change (one winner), and one in
PointMaze that moved part way before it met the wall is two places.

**A bump from another place.** Under noise a node can win samples of two neighbouring
places (a node left between them by a merge, or a sample scattered past the half-way
line); from such a node one primitive moves when the agent stands at one place and bumps
at the other. Read as the node's own, that bump says the move the node made has closed
(the outcome memory then cuts the link, closes the cell it led to and may find the goal
unreachable). So before a bump is learnt, the map checks where it was taken
(:meth:`SensorimotorMap.bumped_elsewhere`):
the primitive's moves from the node (its most reliable link labelled with it, to ``j``)
started about ``w_j - m``, and a bump sensed more than half a step ``|m| / 2`` from there
was taken nearer another place than that one (the places of a lattice of steps ``m`` lie
a step apart, so half a step is the line between two; for a primitive whose moves stand
out of their scatter, as above, while the place radius is the scatter's). Such a bump is
learnt as a bump at the node (Eq. 1-2 on a self transition: its links of that primitive
lose reliability, as the node's share of samples where the primitive bumps grows), makes
no link and merges nothing, and is the winner's, the place it was taken at (:attr:`SensorimotorMap.
bump_from`, what the agent and the graph's map learner report as the node acted from;
-1, no node, when the winner is the same node or the bump is elsewhere for it too).
That check reads one sample, ``x_prev``, which a scatter past the half-way line puts at
the wrong place. A bump leaves the agent where it was, so it has two samples of its
place, ``x_prev`` and ``x``, whose mean scatters ``1/sqrt(2)`` as far as either: when
the node nearest that mean is another place's than the winner of ``x_prev`` (beyond the
radius of its place), the bump was taken there, and is learnt as above with that node as
``bump_from`` (:meth:`SensorimotorMap.bump_place`).
Without noise, or with a scatter inside GWR's radius, the check is off.

**A move within one node.** Eq. 1-2 read a self transition ``i -> i`` as a bump: the
primitive left the agent where it was, so the links of that primitive out of ``i`` lose
reliability (the credit rule) and age. The touch sensor tells a bump from a move, and a
move that was not blocked but whose two samples have one winner is no bump: the node
won samples of two places (under noise a sample scattered past the half-way line, or a
node left between two places by a merge), and which of its links the move took the map
cannot see. Such a step changes no link (:meth:`SensorimotorMap.step`, ``unblocked``;
:func:`kernels.map_step`): no reliability lost, no ageing. Without noise a move always
changes the winner (two places are a step apart, far beyond the matching radius, and
GWR inserts a node for a sample beyond it while ``h_T`` lets every winner insert, as
the default does), so there the rule does not apply.

**A move between other places.** Likewise a move whose two winners lie farther apart
than the primitive moves: a primitive moves the sensation by its mean sensed move ``m``
(:attr:`motion`) wherever it is taken, so from node i's place it leads to the place about
``w_i + m``, and a winner ``j`` more than half a step ``|m| / 2`` from there (the line
between two places of a lattice of steps ``m``, as for a bump taken elsewhere) is not
where a move from i's place ends: one of the two samples was scattered into another
place's node (a diagonal or a two-step link). Learnt as a transition, one such sample
made a link ``i -> j`` of reliability ``E_init`` and, by the credit rule, cut the
reliability of the primitive's true link by ``alpha``; Eq. 6 then ranked a detour above
the true move, and as the greedy walk no longer took it, nothing repaired it (a greedy
probe failed at the same step episode after episode). Such a step changes no link, as a
move within one node (:meth:`SensorimotorMap.mean_step`, :func:`kernels.stray_move`),
when the map can tell which sample strayed: the map has a node where the move leads
from i (the node nearest ``w_i + m`` lies within half a step of it: ``x`` strayed), or
the move started at another node's place (the node nearest the mean of its two
estimates of where it started, ``x_prev`` and ``x - m``, is not i: ``x_prev`` strayed
into i). Otherwise (no node where the move leads, a start at i's place: a node left
between two places stands for both, and the move is the only link the map can make
there) the transition is learnt as before; a move never learnt would be tried again and
again. Only for a primitive whose moves stand out of their scatter (``|m| > 2 sqrt(s)``)
while the place radius is the sensing scatter's (``a_place < a_T``): without noise
places are a step apart and every move reaches one (the rule is off).

**The place the links predict.** A sample scattered nearer a neighbouring node than its
own makes that node the winner, and the action chosen from it is the neighbour's (a
greedy walk then bumps or turns off its route). The links say where the move just made
leads: the target of the previous winner's most reliable link of that primitive (the
previous winner itself after a bump that was not elsewhere). When the input lies within
the radius of a place of that node (``-ln a_place``, the radius within which a sample is
noise on a node's place, above), it wins, though another node may lie a little nearer
(:func:`kernels.match`, ``prior``); the sensation alone decides otherwise. And when
that node is the nearest but the input lies beyond its place's radius, no node is
inserted (:meth:`SensorimotorMap.step`): the sample is the tail of the predicted place's
scatter, not a new place. GWR inserts a node for an input that no node explains; here the
links explain it, and the nearest node agrees. A node inserted from such a tail sample
stays just beyond the radius of its twin (it wins only the tail on its side, and it
habituates before it drifts back), so the merges never join the two, and one action's
links into the place split their reliability between them (the duplicates of issue 28).
Only while the radius is the sensing scatter's (``a_place < a_T``): without noise the
nearest node wins, and GWR's test inserts, as in GWR.

**The mean of a place's samples.** GWR moves the winner ``eps_b h_b`` of the way to each
input, and habituation brings ``h_b`` down to ``1 - 1/kappa`` within a few wins: a node's
weight is then an average in which its first samples keep much of their weight for about
``1 / (eps_b (1 - 1/kappa))`` wins. Without noise the samples of a place coincide and
this is no matter. Under noise a node inserted at one sample stays off its place's centre
by a share of that sample's scatter, for long: nodes of neighbouring places stand nearer
each other than their places do, so a place's samples win a neighbour's node, and a
duplicate inserted from a tail sample stays apart from its twin (the merges never join
them); the links of one action into a place then split between two nodes, and Eq. 5-6
read the split as an unreliable move. So while the place radius is the sensing scatter's
(``a_place < a_T``; with ``merge``, as every rule of one node a place), the winner moves
at least ``1 / n_b`` of the way, ``n_b`` the samples it has won (:attr:`won`; the sample
it was inserted at is its first; :func:`kernels.adapt`): while that is the larger rate,
its weight and context are the mean of its samples, the estimate of its place's centre
whose error falls as the square root of their number; then GWR's rate takes over, a
moving average over about as many samples. A merge adds the two counts. Without noise,
or with a scatter inside GWR's radius, the rule is off.

**The context in primitive steps.** Merge-GNG's context term tells apart nodes of one
sensation by where the agent came from; measured in the sensor's units, ``|C_t - c_n|^2``
weighs a step along an axis by the square of that axis's unit, so a sensor whose axes
have different units (a grid sensed in cells along one axis and fifths of a cell along the
other) splits each place by the direction it was entered from along the larger unit:
places double, links of one move split between them, and learning slows. The context is
therefore measured in primitive steps: ``|Sc (C_t - c_n)|^2`` with ``Sc = l T``, ``T`` the
frame of the learnt forward model (frame.LearntFrame over :attr:`motion`: one primitive
step is one unit) and ``l`` the shortest primitive step, so a step along any axis counts
as the shortest one does (:meth:`SensorimotorMap._context_metric`; learnt at each
episode's start and at each doubling of a primitive's moves, from its second on). Where
``l T`` is an isometry as far as the moves tell (``|Sc^T Sc - I|`` within three of its
standard errors, about ``8 r``, ``r`` the largest relative standard error of a mean step,
``sqrt(s / n) / |m|``; the deviation is about twice the difference of two steps' relative
errors) the sensor's units stand: a grid sensed in one unit, rotated or not, with or
without noise; so where no primitive is a lattice step (MiniGrid's turns). ``d_n`` is
then GWR's.

Storage is fixed-width adjacency (``out[i, :K]`` target ids, -1 = empty slot) so that value
iteration over the map is a few vectorised numpy operations. Node ids are slot indices; a
freed slot is reused by the next insertion (lowest first) and ``version`` counts structural
changes (insertion, deletion) so consumers know when ids were reassigned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from tmgwr_agent.core import kernels
from tmgwr_agent.core.frame import LearntFrame
from tmgwr_agent.core.node_index import INDEX_MIN, NodeIndex
from tmgwr_agent.core.outcome import Outcome
from tmgwr_common.params import Config, param


@dataclass(frozen=True)
class MapConfig(Config):
    """Hyperparameters of the TMGWR map: GWR growth, Merge-GNG context, Eq. 1-2 links."""

    a_T: float = param(0.95, "GWR activity threshold: insert a node when exp(-sqrt(d_b)) < "
                       "a_T", low=0.0, high=1.0, low_open=True, high_open=True)
    h_T: float = param(1.0, "GWR habituation threshold: only a winner with h_b <= h_T spawns "
                       "a node (1: any winner; lower it for noisy sensors)", low=0.0,
                       high=1.0, low_open=True)
    tau_b: float = param(0.3, "habituation rate of the winner", low=0.0, high=1.0,
                         low_open=True)
    tau_n: float = param(0.1, "habituation rate of the winner's neighbours", low=0.0,
                         high=1.0, low_open=True)
    kappa_h: float = param(1.05, "GWR habituation constant kappa (h tends to 1 - 1/kappa)",
                           low=1.0, high=10.0, low_open=True)
    eps_b: float = param(0.2, "learning rate of the winner", low=0.0, high=1.0)
    eps_n: float = param(0.006, "learning rate of the winner's neighbours", low=0.0,
                         high=1.0)
    insert_at: float = param(1.0, "where a new node goes between the winner (0) and the "
                             "input (1); GWR uses 0.5", low=0.0, high=1.0, low_open=True)
    max_age: int = param(100, "links older than this are deleted", low=1, high=1e9,
                         integer=True)
    alpha_c: float = param(0.01, "Merge-GNG weight of the temporal context in the distance",
                           low=0.0, high=1.0, high_open=True)
    beta_c: float = param(0.5, "Merge-GNG context blend: C_t = (1-beta_c) w_prev + beta_c "
                          "c_prev", low=0.0, high=1.0)
    alpha: float = param(0.52, "Eq. 1: learning rate of the sensorimotor-link reliability E "
                         "(Table 2)", low=0.0, high=1.0, low_open=True)
    sigma_a: float = param(0.3, "Eq. 2: width of the Gaussian sim(a_ij, a) between action "
                           "vectors (0.3: orthogonal unit moves match by exp(-11))",
                           low=0.0, low_open=True, high=100.0)
    E_init: float = param(1.0, "reliability of a newly created link before Eq. 1-2 adapts "
                          "it (1 = the binary link of the original TMGWR)", low=0.0,
                          high=1.0)
    E_min: float = param(0.01, "a link whose reliability falls below this is deleted (it is "
                         "no longer a possible transition: E = 0 in the original TMGWR)",
                         low=0.0, high=1.0)
    eta_a: float = param(1.0, "rate at which a link's action vector a_ij follows the action "
                         "that traversed it (0 = fixed at creation)", low=0.0, high=1.0)
    merge: bool = param(True, "merge two live nodes that come within the GWR matching "
                        "radius of each other, links and E combined (sensorimotor_map.py; "
                        "false: GWR as published)")
    link_rule: str = param("credit", "Eq. 1-2 reading: 'literal' or 'credit' "
                           "(docs/interpretation.md)",
                           choices=("literal", "credit"))


class Links(NamedTuple):
    """The outgoing sensorimotor links of one node, what Eq. 6 ranks: target ids
    (-1 = empty slot), reliabilities E and action vectors a_ij, one row per slot."""

    targets: np.ndarray
    E: np.ndarray
    actions: np.ndarray


class RowLog:
    """The node rows a map changed (weights, alive, links, reliabilities, terminal
    flags: what Eq. 4-5' read), in order, so that a consumer asks for the rows changed since
    it last looked (:meth:`since`) instead of comparing every row. A consumer keeps the
    position :attr:`pos` it read up to; positions are absolute, and the log forgets its
    oldest entries when it outgrows its bound, or all of them at a change it cannot list
    (:meth:`invalidate`: a map loaded, rebuilt or replaced): :meth:`since` then answers
    None and the consumer compares every row. Rows may repeat. The node index
    (node_index.py) reads it too: a write of weights or alive flags that is not logged
    leaves the index stale, so the map would pick wrong winners, not only stale values."""

    def __init__(self):
        self._rows = np.empty(256, dtype=np.int64)
        self._len = 0             # entries held
        self._start = 0           # absolute position of _rows[0]

    @property
    def pos(self) -> int:
        """The position after the last entry."""
        return self._start + self._len

    def touch(self, rows) -> None:
        """Rows changed (an int or an array of ints)."""
        if isinstance(rows, (int, np.integer)):
            if self._len < len(self._rows):       # most calls: one row, room for it
                self._rows[self._len] = rows
                self._len += 1
                return
            rows = (rows,)
        if not isinstance(rows, np.ndarray) or rows.dtype != np.int64:
            rows = np.atleast_1d(np.asarray(rows, dtype=np.int64))
        k = len(rows)
        if self._len + k > len(self._rows):
            if self._len + k > 4096:          # forget the oldest: readers that far behind
                self._start += self._len      # compare every row
                self._len = 0
            if k > len(self._rows):
                self._rows = np.empty(2 * k, dtype=np.int64)
            elif self._len + k > len(self._rows):
                self._rows = np.concatenate([self._rows, np.empty_like(self._rows)])
        self._rows[self._len: self._len + k] = rows
        self._len += k

    def buffer(self) -> tuple[np.ndarray, int]:
        """The array of entries and how many it holds, for a kernel that appends rows in
        place while they fit in it (what :meth:`touch` does then), then :meth:`appended`."""
        return self._rows, self._len

    def appended(self, length: int) -> None:
        """A kernel appended entries in place (:meth:`buffer`): it holds ``length``."""
        self._len = length

    def invalidate(self) -> None:
        """Every row may have changed: readers from before compare every row."""
        self._start += self._len + 1
        self._len = 0

    def since(self, pos: int) -> np.ndarray | None:
        """The rows changed after position ``pos`` (a view; may repeat), or None when the
        log no longer holds them all."""
        if pos < self._start or pos > self.pos:
            return None
        return self._rows[pos - self._start: self._len]


@dataclass
class MapSnapshot:
    """What Eq. 4-5 read of the map, as the motivation estimator receives it over the
    graph: weights, alive mask, links and their reliabilities, terminal flags (rows
    ``[0, n)``). :class:`SensorimotorMap` offers the same attributes, so the estimator
    runs on either."""

    w: np.ndarray
    alive: np.ndarray
    out: np.ndarray
    E: np.ndarray
    terminal: np.ndarray
    version: int
    log: RowLog | None = None    # the rows changed, when the source keeps a log

    @property
    def n(self) -> int:
        return len(self.alive)

    def nearest_by_weight(self, x: np.ndarray) -> int:
        """The node whose sensory weight is nearest x (Algorithm 1, line 2: SM.Map(x_g))."""
        return int(kernels.nearest_weight(self.w, self.alive, self.n, x))


def survivor(i: int, merges) -> int:
    """Node i's id after the ``merges`` (pairs ``(keep, gone)``, in order)."""
    for keep, gone in merges:
        if i == gone:
            i = int(keep)
    return i


#: The hyperparameters of :func:`kernels.map_step` (``hp``), in its order, then whether the
#: link rule is ``credit``.
STEP_PARAMETERS = ("alpha_c", "beta_c", "h_T", "eps_b", "eps_n", "tau_b", "tau_n", "kappa_h",
                   "alpha", "sigma_a", "eta_a", "E_init", "E_min", "max_age")
_INITIAL_CAPACITY = 64
_NO_ROWS = np.zeros(0, dtype=np.int64)
_INITIAL_DEGREE = 4
_SENSOR_UNITS = np.zeros((0, 0))   # Sc with no rows: the context in the sensor's units
_ROUNDING = 1e-9                   # an isometry up to rounding (_context_metric)
_STANDARD_ERRORS = 8.0             # ... or within 3 standard errors, 3 * 2 * sqrt(2) r


class SensorimotorMap:
    """A growing map of (weight, context) nodes joined by directed, action-labelled links."""

    def __init__(self, dim: int, action_dim: int = 2, config: MapConfig = MapConfig(),
                 primitives: np.ndarray | None = None):
        """``primitives``: the motor vector of each action (:class:`~tmgwr_agent.core.
        senses.Senses`), what :meth:`experience` labels a link with; :meth:`step` takes
        the vector itself."""
        kernels.announce_compilation()
        self.dim, self.action_dim = dim, action_dim
        self.primitives = None if primitives is None else \
            np.ascontiguousarray(primitives, dtype=float)
        self.config = config
        c = config
        self.a_T, self.h_T = c.a_T, c.h_T
        self.a_place = c.a_T       # the radius of one place, -ln a_place (_place_radius)
        self.tau_b, self.tau_n, self.kappa_h = c.tau_b, c.tau_n, c.kappa_h
        self.eps_b, self.eps_n = c.eps_b, c.eps_n
        self.insert_at = c.insert_at
        self.max_age = c.max_age
        self.alpha_c, self.beta_c = c.alpha_c, c.beta_c
        self.alpha, self.sigma_a, self.eta_a = c.alpha, c.sigma_a, c.eta_a
        self.E_init, self.E_min = c.E_init, c.E_min
        self.link_rule = c.link_rule
        self.merge = c.merge
        self.merges: list[tuple[int, int]] = []   # (keep, gone) of the last step's merges
        # the hyperparameters kernels.map_step reads, in one array (fixed at construction)
        self._hp = np.array([float(getattr(self, k)) for k in STEP_PARAMETERS]
                            + [1.0 if self.link_rule == "credit" else 0.0])
        self._alloc(_INITIAL_CAPACITY, _INITIAL_DEGREE)
        # each primitive's sensed displacement over its moves (not bumps): count, mean,
        # sum of squared deviations (Welford); and the last input (the bump test)
        self.motion = np.zeros((0 if primitives is None else len(primitives), dim + 2))
        self.x_prev = np.full(dim, np.nan)
        self.n = 0                 # slots in use are [0, n); dead slots have alive False
        self.version = 0           # bumped on every structural change
        self.prev: int = -1        # previous winner (-1: start of an episode)
        self.winner: int = -1
        self.inserted = False      # whether the last update inserted a node (its winner)
        self.winner_new = -1       # the node the last insertion made
        self.bump_from: int | None = None   # a bump taken elsewhere: the node it was (-1:
        #                                     none; None: the step's own previous winner)
        self.C_t = np.zeros(dim)   # Merge-GNG context of the last input (kernels.match)
        self.Sc = _SENSOR_UNITS    # the context's metric (_context_metric; none: raw units)
        self.log = RowLog()        # the rows each change touched (the estimator's input)
        self.index = NodeIndex()   # where the step searches for the winner (node_index.py)
        self.rebuild_in_links()    # (none yet: compiles the kernel where maps are made)

    # ------------------------------------------------------------------ storage
    def _alloc(self, cap: int, degree: int) -> None:
        self.w = np.zeros((cap, self.dim))          # sensory weight w_n
        self.c = np.zeros((cap, self.dim))          # temporal context c_n
        self.h = np.ones(cap)                       # habituation h_n
        self.won = np.zeros(cap)                    # samples won (its insertion's first)
        self.alive = np.zeros(cap, dtype=bool)
        self.out = np.full((cap, degree), -1, dtype=np.int64)   # link targets
        self.E = np.zeros((cap, degree))            # reliability E[i, j]
        self.a = np.zeros((cap, degree, self.action_dim))       # action vectors a_ij
        self.age = np.zeros((cap, degree), dtype=np.int64)
        self.terminal = np.zeros(cap, dtype=bool)   # an episode ended on the node
        self.inn = np.full((cap, degree), -1, dtype=np.int64)   # sources of links in
        self._changed = np.empty(1 + 6 * degree, dtype=np.int64)  # rows a step changed

    def _grow_nodes(self) -> None:
        names = ("w", "c", "h", "won", "alive", "out", "E", "a", "age", "terminal", "inn")
        old = [getattr(self, name) for name in names]
        self._alloc(2 * len(self.w), self.out.shape[1])
        for name, arr in zip(names, old):
            getattr(self, name)[: len(arr)] = arr

    def _grow_degree(self) -> None:
        cap, k = self.out.shape
        pad = k
        self.out = np.concatenate([self.out, np.full((cap, pad), -1, np.int64)], axis=1)
        self.E = np.concatenate([self.E, np.zeros((cap, pad))], axis=1)
        self.a = np.concatenate([self.a, np.zeros((cap, pad, self.action_dim))], axis=1)
        self.age = np.concatenate([self.age, np.zeros((cap, pad), np.int64)], axis=1)
        self.inn = np.concatenate([self.inn, np.full((cap, pad), -1, np.int64)], axis=1)
        self._changed = np.empty(1 + 6 * self.out.shape[1], dtype=np.int64)

    @property
    def size(self) -> int:
        return int(self.alive[: self.n].sum())

    def node_ids(self) -> np.ndarray:
        return np.flatnonzero(self.alive[: self.n])

    def links(self):
        """(source, target, action vector, E, age) of every link, sorted by source."""
        src, slot = np.nonzero(self.out[: self.n] >= 0)
        return (src, self.out[src, slot], self.a[src, slot], self.E[src, slot],
                self.age[src, slot])

    def links_of(self, i: int) -> Links:
        """The outgoing links of node i (views into the map's storage)."""
        return Links(self.out[i], self.E[i], self.a[i])

    def link_count(self) -> int:
        return int((self.out[: self.n] >= 0).sum())

    # ------------------------------------------------------------------ matching
    def context(self) -> np.ndarray | None:
        """Merge-GNG context C_t of the current input (None at an episode start); the step
        computes it in :func:`kernels.match`, the loop form of this and of
        :meth:`distances`."""
        if self.prev < 0:
            return None
        return (1.0 - self.beta_c) * self.w[self.prev] + self.beta_c * self.c[self.prev]

    def distances(self, x: np.ndarray, C: np.ndarray) -> np.ndarray:
        """d_n = (1 - alpha_c)|x - w_n|^2 + alpha_c |Sc (C_t - c_n)|^2 (inf for dead slots)."""
        n = self.n
        dx = self.w[:n] - x
        d = (1.0 - self.alpha_c) * np.einsum("ij,ij->i", dx, dx)
        if self.alpha_c > 0.0:
            dc = self.c[:n] - C
            if len(self.Sc):
                dc = dc @ self.Sc.T
            d += self.alpha_c * np.einsum("ij,ij->i", dc, dc)
        d[~self.alive[:n]] = np.inf
        return d

    def nearest_by_weight(self, x: np.ndarray) -> int:
        """The node whose sensory weight is nearest x (Algorithm 1, line 2: SM.Map(x_g))."""
        return int(kernels.nearest_weight(self.w, self.alive, self.n, x))

    # ------------------------------------------------------------------ learning
    def begin_episode(self) -> None:
        """The agent was moved, not walked: no link from the last winner; the context's
        metric learnt anew from the moves so far (:meth:`_context_metric`)."""
        self.prev = -1
        self._context_metric()

    def mark_terminal(self, i: int) -> None:
        """An episode ended on node i (the agent is moved back to the start next), at the
        goal or short of it.

        The flag is the map's memory that i's place is a terminal state of the world, so
        every node of that place gets it (:meth:`nodes_at`: the map may hold more than one
        node for a place, reached in different temporal contexts, and a link into an
        unflagged one led the agent into an old goal in the goal-change scenario); it is
        cleared, on every node of the place, as soon as the agent walks on from a flagged
        node within an episode (:meth:`step`), e.g. when a goal moved away and its old
        cell became an ordinary one. The motivation estimator treats flagged nodes as
        absorbing (no successor in Eq. 5), except the nodes of the current goal."""
        if 0 <= i < self.n:
            at = self.nodes_at(i)
            self.terminal[at] = True
            self.terminal[i] = True
            self.log.touch(at)
            self.log.touch(i)

    def nodes_at(self, i: int) -> np.ndarray:
        """The live nodes whose weights lie within the radius of a place of node i's,
        ``-ln a_place`` (a winner that near inserts no node): i's place."""
        idx = np.flatnonzero(self.alive[: self.n])
        d = self.w[idx] - self.w[i]
        return idx[np.einsum("ij,ij->i", d, d) < math.log(self.a_place) ** 2]

    def experience(self, x: np.ndarray, outcome: Outcome, learn: bool = True) -> int:
        """The map stage of one agent step (Fig. 1a): input x, reached by the outcome's
        motor primitive (or placed at an episode start); returns the winner. A node where
        the task ended the episode is flagged terminal (:meth:`mark_terminal`).
        With ``learn`` False only the winner is found (greedy rollouts)."""
        if outcome.episode_start:
            self.begin_episode()
            motor = None
        else:
            if self.primitives is None:
                raise ValueError("the map was given no motor primitives: experience() "
                                 "labels links with primitives[action]")
            motor = self.primitives[outcome.action]
        before = self.prev
        self.bump_from = None
        at = self.bump_place(before, x) if learn and motor is not None and outcome.bumped \
            and self.merge else -1
        elsewhere = learn and motor is not None and outcome.bumped and self.merge \
            and (at >= 0 or self.bumped_elsewhere(before, outcome.action))
        prior = -1
        if motor is not None and self.merge and self.a_place < self.a_T and not elsewhere:
            prior = before if outcome.bumped else self.link_target(before, outcome.action)
        moved = learn and motor is not None and not outcome.bumped   # (then not elsewhere)
        winner = self.step(x, None if elsewhere else motor, learn=learn, prior=prior,
                           unblocked=not outcome.bumped,
                           sensed=outcome.action if moved else -1)
        if elsewhere:
            winner = self._bump_elsewhere(before, winner, motor, outcome.action, at)
        self.x_prev[:] = x
        if learn and outcome.ends_episode:
            self.mark_terminal(winner)
        return winner

    def step(self, x: np.ndarray, action: np.ndarray | None, learn: bool = True,
             prior: int = -1, unblocked: bool = False, sensed: int = -1) -> int:
        """Present input x reached by motor vector ``action``; returns the winner.
        ``prior``: the node the links predict (``experience``), the winner when x lies
        within the radius of its place; when it is the nearest node, none is inserted
        (the module docstring, "The place the links predict"). ``unblocked``: the touch
        sensor said the action was not blocked, so a winner equal to the previous one is
        no transition the links learn (the module docstring, "A move within one node");
        else it is a bump. ``sensed`` >= 0: the primitive of a move that was not blocked,
        whose sensed displacement from ``x_prev`` joins its statistics after the step
        (:meth:`_sensed_move`; in the step's own kernel call when it makes the whole step).
        Its mean sensed move also tells a move between other places (the module
        docstring, :meth:`mean_step`).

        With ``learn`` False only the winner is found (greedy rollouts).
        """
        x = np.asarray(x, dtype=float)
        self.merges = []
        C = self.C_t    # written by match: context(), x at an episode start (neutral)
        self.inserted = False
        # winner, GWR test, adaptation of the winner and its neighbours; when nothing
        # needs Python (no insertion, no terminal prev, no row to widen) the link stage
        # and the merge's first close pair in the same call (kernels.map_step)
        has_action = action is not None
        a = np.asarray(action, dtype=float) if has_action else self.C_t[:0]
        r2 = math.log(self.a_place) ** 2 if self.merge else -1.0
        moves = self.index.pending(self) if self.n >= INDEX_MIN or self.index.shape[3] \
            else _NO_ROWS     # rows the node index is to follow (node_index.py)
        changed, log = self._changed, self.log
        motion = self.motion
        step, step_r2 = self.mean_step(sensed) \
            if unblocked and learn and self.merge and self.prev >= 0 else (x, -1.0)
        # (with ``merge``, as every rule of one node a place: "A move between other places")
        if step_r2 >= 0.0 and self.nearest_by_weight(
                0.5 * (self.x_prev + x - step)) == self.prev:
            t = self.nearest_by_weight(self.w[self.prev] + step)
            if t < 0 or kernels.stray_move(self.w, self.prev, t, step, step_r2):
                step_r2 = -1.0      # (from prev's place to no node's: learnt as before)
        (b, insert, nm, done, changes, ne, ci, cj, linked, logged, a_place,
         count) = kernels.map_step(
            self.w, self.c, self.h, self.won, self.merge and self.a_place < self.a_T,
            self.alive, self.out, self.inn, self.n, self.prev, x, C, self.Sc, self.a_place,
            learn, self._hp, self.E, self.a, self.age, self.terminal, a, has_action,
            unblocked, step, step_r2, self.winner, r2, prior, *self.index.arrays, moves,
            len(moves), changed, *log.buffer(), motion, sensed if sensed < len(motion) else -1,
            self.x_prev, self.a_T)
        moved = changed[:nm]        # (views of the step's buffer, read before the next step)
        if logged >= 0:             # the kernel logged the rows it changed
            log.appended(logged)
        elif nm:
            log.touch(moved)
        if done:
            if linked:
                self.version += changes
                if logged < 0:
                    log.touch(self.prev)
                    if ne:
                        log.touch(changed[nm:nm + ne])
            if ci >= 0:
                b = self._merge_close(moved, b, (ci, cj))
            self.prev = self.winner = b
            if count > -2:
                self._moved(a_place, count)     # the kernel added the sensed move
            elif sensed >= 0:
                self._sensed_move(x, sensed)
            return b
        if not learn or not insert or b == prior >= 0:   # (the links' place: no insertion)
            winner = b
        elif b < 0:
            winner = self._insert(x, C)
        else:
            lam = self.insert_at
            winner = self._insert(self.w[b] + lam * (x - self.w[b]),
                                  self.c[b] + lam * (C - self.c[b]))
            self._habituate(b, self.tau_b)
        if learn and self.prev >= 0 and action is not None and not (unblocked and (
                winner == self.prev
                or kernels.stray_move(self.w, self.prev, winner, step, step_r2))):
            if self.terminal[self.prev]:        # walked on from prev: its place is not an
                at = self.nodes_at(self.prev)                              # episode end
                self.terminal[at] = False
                self.terminal[self.prev] = False
                self.log.touch(at)
                self.log.touch(self.prev)
            self._update_links(self.prev, winner, np.asarray(action, dtype=float))
        if learn and self.merge and len(moved):
            winner = self._merge_close(moved, winner)
        self.prev = self.winner = winner
        if sensed >= 0:
            self._sensed_move(x, sensed)
        return winner

    def _sync_index(self) -> None:
        """The node index up to date before a search (node_index.py; a scan below
        ``INDEX_MIN`` slots)."""
        if self.n >= INDEX_MIN or self.index.shape[3]:
            self.index.sync(self)

    # ------------------------------------------------------------------ one node a place
    def _merge_close(self, moved: np.ndarray, winner: int,
                     pair: tuple[int, int] | None = None) -> int:
        """Merge every pair of live nodes within the matching radius of which one is in
        ``moved`` (the nodes this step adapted; the module docstring); returns the
        winner's id after the merges. ``pair``: the first close pair, already found."""
        r2 = math.log(self.a_place) ** 2
        rows = np.asarray(moved, dtype=np.int64)
        while True:
            if pair is None:
                self._sync_index()
            i, j = pair if pair is not None else kernels.indexed_close_pair(
                self.w, self.c, self.alive, self.n, rows, self.alpha_c, self.Sc, r2,
                *self.index.arrays)
            pair = None
            if i < 0:
                return winner
            keep, gone = (i, j) if self.h[i] <= self.h[j] else (j, i)
            self._merge(keep, gone)
            winner = keep if winner == gone else winner
            rows = np.append(rows[rows != gone], keep)

    def _sensed_move(self, x: np.ndarray, a: int) -> None:
        """After a learning step by primitive ``a`` that moved (no bump) from the sensation
        ``x_prev`` to ``x``: its sensed displacement ``x - x_prev`` joins the primitive's
        statistics (:attr:`motion`), then ``a_place`` (the module docstring)."""
        if a >= len(self.motion):           # (a map made or loaded without primitives)
            if not np.isfinite(x - self.x_prev).all():
                return
            self.motion = np.concatenate([self.motion,
                                          np.zeros((a + 1 - len(self.motion), self.dim + 2))])
        self._moved(*kernels.sensed_motion(self.motion, a, x, self.x_prev, self.a_T))

    def _moved(self, a_place: float, count: int) -> None:
        """The end of :meth:`_sensed_move` after :func:`kernels.sensed_motion` (the place's
        activity threshold, the primitive's count of moves after it)."""
        if count < 0:                       # no sensation before it
            return
        self.a_place = a_place              # Welford's
        if count >= 2 and count & (count - 1) == 0:   # each doubling of its moves
            self._context_metric()

    def _bump_elsewhere(self, before: int, winner: int, motor: np.ndarray, a: int,
                        at: int = -1) -> int:
        """After a step without a link (the matching and adaptation only) for a bump of
        primitive ``a`` that :meth:`bumped_elsewhere` says was taken at another place than
        the moves of ``a`` from ``before``: Eq. 1-2 as a bump at ``before`` (a self
        transition: the links of ``a`` out of it lose reliability, as for any bump there,
        and no link to the winner is made), and :attr:`bump_from`, the node the bump is
        of: ``at`` when :meth:`bump_place` found one, else the winner when it is another
        node and the bump is not elsewhere for it too, else -1 (no node). Returns the
        winner."""
        before = survivor(before, self.merges)
        at = survivor(at, self.merges)
        if before >= 0 and self.alive[before]:
            self._update_links(before, before, motor)
        if at >= 0 and self.alive[at]:         # the place of its two samples (bump_place)
            self.bump_from = at
        else:
            self.bump_from = winner if winner != before and winner >= 0 \
                and not self.bumped_elsewhere(winner, a) else -1
        return winner

    def bump_place(self, before: int, x: np.ndarray) -> int:
        """The node of the place where a bump sensed at ``x`` after ``x_prev`` was taken
        (the module docstring, "A bump from another place"), when that is another place's
        than ``before``'s, the winner of ``x_prev``, else -1: the node whose weight is
        nearest the mean of the two samples, when it lies beyond the radius of
        ``before``'s place (within it, it is that place).
        Only while the place radius is the sensing scatter's (``a_place < a_T``, as
        :meth:`bumped_elsewhere`)."""
        if not self.a_place < self.a_T or before < 0 or not self.alive[before] \
                or not np.isfinite(self.x_prev).all():
            return -1
        j = self.nearest_by_weight(0.5 * (self.x_prev + np.asarray(x, dtype=float)))
        if j < 0 or j == before:
            return -1
        d = self.w[j] - self.w[before]
        return j if float(d @ d) >= math.log(self.a_place) ** 2 else -1

    def bumped_elsewhere(self, i: int, a: int) -> bool:
        """Whether a bump of primitive ``a``, taken where the last input ``x_prev`` was
        sensed, was taken somewhere else than the moves of ``a`` from node i (the module
        docstring, "A bump from another place"): i's most reliable link labelled with
        ``a`` leads to node j, so those moves started about ``w_j - m`` (``m``: the
        primitive's mean sensed displacement), and the bump's sensation lies more than
        half a step ``|m| / 2`` from there. Only for a primitive whose moves stand out of
        their scatter (``|m| > 2 sqrt(s)``, ``s`` their spread), while the place radius is
        the sensing scatter's (``a_place < a_T``: below GWR's radius a node does not win
        samples of two places a step apart)."""
        if i < 0 or not self.alive[i] or self.primitives is None \
                or not np.isfinite(self.x_prev).all():
            return False
        m, r2 = self.mean_step(a)
        if r2 < 0.0:
            return False
        j = self.link_target(i, a)
        if j < 0:
            return False
        d = self.x_prev - (self.w[j] - m)
        return bool(d @ d > r2)

    def mean_step(self, a: int) -> tuple[np.ndarray, float]:
        """``(m, r2)``: primitive ``a``'s mean sensed move and the squared distance, a
        quarter of ``|m|^2`` (half a step), beyond which a move by it from one node's place
        does not reach another node's (the module docstring, "A move between other
        places", "A bump from another place"); ``r2`` -1 (no test) unless its moves
        stand out of their scatter (``|m| > 2 sqrt(s)``, ``s`` their spread) while the place
        radius is the sensing scatter's (``a_place < a_T``: below GWR's radius a node does
        not win samples of two places a step apart)."""
        if a < 0 or a >= len(self.motion) or not self.a_place < self.a_T:
            return self.x_prev, -1.0
        count, m, m2 = self.motion[a, 0], self.motion[a, 1:-1], self.motion[a, -1]
        mm = float(m @ m)
        if count < 2 or not 4.0 * (m2 / count) < mm:
            return self.x_prev, -1.0
        return np.ascontiguousarray(m), 0.25 * mm

    def link_target(self, i: int, a: int) -> int:
        """The target of node i's most reliable link labelled with primitive ``a``
        (``sim >= 1/2`` by Eq. 2), -1 without one."""
        if i < 0 or self.primitives is None or a >= len(self.primitives):
            return -1
        best, j = 0.0, -1
        for k in np.flatnonzero(self.out[i] >= 0):
            if kernels.sim_action(self.a[i, k], self.primitives[a], self.sigma_a) >= 0.5 \
                    and self.E[i, k] > best:
                best, j = self.E[i, k], int(self.out[i, k])
        return j

    def _place_radius(self) -> None:
        """``a_place``, the activity threshold of one place (the module docstring): GWR's
        ``a_T``, or the sensing scatter ``sqrt(2 s)`` as the radius where it is wider, ``s``
        the least spread of a primitive whose moves stand out of their scatter,
        ``|m| > 2 sqrt(s)`` (the module docstring)."""
        self.a_place = kernels.place_activity(self.motion, self.a_T)

    def _context_metric(self) -> None:
        """``Sc``, the metric of the context's share of ``d_n`` (the module docstring, "The
        context in primitive steps"): ``l T``, ``T`` the learnt frame of the primitives'
        mean sensed displacements (frame.LearntFrame over :attr:`motion`, the primitives
        moved at least twice: their spread known), ``l`` the shortest of their steps;
        none (the sensor's units) while no primitive is a lattice step or while ``l T`` is
        an isometry within three standard errors (``8 r``; a grid sensed in one unit, or
        rotated: ``d_n`` as GWR's)."""
        count, delta = self.motion[:, 0], self.motion[:, 1:-1]
        spread = np.sqrt(self.motion[:, -1] / np.maximum(count, 1.0))
        length = np.sqrt(np.einsum("ij,ij->i", delta, delta))
        steps = (count >= 2) & (length > 0.0) & LearntFrame.consistent(delta, count, spread)
        self.Sc = _SENSOR_UNITS
        if not steps.any():
            return
        ell = float(length[steps].min())
        frame = LearntFrame()
        frame.refresh(delta, np.where(steps, count, 0.0), ell, spread=spread)
        if frame.T is None:
            return
        Sc = ell * frame.T
        chosen = list(frame.chosen)
        r = spread[chosen] / (length[chosen] * np.sqrt(count[chosen]))
        tol = max(_ROUNDING, _STANDARD_ERRORS * float(r.max()))
        if np.abs(Sc.T @ Sc - np.eye(self.dim)).max() > tol:
            self.Sc = np.ascontiguousarray(Sc)

    def _merge(self, keep: int, gone: int) -> None:
        """Node ``gone`` becomes part of node ``keep`` (the module docstring): weights and
        contexts at their midpoint, the fresher habituation, links in and out joined
        (:meth:`_join_link`), terminal flags or-ed; ``gone``'s slot is freed."""
        i, j = keep, gone
        self.w[i] = 0.5 * (self.w[i] + self.w[j])
        self.c[i] = 0.5 * (self.c[i] + self.c[j])
        self.h[i] = max(self.h[i], self.h[j])
        self.won[i] += self.won[j]
        self.terminal[i] = self.terminal[i] or self.terminal[j]
        for s in np.flatnonzero(self.out[j] >= 0):          # j -> t becomes i -> t
            t = int(self.out[j, s])
            if t != i:
                self._join_link(i, t, self.E[j, s], self.a[j, s].copy(), self.age[j, s])
        touched = [i, j]
        for src in np.flatnonzero((self.out[: self.n] == j).any(axis=1)):
            slot = int(np.flatnonzero(self.out[src] == j)[0])   # src -> j becomes src -> i
            link = self.E[src, slot], self.a[src, slot].copy(), self.age[src, slot]
            self.out[src, slot], self.E[src, slot], self.age[src, slot] = -1, 0.0, 0
            self.a[src, slot] = 0.0
            if src != i:
                self._join_link(int(src), i, *link)
                touched.append(int(src))
        self.out[j], self.E[j], self.a[j], self.age[j] = -1, 0.0, 0.0, 0
        self.alive[j] = self.terminal[j] = False
        self.version += 1
        self.merges.append((i, j))
        if self.inserted and self.winner_new in (i, j):   # a new node merged into a known
            self.inserted = False                          # place is that place: not new
        self.rebuild_in_links()
        self.log.touch(np.asarray(touched, dtype=np.int64))

    def _join_link(self, s: int, t: int, E: float, a: np.ndarray, age: int) -> None:
        """Link s -> t (reliability E, action a, age) added to row s: joined with the link
        s -> t already there (same action, ``sim >= 1/2`` by Eq. 2: ``E`` summed up to 1,
        the action the E-weighted mean; else the more reliable one), or in a free slot."""
        have = np.flatnonzero(self.out[s] == t)
        if len(have):
            k = int(have[0])
            E0, a0 = self.E[s, k], self.a[s, k].copy()
            if kernels.sim_action(a0, a, self.sigma_a) >= 0.5:
                if E0 + E > 0.0:
                    self.a[s, k] = (E0 * a0 + E * a) / (E0 + E)
                self.E[s, k] = min(1.0, E0 + E)
            elif E > E0:
                self.E[s, k], self.a[s, k] = E, a
            self.age[s, k] = min(self.age[s, k], age)
            return
        free = np.flatnonzero(self.out[s] < 0)
        if not len(free):
            self._grow_degree()
            free = np.flatnonzero(self.out[s] < 0)
        k = int(free[0])
        self.out[s, k], self.E[s, k], self.a[s, k], self.age[s, k] = t, E, a, age

    def _insert(self, w: np.ndarray, c: np.ndarray) -> int:
        free = np.flatnonzero(~self.alive[: self.n])
        if len(free):
            r = int(free[0])
        else:
            if self.n == len(self.w):
                self._grow_nodes()
            r = self.n
            self.n += 1
        self.w[r], self.c[r], self.h[r], self.won[r], self.alive[r] = w, c, 1.0, 1.0, True
        self.terminal[r] = False
        stale = bool((self.out[r] >= 0).any() or (self.inn[r] >= 0).any())
        self.out[r] = -1
        self.E[r] = 0.0
        self.age[r] = 0
        self.version += 1
        self.inserted = True
        self.winner_new = r
        self.log.touch(r)
        if stale:               # (a freed slot has no links: removed only when unlinked)
            self.rebuild_in_links()
        return r

    def _habituate(self, i: int, tau: float) -> None:
        kernels.habituate(self.h, i, tau, self.kappa_h)

    def _update_links(self, i: int, j: int, a: np.ndarray) -> None:
        """Eq. 1-2 on the transition i -> j under action a, the credit rule, then ageing
        (:func:`kernels.update_links`); nodes left without links are removed (except the
        previous and current winner; :func:`kernels.link_step`)."""
        for _ in range(2):      # again once the rows are wider, when a new link needs it
            changes, ends = kernels.link_step(
                self.out, self.E, self.a, self.age, self.inn, self.alive, self.terminal,
                self.n, i, j, a, self.alpha, self.sigma_a, self.eta_a, self.E_init, self.E_min,
                self.max_age, self.link_rule == "credit", self.prev, self.winner)
            if changes >= 0:
                self.version += changes
                self.log.touch(i)
                if len(ends):
                    self.log.touch(ends)
                return
            self._grow_degree()

    # ------------------------------------------------------------------ persistence
    def state_dict(self) -> dict[str, np.ndarray]:
        """The map's arrays (``x_prev`` only once an input was sensed)."""
        n = self.n
        last = {"x_prev": self.x_prev.copy()} if np.isfinite(self.x_prev).all() else {}
        return {**last, "w": self.w[:n].copy(), "c": self.c[:n].copy(), "h": self.h[:n].copy(),
                "won": self.won[:n].copy(),
                "alive": self.alive[:n].copy(), "out": self.out[:n].copy(),
                "E": self.E[:n].copy(), "a": self.a[:n].copy(), "age": self.age[:n].copy(),
                "terminal": self.terminal[:n].copy(), "motion": self.motion.copy(),
                "meta": np.array([self.version, self.prev, self.winner], dtype=np.int64)}

    def load_state_dict(self, s: dict[str, np.ndarray]) -> None:
        n, k = s["out"].shape
        if s["w"].shape[1] != self.dim or s["a"].shape[2] != self.action_dim:
            raise ValueError(f"saved map has dim {s['w'].shape[1]}/action dim "
                             f"{s['a'].shape[2]}, expected {self.dim}/{self.action_dim}")
        self._alloc(max(_INITIAL_CAPACITY, 1 << max(n - 1, 1).bit_length()), k)
        for name in ("w", "c", "h", "alive", "out", "E", "a", "age"):
            getattr(self, name)[:n] = s[name]
        if "terminal" in s:                 # maps saved before the flag have none set
            self.terminal[:n] = s["terminal"]
        # samples won (maps saved before the count: as many as GWR's rate stands for)
        self.won[:n] = s["won"] if "won" in s else \
            1.0 / np.maximum(self.eps_b * self.h[:n], _ROUNDING)
        # the sensed moves' statistics and the last input (absent from older maps, or
        # of another dimension: learnt anew)
        if "motion" in s and s["motion"].shape[1:] == (self.dim + 2,):
            self.motion = np.array(s["motion"], dtype=float)
        last = s.get("x_prev")
        self.x_prev[:] = last if last is not None and last.shape == (self.dim,) else np.nan
        self._place_radius()
        self._context_metric()
        self.n = n
        self.version, self.prev, self.winner = (int(v) for v in s["meta"])
        self.log.invalidate()
        self.rebuild_in_links()

    def rebuild_in_links(self) -> None:
        """``inn``, the sources of the links into each node (what the step reads instead
        of scanning every row for links into a node), from ``out``: after a load, or an
        edit of ``out`` by hand. The link kernels keep it up to date."""
        while not kernels.in_links(self.out, self.n, self.inn):
            self._grow_degree()

    def save(self, path: str | Path, step_id: int = -1, run_id: int = 0) -> Path:
        """Write the whole map and the last step it learnt (``step_id`` of the graph's run
        ``run_id``, 0 = none) to a .npz file, atomically: a crash never leaves half a
        file."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.name + ".tmp")
        with open(tmp, "wb") as f:
            np.savez(f, **self.state_dict(), step_id=np.array(step_id, dtype=np.int64),
                     run_id=np.array(run_id, dtype=np.uint64))
        tmp.replace(path)
        return path

    @classmethod
    def load(cls, path: str | Path, config: MapConfig = MapConfig(), with_run: bool = False,
             primitives: np.ndarray | None = None
             ) -> tuple[SensorimotorMap, int] | tuple[SensorimotorMap, int, int]:
        """A map read from a :meth:`save` file (its dimensions from the file, the
        hyperparameters ``config``, the agent's motor ``primitives``) and the last step id
        it learnt (-1 if unknown); with ``with_run``, also the run id of that step (0 if
        unknown)."""
        try:
            with np.load(Path(path)) as data:
                state = {k: data[k] for k in data.files}
            step_id = int(state.pop("step_id", -1))
            run_id = int(state.pop("run_id", 0))
            m = cls(dim=int(state["w"].shape[1]), action_dim=int(state["a"].shape[2]),
                    config=config, primitives=primitives)
            m.load_state_dict(state)
        except (OSError, KeyError, ValueError, IndexError) as exc:
            raise ValueError(f"{path}: not a saved sensorimotor map ({exc})") from exc
        return (m, step_id, run_id) if with_run else (m, step_id)
