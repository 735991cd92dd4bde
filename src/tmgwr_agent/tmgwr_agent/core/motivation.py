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
estimator keeps a copy of the last solve's inputs and solves by prioritized sweeping
(Moore & Atkeson 1993, :func:`kernels.prioritized_sweep`): the rows whose links, reward,
absorbing flag or options differ from the copy are queued, each queued node's V is set to
the right-hand side of Eq. 4-5' (:func:`kernels.node_target`), largest change first, and
the nodes that read it are queued when their own residual exceeds ``vi_tol (1 - gamma)
V``; it stops when nothing above that is left. Every node then meets the synchronous
solve's stopping rule, and V is as close to the fixed point as the synchronous solve's
(test_incremental_vi.py). A change that may lower values (a link removed, an E, R or
last option gone, a node made absorbing) is not swept down: V = 0 is reached only
geometrically where two nodes hold each other up (a region cut off its sources), so the
nodes whose value rested on the change are first set to 0 (:func:`kernels.invalidate`,
LPA*'s under-consistent nodes) and solved again from there in order of value. A goal
change, a new map size and a sweep over its budget solve every node from V = 0 in order
of value (:func:`kernels.ordered_solve`): with R = 0 a node is worth at most gamma times
its best successor, so largest first (Dijkstra's order) settles most nodes at their first
update, where synchronous sweeps from 0 take about as many rounds as the map is wide, and
the goal and its neighbours (a 2-cycle converging by gamma^2 a round) are solved among
themselves first; the synchronous solve remains as the fallback of the fallback. Those
rows are not searched for: the map
keeps a log of the rows each step changed (:class:`~tmgwr_agent.core.sensorimotor_map.
RowLog`; a replica, of the slots each change wrote), and the copy, the frame coordinates,
the rewards, the goal node and the absorbing masks are brought up to date on those rows
alone; whatever changes R or the masks on other rows (a full recompute of R, the closed
cells, the goal made terminal) bumps ``_epoch`` and the next solve compares every row.
Both are solutions within ``vi_tol``, not the same bits: where two of a node's links are
worth the same within that tolerance Eq. 6 may choose the other one, and the trajectory
goes on differently from there.

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
or ``none`` = the paper's Eq. 5). Every place, distance and length below (``w``,
``delta``, ``x_g``, ``L``) is measured in the frame of :mod:`tmgwr_agent.core.frame`:
the sensor's own axes for ``grid``, the learnt forward model's primitive steps for
``learnt`` (then ``L`` = 1). Every rule below that looks a place up assumes the
primitives make lattice steps; ``learnt`` checks it from the forward model's spread
(frame.py, "Is the forward model a lattice?") and where it fails uses none of them for
that primitive (:meth:`MotivationEstimator._unplaced_options`,
:meth:`MotivationEstimator._sensed_goal`).

Eq. 5 only knows the links the agent has made: where the map knows no way
to the goal every potential is 0 and the agent can only random-walk; a side corridor never
entered, or a wall that has since opened, never enters the plan. R-max style, every
(node i, motor primitive a) pair whose outcome the map does not know gets a virtual
successor, an *option*, in the max of Eq. 5::

    Delta_V(i) = R_i + gamma max( max_k E[i, k] V(k), max_a O(i, a) ) - V(i)     (Eq. 5')
    O(i, a)    = rho(i, a) S(i, a) + (1 - rho(i, a)) (R_i + gamma max_k E[i, k] V(k))

* ``rho`` is the probability that the option leads on. For a primitive never taken from i
  it is the chance the agent's own experience gives that a move opens: of its tried
  (node, primitive) pairs of live nodes, the share ``k / t`` whose last try moved it,
  smoothed by Laplace's rule, ``(k + 1) / (t + 2)`` (1/2 before any try; re-estimated
  with the options, at least once an episode; ``untried_rho``, negative by default, fixes
  it instead: 1 is R-max's optimistic bound). In a maze of corridors about half the moves
  bump, in an open field few do, and the agent learns which world it is in: an untried
  move beside a good route is tried only when ``rho`` times its saving beats the bump's
  step. The *untried chain* of an episode (``chain``) is the exception: at its first
  solve, a breadth-first search from its start over the links and the untried moves
  between known places (a primitive never taken from i whose predicted cell holds a known
  node) finds the shortest way to the goal; when it is shorter than the known route (or
  no route is known), its untried moves have ``rho = 1`` this episode, planned as open as
  the re-tests below are (:func:`kernels.untried_chain`). Each hop's odds alone make a
  way of ``k`` untried moves worth about ``rho^k`` of its saving, and a short cut along
  cells known but never walked in that direction was never taken (a generated large
  maze kept a greedy path two steps longer than its shortest for good). With a route as
  short as any such way (a converged agent) there is no chain. With the bound (``rho =
  1``) for every untried move the agent tried almost every untried pair whose L1
  heuristic beat the route, and detours after blocks grew. 1 also
  for a move whose link the map has since deleted (GWR ageing: a forgotten piece of a
  route is walked again when it may be worth it); when the node it led to is gone, or no
  longer within ``L / 2`` of the predicted cell (its slot reused), the cell is looked up
  as for any move. A pair whose last outcome was a bump is a remembered wall, *trusted*
  for ``T = stale_horizon`` episodes after the bump (``rho = 0``: no option) and *stale*
  after that (R-max's known threshold with forgetting). A wall can only be seen to have
  opened by re-testing it (the agent senses its position and its touch sensor, nothing at
  a distance), and a shortcut is news only if the agent goes and looks; the clock is the
  episode, the unit of the task. Which stale walls an episode re-tests is decided once,
  at its start (the *re-tests*, below); those have ``rho = stale_prior`` = 1, planned as
  open: a test is worth its cost over all the episodes a shortcut would serve, not over
  this one, so the one-episode odds of Eq. 5' are not what decides it (with ``rho`` =
  1/2, as before the re-tests were chosen, an opening that saves two steps a cell off the
  route never paid for its way there and back within the episode, and such openings were
  never found). The others have
  no option. A failed test leaves the agent where it was after one step, hence the ``(1 -
  rho)`` term.
* *A cell that closed*: when a move made before bumps now, the cell it led to has
  closed, from every side: the node it led to (while still at the predicted cell) is
  terminal in Eq. 5, worth its own R (no successor), for the ``T`` episodes the bump
  is trusted, or until the agent stands on it. Without it the agent, having bumped into
  a block, walked round to bump into it again from its other sides along the links it
  knew into it (held-out open fields: one block cell bumped from three sides). The stuck
  test (below) ignores it: those links never bumped.
* The *re-tests* of an episode (``stale_rank``): a re-test costs a step and often a
  detour, so an episode re-tests at most ``B = stale_budget`` times ``d`` stale walls,
  rounded up (at least one; ``stale_budget`` 0.1, the share of steps the paper's agent
  spends on its random walk at Eq. 7's floor), ``d`` the steps of the known route from
  the episode's start, read off the potentials of Eq. 5 without options there
  (``V0(start) = gamma^d V0(g)``; before a route is known, the number of nodes). At the
  episode's first solve every stale wall gets what it would save if it opened, ``s = d -
  (d_S(i) + 1 + k + 1 + d_G(q))`` steps on the known route (``d_S``, ``d_G``: link steps
  from the start and to the goal over the links the outcome memory does not contradict;
  ``q`` its best exit, ``k`` cells along its run, :func:`kernels.stale_savings`), and
  what a failed test would cost, ``c = d_S(i) + 1 + d_G(i) - d`` (at least 1); the ``B``
  walls with ``s > 0`` and the most ``t s / c``, ``t`` the episodes since the wall was
  last bumped, are this episode's re-tests (ties: the nearest first). Walls change, if at
  all, at some rate, so the chance a wall has opened grows with ``t``, and the gain of
  finding it is that chance times ``s`` (each episode after), against ``c``. A wall just
  re-tested waits, a long-unchecked one rises, so no wall waits for ever behind others
  (with the re-tests chosen as Eq. 5' ranked them from where the agent stood, more than
  ``T`` times ``B`` walls near the route starved one further off: a generated braided
  maze never found its opening); the cost keeps a far wall from sending the agent on a
  long excursion in an episode that meets a block. An episode in which a move made
  before has bumped (the known route broke) re-tests none from then on: the agent is
  finding its way round, and an old wall re-tested on the way costs steps the detour
  needs. A re-test is an action
  at a pair known closed while not *stuck* (below). ``stale_rank`` off: every stale wall
  has ``rho = stale_prior`` until ``B`` re-tests are used up, Eq. 5' ranking them from
  where the agent stands.
* ``S`` is what the successor is worth. A known node when there is one: where the move
  once led, else the node at the predicted position ``w_i + delta_a`` (``delta_a``: the
  mean sensed displacement of primitive a over the agent's moves, its own forward model;
  a node lookup by position, :func:`kernels.cell_grid`); so an untried move between two
  known places is worth what the place is, not more. A remembered wall cell: ``gamma``
  times the best ``gamma^k V(q)`` of its exits, the known nodes ``q`` next to it or
  next to a run of unknown cells from it, ``k`` cells along (a wall that opens opens
  along its run: straight on, a corridor cut through a block, or sideways, a strip of
  an obstacle entered at one end; :func:`kernels.wall_exits`). A run stops after its
  first cell next to known space and at the known extent of the world (the maze's outer
  wall never leads round). It pays to re-test only a wall whose far side is known and
  nearer the goal; with no exit, no option. (With the exits next to the cell and
  straight on only, an opened strip entered from its end was worth nothing, and such
  openings in open fields were rarely found.)
  Unknown space:
  ``U = V* gamma^h``, ``h = |w_i + delta_a - x_g|_1 / L``, the fewest steps of length L
  from the predicted successor to the goal sensation ``x_g`` (the four primitives move
  along the axes, hence L1: it never overestimates, so no shorter route is missed, the
  A* argument), and ``V* = 1 / (1 - gamma^2)``, the potential of a represented goal node
  (R_g = 1, and Eq. 5 returns to it every second step), so an option at h steps is worth
  exactly a known route of h steps. The agent leaves a known route of length d for an
  unknown only if the way there plus ``1 + h`` is shorter than d: it explores where a
  shorter route may exist and nowhere else; the horizon is the goal's distance in the
  map, no constant.
* *Stuck*: the goal is represented but no link path leads from the agent's node to it
  over the links its outcome memory does not contradict (a link whose primitive bumped
  last time counts as gone). The agent's knowledge says the task is impossible, so every
  remembered wall is doubted evenly, ``T = N``, up to ``rho``'s limit ``p``: the chance
  that a wall known closed has opened, from the agent's own re-tests, the share of its
  actions at a pair known closed that moved it, ``(k + 1) / (t + 2)`` (Laplace's rule,
  as the open prior of untried moves: 1/2 before any re-test,
  :meth:`MotivationEstimator.wall_prior`); walls without a known other side get the
  optimistic U. With ``p`` fixed at 1/2 a wall known closed was as likely open as a move
  never tried, and the L1 distance ranked them: on the default maze (a, with
  ``config/tuned/tmgwr.yaml``, trial 1, one training episode) the agent walked back
  along its route to the start bumping every side wall nearer the goal than the untried
  way round (117 steps against an oracle of 61; now 62); each failed test now lowers
  ``p`` for all walls. A wall re-tested
  in vain is doubted over ``T + e`` instead, ``e`` the steps it had been known closed at
  its last bump (from the first bump of its current run of bumps): each failed re-test
  is evidence the wall stays, so the re-tests back off and the agent goes farther afield.
  Without it the nearest wall on the lost route (the block itself) was re-tested every
  few dozen steps and the agent never got far from it (one held-out suite trial took
  over a hundred times the oracle's steps). While stuck the clock is the step (the task
  is impossible now, not in a few episodes) and the re-test budget does not apply.
* *The goal when the route broke*: an episode ends at the goal, so the agent never moves
  from a goal node, and its potential in Eq. 5' is ``R_g`` plus what its own untried
  moves promise (about 10 here, against the ``V* = 17`` the unknown is scaled to: a goal
  that Eq. 5 can step off and back onto). Known ways near the goal are then worth less
  than unknown space at the same distance, and a neighbour's untried move can outrank
  the step into the goal. In a training episode that look round pays, since the map
  learns the goal's surroundings (with the goal a terminal state worth ``V*`` in every
  episode, both blocks and openings were handled worse). In an episode whose known route
  broke (a move made before bumped: ``broken``) the agent is finding its way round and
  the look only delays it: there the goal nodes are what the task makes them, terminal
  states worth ``V*`` (:meth:`MotivationEstimator._goal_terminal`): without it a
  generated large maze's agent stood beside the goal after the block and then searched
  the unknown for many times the route's length.
* The goal node exists only once the map represents the goal (a node within ``L / 2`` of
  the goal region, i.e. the goal has been sensed): before that ``R = 0`` everywhere and
  the options alone lead the agent, by the nearest plausible unknown, towards the goal
  sensation. (The paper's ``g = SM.Map(x_g)`` is otherwise the node *most like* a goal in
  unvisited space, often a dead end behind a wall, where Eq. 6 then oscillated; this
  replaces ``goal_search``.) The goal region is what the world declares
  (``Senses.goal_tolerance``): the sensations within that distance of the goal sensation,
  any of which ends the episode at the goal; the goal sensation alone when it is 0 (a grid
  cell). Why half a step beyond it: the agent senses only where its primitives stop, places
  one step ``L`` apart, so the sensation at which it first meets the region, and the node
  that matched it, may lie up to half a step off any given point of it; a region the
  primitives end *inside* is met at its edge (an episode stops there), never nearer its
  centre, so without the tolerance a goal wider than a step is never represented.
* The options are part of the potentials the action selector climbs (Eq. 6 ranks them
  with the links: :meth:`MotivationEstimator.options_of`), which replaces the former
  ``try_untried`` rule. The experimenter's greedy probe (``explore`` False) is the learnt
  policy: it climbs the potentials of Eq. 5 without options (:meth:`exploit`), as
  Dyna-Q+'s probe reads its bonus-free twin.

Costs: the options are recomputed in full when the map's structure, the episode (when
stuck, a tick of the step clock), the stuck state or the re-test budget changes, else only
on the rows whose outcome memory changed; the reachability pass and the option loop are a
few linear passes over the map. Reading the route costs one solve of Eq. 5 without
options per episode, choosing its re-tests two breadth-first searches over the links and
the exits of every stale wall (it raises the mean step, not the median), its untried
chain one more (over the links and the untried moves).

Terminal nodes (``absorbing_terminals``, our addition, on by default; off = Eq. 5 on every
node). The agent notices when an episode ends: it is moved back to the start instead of
walking on. The map flags the node it stood on
(:meth:`~tmgwr_agent.core.sensorimotor_map.SensorimotorMap.mark_terminal`) until it walks
on from it, and value iteration treats a flagged node as a terminal state, as any MDP
solver would: ``V(i) = R_i``, no successor, no option; except the nodes of the current goal
(``R_i >= 1/2``), which keep Eq. 5 (unless the route broke, above). Without this a route
through a cell that ends the episode (the previous goal in the goal-change scenario of
section 5.2.1, which stays a termination point) looks as good as any other, and the agent
keeps being sent home through it. The goal's own cell is flagged too, while it is the
goal, so that when the goal moves the old goal is known to end episodes from the first
episode on (the agent cannot tell a goal cell from a terminal cell; if the old goal became
an ordinary cell, the flag goes the first time the agent walks on from it). Episodes cut
by a step limit flag nothing.

The outcome memory (primitives tried per node, step and episode of the last bump and since
when a pair is known closed, where each move led, the step and episode clocks, the known
route, this episode's re-tests and untried chain, the forward model ``delta`` and its
spread, the nodes where the goal was sensed) is plain data:
:meth:`state_dict` / :meth:`load_state_dict`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tmgwr_agent.core import kernels
from tmgwr_agent.core.frame import Frame, make_frame
from tmgwr_agent.core.outcome import Outcome
from tmgwr_agent.core.sensorimotor_map import Links, SensorimotorMap
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
#: A node with R_i = sim(i, g) at least this represents the goal (a source of the
#: reachability test; never absorbing).
GOAL_R = 0.5


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
                         "frame.py)", choices=("none", "grid", "learnt"))
    stale_prior: float = param(1.0, "Eq. 5': rho of a stale remembered wall the episode "
                               "re-tests (1: planned as open, the test decided by the "
                               "ranking; 1/2: as likely open as closed)", low=0.0,
                               high=1.0)
    stale_horizon: float = param(6.0, "Eq. 5': episodes a remembered wall is trusted before "
                                 "it goes stale (0: walls never go stale unless stuck)",
                                 low=0.0, high=1e6)
    stale_budget: float = param(0.1, "Eq. 5': re-tests of stale walls per episode, at most "
                                "this share of the known route's steps rounded up (at least "
                                "1; 0: none)",
                                low=0.0, high=1.0)
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


def laplace(k: int, t: int) -> float:
    """Laplace's rule of succession: the chance of a success after k in t trials,
    (k + 1) / (t + 2) (1/2 before any trial)."""
    return (k + 1.0) / (t + 2.0)


def grown(a: np.ndarray, n: int, fill) -> np.ndarray:
    """``a`` with at least n rows (doubling), new rows set to ``fill``."""
    if len(a) >= n:
        return a
    b = np.full((max(n, 2 * len(a)),) + a.shape[1:], fill, dtype=a.dtype)
    b[: len(a)] = a
    return b


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
        """The state after a full solve on map m (rewards R, the absorbing mask)."""
        return cls(n, est.goal_node, m.out[:n].copy(), m.E[:n].copy(), R[:n].copy(),
                   absorbing[:n].copy(), est.rho.copy(), est.U.copy(), est.osucc.copy(),
                   est.onb.copy(), est.ong.copy(),
                   *kernels.predecessors(m.out, n, m.alive, est.osucc, est.onb),
                   log=getattr(m, "log", None), epoch=est._epoch)


class MotivationEstimator:
    """Holds the goal, the potentials V and the outcome memory of Eq. 5'; :meth:`record`
    notes what an action did, :meth:`update` re-solves Eq. 4-5'."""

    def __init__(self, config: MotivationConfig = MotivationConfig(), *,
                 primitives: np.ndarray, goal_tolerance: float = 0.0):
        """``primitives``: the motor vector of each action (:class:`~tmgwr_agent.core.
        senses.Senses`): an option's action label; their number sizes the outcome
        memory. ``goal_tolerance``: the world's (``Senses``), in the units of the goal
        sensation given to :meth:`set_goal`."""
        kernels.announce_compilation()
        self.config = config
        self.primitives = np.ascontiguousarray(primitives, dtype=float)
        self.goal_tolerance = float(goal_tolerance)
        P = self.n_primitives = len(self.primitives)
        self.gamma, self.beta = config.gamma, config.beta
        self.goal_sigma, self.goal_sim_floor = config.goal_sigma, config.goal_sim_floor
        self.vi_tol, self.vi_max_sweeps = config.vi_tol, config.vi_max_sweeps
        self.vi_incremental = config.vi_incremental
        self._inc: IncrementalState | None = None   # the copy of the last solve's inputs
        self._opt_rows: np.ndarray | None = None    # option rows recomputed since
        self.solves = {"incremental": 0, "full": 0}   # and why the incremental declined
        self.absorbing_terminals = config.absorbing_terminals
        self.value_unknown = config.unknown != "none"
        self.frame = make_frame(config.unknown)     # where places are measured (frame.py)
        self.lattice = np.ones(P, dtype=bool)       # primitives whose options are valued
        self._frame_episode = -1      # the episode the frame's basis was chosen in
        self._F: Frame | None = None  # the frame's coordinates of the last _prepare
        self.stale_prior, self.stale_horizon = config.stale_prior, config.stale_horizon
        self.stale_budget = config.stale_budget
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
        self.sel = np.ones((64, P), dtype=bool)  # this episode's re-tests
        self.chain = np.zeros((64, P), dtype=bool)  # its untried chain
        self._closed: np.ndarray | None = None   # its trusted marks (derived, cached)
        self.clock = 0                # learning steps recorded
        self.episode = 0              # episodes started
        self.route = 0.0              # steps of the known route from this episode's start
        self.retests = 0              # stale walls re-tested this episode (not stuck)
        self.wall_tests = 0           # actions at a pair known closed, ever
        self.wall_opened = 0          # of those, the ones that moved
        self.broken = False           # a move made before bumped this episode
        self._route_due = False       # the route is read off V0 at the episode's first solve
        self._stuck = False           # stuck when the last update solved Eq. 5'
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
        self._dirty: set[int] = set()    # rows whose outcome memory changed since update
        self._alive_version, self._alive = -1, 0
        self._winner = -1                # the agent's node (from record)
        self._bumps = 0                  # bumps recorded (a key of the stuck test)
        self._reach_key: tuple = ()
        self._reach = np.zeros(0, dtype=bool)
        # What changed since the last _prepare: the map's change log (RowLog) and its
        # position then; the inputs R was computed from (its rows are recomputed alone
        # while they hold) and the nearest node to the goal then.
        self._prep_log, self._prep_pos = None, -1
        self._R_key: tuple | None = None
        self._g_raw = -1
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

    # ------------------------------------------------------------------ goal
    def set_goal(self, goal_x: np.ndarray) -> None:
        """A new goal state: the potentials restart from 0 (Algorithm 1, line 5)."""
        self.goal_x = np.asarray(goal_x, dtype=float)
        self.goal_seen[:] = False
        self._options_key = ()
        self.route = 0.0                  # the route to the new goal is not known yet
        self.V[:] = 0.0
        self._inc = None
        self._R_key = None
        self.V0[:] = 0.0
        self._v0_fresh = False
        self._v0_zero = True              # V0 restarts from 0 too: solved in order

    def follow_goal(self, goal_x: np.ndarray) -> bool:
        """The goal sensation that came with this step: :meth:`set_goal` when it differs
        from the current goal (the graph's estimator learns goal changes this way);
        returns whether it did."""
        goal_x = np.asarray(goal_x, dtype=float)
        if self.goal_x is not None and np.array_equal(goal_x, self.goal_x):
            return False
        self.set_goal(goal_x)
        return True

    # ------------------------------------------------------------------ outcome memory
    def record(self, node: int, winner: int, inserted: bool, outcome: Outcome,
               w: np.ndarray) -> None:
        """What the last learning step did: primitive ``outcome.action`` taken from
        ``node`` led to ``winner`` (``inserted``: a new node) or bumped. The pair becomes
        known (a bump remembers its step, for staleness), a new node starts with every
        primitive untried, and a move updates the forward model ``delta`` (the mean of
        ``w[winner] - w[node]`` over the moves made with the primitive; ``w``: the map's
        weights). An episode start starts the episode clock and its budget for stale
        walls; an action at a pair known closed is a test of a wall (counted for
        :meth:`wall_prior`), and when the agent was not stuck a re-test of a stale wall
        (counted against the episode's budget)."""
        self._winner = winner
        if outcome.episode_start:
            self._route_due = True
            self.episode += 1
            self.retests = 0
            self.broken = False
            self.sel[:] = True                # until the route is read (_plan_episode)
            self.chain[:] = False
            self._closed = None               # marks expire by the episode
            return
        self.clock += 1
        top = max(node, winner) + 1
        if top > len(self.tried):
            self._grow_memory(top)
        self._size_forward_model(w.shape[1])
        if inserted and winner >= 0:
            self._dirty.add(winner)
        if (outcome.goal_reached or inserted) and winner >= 0 \
                and self.goal_seen[winner] != outcome.goal_reached:
            self.goal_seen[winner] = outcome.goal_reached   # a goal node, or a new slot
            self._R_key = None
        if 0 <= node and self.bump_t[node, outcome.action] >= 0:
            self.wall_tests += 1
            self.wall_opened += not outcome.bumped
            self.retests += not self._stuck
        a = outcome.action
        # a move made before bumps now: the known route broke, the cell it led to closed
        broke = bool(outcome.bumped and 0 <= node and self.bump_t[node, a] < 0
                     and self.succ[node, a] >= 0)
        self.broken |= broke
        if broke:
            self._close_cell(node, a, w)
        elif winner >= 0 and (inserted or not outcome.bumped):
            self._mark_closed(winner, -1)     # a node stood on (or a new one) is open
        moved = self.moves[a]
        if kernels.record_outcome(self.tried, self.bump_t, self.closed_t, self.bump_e,
                                  self.succ, self.delta, self.moves, w, node, winner,
                                  inserted, outcome.action, outcome.bumped, self.clock,
                                  self.episode):
            self._dirty.add(node)
            self._bumps += 1
        if self.moves[a] != moved:            # a move: the forward model's spread too
            d = w[winner] - w[node]
            self.delta_sq[a] += (float(d @ d) - self.delta_sq[a]) / self.moves[a]

    #: The outcome memory's per-node arrays and the value of a new node's row.
    _MEMORY = (("tried", False), ("bump_t", -1), ("closed_t", -1), ("bump_e", -1),
               ("succ", -1), ("closed_e", -1), ("sel", True), ("chain", False),
               ("goal_seen", False))

    def _grow_memory(self, n: int) -> None:
        """The outcome memory with at least n node rows (:func:`grown`)."""
        for name, fill in self._MEMORY:
            setattr(self, name, grown(getattr(self, name), n, fill))

    def merge(self, merges) -> None:
        """The map merged node ``gone`` into node ``keep`` for each pair of ``merges``
        (:attr:`~tmgwr_agent.core.sensorimotor_map.SensorimotorMap.merges`, in order):
        ``keep`` takes ``gone``'s outcome memory of each primitive it has not tried itself,
        every move remembered to lead to ``gone`` leads to ``keep``, ``gone``'s row is a
        new node's, and the options are recomputed in full at the next update."""
        for keep, gone in merges:
            keep, gone = int(keep), int(gone)
            if max(keep, gone) >= len(self.tried):
                self._grow_memory(max(keep, gone) + 1)
            take = ~self.tried[keep] & self.tried[gone]
            for name, fill in self._MEMORY:
                a = getattr(self, name)
                if name in ("sel", "chain"):        # this episode's re-tests, its chain
                    a[keep] |= a[gone]
                elif a.ndim == 2:
                    a[keep, take] = a[gone, take]
                else:                               # closed_e: the later closing
                    a[keep] = max(a[keep], a[gone])
                a[gone] = fill
            self.succ[self.succ == gone] = keep
            for V in (self.V, self.V0):
                if gone < len(V) - 1 and keep < len(V) - 1:
                    V[keep], V[gone] = max(V[keep], V[gone]), 0.0
            if self._winner == gone:
                self._winner = keep
        if len(merges):
            self._closed = None
            self._options_key = ()

    def _close_cell(self, node: int, a: int, w: np.ndarray) -> None:
        """Primitive a, a move made before from ``node``, bumps now: the cell it led to has
        closed, from every side (the node it led to, while that node is still at the
        predicted cell; a map loaded or rebuilt since may hold fewer nodes than ``succ``
        remembers)."""
        j = self.succ[node, a]
        if j == node or j >= len(w) or not self.lattice[a]:   # no cell it predicts
            return
        F = self.frame.of(w[[node, j]], np.zeros(w.shape[1]), self.delta[[a]], self._scale,
                          cache=False)
        if np.abs(F.w[1] - F.w[0] - F.delta[0]).max() < 0.5 * F.L:
            self._mark_closed(j, self.episode)

    def _mark_closed(self, j: int, episode: int) -> None:
        """Node j's cell closed in ``episode`` (-1: open)."""
        if self.closed_e[j] != episode:
            self.closed_e[j] = episode
            self._closed = None

    def state_dict(self) -> dict[str, np.ndarray | float | int]:
        """The outcome memory, as plain arrays and numbers (node rows ``[0, n)`` of the
        map it belongs to)."""
        return {"tried": self.tried.copy(), "bump_t": self.bump_t.copy(),
                "closed_t": self.closed_t.copy(), "bump_e": self.bump_e.copy(),
                "succ": self.succ.copy(), "closed_e": self.closed_e.copy(),
                "goal_seen": self.goal_seen.copy(),
                "clock": int(self.clock), "delta": self.delta.copy(),
                "delta_sq": self.delta_sq.copy(),
                "moves": self.moves.copy(), "episode": int(self.episode),
                "route": float(self.route), "retests": int(self.retests),
                "wall_tests": int(self.wall_tests), "wall_opened": int(self.wall_opened),
                "route_due": int(self._route_due), "sel": self.sel.copy(),
                "chain": self.chain.copy()}

    def load_state_dict(self, d: dict) -> None:
        self.tried = np.array(d["tried"], dtype=bool)
        self.bump_t = np.array(d["bump_t"], dtype=np.int64)
        # closed_t is absent from older checkpoints: each bump then counts as the first
        self.closed_t = np.array(d.get("closed_t", d["bump_t"]), dtype=np.int64)
        self.succ = np.array(d["succ"], dtype=np.int64)
        self.closed_e = grown(np.array(d.get("closed_e", ()), dtype=np.int64),
                              len(self.succ), -1)            # older checkpoints: none
        self._closed = None
        self.goal_seen = grown(np.array(d.get("goal_seen", ()), dtype=bool), len(self.succ),
                               False)                        # older checkpoints: none
        self.clock = int(d["clock"])
        # absent from older checkpoints: the episode counters start afresh and every
        # remembered wall is trusted from now on
        self.episode = int(d.get("episode", 0))
        self.bump_e = np.array(d["bump_e"], dtype=np.int64) if "bump_e" in d else \
            np.where(self.bump_t >= 0, self.episode, -1)
        self.route = float(d.get("route", 0.0))
        self.retests = int(d.get("retests", 0))
        self.wall_tests = int(d.get("wall_tests", 0))      # older checkpoints: no re-test
        self.wall_opened = int(d.get("wall_opened", 0))
        self._route_due = bool(d.get("route_due", 0))
        self.sel = grown(np.array(d["sel"], dtype=bool), len(self.succ), True) \
            if "sel" in d else np.ones(self.succ.shape, dtype=bool)   # older: every one
        self.chain = grown(np.array(d.get("chain", np.zeros((0, self.n_primitives))), dtype=bool),
                           len(self.succ), False)                      # older: none
        self.delta = np.array(d["delta"], dtype=float)
        # absent from older checkpoints: no spread (every displacement its mean)
        self.delta_sq = np.array(d["delta_sq"], dtype=float) if "delta_sq" in d else \
            np.einsum("ij,ij->i", self.delta, self.delta) if self.delta.size else \
            np.zeros(self.n_primitives)
        self.moves = np.array(d["moves"], dtype=np.int64)
        self._options_key = ()
        self._inc = None                  # the next solve is a full one

    # ------------------------------------------------------------------ Eq. 4-5'
    @staticmethod
    def link_scale(m: SensorimotorMap) -> float:
        """Median length of the map's links in feature space (0 if it has none)."""
        src, tgt = np.nonzero(m.out[: m.n] >= 0)
        if not len(src):
            return 0.0
        d = m.w[src] - m.w[m.out[src, tgt]]
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

    def _size_forward_model(self, dim: int) -> None:
        """The forward model ``delta`` for sensations of ``dim`` values (zero: unknown)."""
        if self.delta.shape != (self.n_primitives, dim):
            self.delta = np.zeros((self.n_primitives, dim))
            self.delta_sq = np.zeros(self.n_primitives)

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
        if self.value_unknown and not self.lattice.any():
            return self._sensed_goal(m, n)
        if g < 0 or (self.value_unknown                   # represented only once sensed
                     and not self._represents_goal(F, m, g)):
            self.R = np.zeros(n)
            self._R_key = None
            self._epoch += 1
            return n
        self.goal_node = g
        self.R = self.rewards(F, m, g, None if g_moved else rows)
        return n

    def _sensed_goal(self, m: SensorimotorMap, n: int) -> int:
        """Goal node and rewards without a lattice (no primitive consistent, frame.py):
        the test "a node within half a step of the goal sensation" and Eq. 10's width in
        link lengths both measure steps by a lattice, so the goal is represented by the
        nodes where the agent sensed it (``goal_seen``, the outcome's goal sensing): R = 1
        there, 0 elsewhere, the goal node the one of them nearest the goal sensation (-1
        before any: the options lead). Returns n."""
        seen = self.goal_seen[:n] & m.alive[:n]
        R = seen.astype(float)
        if len(self.R) != n or not np.array_equal(R, self.R):
            self.R = R
            self._R_key = None
            self._epoch += 1
        idx = np.flatnonzero(seen)
        if not len(idx) or self.goal_x is None:
            self.goal_node = -1
            return n
        d = m.w[idx] - self.goal_x
        self.goal_node = int(idx[np.argmin(np.einsum("ij,ij->i", d, d))])
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

    def spread(self) -> np.ndarray:
        """Per primitive, the spread of its sensed displacements about their mean
        ``delta``: the root mean square of ``|d - delta_a|`` over its moves (0 before
        any)."""
        if not self.delta.size:
            return np.zeros(self.n_primitives)
        var = self.delta_sq - np.einsum("ij,ij->i", self.delta, self.delta)
        return np.sqrt(np.maximum(var, 0.0))

    def _follow_lattice(self, lattice: np.ndarray) -> None:
        """The primitives the frame finds consistent (frame.py), whose options the lattice
        rules value (the others: :meth:`_unplaced_options`). A change restarts the
        potentials and recomputes every option, as a new goal does."""
        if np.array_equal(lattice, self.lattice):
            return
        self.lattice = lattice.copy()
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
            m.terminal, self.absorbing_terminals, cells, self.value_unknown, self.R, GOAL_R,
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
        goal when the route broke, in the module docstring)."""
        goal = self.R[:n] >= GOAL_R
        return np.where(goal, self.v_star, self.R[:n]), absorbing | goal

    def closed_cells(self, n: int) -> np.ndarray:
        """The nodes of cells that closed, while trusted (``stale_horizon`` episodes since),
        as a mask of n; recomputed only when a mark, the episode or n changed (it is read
        at every solve)."""
        if self._closed is None or len(self._closed) != n:
            k = min(n, len(self.closed_e))
            e = self.closed_e[:k]
            self._closed = np.zeros(n, dtype=bool)
            self._closed[:k] = (e >= 0) & (self.episode - e < self.stale_horizon)
            self._epoch += 1                # absorbing flags off the map's log
        return self._closed

    def stuck_clock(self, nodes: int) -> tuple[int, float]:
        """(clock, T) for the doubt of walls while stuck: ``T = nodes`` steps (a bump older
        than a walk over the map is as doubtful as any); the clock advances in steps of
        T / 8 (rho changes at those ticks only, so the warm-started value iteration is not
        re-solved for a drift of every option each step)."""
        tick = max(1, nodes // 8)
        return self.clock - self.clock % tick, float(nodes)

    def budget_spent(self, n: int) -> bool:
        """This episode's re-tests of stale walls are used up: at most ``stale_budget``
        times the steps of the known route from the episode's start (the number of nodes
        before a route is known), rounded up, and at least one, unless ``stale_budget`` is
        0. (Rounded down instead, fewer openings were found within 10 episodes and no
        block was won more.)"""
        return self.stale_budget <= 0.0 or self.broken or \
            self.retests >= max(1.0, self.stale_budget * (self.route or n))

    def _read_route(self, m: SensorimotorMap, n: int) -> None:
        """At an episode's first solve: the steps ``d`` of the known route from where it
        starts, read off the potentials of Eq. 5 without options, ``V0(start) = gamma^d
        V0(g)``."""
        self._route_due = False
        V0 = self.exploit(m)
        v, vg = (V0[self._winner] if 0 <= self._winner < n else 0.0), V0[self.goal_node]
        if 0.0 < v <= vg:
            self.route = max(1.0, math.log(v / vg) / math.log(self.gamma))

    def _plan_episode(self, m: SensorimotorMap, n: int) -> None:
        """At an episode's first solve: its re-tests (:meth:`_select_retests`) and its
        untried chain (``chain``: the untried moves between known places on the shortest
        way from its start to the goal over the links and such moves, when it is shorter
        than the known route or no route is known, :func:`kernels.untried_chain`), from
        the link steps from the start and to the goal over the links the outcome memory
        does not contradict. Every stale wall stays a re-test when ``stale_rank`` is off
        or no route is known."""
        self.sel[:] = True
        self.chain[:] = False
        start = self._winner
        if not 0 <= start < n:
            return
        absorbing = self._absorbing(m, n)
        Eb = kernels.contradicted(m.out, m.E, n, self.bump_t, self.succ)
        ds, dg = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
        kernels.link_steps(m.out, Eb, n, m.alive, absorbing, start, False, ds)
        kernels.link_steps(m.out, Eb, n, m.alive, absorbing, self.goal_node, True, dg)
        F = self._F
        grid, origin = kernels.cell_grid(F.w, m.alive, n, F.L)
        route = int(dg[start])
        if route >= 0 and self.stale_rank and self.stale_budget > 0.0 \
                and self.stale_horizon > 0.0:
            self._select_retests(m, n, ds, dg, route, grid, origin)
        kernels.untried_chain(m.out, Eb, n, m.alive, absorbing, F.w, F.delta, F.L,
                              grid, origin, self.tried, start, self.goal_node,
                              route if route >= 0 else n + 1, self.chain)

    def _select_retests(self, m: SensorimotorMap, n: int, ds: np.ndarray, dg: np.ndarray,
                        route: int, grid: np.ndarray, origin: np.ndarray) -> None:
        """The stale walls this episode may re-test (``sel``), the budget's worth
        (:meth:`budget_spent`) of those that would save the most steps on the known route
        (``route`` link steps; ``ds``, ``dg``: link steps from the start and to the goal)
        if they opened (:func:`kernels.stale_savings`; ties: the nearest first)."""
        ri, ra, rs = (np.empty(n * self.n_primitives, dtype=np.int64) for _ in range(3))
        F = self._F
        c = kernels.stale_savings(F.w, m.alive, n, F.delta, F.L, self.gamma, grid,
                                  origin, self.tried, self.bump_e, self.succ, self.episode,
                                  self.stale_horizon, ds, dg, route,
                                  np.full((n, self.n_primitives, self.n_primitives), -1, np.int64),
                                  np.zeros((n, self.n_primitives, self.n_primitives)), ri, ra, rs)
        budget = math.ceil(max(1.0, self.stale_budget * (self.route or n)))
        ri, ra, rs = ri[:c], ra[:c], rs[:c]
        cost = np.maximum(ds[ri] + 1 + dg[ri] - route, 1)   # steps lost if it stays shut
        key = (self.episode - self.bump_e[ri, ra]) * rs / cost
        order = np.lexsort((ds[ri], -key))[:budget]        # the most first, then nearest
        self.sel[:] = False
        self.sel[ri[order], ra[order]] = True

    def _options(self, m: SensorimotorMap, n: int) -> None:
        """U and rho of every option (:func:`kernels.option_values`), recomputed in full
        when the map's structure, the goal, the node count, the stuck state, the stale
        clock (episodes; when stuck, ticks of the step clock) or the re-test budget
        changed, else only on the rows whose outcome memory :meth:`record` changed
        (weights drift a little between full passes; a pow per pair and step would
        dominate the step time). Absorbing nodes keep theirs unused (Eq. 5' gives them
        no successor)."""
        stuck = self._stuck = self.stuck(m, n)
        nodes = self.nodes_alive(m, n)
        clock, T = self.stuck_clock(nodes)
        spent = not stuck and self.budget_spent(nodes)
        rho_max = self.wall_prior() if stuck else 0.0 if spent else self.stale_prior
        F = self._F
        key = ((m.version, self.frame.version), clock if stuck else self.episode, n, stuck,
               spent, rho_max)
        if key != self._options_key:
            if self._options_key[:1] != key[:1]:
                self._grid, self._origin = kernels.cell_grid(F.w, m.alive, n, F.L)
            self._options_key = key
            self.rho_new = self.open_prior(m, n)
            rows = np.arange(n)
        elif self._dirty:
            rows = np.fromiter(self._dirty, dtype=np.int64)
        else:
            return
        self._dirty.clear()
        self._opt_rows = rows if self._opt_rows is None or len(rows) == n else \
            np.union1d(self._opt_rows, rows)
        kernels.option_values(F.w, m.out, m.alive, n, rows, F.goal, F.delta,
                              F.L, self.v_star, self.gamma, self.tried, self.bump_t,
                              self.closed_t, self.bump_e, self.succ, clock, T, self.episode,
                              self.stale_horizon, rho_max, self.rho_new, stuck, self._grid,
                              self._origin, self.V, self.sel, self.chain,
                              self.U, self.rho, self.osucc, self.onb, self.ong)
        if not self.lattice.all():
            self._unplaced_options(m, rows[rows < n], np.flatnonzero(~self.lattice))

    def _unplaced_options(self, m: SensorimotorMap, rows: np.ndarray,
                          prims: np.ndarray) -> None:
        """The options of the primitives ``prims`` that make no lattice step (frame.py),
        on the nodes ``rows``. The forward model cannot place their successor, so no rule
        that looks a place up applies (a known node there, a wall's exits, the untried
        chain, a closed cell): only a primitive never taken from i has an option, into
        unknown space, ``rho = rho_new`` and ``U = V* gamma^h``, ``h = max(0, |w_i - x_g|
        / l - 1)`` with ``l`` the root mean square step of the longest-moving primitive:
        a path of k moves covers about k l at most (the triangle inequality, in the
        sensation's own norm), so h does not overestimate the steps from the successor to
        the goal (the A* argument of the module docstring holds without a lattice)."""
        r, a = rows[:, None], prims[None, :]
        untried = ~self.tried[r, a] & m.alive[rows][:, None]
        step = math.sqrt(max(float(self.delta_sq.max()), 0.0))
        gap = np.sqrt(np.einsum("ij,ij->i", m.w[rows] - self.goal_x, m.w[rows] - self.goal_x))
        h = np.maximum(gap / step - 1.0, 0.0) if step > 0.0 else np.zeros(len(rows))
        self.rho[r, a] = np.where(untried, self.rho_new, 0.0)
        self.U[r, a] = np.where(untried, (self.v_star * self.gamma ** h)[:, None], 0.0)
        self.osucc[r, a] = -1

    def open_prior(self, m: SensorimotorMap, n: int) -> float:
        """rho of a primitive never tried (Eq. 5'): ``untried_rho``, or when that is
        negative the chance that a move opens, estimated from the agent's own outcomes as
        the share of its tried pairs (of live nodes) whose last try moved it, (k + 1) /
        (t + 2) (Laplace's rule: 1/2 before any try)."""
        if self.untried_rho >= 0.0:
            return self.untried_rho
        k = min(n, len(self.tried))
        tried = self.tried[:k] & m.alive[:k, None]
        t = int(np.count_nonzero(tried))
        opened = int(np.count_nonzero(tried & (self.bump_t[:k] < 0)))
        return laplace(opened, t)

    def wall_prior(self) -> float:
        """rho's limit for a remembered wall while stuck: the chance that a wall known
        closed has opened, estimated from the agent's own re-tests as the share that
        moved it, (k + 1) / (t + 2) (Laplace's rule: 1/2 before any re-test)."""
        return laplace(self.wall_opened, self.wall_tests)

    def stuck(self, m: SensorimotorMap, n: int) -> bool:
        """The goal is represented but no link path leads from the agent's node to it
        over the links the outcome memory does not contradict (a link whose primitive
        bumped last time counts as gone): the agent's knowledge says the task is
        impossible, so all its remembered walls are doubted (``rho``'s limit
        :meth:`wall_prior` instead of ``stale_prior``; older bumps first). Cached per
        map version, goal node, terminal flags and bump count."""
        if self.goal_node < 0 or not 0 <= self._winner < n:
            return False
        absorbing = self._absorbing(m, n, closed=False)
        key = (m.version, self.goal_node, self._abs_count, self._bumps)
        if key != self._reach_key:
            self._reach_key = key
            self._reach = np.zeros(n, dtype=bool)
            Eb = kernels.contradicted(m.out, m.E, n, self.bump_t, self.succ)
            kernels.reaches_source(m.out, Eb, n, absorbing, m.alive, self.R >= GOAL_R,
                                   self._reach)
        return not self._reach[self._winner]

    def nodes_alive(self, m: SensorimotorMap, n: int) -> int:
        if self._alive_version != m.version:
            self._alive_version = m.version
            self._alive = int(m.alive[:n].sum())
        return self._alive

    def update(self, m: SensorimotorMap, skip: bool = False) -> np.ndarray | None:
        """Solve Eq. 4-5' on the current map; returns V[:n]. With ``skip`` (the next action
        is the random walk, its epsilon draw made ahead: :meth:`~tmgwr_agent.core.
        exploration.EpsilonGreedy.draw_ahead`) nothing is solved and None returned:
        ``solved`` is False and the goal node -1 (not known) until an update solves
        again, on the map of its own step, warm-started from the last solution (the
        outcome memory, :meth:`record`, is kept every step all the same)."""
        self._v0_fresh = False
        self.sweeps = 0
        self.solved = not skip
        if skip:
            self.goal_node = -1
            return None
        n = self._prepare(m)
        if self.goal_x is None or n == 0:
            self.V[:] = 0.0
            return self.V[:n]
        absorbing = self._absorbing(m, n)
        R = self.R
        if self.value_unknown:
            if self._route_due and self.goal_node >= 0:
                self._read_route(m, n)
                self._plan_episode(m, n)
            self._options(m, n)
            if self.broken:
                R, absorbing = self._goal_terminal(n, absorbing)
            if self.broken != self._broken_solved:
                self._broken_solved = self.broken
                self._epoch += 1            # the goal nodes' R and flags: off the log
        self.sweeps = self._solve(m, n, R, absorbing)          # Eq. 4-5'
        return self.V[:n]

    def _solve(self, m: SensorimotorMap, n: int, R: np.ndarray, absorbing: np.ndarray
               ) -> int:
        """Eq. 4-5' on this map: with ``vi_incremental`` by prioritized sweeping from the
        last solution (:meth:`_incremental`), and when that declines (a goal change, a new
        map size, a sweep over budget) by an ordered solve from V = 0 (:meth:`_ordered`);
        without it, or when that too outgrows its budget, by synchronous sweeps
        warm-started from the last V (:func:`kernels.value_iteration`). Returns the sweeps
        of a synchronous solve (0: solved without). Either way every node ends with
        ``|beta (T(i) - V(i))| <= vi_tol V(i)`` (``T``: the right-hand side of Eq. 4-5',
        :func:`kernels.node_target`), the synchronous solve's stopping rule."""
        rows, self._opt_rows = self._opt_rows, None
        if self.vi_incremental and (self._incremental(m, n, R, absorbing, rows)
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
        done = kernels.ordered_solve(
            m.out, m.E, R, self.V, n, self.gamma, self.vi_tol * (1.0 - self.gamma), V_FLOOR,
            absorbing, m.alive, self.U, self.rho, self.osucc, self.onb, self.ong, inc.first,
            inc.pred, np.arange(n, dtype=np.int64), n, ORDERED_BUDGET * n, inc.heap,
            inc.pos, inc.key)
        if done < 0:
            return self._declined("ordered_budget")
        self.solves["ordered"] = self.solves.get("ordered", 0) + 1
        return True

    def _incremental(self, m: SensorimotorMap, n: int, R: np.ndarray, absorbing: np.ndarray,
                     rows: np.ndarray | None) -> bool:
        """Prioritized sweeping from the last solution, seeded with the rows that changed
        since (:func:`kernels.changed_rows`, and :func:`kernels.changed_options` over the
        option rows recomputed since), at most ``INCREMENTAL_BUDGET`` updates a node. A
        change that may lower values (a link removed, an E, R or last option gone, a node
        made absorbing: ``lost``) first sets to 0 the nodes whose value rested on it
        (:func:`kernels.invalidate`; lowered by sweeping, two nodes that held each other
        up fall only geometrically) and solves them again in order of value
        (:func:`kernels.ordered_solve`). Declines (False) without a last solution of a
        map of this size and goal, or when the sweep outgrows its budget."""
        inc = self._inc
        if inc is None or inc.goal_node != self.goal_node:
            return self._declined("goal")
        if inc.n != n or inc.out0.shape != m.out[:n].shape or inc.rho0.shape != self.rho.shape:
            return self._declined("size")
        log = getattr(m, "log", None)
        logged = log.since(inc.log_pos) if log is not None and log is inc.log and \
            inc.epoch == self._epoch else None       # None: compare every row
        c, lost, relinked = kernels.changed_rows(
            m.out, m.E, R, absorbing, inc.out0, inc.E0, inc.R0, inc.abs0, n, inc.seeds,
            _NO_ROWS if logged is None else logged, -1 if logged is None else len(logged))
        inc.log, inc.log_pos, inc.epoch = log, (log.pos if log is not None else -1), self._epoch
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
        tol = self.vi_tol * (1.0 - self.gamma)
        args = (m.out, m.E, R, self.V, n, self.gamma, tol, V_FLOOR, absorbing, m.alive,
                self.U, self.rho, self.osucc, self.onb, self.ong, inc.first, inc.pred)
        if lost:
            self.solves["invalidated"] = self.solves.get("invalidated", 0) + 1
            k = kernels.invalidate(*args, inc.seeds, c, inc.found, inc.mark)
            seeds = np.concatenate((inc.seeds[:c], inc.found[:k]))
            done = kernels.ordered_solve(*args, seeds, len(seeds), INCREMENTAL_BUDGET * n,
                                         inc.heap, inc.pos, inc.key)
        else:
            done = kernels.prioritized_sweep(*args, inc.seeds, c, INCREMENTAL_BUDGET * n,
                                             inc.heap, inc.pos, inc.key)
        if done < 0:
            self.solves["incremental"] -= 1
            return self._declined("budget")
        return True

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
