"""Motivation estimator (section 3.3, Eq. 4-5, Algorithm 1): value iteration on the map,
with the value of what the map does not know (our Eq. 5', the paper's future work).

For the goal node ``g`` (the node nearest the goal state, Algorithm 1 line 2) every node
gets the immediate reward ``R_i = sim(i, g)`` (Eq. 10), a Gaussian of the distance between
the nodes' weights, and the motivation potentials are iterated to a fixed point::

    V(i) <- V(i) + beta * Delta_V(i)                               (Eq. 4)
    Delta_V(i) = sim(i, g) + gamma * max_k E[i, k] V(k) - V(i)     (Eq. 5)

over the sensorimotor neighbourhood ``k`` of ``i`` (its outgoing links): read it in
:mod:`tmgwr_agent.core.value_iteration`, the numpy reference of the compiled solver this
module calls (:func:`kernels.value_iteration`, tested equal). The sweep is
synchronous (all nodes from the previous V) and stops when every node's change ``|beta
Delta_V(i)|`` is below ``vi_tol * V(i)`` (a relative tolerance: potentials fall
geometrically with the distance to the goal and the choice between two far neighbours needs
the same relative precision as near the goal), or after ``vi_max_sweeps``. V is
warm-started from the last solution, so a step that changed the map a little costs a few
sweeps; a new goal restarts from V = 0 (Algorithm 1 line 5).

**Incremental solution** (``vi_incremental``, on by default; off: the synchronous solve
every step). A converged step changes almost nothing (the traversed link's E, a node's
weights, sometimes an option), yet a sweep visits every node. So between full solves the
estimator keeps a copy of the last solve's inputs and solves by prioritized sweeping (Moore
& Atkeson 1993, :func:`kernels.prioritized_sweep`): the rows whose links, reward, absorbing
flag or options differ from the copy are queued, each queued node's V is set to the
right-hand side of Eq. 4-5' (:func:`kernels.node_target`), largest change first, and the
nodes that read it are queued when their own residual exceeds the synchronous solve's
stopping rule (:func:`sweep_tolerance`); it stops when nothing above that is left. Every
node then meets that rule, and V is within ``vi_tol / (beta (1 - gamma))`` of the fixed
point, the synchronous solve's own bound (test_incremental_vi.py). A change below the rule
is not propagated: a traversed link's E creeping towards 1 would otherwise move every value
upstream of it by a tiny fraction, over the whole map. A change that may lower values (a
link removed, an E, R or last option gone, an option worth less, a node made absorbing) is
not swept down: V = 0 is reached only geometrically where two nodes hold each other up (a
region cut off its sources), so the nodes whose value rested on the change are first set to
0 (:func:`kernels.invalidate`, LPA*'s under-consistent nodes) and solved again from there
in order of value. A goal change, a new map size and a sweep over its budget solve every
node from V = 0 in order of value (:func:`kernels.ordered_solve`): with R = 0 a node is
worth at most gamma times its best successor, so largest first (Dijkstra's order) settles
most nodes at their first update, where synchronous sweeps from 0 take about as many rounds
as the map is wide, and the goal and its neighbours (a 2-cycle converging by gamma^2 a
round) are solved among themselves first; the synchronous solve remains as the fallback of
the fallback. Those rows are not searched for: the map keeps a log of the rows each step
changed (:class:`~tmgwr_agent.core.sensorimotor_map.RowLog`; a replica, of the slots each
change wrote), and the copy, the frame coordinates, the rewards, the goal node and the
absorbing masks are brought up to date on those rows alone; whatever changes R or the masks
on other rows (a full recompute of R, the closed cells, the goal made terminal) bumps
``_epoch`` and the next solve compares every row. Both are solutions within ``vi_tol``, not
the same bits: where two of a node's links are worth the same within that tolerance Eq. 6
may choose the other one, and the trajectory goes on differently from there.

**Exactly 0 without a route.** Before the sweeps a reverse breadth-first search from the
sources (nodes with R > 0, or with an option below) over the links with E > 0 finds the
nodes from which some link path leads to a source (:func:`kernels.reaches_source`); every
other node gets V = 0 exactly, the fixed point of Eq. 4-5 there. Without it a region whose
last link to the goal was deleted kept warm-started potentials that shrink only a few per
cent a sweep and pass the relative stopping test as numerical dust (1e-149), and Eq. 6
followed the gradient of that dust for over a hundred steps. This is part of solving
Eq. 4-5 and holds for the paper's agent as well.

The width of ``sim(i, g)`` is not in the paper. We take ``sigma_g = goal_sigma * L`` where
``L`` is the median length of the map's links in feature space, i.e. the distance between
consecutive sensations: the reward is then concentrated on the goal node and its
sensorimotor neighbours whatever the map's scale, so a node that is near the goal in
sensor space but far from it along the map (behind a wall) is not a rival attractor. The
Gaussian is cut below ``goal_sim_floor`` (1e-3: beyond about 1.9 link lengths).

**The value of the unknown** (``unknown``, our addition: ``learnt`` by default, ``grid``,
or ``none`` = the paper's Eq. 5): the options of Eq. 5', their outcome memory and their
rules are a model of the unknown, a plug-in chosen by ``unknown`` from one registry
(:data:`tmgwr_agent.core.unknown.UNKNOWN`); read them in :mod:`tmgwr_agent.core.unknown`.
This module asks the model what :class:`~tmgwr_agent.core.unknown.ModelOfUnknown` lists
and solves Eq. 4-5' with the options it gives (``U``, ``rho`` and the successor arrays).

Terminal nodes (``absorbing_terminals``, our addition, on by default; off = Eq. 5 on every
node). The agent notices when an episode ends: it is moved back to the start instead of
walking on. The map flags the node it stood on
(:meth:`~tmgwr_agent.core.sensorimotor_map.SensorimotorMap.mark_terminal`) until it walks
on from it, and value iteration treats a flagged node as a terminal state, as any MDP
solver would: ``V(i) = R_i``, no successor, no option; except the nodes of the current goal
(``R_i >= 1/2``), which keep Eq. 5 (unless the route broke: :mod:`tmgwr_agent.core.
unknown`). Without this a route
through a cell that ends the episode (the previous goal in the goal-change scenario of
section 5.2.1, which stays a termination point) looks as good as any other, and the agent
keeps being sent home through it. The goal's own cell is flagged too, while it is the
goal, so that when the goal moves the old goal is known to end episodes from the first
episode on (the agent cannot tell a goal cell from a terminal cell; if the old goal became
an ordinary cell, the flag goes the first time the agent walks on from it). Episodes cut
by a step limit flag nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tmgwr_agent.core import kernels
from tmgwr_agent.core.frame import Frame
from tmgwr_agent.core.sensorimotor_map import Links, SensorimotorMap
from tmgwr_agent.core.unknown import GOAL_R, NO_BELIEF, UNKNOWN, OptionRules, OutcomeMemory, grown
from tmgwr_common.params import Config, param

#: Potentials below this are 0: gamma**d for d > 10,000 steps.
V_FLOOR = 1e-150
_NO_ROWS = np.zeros(0, dtype=np.int64)
#: Updates a node an ordered solve from V = 0 may make before the synchronous solve
#: takes over (MotivationEstimator._ordered).
ORDERED_BUDGET = 8
#: Updates a node an incremental solve may make before the ordered solve from V = 0
#: takes over (which makes a few a node).
INCREMENTAL_BUDGET = 3


@dataclass(frozen=True)
class MotivationConfig(Config):
    """Hyperparameters of the motivation estimator (Eq. 4-5, Algorithm 1, Eq. 5')."""

    gamma: float = param(0.97, "Eq. 5: discount factor (Table 2)", low=0.0, high=1.0,
                         low_open=True, high_open=True)
    beta: float = param(0.80, "Eq. 4: learning rate of the value iteration (Table 2)",
                        low=0.0, high=1.0, low_open=True)
    goal_sigma: float = param(0.3, "width of sim(i, g) in units of the median link length",
                              low=0.0, low_open=True, high=100.0)
    goal_sim_floor: float = param(1e-3, "sim(i, g) below this counts as 0 (compact "
                                  "support)", low=0.0, high=1.0, high_open=True)
    vi_tol: float = param(1e-4, "stop when |beta Delta_V(i)| <= vi_tol * V(i) for every "
                          "node", low=0.0, low_open=True, high=1.0)
    vi_max_sweeps: int = param(5000, "upper bound on sweeps per call", low=1, high=1e9,
                               integer=True)
    vi_incremental: bool = param(True, "solve Eq. 4-5' incrementally between full solves: "
                                 "prioritized sweeping from the rows that changed "
                                 "(motivation.py; false: a full solve every step)")
    absorbing_terminals: bool = param(True, "nodes where an episode ended have no successor "
                                      "in Eq. 5 (false: the paper's Eq. 5 on every node)")
    unknown: str = param("learnt", "Eq. 5': the value of what the map does not know: "
                         "'none' (the paper's Eq. 5), 'grid' (measured on the sensor's "
                         "axes), 'learnt' (measured in the learnt forward model's frame; "
                         "frame.py)", choices=tuple(UNKNOWN))
    stale_prior: float = param(1.0, "Eq. 5': rho of a stale remembered wall the episode "
                               "re-tests (1: planned as open, the test decided by the "
                               "ranking; 1/2: as likely open as closed)", low=0.0,
                               high=1.0)
    stale_horizon: float = param(6.0, "Eq. 5': episodes a remembered wall is trusted before "
                                 "it goes stale (0: walls never go stale unless stuck)",
                                 low=0.0, high=1e6)
    stale_budget: float = param(0.1, "Eq. 5': re-tests of stale walls per episode, at most "
                                "this share of the known route's steps (rounded up, at "
                                "least 1, with retest_rate 'fixed'; 0: none)",
                                low=0.0, high=1.0)
    retest_rate: str = param("fixed", "Eq. 5': 'fixed' re-tests stale_budget's share every "
                             "episode; 'learnt' scales it by the chance the world changed "
                             "while the longest-waiting stale wall waited, from the "
                             "episodes in which the agent saw it change (unknown.py)",
                             choices=("fixed", "learnt"))
    stale_rank: bool = param(True, "Eq. 5': an episode offers as re-tests only the stale "
                             "walls that would save the most steps on the known route, "
                             "as many as its re-test budget (false: every stale wall, the "
                             "most valuable from where the agent stands first)")
    untried_rho: float = param(-1.0, "Eq. 5': rho of a primitive never tried (1: the "
                               "optimistic bound; negative: the share of the agent's tried "
                               "moves that opened, re-estimated with the options)",
                               low=-1.0, high=1.0)


#: R_i, gamma and the option arrays U, rho, osucc, onb, ong (:meth:`MotivationEstimator.
#: option_terms`).
OptionTerms = tuple




def sweep_tolerance(vi_tol: float, beta: float) -> float:
    """The relative residual ``s`` the incremental solve leaves a node (``|T(i) - V(i)|
    <= s T(i)``, :func:`kernels.prioritized_sweep`; ``T``: :func:`kernels.node_target`):
    the largest that still meets the synchronous solve's stopping rule ``|beta (T(i) -
    V(i))| <= vi_tol V(i)``. From ``T <= V + s T``: ``beta |T - V| <= beta s / (1 - s)
    V``, at most ``vi_tol V`` when ``s = vi_tol / (beta + vi_tol)``."""
    return vi_tol / (beta + vi_tol)


class IncrementalState:
    """What the incremental solve of Eq. 4-5' keeps between calls (:meth:`MotivationEstimator.
    _incremental`): a copy of the inputs of the last solve (links, reliabilities, rewards,
    absorbing flags, options), the predecessors of every node (who reads whose value,
    :func:`kernels.predecessors`) and the work arrays of the priority queue."""

    def __init__(self, n: int, goal_node: int, out0, E0, R0, abs0, rho0, U0, osucc0, onb0,
                 ong0, first, pred, log=None, epoch: int = 0):
        self.n, self.goal_node = n, goal_node
        # the map's change log and its position at the copy, the estimator's epoch
        # (MotivationEstimator._epoch): while both hold, only the rows logged since can
        # differ from the copy
        self.log, self.log_pos, self.epoch = log, (log.pos if log is not None else -1), epoch
        self.out0, self.E0, self.R0, self.abs0 = out0, E0, R0, abs0
        self.rho0, self.U0, self.osucc0, self.onb0, self.ong0 = rho0, U0, osucc0, onb0, ong0
        self.first, self.pred = first, pred
        self.seeds = np.empty(2 * n + 1, dtype=np.int64)
        self.heap = np.empty(n + 1, dtype=np.int64)
        self.pos = np.full(n + 1, -1, dtype=np.int64)
        self.key = np.zeros(n + 1)
        self.found = np.empty(n + 1, dtype=np.int64)     # kernels.invalidate's work arrays
        self.mark = np.zeros(n + 1, dtype=bool)

    @classmethod
    def of(cls, m: SensorimotorMap, n: int, R: np.ndarray, absorbing: np.ndarray,
           est: "MotivationEstimator") -> "IncrementalState":
        """The state after a full solve on map m (rewards R, the absorbing mask); the
        estimator's last state (or the one a goal change retired, ``_spare``) is written
        over when its arrays have these shapes (a goal change on a map of the same size:
        no new pages to fault in)."""
        old = est._inc if est._inc is not None else getattr(est, "_spare", None)
        est._spare = None
        src = (m.out[:n], m.E[:n], R[:n], absorbing[:n], est.rho, est.U, est.osucc,
               est.onb, est.ong)
        if old is None or old.n != n or any(a.shape != b.shape for a, b in zip(
                old.copies(), src)):
            return cls(n, est.goal_node, *(a.copy() for a in src),
                       *kernels.predecessors(m.out, n, m.alive, est.osucc, est.onb),
                       log=getattr(m, "log", None), epoch=est._epoch)
        for a, b in zip(old.copies(), src):
            np.copyto(a, b)
        old.goal_node = est.goal_node
        old.first, old.pred = kernels.predecessors(m.out, n, m.alive, est.osucc, est.onb)
        log = getattr(m, "log", None)
        old.log, old.log_pos, old.epoch = log, (log.pos if log is not None else -1), \
            est._epoch
        return old

    def copies(self) -> tuple:
        """The copy of the last solve's inputs, in the order of :meth:`of`."""
        return (self.out0, self.E0, self.R0, self.abs0, self.rho0, self.U0, self.osucc0,
                self.onb0, self.ong0)


class MotivationEstimator(OutcomeMemory, OptionRules):
    """Holds the goal and the potentials V; :meth:`update` re-solves Eq. 4-5'. The model of
    the unknown (Eq. 5', :mod:`tmgwr_agent.core.unknown`) is mixed in: its outcome memory
    (:class:`~tmgwr_agent.core.unknown.OutcomeMemory`, whose ``record`` notes what an
    action did) and its option rules (:class:`~tmgwr_agent.core.unknown.OptionRules`)."""

    #: The fused paths of a converged step (:meth:`_fused_update`, :meth:`_prepare_rows`);
    #: False: the general path every step (the same state to the bit: test_fused_step.py).
    fused = True

    def __init__(self, config: MotivationConfig = MotivationConfig(), *,
                 primitives: np.ndarray, goal_tolerance: float = 0.0,
                 bounds: tuple[np.ndarray, np.ndarray] | None = None):
        """``primitives``: the motor vector of each action (:class:`~tmgwr_agent.core.
        senses.Senses`): an option's action label; their number sizes the outcome
        memory. ``goal_tolerance``: the world's (``Senses``), in the units of the goal
        sensation given to :meth:`set_goal`. ``bounds``: the sensor's range (``Senses``
        ``low``, ``high``) in the same units, or None (unbounded): no option leads outside
        it (:meth:`~tmgwr_agent.core.unknown.OptionRules.outside_options`)."""
        kernels.announce_compilation()
        self.config = config
        self.primitives = np.ascontiguousarray(primitives, dtype=float)
        self.goal_tolerance = float(goal_tolerance)
        self.bounds = None if bounds is None else \
            tuple(np.asarray(b, dtype=float) for b in bounds)
        P = self.n_primitives = len(self.primitives)
        self.gamma, self.beta = config.gamma, config.beta
        self.goal_sigma, self.goal_sim_floor = config.goal_sigma, config.goal_sim_floor
        self.vi_tol, self.vi_max_sweeps = config.vi_tol, config.vi_max_sweeps
        self.vi_incremental = config.vi_incremental
        self._sweep_tol = sweep_tolerance(self.vi_tol, self.beta)
        self._inc: IncrementalState | None = None   # the copy of the last solve's inputs
        self._spare: IncrementalState | None = None  # a retired one, its arrays to reuse
        self._opt_rows: np.ndarray | None = None    # option rows recomputed since
        self.solves = {"incremental": 0, "full": 0}   # and why the incremental declined
        self.absorbing_terminals = config.absorbing_terminals
        model = UNKNOWN[config.unknown]            # the model of the unknown (unknown.py)
        self.value_unknown = model.options
        self.frame = model.frame()                 # where places are measured (frame.py)
        self.lattice = np.ones(P, dtype=bool)       # primitives whose options are valued
        self._placed = True           # some primitive of the lattice (lattice.any())
        self._frame_episode = -1      # the episode the frame's basis was chosen in
        self._F: Frame | None = None  # the frame's coordinates of the last _prepare
        self.stale_prior, self.stale_horizon = config.stale_prior, config.stale_horizon
        self.stale_budget = config.stale_budget
        self.retest_rate = config.retest_rate
        self.stale_rank = config.stale_rank
        self.untried_rho = config.untried_rho
        self.rho_new = 1.0            # rho of an untried primitive (open_prior)
        self.v_star = 1.0 / (1.0 - self.gamma ** 2)
        self.goal_x: np.ndarray | None = None
        self.goal_node = -1
        self.V = np.zeros(1)          # V[:n]; V[n] stays 0 (target of empty link slots)
        self.sweeps = 0               # sweeps of the last update
        self.solved = False           # V solves Eq. 4-5' on the map of the last update
        self._scale_version = -1      # map version the cached link scale belongs to
        self._scale = 1.0
        # outcome memory (Eq. 5'): per node slot and primitive
        self.tried = np.zeros((64, P), dtype=bool)
        self.bump_t = np.full((64, P), -1, dtype=np.int64)
        self.closed_t = np.full((64, P), -1, dtype=np.int64)  # first bump of a run
        self.bump_e = np.full((64, P), -1, dtype=np.int64)    # episode of a bump
        self.succ = np.full((64, P), -1, dtype=np.int64)   # where a move led
        self.closed_e = np.full(64, -1, dtype=np.int64)   # episode a node's cell closed
        self.goal_seen = np.zeros(64, dtype=bool)   # the current goal was sensed there
        self.goals_told: list[np.ndarray] = []   # goal sensations set (terminal regions)
        self._region = np.zeros(0, dtype=bool)   # nodes of a terminal region (no lattice)
        self._region_x = np.zeros((0, 0))        # and the goal sensations at its centres
        self.sel = np.ones((64, P), dtype=bool)  # this episode's re-tests
        self.chain = np.zeros((64, P), dtype=bool)  # its untried chain
        self._closed: np.ndarray | None = None   # its trusted marks (derived, cached)
        self.clock = 0                # learning steps recorded
        self.episode = 0              # episodes started
        self.route = 0.0              # steps of the known route from this episode's start
        self.retests = 0              # stale walls re-tested this episode (not stuck)
        self.wall_tests = 0           # actions at a pair known closed, ever
        self.wall_opened = 0          # of those, the ones that moved
        self.changes = 0              # episodes in which the world was seen to change
        self._changed = False         # this one: a wall known closed opened, or a break
        self.q_change = 0.5           # the chance it changes in an episode (Laplace)
        self.waited = 1.0             # the longest a stale wall has waited, this episode
        self.carry = 0.0              # re-test allowance carried from the last episode
        self._allowance = 0.0         # this episode's re-test allowance, last computed
        self.broken = False           # a move made before bumped this episode
        self.break_t = -1             # the clock of the last such bump, ever
        self._route_due = False       # the route is read off V0 at the episode's first solve
        self._stuck = False           # stuck when the last update solved Eq. 5'
        self._affine_fit = {}         # per primitive: (key, its affine forward model)
        self.delta = np.zeros((P, 0))     # mean sensed displacement per primitive
        self.delta_sq = np.zeros(P)       # and the mean of its squared length
        self.moves = np.zeros(P, dtype=np.int64)
        self.U = np.zeros((64, P))
        self.rho = np.zeros((64, P))
        self.osucc = np.full((64, P), -1, dtype=np.int64)   # option successors
        self.onb = np.full((64, P, P), -1, dtype=np.int64)
        self.ong = np.zeros((64, P, P))   # their discounts
        self._grid = np.full((0, 0), -1, dtype=np.int64)
        self._origin = np.zeros(2)
        self.R = np.zeros(1)
        self.V0 = np.zeros(1)         # Eq. 5 without options (exploit), computed on demand
        self._v0_fresh = False
        self._v0_zero = True
        self._options_key: tuple = ()
        self._belief = NO_BELIEF          # the free-space belief after a break (unknown.py)
        self._opt_log, self._opt_pos, self._opt_L = None, -1, 0.0   # of the last key change
        self._dirty: set[int] = set()    # rows whose outcome memory changed since update
        self._alive_version, self._alive = -1, 0
        self._winner = -1                # the agent's node (from record)
        self._bumps = 0                  # bumps recorded (a key of the stuck test)
        self._reach_key: tuple = ()
        # stuck's search (kernels.reaches_source_from): what it knows of each node (by
        # stamp), its work arrays and counters, and the flags of its key's change
        self._reach = self._reach_seen = self._reach_stack = np.zeros(0, dtype=np.int64)
        self._reach_stamp = self._reach_search = 0
        self._reach_abs = self._reach_src = np.zeros(0, dtype=bool)
        # What changed since the last _prepare: the map's change log (RowLog) and its
        # position then; the inputs R was computed from (its rows are recomputed alone
        # while they hold) and the nearest node to the goal then.
        self._prep_log, self._prep_pos = None, -1
        self._R_key: tuple | None = None
        self._g_raw = -1
        self._represented = -1     # the goal node the last _prepare found represents it
        self.fused_steps = 0       # steps prepared by the fused path (_prepare_rows)
        # Bumped whenever R or the absorbing mask may change on rows the map's log does
        # not list (a full recompute of R, the closed cells, the goal terminal): the
        # incremental solve then compares every row with its copy.
        self._epoch = 0
        self._broken_solved = False
        # the absorbing masks (_absorbing), and the rows they were last brought up to
        self._abs = self._abs_terminal = np.zeros(0, bool)
        self._abs_key: tuple = ()
        self._abs_log, self._abs_pos, self._abs_count = None, -1, 0
        self._abs_seen: tuple | None = None     # (log, prepare) positions of the last call
        self._closed_none = np.zeros(0, bool)

    def set_senses(self, goal_tolerance: float,
                   bounds: tuple[np.ndarray, np.ndarray] | None) -> bool:
        """The world's goal region and sensor's range, as the constructor takes them, told
        after construction (the graph's estimator hears them from the world, SensorInfo);
        returns whether they changed. A change leaves V as it is (the next solve starts
        from it) and has every input derived from them recomputed at the next update."""
        tol = float(goal_tolerance)
        if not math.isfinite(tol) or tol < 0.0:
            raise ValueError(f"the goal tolerance must be a finite distance >= 0, got "
                             f"{goal_tolerance}")
        b = None if bounds is None else tuple(np.asarray(x, dtype=float) for x in bounds)
        same_b = (b is None) == (self.bounds is None) and (
            b is None or all(np.array_equal(x, y) for x, y in zip(b, self.bounds)))
        if tol == self.goal_tolerance and same_b:
            return False
        self.goal_tolerance, self.bounds = tol, b
        self._options_key = ()
        self._retire_incremental()
        self._R_key = None
        self._abs_key = ()
        self._v0_fresh = False
        self._epoch += 1
        return True

    # ------------------------------------------------------------------ goal
    def set_goal(self, goal_x: np.ndarray) -> None:
        """A new goal state: the potentials restart from 0 (Algorithm 1, line 5)."""
        self.goal_x = np.asarray(goal_x, dtype=float)
        self.goal_seen[:] = False
        self._options_key = ()
        self.route = 0.0                  # the route to the new goal is not known yet
        self.V[:] = 0.0
        self._retire_incremental()
        self._R_key = None
        self.V0[:] = 0.0
        self._v0_fresh = False
        self._v0_zero = True              # V0 restarts from 0 too: solved in order

    def _retire_incremental(self) -> None:
        """The next solve is a full one (from V = 0); the copy of the inputs is kept aside
        for it to write over (:meth:`IncrementalState.of`)."""
        if self._inc is not None:
            self._spare = self._inc
        self._inc = None

    def follow_goal(self, goal_x: np.ndarray) -> bool:
        """The goal sensation that came with this step: :meth:`set_goal` when it differs
        from the current goal (the graph's estimator learns goal changes this way);
        returns whether it did."""
        goal_x = np.asarray(goal_x, dtype=float)
        if self.goal_x is not None and np.array_equal(goal_x, self.goal_x):
            return False
        self.set_goal(goal_x)
        return True

    # ------------------------------------------------------------------ Eq. 4-5'
    @staticmethod
    def link_scale(m: SensorimotorMap) -> float:
        """Median length of the map's links in feature space (0 if it has none); the
        links' differences gathered by :func:`kernels.link_differences`."""
        d = np.empty((m.n * m.out.shape[1], m.w.shape[1]))
        d = d[:kernels.link_differences(m.w, m.out, m.n, d)]
        if not len(d):
            return 0.0
        return float(np.median(np.sqrt(np.einsum("ij,ij->i", d, d))))

    def rewards(self, F: Frame, m: SensorimotorMap, g: int,
                rows: np.ndarray | None = None) -> np.ndarray:
        """Eq. 10: R_i = sim(i, g) = exp(-|w_i - w_g|^2 / (2 sigma_g^2)), 0 for dead slots
        (the weights in the frame ``F``, ``sigma_g = goal_sigma L``). With ``rows``
        (nodes whose weights or alive flag changed since the last call, which had the same
        goal node, frame and map size, and where the goal node's own did not) only those
        are recomputed, in place; else a new array and a new :attr:`_epoch`."""
        R, k = self.R, -1
        key = (m.n, g, F.L, self.frame.version)
        if rows is not None and key == self._R_key and len(R) == m.n:
            k = len(rows)
        else:
            R, rows = np.empty(m.n), _NO_ROWS
            self._epoch += 1
        kernels.goal_rewards(F.w, m.alive, m.n, g, self.goal_sigma * F.L,
                             self.goal_sim_floor, R, rows, k)
        self._R_key = key
        return R

    def _changed_since_prepare(self, m: SensorimotorMap) -> np.ndarray | None:
        """The rows of m the map's change log lists since the last :meth:`_prepare` (None:
        unknown, every row may have changed)."""
        log = getattr(m, "log", None)
        rows = log.since(self._prep_pos) if log is not None and log is self._prep_log \
            else None
        self._prep_log, self._prep_pos = log, (log.pos if log is not None else -1)
        return rows

    def _prepare(self, m: SensorimotorMap) -> int:
        """Sizes, goal node and rewards of this map; returns n. Only the rows the map's
        change log lists are looked at again when it can tell (:meth:`rewards`,
        :func:`kernels.nearest_weight_among`, the frame's coordinates)."""
        n = self._prepare_rows(m) if self.fused else -1
        if n >= 0:
            return n
        self._represented = -1
        n = m.n
        rows = self._changed_since_prepare(m)
        self._size_forward_model(m.w.shape[1])
        if len(self.V) != n + 1:                      # the map grew: extend, keep values
            self.V = self._extended(self.V, n)
            self.V0 = self._extended(self.V0, n)
        if len(self.U) < n:
            self._grow_memory(n)
            self.U = grown(self.U, n, 0.0)
            self.rho = grown(self.rho, n, 0.0)
            self.osucc = grown(self.osucc, n, -1)
            self.onb = grown(self.onb, n, -1)
            self.ong = grown(self.ong, n, 0.0)
        self.goal_node = -1
        if self._scale_version != m.version:          # links only change with the version
            self._scale = self.link_scale(m) or 1.0
            self._scale_version = m.version
        F = self._in_frame(m, rows)
        g, g_moved = self._nearest_goal(m, n, rows)
        if self.value_unknown and not self._placed:
            return self.sensed_goal(m, n)
        return self._goal_rewards(F, m, n, g, None if g_moved else rows)

    def _goal_rewards(self, F: Frame, m: SensorimotorMap, n: int, g: int,
                      rows: np.ndarray | None) -> int:
        """The end of :meth:`_prepare`: the goal node ``g`` when it represents the goal,
        and the rewards of Eq. 10 (on ``rows`` alone when not None); returns n."""
        self._represented = -1
        if g < 0 or (self.value_unknown                   # represented only once sensed
                     and not self._represents_goal(F, m, g)):
            self.R = np.zeros(n)
            self._R_key = None
            self._epoch += 1
            return n
        self._represented = g
        self.goal_node = g
        self.R = self.rewards(F, m, g, rows)
        return n

    def _prepare_rows(self, m: SensorimotorMap) -> int:
        """:meth:`_prepare`, and :meth:`_absorbing` brought up to date, for the common
        step of a converged map, in one kernel call (:func:`kernels.prepare_rows`): when
        the map's log lists the rows changed since the last preparation, and sizes,
        frame, goal node and the keys of the rewards and flags held (so the general path
        would only look at those rows again, by the same kernels). Returns n, or -1
        with nothing changed: the general path (the rest of :meth:`_prepare`) then runs.
        When the nearest node to the goal moved, the general path's end
        (:meth:`_goal_rewards`, in full) follows the kernel's row updates."""
        prep = self._rows_to_prepare(m)
        if prep is None:
            return -1
        args, F, abs_k = prep
        return self._rows_prepared(m, F, abs_k, *kernels.prepare_rows(*args))

    def _rows_to_prepare(self, m: SensorimotorMap) -> tuple | None:
        """The arguments of :func:`kernels.prepare_rows` for this step, the frame it
        writes and the count of absorbing rows it brings up to date (-1: none), when
        :meth:`_prepare_rows` applies (the log's position then taken as prepared); None
        when the general path is to run."""
        log = getattr(m, "log", None)
        if log is None or log is not self._prep_log or self.goal_x is None:
            return None
        rows = log.since(self._prep_pos)
        n, g0 = m.n, self._g_raw
        if rows is None or len(self.V) != n + 1 or len(self.U) < n \
                or self._scale_version != m.version or self._frame_episode != self.episode \
                or not self._placed or not self.frame.complete \
                or self.delta.shape != (self.n_primitives, m.w.shape[1]) \
                or self._represented != g0 or not 0 <= g0 < n or not m.alive[g0] \
                or self._R_key != (n, g0, 1.0, self.frame.version) or len(self.R) != n \
                or g0 in rows.tolist():
            return None
        cached = self.frame.cached(m.w, self.goal_x, self.delta)
        if cached is None:
            return None
        T, x, goal, delta = cached
        # the absorbing flags' rows (_absorbing), when their key holds
        cells = self._closed if self.value_unknown else self._no_cells(n)
        abs_rows = None if log is not self._abs_log else rows \
            if self._abs_pos == self._prep_pos else log.since(self._abs_pos)
        if self._abs_key != (n, self._epoch, id(self.R)) or abs_rows is None \
                or cells is None or len(cells) != n:
            abs_rows, abs_k = _NO_ROWS, -1
        elif self._abs_seen == (log.pos, log.pos, True):
            abs_rows, abs_k = _NO_ROWS, 0                # nothing new
        else:
            abs_k = len(abs_rows)
        if cells is None:           # marks changed, recomputed at the solve: no flags now
            cells = self._no_cells(n)           # (an array all the same: numba types it)
        self._prep_pos = log.pos
        return ((m.w, m.alive, T, x, self.delta, delta, rows, len(rows), self.goal_x, g0,
                 self.goal_sigma, self.goal_sim_floor, self.R, self.terminal_of(m, n),
                 self.absorbing_terminals, cells, self.value_unknown, GOAL_R, n, abs_rows,
                 abs_k, self._abs, self._abs_terminal, self._abs_count),
                Frame(x, goal, delta, 1.0), abs_k)

    def _rows_prepared(self, m: SensorimotorMap, F: Frame, abs_k: int, g: int, count: int
                       ) -> int:
        """The end of :meth:`_prepare_rows` after its kernel (the nearest node ``g``, the
        terminal-only ``count``); returns n."""
        n, g0 = m.n, self._g_raw
        self._F = F
        self._g_raw = g
        self.goal_node = -1
        if g != g0:
            return self._goal_rewards(F, m, n, g, None)
        self.goal_node = g
        if abs_k >= 0:
            pos = self._prep_pos
            self._abs_count = count
            self._abs_pos = pos
            self._abs_seen = (pos, pos, True)
        self.fused_steps += 1
        return n

    def _represents_goal(self, F: Frame, m: SensorimotorMap, g: int) -> bool:
        """Does node ``g`` represent the goal: is it within half a step (``F.L / 2``, in
        the frame) of the world's goal region, the sensations within ``goal_tolerance`` of
        the goal sensation? (A point region when the tolerance is 0.)"""
        gap = math.dist(F.w[g].tolist(), F.goal.tolist())
        if self.goal_tolerance > 0.0:      # the part of the gap outside the region
            d = math.dist(m.w[g].tolist(), self.goal_x.tolist())
            gap *= max(0.0, 1.0 - self.goal_tolerance / d) if d > 0.0 else 0.0
        return gap <= 0.5 * F.L

    def _nearest_goal(self, m: SensorimotorMap, n: int, rows: np.ndarray | None
                      ) -> tuple[int, bool]:
        """The node nearest the goal sensation (Algorithm 1, line 2; -1: no goal or no
        node): among the last one and the changed ``rows`` when the last one's did not
        change, else by a scan (:meth:`~tmgwr_agent.core.sensorimotor_map.
        SensorimotorMap.nearest_by_weight`); and whether its row is among ``rows``
        (True when ``rows`` is None)."""
        g0 = self._g_raw
        moved = rows is None or g0 in rows.tolist()
        if self.goal_x is None or not n:
            g = -1
        elif not moved and self._R_key is not None and self._R_key[0] == n \
                and 0 <= g0 < n and m.alive[g0]:
            g = int(kernels.nearest_weight_among(m.w, m.alive, self.goal_x, g0, rows,
                                                 len(rows)))
        else:
            g = m.nearest_by_weight(self.goal_x)
        self._g_raw = g
        return g, moved or g != g0

    def _in_frame(self, m: SensorimotorMap, rows: np.ndarray | None = None) -> Frame:
        """The map's weights, the goal and the forward model in the frame of the value of
        the unknown (frame.py; the sensor's own for ``grid`` and ``none``), its basis
        chosen afresh at an episode's first solve and, within an episode, only when it
        gains a direction; ``rows``: the only rows of the map changed since the last call
        (None: unknown)."""
        again = self._frame_episode != self.episode
        if again or not self.frame.complete:
            self.frame.refresh(self.delta, self.moves, self._scale, again, self.spread())
            self._frame_episode = self.episode
            self._follow_lattice(self.frame.lattice(self.n_primitives))
        goal = self.goal_x if self.goal_x is not None else np.zeros(m.w.shape[1])
        self._F = self.frame.of(m.w, goal, self.delta, self._scale, rows)
        return self._F

    def _follow_lattice(self, lattice: np.ndarray) -> None:
        """The primitives the frame finds consistent (frame.py), whose options the lattice
        rules value (the others: :meth:`~tmgwr_agent.core.unknown.OptionRules.
        _unplaced_options`). A change restarts the potentials and recomputes every option,
        as a new goal does."""
        if np.array_equal(lattice, self.lattice):
            return
        self.lattice = lattice.copy()
        self._placed = bool(lattice.any())
        self._options_key = ()
        self.rho[:] = 0.0                 # recomputed in full when any is valued
        self.U[:] = 0.0
        self.osucc[:] = -1
        self._inc = None
        self._R_key = None
        self._epoch += 1
        self.V[:] = 0.0
        self.V0[:] = 0.0
        self._v0_fresh = False

    @staticmethod
    def _extended(V: np.ndarray, n: int) -> np.ndarray:
        W = np.zeros(n + 1)
        k = min(n, len(V) - 1)
        W[:k] = V[:k]
        return W

    def _absorbing(self, m: SensorimotorMap, n: int, closed: bool = True) -> np.ndarray:
        """Flagged terminal nodes, and with the value of the unknown (``closed``) the nodes
        of closed cells while trusted (``stale_horizon`` episodes), except those of the
        current goal (R >= 1/2). Both masks are kept (not to be written to) and only the
        rows the map's log lists since the last :meth:`_prepare` are looked at again, while
        R and the closed cells changed on no other row (:attr:`_epoch`)."""
        cells = self.closed_cells(n) if self.value_unknown else self._no_cells(n)
        log = getattr(m, "log", None)
        rows = None
        if self._abs_key == (n, self._epoch, id(self.R)) and log is not None \
                and log is self._abs_log:
            if self._abs_seen == (log.pos, self._prep_pos, self._prep_log is log):
                return self._abs if closed else self._abs_terminal    # nothing new
            rows = log.since(self._abs_pos)
        if rows is None:
            self._abs, self._abs_terminal = np.zeros(n, bool), np.zeros(n, bool)
        self._abs_count = kernels.absorbing_flags(
            self.terminal_of(m, n), self.absorbing_terminals, cells, self.value_unknown,
            self.R, GOAL_R,
            n, _NO_ROWS if rows is None else rows, -1 if rows is None else len(rows),
            self._abs, self._abs_terminal, self._abs_count)
        self._abs_key = (n, self._epoch, id(self.R))
        # R is of the last _prepare: rows logged after it are looked at again next time
        self._abs_log = log
        self._abs_pos = self._prep_pos if log is self._prep_log else -1
        self._abs_seen = (log.pos, self._prep_pos, self._prep_log is log) \
            if log is not None else None
        return self._abs if closed else self._abs_terminal

    def _no_cells(self, n: int) -> np.ndarray:
        if len(self._closed_none) != n:
            self._closed_none = np.zeros(n, bool)
        return self._closed_none

    def _goal_terminal(self, n: int, absorbing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """R and the absorbing mask with the goal nodes (R >= GOAL_R) terminal states
        worth ``V*``, as the task has them (in an episode whose known route broke: the
        goal when the route broke, in :mod:`tmgwr_agent.core.unknown`)."""
        goal = self.R[:n] >= GOAL_R
        return np.where(goal, self.v_star, self.R[:n]), absorbing | goal

    def update(self, m: SensorimotorMap, skip: bool = False) -> np.ndarray | None:
        """Solve Eq. 4-5' on the current map; returns V[:n]. With ``skip`` (the next action
        is the random walk, its epsilon draw made ahead: :meth:`~tmgwr_agent.core.
        exploration.EpsilonGreedy.draw_ahead`) nothing is solved and None returned:
        ``solved`` is False and the goal node -1 (not known) until an update solves
        again, on the map of its own step, warm-started from the last solution (the
        outcome memory, ``record``, is kept every step all the same)."""
        self._v0_fresh = False
        self.sweeps = 0
        self.solved = not skip
        if skip:
            self.goal_node = -1
            return None
        n, solved = self._fused_update(m) if self.fused else (-1, False)
        if solved:
            return self.V[:n]
        if n < 0:
            n = self._prepare(m)
        if self.goal_x is None or n == 0:
            self.V[:] = 0.0
            return self.V[:n]
        absorbing = self._absorbing(m, n)
        R = self.R
        if self.value_unknown:
            if self._route_due and self.goal_node >= 0:
                self._read_route(m, n)
                self.plan_episode(m, n)
            self.refresh_options(m, n)
            if self.broken:
                R, absorbing = self._goal_terminal(n, absorbing)
            if self.broken != self._broken_solved:
                self._broken_solved = self.broken
                self._epoch += 1            # the goal nodes' R and flags: off the log
        self.sweeps = self._solve(m, n, R, absorbing)          # Eq. 4-5'
        return self.V[:n]

    def _fused_update(self, m: SensorimotorMap) -> tuple[int, bool]:
        """:meth:`update` of a converged step in one kernel call
        (:func:`kernels.converged_step`: :func:`kernels.prepare_rows`, then
        :func:`kernels.changed_rows_sweep`), when :meth:`_prepare_rows` applies, the
        absorbing flags come up to date with it, nothing else is due before the solve
        (no route to read, no option to recompute: :meth:`refresh_options` would return
        at once, its stuck test answered without a search) and the incremental solve has
        its copy of this map's inputs. Returns ``(n, solved)``: n -1 with nothing done
        (the general path runs); with ``solved`` False, the map prepared and the rest of
        the general path (from the absorbing flags on) to run, as when the goal's node
        or the terminal count changed in the kernel."""
        prep = self._rows_to_prepare(m)
        if prep is None:
            return -1, False
        args, F, abs_k = prep
        n, g0 = m.n, self._g_raw
        stuck = False
        if abs_k < 0 or self._opt_rows is not None or not self.vi_incremental \
                or self.broken or self._broken_solved:
            sweep = None
        elif self.value_unknown and (self._route_due or self._dirty or (
                stuck := self.stuck_known(m, n, g0)) is None
                or self.options_key(m, n, stuck)[0] != self._options_key):
            sweep = None
        elif self._no_last_solution(m, n, g0):
            sweep = None
        else:
            sweep = self._sweep_args(m, n, self.R, self._abs, True)
        if sweep is None:
            return self._rows_prepared(m, F, abs_k, *kernels.prepare_rows(*args)), False
        g, count, *found = kernels.converged_step(*args, *sweep)
        n = self._rows_prepared(m, F, abs_k, g, count)
        if found[0] < 0:                        # the goal's node or the count changed
            return n, False
        if self.value_unknown:
            self._stuck = stuck                 # (refresh_options: nothing to recompute)
        self.sweeps = 0 if self._incremental(m, n, self.R, self._abs, None, found) else \
            self._solve(m, n, self.R, self._abs, incremental=False)
        return n, True

    def _sweep_args(self, m: SensorimotorMap, n: int, R: np.ndarray, absorbing: np.ndarray,
                    sweep: bool) -> tuple:
        """The arguments of :func:`kernels.changed_rows_sweep` on this map, from the last
        solution (:meth:`_no_last_solution` finds one); ``sweep``: no option rows to
        compare, so a change that needs nothing more is swept at once."""
        inc, log = self._inc, getattr(m, "log", None)
        logged = log.since(inc.log_pos) if log is not None and log is inc.log and \
            inc.epoch == self._epoch else None       # None: compare every row
        return (m.out, m.E, R, absorbing, inc.out0, inc.E0, inc.R0, inc.abs0, n, inc.seeds,
                _NO_ROWS if logged is None else logged, -1 if logged is None else len(logged),
                sweep, self.V, self.gamma, self._sweep_tol, V_FLOOR, m.alive, self.U,
                self.rho, self.osucc, self.onb, self.ong, inc.first, inc.pred,
                INCREMENTAL_BUDGET * n, inc.heap, inc.pos, inc.key)

    def _no_last_solution(self, m: SensorimotorMap, n: int, g: int) -> str:
        """Why the incremental solve has no last solution to go on from ("": it has one):
        none, or of another goal node than ``g`` ("goal"), or of a map of another size
        ("size")."""
        inc = self._inc
        if inc is None or inc.goal_node != g:
            return "goal"
        if inc.n != n or inc.out0.shape[1] != m.out.shape[1] or \
                inc.rho0.shape != self.rho.shape:
            return "size"
        return ""

    def _solve(self, m: SensorimotorMap, n: int, R: np.ndarray, absorbing: np.ndarray,
               incremental: bool = True) -> int:
        """Eq. 4-5' on this map: with ``vi_incremental`` by prioritized sweeping from the
        last solution (:meth:`_incremental`), and when that declines (a goal change, a new
        map size, a sweep over budget) by an ordered solve from V = 0 (:meth:`_ordered`);
        without it, or when that too outgrows its budget, by synchronous sweeps
        warm-started from the last V (:func:`kernels.value_iteration`). Returns the sweeps
        of a synchronous solve (0: solved without). Either way every node ends with
        ``|beta (T(i) - V(i))| <= vi_tol V(i)`` (``T``: the right-hand side of Eq. 4-5',
        :func:`kernels.node_target`), the synchronous solve's stopping rule."""
        rows, self._opt_rows = self._opt_rows, None
        if self.vi_incremental and ((incremental and self._incremental(m, n, R, absorbing,
                                                                       rows))
                                    or self._ordered(m, n, R, absorbing)):
            return 0
        sweeps = kernels.value_iteration(
            m.out, m.E, R, self.V, n, self.beta, self.gamma, self.vi_tol, V_FLOOR,
            self.vi_max_sweeps, absorbing, m.alive, self.U[:n], self.rho[:n],
            self.osucc[:n], self.onb[:n], self.ong[:n])
        self.solves["full"] += 1
        if self.vi_incremental:
            self._inc = IncrementalState.of(m, n, R, absorbing, self)
        return sweeps

    def _ordered(self, m: SensorimotorMap, n: int, R: np.ndarray, absorbing: np.ndarray
                 ) -> bool:
        """Eq. 4-5' from V = 0 on every node, the largest values first
        (:func:`kernels.ordered_solve`: the goal's cluster solved among itself, then
        outwards as Dijkstra's algorithm settles distances), with a fresh copy of the
        inputs for the incremental solves after it. False (V left to the synchronous
        solve) after ``ORDERED_BUDGET`` updates a node."""
        inc = self._inc = IncrementalState.of(m, n, R, absorbing, self)
        self.V[:n] = 0.0
        if not self._ordered_all(m, n, R, absorbing, inc):
            return self._declined("ordered_budget")
        self.solves["ordered"] = self.solves.get("ordered", 0) + 1
        return True

    def _incremental(self, m: SensorimotorMap, n: int, R: np.ndarray, absorbing: np.ndarray,
                     rows: np.ndarray | None, found: tuple | None = None) -> bool:
        """Prioritized sweeping from the last solution, seeded with the rows that changed
        since (:func:`kernels.changed_rows`, and :func:`kernels.changed_options` over the
        option rows recomputed since), at most ``INCREMENTAL_BUDGET`` updates a node. A
        change that may lower values (a link removed, an E, R or last option gone, a node
        made absorbing: ``lost``) first sets to 0 the nodes whose value rested on it
        (:func:`kernels.invalidate`; lowered by sweeping, two nodes that held each other
        up fall only geometrically) and solves them again in order of value
        (:func:`kernels.ordered_solve`). Declines (False) without a last solution of a
        map of this size and goal, or when the sweep outgrows its budget. ``found``: what
        :func:`kernels.changed_rows_sweep` returned on this map when the fused step
        (:meth:`_fused_update`) called it."""
        if found is None:
            why = self._no_last_solution(m, n, self.goal_node)
            if why:
                return self._declined(why)
            found = kernels.changed_rows_sweep(*self._sweep_args(m, n, R, absorbing,
                                                                 rows is None))
        c, lost, relinked, swept, done = found
        inc, log, tol = self._inc, getattr(m, "log", None), self._sweep_tol
        inc.log, inc.log_pos, inc.epoch = log, (log.pos if log is not None else -1), self._epoch
        if swept:
            if done < 0:
                return self._continued(m, n, R, absorbing)
            self.solves["incremental"] += 1
            return True
        relinked_o = False
        if rows is not None:
            c, lost_o, relinked_o = kernels.changed_options(
                rows, len(rows), self.rho, self.U, self.osucc, self.onb, self.ong, inc.rho0,
                inc.U0, inc.osucc0, inc.onb0, inc.ong0, inc.seeds, c)
            lost |= lost_o
        self.solves["incremental"] += 1
        if c == 0:
            return True
        if relinked or relinked_o:
            inc.first, inc.pred = kernels.predecessors(m.out, n, m.alive, self.osucc,
                                                       self.onb)
        args = (m.out, m.E, R, self.V, n, self.gamma, tol, V_FLOOR, absorbing, m.alive,
                self.U, self.rho, self.osucc, self.onb, self.ong, inc.first, inc.pred)
        if lost:
            self.solves["invalidated"] = self.solves.get("invalidated", 0) + 1
            _, done = kernels.invalidate_solve(*args, inc.seeds, c, inc.found, inc.mark,
                                               INCREMENTAL_BUDGET * n, inc.heap, inc.pos,
                                               inc.key)
        else:
            done = kernels.prioritized_sweep(*args, inc.seeds, c, INCREMENTAL_BUDGET * n,
                                             inc.heap, inc.pos, inc.key)
        if done < 0:
            self.solves["incremental"] -= 1
            return self._continued(m, n, R, absorbing)
        return True

    def _continued(self, m: SensorimotorMap, n: int, R: np.ndarray, absorbing: np.ndarray
                   ) -> bool:
        """An incremental solve over its budget goes on from the V it left, not from V = 0:
        every node whose target (:func:`kernels.node_target`) is off its V by more than
        the tolerance is queued and solved in order of value (:func:`kernels.ordered_solve`
        over all nodes), at most ``ORDERED_BUDGET`` updates a node. Eq. 4-5' is a
        contraction (gamma < 1, E and rho at most 1), so its fixed point is one whatever V
        it starts from, and a solve that ends with every node meeting the stopping rule
        ends where one from V = 0 does, within the same tolerance; the copy of the inputs
        and the predecessors are already those of this map (the incremental solve brought
        them up to date). False (counted ``budget``: the ordered solve from V = 0 takes
        over) when this too outgrows its budget."""
        inc = self._inc
        if not self._ordered_all(m, n, R, absorbing, inc):
            return self._declined("budget")
        self.solves["continued"] = self.solves.get("continued", 0) + 1
        return True

    def _ordered_all(self, m: SensorimotorMap, n: int, R: np.ndarray, absorbing: np.ndarray,
                     inc: IncrementalState) -> bool:
        """:func:`kernels.ordered_solve` seeded with every node, from the current V, within
        ``ORDERED_BUDGET`` updates a node; False when it outgrows that budget."""
        return kernels.ordered_solve(
            m.out, m.E, R, self.V, n, self.gamma, self.vi_tol * (1.0 - self.gamma), V_FLOOR,
            absorbing, m.alive, self.U, self.rho, self.osucc, self.onb, self.ong, inc.first,
            inc.pred, np.arange(n, dtype=np.int64), n, ORDERED_BUDGET * n, inc.heap,
            inc.pos, inc.key) >= 0

    def _declined(self, why: str) -> bool:
        """Count why an incremental solve declined (``solves``); False."""
        self.solves[why] = self.solves.get(why, 0) + 1
        return False

    def exploit(self, m: SensorimotorMap) -> np.ndarray:
        """The potentials of Eq. 5 without options (the learnt policy, for the greedy
        probe), on the map of the last :meth:`update`; V0 (n + 1 entries), computed once
        per update, warm-started; after a goal change (V0 = 0) with ``vi_incremental`` by
        an ordered solve (:func:`kernels.ordered_solve`: from 0 the synchronous sweeps
        take about as many rounds as the map is wide)."""
        if not self.value_unknown:
            if not self.solved:
                self.update(m)
            return self.V
        if not self._v0_fresh:
            n = self._prepare(m)
            if self.goal_x is None or n == 0:
                self.V0[:] = 0.0
            elif not (self.vi_incremental and self._v0_zero and self._exploit_ordered(m, n)):
                kernels.value_iteration(                     # Eq. 4-5, no option
                    m.out, m.E, self.R, self.V0, n, self.beta, self.gamma, self.vi_tol,
                    V_FLOOR, self.vi_max_sweeps, self._absorbing(m, n), m.alive,
                    self.U[:n], np.zeros((n, self.n_primitives)), self.osucc[:n], self.onb[:n],
                    self.ong[:n])
                self._v0_zero = False
            self._v0_fresh = True
        return self.V0

    def _exploit_ordered(self, m: SensorimotorMap, n: int) -> bool:
        """V0 (Eq. 4-5 without options) from 0 by an ordered solve; False (V0 left to the
        synchronous solve, from 0) after ``ORDERED_BUDGET`` updates a node."""
        self.V0[:] = 0.0
        heap, pos = np.empty(n + 1, dtype=np.int64), np.full(n + 1, -1, np.int64)
        done = kernels.ordered_solve(
            m.out, m.E, self.R, self.V0, n, self.gamma, self.vi_tol * (1.0 - self.gamma),
            V_FLOOR, self._absorbing(m, n), m.alive, self.U,
            np.zeros((n, self.n_primitives)), self.osucc, self.onb, self.ong,
            *kernels.predecessors(m.out, n, m.alive, self.osucc, self.onb),
            np.arange(n, dtype=np.int64), n, ORDERED_BUDGET * n, heap, pos, np.zeros(n + 1))
        if done < 0:
            self.V0[:] = 0.0
            return False
        self._v0_zero = self.goal_node < 0   # (no goal yet: solved again from 0 later)
        return True

    def options_of(self, i: int, links: Links) -> Links:
        """Node i's links followed by its options as virtual links (Eq. 6 ranks both):
        an option's target is i itself, its reliability ``O(i, a) / V(i)`` so that
        ``E V(target)`` is its successor value, its action the primitive's vector. Over
        the graph they travel in the MotivationField's winner-link arrays."""
        if not self.value_unknown or i < 0 or i >= len(self.V) - 1:
            return links
        R_i = self.R[i] if i < len(self.R) else 0.0
        return Links(*kernels.option_links(links.targets, links.E, links.actions, self.V, i,
                                           self.U, self.rho, self.osucc, self.onb,
                                           self.ong, R_i,
                                           self.gamma, self.primitives))

    def option_terms(self, i: int) -> OptionTerms | None:
        """What Eq. 6 needs to rank node i's options beside its links without building
        them (:func:`kernels.eq6_choices`), None when :meth:`options_of` adds none."""
        if not self.value_unknown or i < 0 or i >= len(self.V) - 1:
            return None
        return (self.R[i] if i < len(self.R) else 0.0, self.gamma, self.U, self.rho,
                self.osucc, self.onb, self.ong)

    def links_of(self, m: SensorimotorMap, i: int) -> Links:
        """:meth:`options_of` node i's links in map m (what Eq. 6 ranks in-process)."""
        return self.options_of(i, m.links_of(i))
