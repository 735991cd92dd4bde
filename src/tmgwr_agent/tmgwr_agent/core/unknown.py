"""The value of the unknown (Eq. 5', our addition): a model of what the map does not know,
the plug-in of the motivation estimator (:mod:`tmgwr_agent.core.motivation`).

The estimator solves Eq. 4-5 on the map; what it asks of a model of the unknown is small
(:class:`ModelOfUnknown`, as nav2's planner plug-ins implement one interface): note what
each action did (:meth:`~OutcomeMemory.record`), follow a merge of nodes
(:meth:`~OutcomeMemory.merge`), plan an episode at its first solve
(:meth:`~OptionRules.plan_episode`), give the options of the rows that changed
(:meth:`~OptionRules.refresh_options`: ``U``, ``rho`` and the successor arrays ``osucc``,
``onb``, ``ong`` that the solve and Eq. 6 read), the cells that closed
(:meth:`~OptionRules.closed_cells`, absorbing in Eq. 5) and the goal without a lattice
(:meth:`~OptionRules.sensed_goal`), and save and load its memory
(:meth:`~OutcomeMemory.state_dict`, :meth:`~OutcomeMemory.load_state_dict`). The models,
by the estimator's ``unknown`` parameter, are listed once, in :data:`UNKNOWN`:

* ``none``: the paper's Eq. 5, no options (the outcome memory is still kept, so a
  checkpoint has the same keys whatever the model).
* ``grid``: the rules below in the sensor's own frame (:class:`~tmgwr_agent.core.frame.
  SensorFrame`). The assumptions it makes, every one of them: the primitives move along
  the sensor's axes, each by the same length ``L`` (the median link length) on every axis,
  wherever they are taken (a lattice, declared, not checked); hence the L1 distance over
  ``L`` counts the steps to the goal, an axis-aligned cell of side ``L`` holds one place
  (the node lookup of a predicted successor, the closed-cell test, a wall's run), and the
  primitives come in opposite pairs. True of the grid world sensed as (row, col) in one
  unit; false as soon as the axes are scaled differently, rotated or noisy.
* ``learnt`` (the default): the same rules in the frame of the agent's own forward model
  (:class:`~tmgwr_agent.core.frame.LearntFrame`), which checks the lattice from the
  forward model's spread and uses no rule that places a successor by the mean
  displacement for a primitive that fails it (:meth:`~OptionRules.sensed_goal`,
  :meth:`~OptionRules._unplaced_options`: an untried move there is valued from the
  successor a local forward model predicts, and the regions of earlier goals where
  episodes ended are terminal, :meth:`~OptionRules._terminal_regions`).

Today the two rule sets share their code, :class:`OutcomeMemory` and :class:`OptionRules`,
mixins of :class:`~tmgwr_agent.core.motivation.MotivationEstimator` that read the
estimator's state (the potentials ``V``, rewards ``R``, goal node, frame coordinates);
only the frame tells them apart.

**The value of the unknown** (``unknown``, our addition: ``learnt`` by default, ``grid``,
or ``none`` = the paper's Eq. 5). Every place, distance and length below (``w``,
``delta``, ``x_g``, ``L``) is measured in the frame of :mod:`tmgwr_agent.core.frame`:
the sensor's own axes for ``grid``, the learnt forward model's primitive steps for
``learnt`` (then ``L`` = 1). Every rule below that looks a place up assumes the
primitives make lattice steps; ``learnt`` checks it from the forward model's spread
(frame.py, "Is the forward model a lattice?") and where it fails uses none of them for
that primitive (:meth:`OptionRules._unplaced_options`,
:meth:`OptionRules.sensed_goal`).

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
  knew into it (held-out open fields: one block cell bumped from three sides). Without
  a lattice no cell is predicted, and the place the move led to (the node it reached,
  ``succ``) is what closed; it is terminal as a cell is. Without that, the node before
  a block kept its potential through the broken link until Eq. 1-2 wore its reliability
  down, and the agent bumped into the block again and again. The stuck test (below)
  ignores it: those links never bumped.
* The *re-tests* of an episode (``stale_rank``): a re-test costs a step and often a
  detour, so an episode re-tests at most ``B = stale_budget`` times ``d`` stale walls,
  rounded up (at least one; ``stale_budget`` 0.1, the share of steps the paper's agent
  spends on its random walk at Eq. 7's floor), ``d`` the steps of the known route from
  the episode's start, read off the potentials of Eq. 5 without options there
  (``V0(start) = gamma^d V0(g)``; before a route is known, the number of nodes). That
  is a tax on every episode, paid for a wall that may never open: with ``retest_rate``
  ``learnt`` (agent ``tmgwr:settle``) the agent learns how often its world changes and
  pays it in proportion. ``B = stale_budget d p``, ``p = 1 - (1 - q)^t`` the chance the
  world changed while the stale wall that has waited longest (``t`` episodes since its
  last bump; ``T = stale_horizon`` before the re-tests are ranked) waited, ``q`` the
  chance it changes in an episode by Laplace's rule over the episodes so far, ``(k + 1)
  / (e + 2)``, ``k`` of them in which it was seen to change (a wall known closed opened,
  or the known route broke), fixed as the episode begins; whole re-tests only, the
  fraction and what an episode left unused (up to one re-test) carrying over
  (:meth:`OptionRules.retest_budget`). In a world that stays, the re-tests thin out as
  ``q`` falls and a learnt route's episodes approach its length; a change seen raises
  ``q`` and the re-tests with it. A wall waits at most until ``p`` buys its test, so
  none waits for ever (with ``t = T`` a wall off the route, dear to test, waited behind
  the cheap ones beside it, and after a long unchanging spell some openings were never
  found). Fixed is the default: at the same ``stale_budget`` the thinned re-tests find
  an opening after an unchanging spell later. At the
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
  Without a lattice (:meth:`OptionRules._unplaced_options`: the wall's cell cannot be
  looked up, so its option is valued as unknown space) two facts of the agent's own
  history decide which walls it doubts. *The break dates the change*: the route broke at
  the bump of a move made before (``break_t``, the clock of the last such bump), so the
  world changed after the route was last walked; every wall bumped before that bump may
  have changed with it, however long before, and is doubted at the limit ``p``; only the
  walls bumped since (re-tested in vain while finding the way round) follow the clock
  above. Ranked by the age of their bumps instead, the walls bumped last in training,
  often those beside the route just learnt and so near the opening, were re-tested last.
  *Nothing is known beyond the known extent*: a wall whose cell (the successor the local
  forward model predicts) lies more than half a step outside the box that the map's
  places and the goal sensation span is not doubted: nothing was ever sensed there and
  the goal is not there, so a way through it would have to lead back in through space
  never sensed, which is the untried moves' to find (the lattice's wall runs stop at the
  known extent for the same reason, :func:`kernels.wall_exits`). Without it the maze's
  outer wall, valued as unknown space as near the goal as any inner wall, was re-tested
  cell by cell before the opening.
* *The free-space belief after a break* (the belief of a free-space planner, D* Lite's:
  unknown space is free, what bumped is closed; Koenig & Likhachev 2002). The L1 count
  ``h`` of an option's cell passes through every wall the agent knows of. While the route
  is known that matters little (an option pays only where it beats the route); once it
  broke (``broken``) the options lead the agent, and the L1 count ranked a cell of the
  world's outer wall as near the goal as a cell of the wall that holds the way round: after
  a block in the generated blocking family the agent tested the outer wall and swept the
  inner one back and forth. After a break, then, ``h`` is the fewest lattice moves from the
  option's cell to the goal's over the cells not believed closed
  (:func:`kernels.belief_steps`): believed closed are the cells that closed (above) and
  the cells remembered walls predict where no node lies; every other cell of the box the
  places and the goal span, and of the ring just beyond it, is believed open. The walls
  the agent knows lie in that ring at most; beyond it nothing was ever sensed and the goal
  is not there, so, as for the walls above, a way out there is the untried moves' to find
  as the box grows. A remembered wall, supposed open by its option, is one move more than
  its best neighbour; a cell with no believed way is worth nothing. An option whose cell is
  no nearer the goal by the belief than its own node's is dropped (not a re-test chosen
  at the episode's start: those are valued by their exits): it lies on no shortest
  believed way, and a free-space planner tries only the moves of its shortest believed
  path. When the node itself has no believed way (every way it knows of is closed), its
  options stay, valued by the belief. Only while the cells hold the places
  (:meth:`OptionRules.cells_hold`: every lattice primitive moves one cell along an axis,
  and its sensed moves hardly scatter: no sensor noise).
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
  policy: it climbs the potentials of Eq. 5 without options (:meth:`~tmgwr_agent.core.motivation.
  MotivationEstimator.exploit`), as
  Dyna-Q+'s probe reads its bonus-free twin.

Costs: the options are recomputed in full when the map's structure, the episode (when
stuck, a tick of the step clock), the stuck state or the re-test budget changes, else only
on the rows whose outcome memory changed; the reachability pass and the option loop are a
few linear passes over the map. Reading the route costs one solve of Eq. 5 without
options per episode, choosing its re-tests two breadth-first searches over the links and
the exits of every stale wall (it raises the mean step, not the median), its untried
chain one more (over the links and the untried moves).

The outcome memory (primitives tried per node, step and episode of the last bump and since
when a pair is known closed, where each move led, the step and episode clocks, the known
route, this episode's re-tests and untried chain, the forward model ``delta`` and its
spread, the nodes where the goal was sensed, the goal sensations set so far) is plain data:
:meth:`OutcomeMemory.state_dict` / :meth:`OutcomeMemory.load_state_dict`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from tmgwr_agent.core import kernels
from tmgwr_agent.core.frame import LearntFrame, SensorFrame
from tmgwr_agent.core.outcome import Outcome
from tmgwr_agent.core.sensorimotor_map import SensorimotorMap

#: No free-space belief (before a break, or where the cells do not hold the places:
#: ``OptionRules.cells_hold``): an empty table.
NO_BELIEF = (np.full((0, 0), -1, dtype=np.int64), np.zeros(2))

#: A node with R_i = sim(i, g) at least this represents the goal (a source of the
#: reachability test; never absorbing).
GOAL_R = 0.5


def laplace(k: int, t: int) -> float:
    """Laplace's rule of succession: the chance of a success after k in t trials,
    (k + 1) / (t + 2) (1/2 before any trial)."""
    return (k + 1.0) / (t + 2.0)


def union_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The sorted rows of either list (row numbers >= 0), as ``np.union1d`` gives them,
    by a mask instead of a sort (the lists can hold every row of a large map)."""
    mask = np.zeros(max(int(a.max(initial=-1)), int(b.max(initial=-1))) + 1, dtype=bool)
    mask[a] = True
    mask[b] = True
    return np.flatnonzero(mask)


def grown(a: np.ndarray, n: int, fill) -> np.ndarray:
    """``a`` with at least n rows (doubling), new rows set to ``fill``."""
    if len(a) >= n:
        return a
    b = np.full((max(n, 2 * len(a)),) + a.shape[1:], fill, dtype=a.dtype)
    b[: len(a)] = a
    return b


@dataclass(frozen=True)
class Model:
    """A model of the unknown: the frame its rules measure places in (frame.py; the
    estimator measures Eq. 10's width in it too) and whether it gives options (Eq. 5')."""

    name: str
    frame: type
    options: bool


#: The models of the unknown, by the estimator's ``unknown`` parameter (its choices).
UNKNOWN = {m.name: m for m in (Model("none", SensorFrame, False),
                               Model("grid", SensorFrame, True),
                               Model("learnt", LearntFrame, True))}


@runtime_checkable
class ModelOfUnknown(Protocol):
    """What the motivation estimator asks of a model of the unknown."""

    #: the options of Eq. 5' per (node, primitive), which the solve and Eq. 6 read
    U: np.ndarray
    rho: np.ndarray
    osucc: np.ndarray
    onb: np.ndarray
    ong: np.ndarray

    def record(self, node: int, winner: int, inserted: bool, outcome: Outcome,
               w: np.ndarray) -> None:
        """What the last learning step did."""

    def merge(self, merges) -> None:
        """The map merged node ``gone`` into ``keep`` for each pair of ``merges``."""

    def state_dict(self) -> dict: ...

    def load_state_dict(self, d: dict) -> None: ...

    def sensed_goal(self, m: SensorimotorMap, n: int) -> int:
        """Goal node and rewards without a lattice; returns n."""

    def closed_cells(self, n: int) -> np.ndarray:
        """The nodes of cells that closed, as a mask of n (absorbing in Eq. 5)."""

    def plan_episode(self, m: SensorimotorMap, n: int) -> None:
        """At an episode's first solve: what the episode may try."""

    def refresh_options(self, m: SensorimotorMap, n: int) -> None:
        """U, rho and the successor arrays of the rows that changed."""


class OutcomeMemory:
    """The outcome memory of Eq. 5' (a mixin of the estimator): what each (node, primitive)
    pair did, the episode and step clocks, the forward model ``delta`` and its spread."""

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
            self.carry = min(1.0, max(0.0, self._allowance - self.retests))
            self.changes += self._changed
            self._changed = False
            self.q_change = laplace(self.changes, self.episode - 1)
            self.waited = max(1.0, self.stale_horizon)
            self.retests = 0
            self.broken = False
            self.sel[:] = True                # until the route is read (plan_episode)
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
        if 0 <= node:
            self.forget_region(node, w)
        if 0 <= node and self.bump_t[node, outcome.action] >= 0:
            self.wall_tests += 1
            self.wall_opened += not outcome.bumped
            self.retests += not self._stuck
            self._changed |= not outcome.bumped        # a wall known closed opened
        a = outcome.action
        # a move made before bumps now: the known route broke, the cell it led to closed
        broke = bool(outcome.bumped and 0 <= node and self.bump_t[node, a] < 0
                     and self.succ[node, a] >= 0)
        self.broken |= broke
        self._changed |= broke
        if broke:
            self.break_t = self.clock
            self._close_cell(node, a, w)
        elif winner >= 0 and (inserted or not outcome.bumped):
            self._mark_closed(winner, -1)     # a node stood on (or a new one) is open
        if kernels.record_outcome(self.tried, self.bump_t, self.closed_t, self.bump_e,
                                  self.succ, self.delta, self.delta_sq, self.moves, w, node,
                                  winner, inserted, outcome.action, outcome.bumped,
                                  self.clock, self.episode):
            self._dirty.add(node)
            self._bumps += 1

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
            self._affine_fit = {}
            self._options_key = ()

    def _close_cell(self, node: int, a: int, w: np.ndarray) -> None:
        """Primitive a, a move made before from ``node``, bumps now: the cell it led to has
        closed, from every side (the node it led to, while that node is still at the
        predicted cell; a map loaded or rebuilt since may hold fewer nodes than ``succ``
        remembers). Without a lattice (no cell predicted), the node it led to."""
        j = self.succ[node, a]
        if j == node or j >= len(w):
            return
        if not self.lattice[a]:
            self._mark_closed(j, self.episode)
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
                "goals_told": np.array(self.goals_told, dtype=float).reshape(
                    len(self.goals_told), -1) if self.goals_told else np.zeros((0, 0)),
                "clock": int(self.clock), "delta": self.delta.copy(),
                "delta_sq": self.delta_sq.copy(),
                "moves": self.moves.copy(), "episode": int(self.episode),
                "route": float(self.route), "retests": int(self.retests),
                "wall_tests": int(self.wall_tests), "wall_opened": int(self.wall_opened),
                "changes": int(self.changes), "changed": int(self._changed),
                "q_change": float(self.q_change), "waited": float(self.waited),
                "carry": float(self.carry), "allowance": float(self._allowance),
                "break_t": int(self.break_t),
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
        # absent from older checkpoints: no earlier goal (no terminal region)
        self.goals_told = [np.array(x, dtype=float) for x in d.get("goals_told", ())]
        self._region = np.zeros(0, dtype=bool)
        self._region_x = np.zeros((0, 0))
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
        # absent from older checkpoints: no change seen yet
        self.changes = int(d.get("changes", 0))
        self._changed = bool(d.get("changed", 0))
        self.q_change = float(d.get("q_change", 0.5))
        self.waited = float(d.get("waited", max(1.0, self.stale_horizon)))
        self.carry = float(d.get("carry", 0.0))
        self._allowance = float(d.get("allowance", 0.0))
        self.break_t = int(d.get("break_t", -1))          # older checkpoints: no break
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
        self._affine_fit = {}             # fitted again on the loaded memory
        self._options_key = ()
        self._inc = None                  # the next solve is a full one

    def _size_forward_model(self, dim: int) -> None:
        """The forward model ``delta`` for sensations of ``dim`` values (zero: unknown)."""
        if self.delta.shape != (self.n_primitives, dim):
            self.delta = np.zeros((self.n_primitives, dim))
            self.delta_sq = np.zeros(self.n_primitives)

    def spread(self) -> np.ndarray:
        """Per primitive, the spread of its sensed displacements about their mean
        ``delta``: the root mean square of ``|d - delta_a|`` over its moves (0 before
        any)."""
        if not self.delta.size:
            return np.zeros(self.n_primitives)
        var = self.delta_sq - np.einsum("ij,ij->i", self.delta, self.delta)
        return np.sqrt(np.maximum(var, 0.0))


class OptionRules:
    """The rules of Eq. 5' (a mixin of the estimator, shared by ``grid`` and ``learnt``):
    this episode's re-tests and untried chain, the closed cells, the stuck test and the
    options U, rho of every (node, primitive) pair."""

    def sensed_goal(self, m: SensorimotorMap, n: int) -> int:
        """Goal node and rewards without a lattice (no primitive consistent, frame.py):
        the test "a node within half a step of the goal sensation" and Eq. 10's width in
        link lengths both measure steps by a lattice, so the goal is represented by the
        nodes where the agent sensed it: where the world said so (``goal_seen``, the
        outcome's goal sensing, since the goal was set), and the nodes whose weights lie in
        the goal region itself, within ``goal_tolerance`` of the goal sensation (no step
        beyond it: that needs a lattice). R = 1 there, 0 elsewhere, the goal node the one
        of them nearest the goal sensation (-1 before any: the options lead). Returns n.

        Why the region: a node's weights are a mean of the sensations it matched, and the
        world declares every sensation of the region a goal sensation, so a node whose
        weights lie in it is a place the agent has sensed the goal at, whatever the goal
        was then. Without it, a goal moved to a place the map already holds is not
        represented until an episode happens to end there again, and the agent, every
        potential 0 and no unknown left to lead it, random-walks until then."""
        seen = self.goal_seen[:n] & m.alive[:n]
        if self.goal_x is not None:
            d = m.w[:n] - self.goal_x
            seen |= m.alive[:n] & (np.einsum("ij,ij->i", d, d) <= self.goal_tolerance ** 2)
        self._terminal_regions(m, n)
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

    def _terminal_regions(self, m: SensorimotorMap, n: int) -> None:
        """The terminal regions without a lattice (``_region``, a mask of n; their centres
        ``_region_x``): the goal region (``goal_tolerance`` about a goal sensation) of each
        earlier goal the agent was told, once one of its nodes is flagged terminal (an
        episode ended there: :meth:`~tmgwr_agent.core.sensorimotor_map.SensorimotorMap.
        mark_terminal`). Every node in such a region is absorbing in Eq. 5 as a flagged one
        is (:meth:`terminal_of`), and an untried move predicted into one has no option
        (:meth:`_unplaced_options`). A region is forgotten when the agent walks on from a
        node in it (:meth:`forget_region`).

        Why the region: the world declares that a goal is a region, and the agent cannot
        tell a goal from another place where episodes end; an episode end is the region's,
        not the node's. The flags are the map's, one place each (its nodes within the
        place radius), and a region may hold several places the agent reached in different
        ways (MiniGrid: one per heading at the goal cell); without it a link into a place
        of an old goal that the episode ends had never ended at, or an untried move into
        one, ended episodes at the old goal. A goal sensation with no tolerance is a point,
        and its flags are the region."""
        x = self.goal_x
        if x is not None and not any(np.array_equal(x, c) for c in self.goals_told):
            self.goals_told.append(x.copy())
        region = np.zeros(n, dtype=bool)
        centres = []
        if self.goal_tolerance > 0.0:
            for c in self.goals_told:
                if x is not None and np.array_equal(c, x):
                    continue                        # the current goal: R >= 1/2 there
                d = m.w[:n] - c
                inside = m.alive[:n] & (np.einsum("ij,ij->i", d, d)
                                        <= self.goal_tolerance ** 2)
                if (inside & m.terminal[:n]).any():
                    region |= inside
                    centres.append(c)
        if len(region) != len(self._region) or not np.array_equal(region, self._region):
            self._epoch += 1                        # absorbing rows the log does not list
        self._region = region
        self._region_x = np.array(centres).reshape(len(centres), m.w.shape[1])

    def terminal_of(self, m: SensorimotorMap, n: int) -> np.ndarray:
        """The terminal nodes of Eq. 5: the map's flags and the terminal regions
        (:meth:`_terminal_regions`)."""
        if len(self._region) < n or not self._region[:n].any():
            return m.terminal
        return m.terminal[:n] | self._region[:n]

    def forget_region(self, i: int, w: np.ndarray) -> None:
        """The agent acted from node i within an episode: a terminal region holding i's
        weights does not end episodes (it would have ended this one), and is forgotten."""
        if not 0 <= i < len(self._region) or not self._region[i]:
            return
        d = self._region_x - w[i]
        near = np.einsum("ij,ij->i", d, d) <= self.goal_tolerance ** 2
        for c in self._region_x[near]:
            self.goals_told = [g for g in self.goals_told if not np.array_equal(g, c)]

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

    def retest_budget(self, n: int) -> int:
        """This episode's re-tests of stale walls, from ``d``, the steps of the known route
        from its start (the number of nodes before a route is known). ``retest_rate``
        fixed: ``stale_budget d`` rounded up, at least one. Learnt: ``stale_budget d p``,
        ``p = 1 - (1 - q_change)^waited`` the chance the world changed while the stale
        wall that has waited longest waited, plus what the last episode left unused
        (``carry``, at most one re-test), rounded down (the route read off the potentials
        is a float: 4 steps may read 3.9999999); the fraction carries over."""
        d = self.route or n
        if self.retest_rate == "fixed":
            return math.ceil(max(1.0, self.stale_budget * d))
        p = 1.0 - (1.0 - self.q_change) ** self.waited        # it changed since
        self._allowance = self.carry + self.stale_budget * d * p
        return math.floor(self._allowance + 1e-6)

    def budget_spent(self, n: int) -> bool:
        """This episode's re-tests of stale walls are used up (:meth:`retest_budget`), or
        ``stale_budget`` is 0, or the route broke."""
        return self.stale_budget <= 0.0 or self.broken or \
            self.retests >= self.retest_budget(n)

    def _read_route(self, m: SensorimotorMap, n: int) -> None:
        """At an episode's first solve: the steps ``d`` of the known route from where it
        starts, read off the potentials of Eq. 5 without options, ``V0(start) = gamma^d
        V0(g)``."""
        self._route_due = False
        V0 = self.exploit(m)
        v, vg = (V0[self._winner] if 0 <= self._winner < n else 0.0), V0[self.goal_node]
        if 0.0 < v <= vg:
            self.route = max(1.0, math.log(v / vg) / math.log(self.gamma))

    def plan_episode(self, m: SensorimotorMap, n: int) -> None:
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
        ri, ra, rs = ri[:c], ra[:c], rs[:c]
        if c:                               # the longest a stale wall has waited
            self.waited = float(np.max(self.episode - self.bump_e[ri, ra]))
        budget = self.retest_budget(n)
        cost = np.maximum(ds[ri] + 1 + dg[ri] - route, 1)   # steps lost if it stays shut
        key = (self.episode - self.bump_e[ri, ra]) * rs / cost
        order = np.lexsort((ds[ri], -key))[:budget]        # the most first, then nearest
        self.sel[:] = False
        self.sel[ri[order], ra[order]] = True

    def refresh_options(self, m: SensorimotorMap, n: int) -> None:
        """U and rho of every option (:func:`kernels.option_values`), recomputed in full
        when the goal, the frame, the node count, the stuck state, the stale clock
        (episodes; when stuck, ticks of the step clock) or the re-test budget changed;
        when only the map's structure changed (its version), on the rows whose options
        read what the map's change log lists (:meth:`_changed_option_rows`, the same
        values as a full pass on the same forward model); else only on the rows whose
        outcome memory :meth:`record` changed. Weights and the forward model drift a
        little between passes, and a row keeps the values of its last pass (a pow per
        pair and step would dominate the step time). Absorbing nodes keep theirs unused
        (Eq. 5' gives them no successor)."""
        stuck = self._stuck = self.stuck(m, n)
        key, clock, T, rho_max = self.options_key(m, n, stuck)
        F = self._F
        if key != self._options_key:
            rows = None
            if self._options_key[:1] != key[:1]:
                was = self._grid, self._origin
                self._grid, self._origin = kernels.cell_grid(F.w, m.alive, n, F.L)
                if self._options_key[1:] == key[1:] and key[0][1] == self._options_key[0][1]:
                    rows = self._changed_option_rows(m, n, F, *was, stuck)
            self._options_key = key
            self._belief = self.free_space_belief(m, n) if key[-1] else NO_BELIEF
            if rows is None:
                self.rho_new = self.open_prior(m, n)
                rows = np.arange(n)
            log = getattr(m, "log", None)
            self._opt_log, self._opt_L = log, F.L
            self._opt_pos = log.pos if log is not None else -1
            rows = union_rows(rows, np.fromiter(self._dirty, dtype=np.int64)) \
                if len(rows) < n and self._dirty else rows
        elif self._dirty:
            rows = np.fromiter(self._dirty, dtype=np.int64)
        else:
            return
        self._dirty.clear()
        self._opt_rows = rows if self._opt_rows is None or len(rows) == n else \
            union_rows(self._opt_rows, rows)
        bdist, borigin = self._belief
        kernels.option_values(F.w, m.out, m.alive, n, rows, F.goal, F.delta,
                              F.L, self.v_star, self.gamma, self.tried, self.bump_t,
                              self.closed_t, self.bump_e, self.succ, clock, T, self.episode,
                              self.stale_horizon, rho_max, self.rho_new, stuck, self._grid,
                              self._origin, self.V, self.sel, self.chain,
                              self.U, self.rho, self.osucc, self.onb, self.ong,
                              bdist, borigin, self.lattice)
        if not self.lattice.all():
            self._unplaced_options(m, rows[rows < n], np.flatnonzero(~self.lattice),
                                   rho_max if stuck else 0.0, clock, T)
        if self.bounds is not None:
            self.outside_options(m, n)

    #: How far (a share of a cell) a move may lie off one cell along an axis for the
    #: belief's cells to hold the places.
    CELL_SLACK = 0.25
    #: How far its sensed moves may scatter (a share of its length): sensing without
    #: noise (then the spread is 0), so that no place is misread. Under sensor noise a
    #: misread place puts its wall in the wrong cell and the wrong closed cell stays:
    #: with the belief some noisy trials looped between walls they had just tested.
    CELL_SCATTER = 0.05

    def cells_hold(self) -> bool:
        """Whether the free-space belief's cells are the places the moves join: every
        lattice primitive that moved moves one cell along an axis of the frame, within
        :attr:`CELL_SLACK` of a cell, and its sensed moves scatter within
        :attr:`CELL_SCATTER` of its length. Not so for a grid model on rotated or
        rescaled sensor axes (a move joins cells that are not neighbours), nor under
        sensor noise (rounded to cells, scattered places put the walls they bumped into
        in the wrong cells)."""
        F = self._F
        moved = self.lattice & (self.moves > 0)
        if F is None or not moved.any() or F.delta.shape[1] != 2:
            return False
        d = F.delta[moved] / F.L
        cell = np.floor(d + 0.5)
        return bool((np.abs(cell).sum(axis=1) == 1).all()
                    and (np.abs(d - cell) <= self.CELL_SLACK).all()
                    and LearntFrame.consistent(self.delta, self.moves, self.spread(),
                                               self.CELL_SCATTER)[moved].all())

    def free_space_belief(self, m: SensorimotorMap, n: int) -> tuple[np.ndarray, np.ndarray]:
        """The free-space belief's steps to the goal and its table's origin
        (:func:`kernels.belief_steps`; the module docstring), in the frame of the last
        refresh."""
        F = self._F
        return kernels.belief_steps(F.w, m.alive, n, self.tried, self.bump_t,
                                    self.closed_cells(n), F.delta, self.lattice, F.L, F.goal)

    def options_key(self, m: SensorimotorMap, n: int, stuck: bool
                    ) -> tuple[tuple, int, float, float]:
        """What the options of :meth:`refresh_options` depend on beyond the rows that
        changed, as a key (a change recomputes them), with the stuck clock and its T
        (:meth:`stuck_clock`) and rho's limit for a remembered wall."""
        nodes = self.nodes_alive(m, n)
        clock, T = self.stuck_clock(nodes)
        spent = not stuck and self.budget_spent(nodes)
        rho_max = self.wall_prior() if stuck else 0.0 if spent else self.stale_prior
        # a break re-values the moves off the lattice (_unplaced_options reads ``broken``)
        # and, where the cells hold the places, the others (the free-space belief); so
        # does each pair found shut since (a wall more in the belief; off the lattice its
        # place shuts others: _shut_places, when some primitive only turns; without one
        # such a refresh is in vain, and cheaper than finding the turns, which refits
        # their forward models, every step)
        off = self.broken and not self.lattice.all()
        belief = self.broken and self.cells_hold()
        shut = int(np.count_nonzero(self.bump_t[:n] >= self.break_t)) if off or belief else -1
        key = ((m.version, self.frame.version), clock if stuck else self.episode, n, stuck,
               spent, rho_max, off, shut, belief)
        return key, clock, T, rho_max

    def outside_options(self, m: SensorimotorMap, n: int) -> None:
        """No option whose predicted successor ``w_i + delta_a`` (the forward model's, in
        the map's units) lies outside the sensor's range (``bounds``: the bounds of the
        world's observation ``Box``, scaled as the sensation is): a move cannot end at a
        sensation the sensor never gives, so neither an untried move nor a remembered
        wall there can lead anywhere. Without it the agent, its route broken, counted
        every untried move into the world's outer edge as a way round as likely as any
        other untried move, and walked the edge testing them. Applied over every row
        (rows a refresh did not write were cleared by an earlier one), so whatever an
        incremental refresh wrote (:func:`kernels.untried_rho` writes ``rho`` on every
        untried pair) stays cleared. Only for the primitives that make lattice steps
        (frame.py): the forward model places no other's successor."""
        out = self._outside(m, n) & (self.rho[:n] > 0.0)
        if out.any():
            self.rho[:n][out] = 0.0
            self.U[:n][out] = 0.0
            self.osucc[:n][out] = -1

    def _changed_option_rows(self, m: SensorimotorMap, n: int, F, grid_was: np.ndarray,
                             origin_was: np.ndarray, stuck: bool) -> np.ndarray | None:
        """When only the map's structure changed since the options were last valued in
        full or by this method (a link made or deleted, a node inserted or removed), the
        rows whose options may read what changed (:func:`kernels.option_rows_changed`,
        from the rows the map's change log lists since then); None when a full refresh
        is due: the log cannot list them, the link length or the node lookup's extent
        moved. Sets ``rho_new``: a change writes it on every untried pair
        (:func:`kernels.untried_rho`; those rows join the ones the solve compares), or
        re-values their rows when it goes to or from 0."""
        log = getattr(m, "log", None)
        touched_rows = log.since(self._opt_pos) if log is not None and \
            log is self._opt_log else None
        if touched_rows is None or F.L != self._opt_L or grid_was.shape != self._grid.shape \
                or not np.array_equal(self._origin, origin_was):
            return None
        touched = np.zeros(n, dtype=bool)
        touched[touched_rows[touched_rows < n]] = True
        rho_new, self.rho_new = self.rho_new, self.open_prior(m, n)
        rows = np.empty(n, dtype=np.int64)
        untried = rho_new != self.rho_new
        if untried and rho_new > 0.0 and self.rho_new > 0.0:   # rho alone follows it
            c = kernels.untried_rho(m.alive, n, self.tried, self.chain, self.lattice,
                                    self.rho_new, self.rho, rows)
            self._opt_rows = rows[:c].copy() if self._opt_rows is None else \
                union_rows(self._opt_rows, rows[:c])            # for the solve to compare
            untried = False
        c = kernels.option_rows_changed(F.w, m.alive, n, touched, F.delta, F.L, grid_was,
                                        self._grid, self._origin, self.tried, self.bump_e,
                                        self.succ, self.sel, self.episode,
                                        self.stale_horizon, stuck, untried, rows)
        return rows[:c]

    def _unplaced_options(self, m: SensorimotorMap, rows: np.ndarray, prims: np.ndarray,
                          doubt: float = 0.0, clock: int = 0, T: float = 0.0) -> None:
        """The options of the primitives ``prims`` that make no lattice step (frame.py),
        on the nodes ``rows``. The mean forward model cannot place their successor, so no
        rule that looks a cell up applies (a wall's exits, the untried chain, a closed
        cell; a known node there only as below). A primitive never taken from i has an
        option into unknown space, ``rho = rho_new`` and ``U = V* gamma^h``, ``h = |x -
        x_g| / l``: ``x`` the successor the local forward model predicts
        (:meth:`_predicted`), ``l`` the root mean square step of the longest-moving
        primitive (a path of k moves covers about k l at most: the triangle inequality, in
        the sensation's own norm, so h does not overestimate the steps from a rightly
        predicted successor to the goal, the A* argument of the module docstring); ``h =
        0`` when x lies in the goal region (within ``goal_tolerance`` of x_g), and no
        option when it lies in a terminal region (:meth:`_terminal_regions`: the move is
        predicted to end the episode short of the goal, worth its R = 0). Before the
        primitive has moved anywhere, ``h = max(0, |w_i - x_g| / l - 1)``, the bound from
        i itself.

        *A known place is no unknown space*, in an episode whose known route broke
        (``broken``): when x is the place of a live node q (:meth:`_known_place`, within
        half a step of it) that the map links with i, either way (the agent has moved
        between the two), the untried move is worth what q is, ``S = V(q)`` (``osucc``), as
        an untried move between two known cells is on a lattice. The link is asked for
        because the local model predicts from the nearest node whose try of a moved, which
        may differ from i in what the move depends on (MiniGrid: a forward predicted from a
        node facing another way lands on a known place off its true direction); a place the
        map never linked with i is no evidence that the move reaches it, and the option
        stays unknown space. Without the rule an untried turn to a heading the agent knew
        was valued as unknown space, ``l`` (the turn's longer step) making it look nearer
        the goal than the known route, and the agent turned through the headings of the
        cells on its way (after a block, on its way round). In a training episode the move
        stays unknown space, as the goal stays a state the agent may step off (module
        docstring, *The goal when the route broke*): there the look round pays, the map
        learning the moves between the places it knows. Valued as q while training, an
        untried turn was worth what q's own untried moves promised with their odds ``rho``
        counted once more for the turn (``rho^2`` for a way into unknown space through a
        known place): it lost to the known route, the agent kept the first route it found,
        and a registered MiniGrid id took more episodes to learn a shortest one.

        *A turn needs no link*: a primitive that only turns the agent where it stands
        (:meth:`_turns`: it never bumped, and repeated it comes back to where it started,
        as the affine forward model predicts it) is stopped by no wall and does not leave
        the location, so the known place it is predicted onto is the place it reaches,
        whether or not the map links the two (the agent met that heading there coming
        another way). Without it an untried turn at a cell whose headings the agent had
        met by different ways was unknown space, and after a block the agent turned a
        full circle through the headings it knew there before it walked on.

        *One move on*, in an episode whose known route broke: ``h`` is at least ``1 +
        min_b h(x_b)`` (:meth:`_one_move_on`), ``x_b`` the successor of primitive b from x
        as the local forward model predicts it. Every way from x to the goal (x outside
        the goal region) starts with one of the primitives, so this bounds the moves from
        a rightly predicted x from below as the distance bound does, and the larger of the
        two is the bound kept (Eq. 5', the A* argument of the module docstring). The
        distance bound cannot tell a move that only changes what the next move does from
        one that brings the goal nearer: a move whose successor lies no nearer the goal
        than its node (MiniGrid's turn: the goal sensation has no heading, so every
        heading at a place is as far from it) was worth as much as the node's own bound,
        whichever way it turned; after a block the agent turned through the headings of
        the places on its way round, one turn after another, where a single turn faced
        the move that leads on. One move on, a move whose successor has a primitive that
        brings the goal nearer is worth more than one whose successor has none. In a
        training episode the distance bound stands, as the known place above does: there
        the look round pays.

        *A wall that leads only back*, while stuck in an episode whose known route broke:
        a remembered wall has no option when every way on from the place it would lead
        to, over places the map does not know, ends at places the agent reaches already
        (:meth:`_leads_on`, as the affine forward model predicts the moves). Opening it
        would lead nowhere the agent cannot walk to now, so it is no way round, whatever
        the chance it opened: on a lattice a wall's option is valued by its known exits
        for the same reason (module docstring, ``S``). Without it the agent bumped a pillar
        inside the region it was stuck in from each of its sides before it walked on to
        the walls between it and the goal. Only where the affine model fits: the nearest
        node's prediction, off the true direction, closed walls that led on.

        *A place shut from one side is shut from the others*, in an episode whose known
        route broke: a place a move bumped into since the break (``break_t``) is shut
        (:meth:`_shut_places`), and so is every place that a primitive which only turns
        the agent (:meth:`_turns`: it never bumped, and repeated it comes back to where
        it started, as the affine forward model predicts it) leads to from it, again and
        again. Such a move is stopped by no wall and goes nowhere, so the places it joins
        are one location, and the closing of a cell is a closing from every side (*A cell
        that closed*, module docstring). An untried move or a wall bumped before the break
        whose successor lies within half the shortest step of a shut place is doubted as
        that bump is (the clock above from the bump, ``rho`` 0 while not stuck), and no
        way on leads through a shut place in the bound one move on. MiniGrid's
        sensation holds the heading, so the places of one cell faced four ways lie far
        apart: without the rule the agent, having tested a wall's cell from the side,
        bumped into it again from below once it had passed the opening, and turned
        towards such a cell (a turn whose forward led into it looked a move nearer the
        goal) before it walked on. Only where the affine fit holds (the bumping primitive's
        and those that never bumped): the nearest node's prediction may lie off the true
        direction.

        *Steps of the moves that lead on*, in an episode whose known route broke: ``l``
        in these bounds is the most one of the agent's moves has brought it nearer the
        goal sensation, over the moves its outcome memory holds (:meth:`_nearer`; at
        most the longest step, by the triangle inequality). The bound counts how many
        moves the distance takes, and a move covers of it only what it brings the goal
        nearer, not its whole step: a move that changes only what the next move does
        (MiniGrid's turn, the goal sensation without a heading) has a long step and
        brings the goal no nearer, and with ``l`` its step every place after a block
        looked nearer the goal than it is, so every untried move near the
        agent beat the known way round and the agent looked into each. Measured on the
        agent's own moves, as the forward model is; in a training episode the step
        stands, as the bounds above do.

        Why the local model: the mean displacement of a primitive whose effect depends on
        where it is taken (MiniGrid's forward, by the heading) predicts nothing, and with
        the bound from i every untried move within a few steps of the goal looked as good
        as one into the goal, and one into an old goal's cell (no node of the region there
        yet) as good as any: the agent walked off its route into the old goal.

        While stuck (:meth:`stuck`; ``doubt`` = the wall prior, ``clock`` and ``T`` of
        :meth:`stuck_clock`), a remembered wall is doubted as on a lattice
        (:func:`kernels.option_values`): ``rho = doubt (1 - exp(-tau / (T + e)))``, ``tau``
        the steps since its bump, ``e`` those it had been known closed before it, and its
        successor is valued as an untried move's. Without it a remembered wall had no
        option without a lattice: a block that left only a way through a wall that had
        opened was passed only when a random walk, every potential 0, hit the opening.
        A wall bumped before the route broke (``break_t``) is doubted at the limit, and a
        wall whose cell lies beyond the known extent (:meth:`_known_extent`, half a step
        out) not at all: the module docstring, *Stuck*, says why.

        A primitive whose last try from i moved it to ``j = succ[i, a]`` while the map
        has since deleted that link (it aged out: :mod:`~tmgwr_agent.core.
        sensorimotor_map`) has an option into j with ``rho = 1``, as on a lattice
        (:func:`kernels.option_values`): the deletion forgot a move nothing contradicted,
        and where the map cannot place a successor the outcome memory is the only place
        that knows it. Without it a route whose links aged out while the agent did not
        use them (a goal moved to a part of the map it left) is neither known nor
        unknown, and the agent random-walks round it. j must be alive and within one
        move's reach of i (twice ``l``): a slot freed and reused elsewhere is not."""
        r, a = rows[:, None], prims[None, :]
        live = m.alive[rows][:, None]
        untried = ~self.tried[r, a] & live
        bump = self.bump_t[r, a]
        wall = live & self.tried[r, a] & (bump >= 0) & (bump < clock) & (doubt > 0.0) \
            & (T > 0.0)
        known_for = np.where(self.closed_t[r, a] >= 0, bump - self.closed_t[r, a], 0)
        fresh = 1.0 - np.exp(-(clock - bump) / (T + known_for))
        rho_w = np.where(wall, doubt * np.where(bump < self.break_t, 1.0, fresh), 0.0)
        unknown = untried | wall
        step = math.sqrt(max(float(self.delta_sq.max()), 0.0))
        nearer = self._nearer(m, step) if self.broken else step
        gap = np.sqrt(np.einsum("ij,ij->i", m.w[rows] - self.goal_x, m.w[rows] - self.goal_x))
        h = np.maximum(gap / nearer - 1.0, 0.0) if step > 0.0 else np.zeros(len(rows))
        h = np.repeat(h[:, None], len(prims), axis=1)
        rho_u = np.where(wall, rho_w, self.rho_new)
        if wall.any():
            lo, hi = self._known_extent(m)
        placed = np.full((len(rows), len(prims)), -1, dtype=np.int64)
        reach = shut = turns = None
        for c, p in enumerate(prims):
            q = np.flatnonzero(unknown[:, c])
            x = self._predicted(m, rows[q], int(p)) if len(q) and step > 0.0 else None
            if x is None:
                continue
            h[q, c] = self._steps_bound(x, nearer)
            if self.broken:
                if shut is None:
                    shut = self._shut_places(m)
                h[q, c] = np.where(h[q, c] > 0.0,
                                   np.maximum(h[q, c], self._one_move_on(m, x, nearer, shut)),
                                   0.0)
            if len(self._region_x):
                d = x[:, None, :] - self._region_x[None, :, :]
                ends = (np.einsum("ijk,ijk->ij", d, d) <= self.goal_tolerance ** 2).any(axis=1)
                rho_u[q[ends], c] = 0.0
            if wall[q, c].any():
                beyond = ((x < lo - 0.5 * step) | (x > hi + 0.5 * step)).any(axis=1)
                rho_u[q[beyond & wall[q, c]], c] = 0.0
            t = ~wall[q, c]
            if t.any() and self.broken:
                if turns is None:
                    turns = self._turns(m)
                placed[q[t], c] = self._known_place(m, x[t], rows[q[t]],
                                                    need_link=int(p) not in turns)
            s = wall[q, c]
            if s.any() and self._stuck and self.broken:
                if reach is None:
                    reach = self._reached(m)
                rho_u[q[s][~self._leads_on(m, x[s], reach, step)], c] = 0.0
            if self.broken:
                tc = self._shut_since(m, x, *shut)
                hit = (tc >= 0) & (tc > np.where(wall[q, c], bump[q, c], -1))
                if hit.any():
                    fresh_c = 1.0 - np.exp(-(clock - tc[hit]) / T) if T > 0.0 else 0.0
                    rho_u[q[hit], c] = np.minimum(rho_u[q[hit], c], doubt * fresh_c)
        j = self.succ[r, a]
        jc = np.maximum(j, 0)
        lost = (live & self.tried[r, a] & (self.bump_t[r, a] < 0) & (j >= 0) & (j != r)
                & m.alive[jc] & ~(m.out[rows][:, None, :] == j[..., None]).any(axis=-1))
        if lost.any():
            d = m.w[jc] - m.w[rows][:, None, :]
            lost &= np.einsum("ijk,ijk->ij", d, d) <= (2.0 * step) ** 2
        self.rho[r, a] = np.where(unknown, rho_u, np.where(lost, 1.0, 0.0))
        self.U[r, a] = np.where(unknown & (rho_u > 0.0) & (placed < 0),
                                self.v_star * self.gamma ** h, 0.0)
        self.osucc[r, a] = np.where(lost, j, placed)

    def _nearer(self, m: SensorimotorMap, step: float) -> float:
        """The most one move of the agent's has brought it nearer the goal sensation:
        ``max |w_k - x_g| - |w_j - x_g|`` over the moves its outcome memory holds (k's
        last try of a primitive moved it to ``j = succ[k, a]``, both alive), at most
        ``step`` (the triangle inequality); ``step`` when no move came nearer:
        :meth:`_unplaced_options`, *Steps of the moves that lead on*."""
        k, j = self._moves(m)
        if not len(k):
            return step
        n = m.n
        dist = np.sqrt(np.einsum("ij,ij->i", m.w[:n] - self.goal_x, m.w[:n] - self.goal_x))
        most = float((dist[k] - dist[j]).max())
        return min(most, step) if most > 0.0 else step

    def _steps_bound(self, x: np.ndarray, step: float) -> np.ndarray:
        """The fewest moves from each sensation ``x[k]`` to the goal as the triangle
        inequality bounds them, ``|x - x_g| / l`` (``l = step``: the longest-moving
        primitive's root mean square step, or after a break the most a move came nearer
        the goal, :meth:`_nearer`), 0 in the goal region (within ``goal_tolerance`` of
        x_g): :meth:`_unplaced_options`."""
        dx = x - self.goal_x
        gx = np.sqrt(np.einsum("ij,ij->i", dx, dx))
        return np.where(gx <= self.goal_tolerance, 0.0, gx / step)

    def _one_move_on(self, m: SensorimotorMap, x: np.ndarray, step: float,
                     shut: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """The same bound one move further on: ``1 + min_b`` :meth:`_steps_bound` of
        ``x_b``, the successor of primitive b from ``x`` as the local forward model
        predicts it (:meth:`_predicted` from those places), over the ``x_b`` that are no
        place found shut (``shut``, :meth:`_shut_places`: no way on leads through one);
        ``-inf`` (no bound) while some primitive has not moved from any live node."""
        best = np.full(len(x), np.inf)
        for b in range(self.n_primitives):
            y = self._predicted(m, None, b, at=x)
            if y is None:
                return np.full(len(x), -np.inf)
            bound = self._steps_bound(y, step)
            if shut is not None:
                bound = np.where(self._shut_since(m, y, *shut) >= 0, np.inf, bound)
            best = np.minimum(best, bound)
        return 1.0 + best

    def _known_place(self, m: SensorimotorMap, x: np.ndarray, rows: np.ndarray,
                     need_link: bool = True) -> np.ndarray:
        """For each predicted successor ``x[k]`` of a move from node ``rows[k]``: the live
        node nearest it when within half the shortest step of the forward model (the
        places a move joins lie a step apart, so half a step is the line between two) and
        the map links it with ``rows[k]`` either way (asked only when ``need_link``);
        else -1 (also for ``rows[k]`` itself). The nearest node by
        :func:`kernels.nearest_weight`, a scan per successor (no successors x nodes
        matrix: a full refresh asks for every row)."""
        n = m.n
        out = np.full(len(x), -1, dtype=np.int64)
        s2 = self._shortest_step2()
        if not len(x) or not s2 or not m.alive[:n].any():
            return out
        half2 = 0.25 * s2
        for k in range(len(x)):
            q = kernels.nearest_weight(m.w, m.alive, n, x[k])
            d = x[k] - m.w[q]
            if q != rows[k] and d @ d < half2:
                out[k] = q
        if not need_link:
            return out
        q = np.maximum(out, 0)
        linked = (m.out[rows] == q[:, None]).any(axis=1) | \
            (m.out[q] == rows[:, None]).any(axis=1)
        out[~linked] = -1
        return out

    def _reached(self, m: SensorimotorMap) -> np.ndarray:
        """The live nodes the agent's node reaches over the links the outcome memory does
        not contradict (a mask of the map's rows)."""
        n = m.n
        Eb = kernels.contradicted(m.out, m.E, n, self.bump_t, self.succ)
        ds = np.empty(n, dtype=np.int64)
        kernels.link_steps(m.out, Eb, n, m.alive, self._absorbing(m, n, closed=False),
                           self._winner, False, ds)
        return ds >= 0

    def _leads_on(self, m: SensorimotorMap, x: np.ndarray, reach: np.ndarray,
                  step: float) -> np.ndarray:
        """For each place ``x[k]``: some way on from it, over places the map does not
        know, as the forward model predicts the moves (:meth:`_predicted`), leads to a
        known place the agent does not reach (``reach``, :meth:`_reached`), or further
        than twice ``step`` from x (the way leaves the place's surroundings: unknown
        space, valued by its bound); True for every place while some primitive has no
        affine model (:meth:`_affine`). A place is known when a live node lies within
        half the shortest step of it (as in :meth:`_known_place`). Breadth-first over the
        predicted places, each met once: :meth:`_unplaced_options`, *A wall that leads
        only back*."""
        n = m.n
        s2 = self._shortest_step2()
        out = np.ones(len(x), dtype=bool)
        if not s2 or not len(x) or not m.alive[:n].any():
            return out
        if any(self._affine(m, b) is None for b in range(self.n_primitives)):
            return out
        half2 = 0.25 * s2
        r2 = (2.0 * step) ** 2
        live = np.flatnonzero(m.alive[:n])
        wl = m.w[live]
        wl2 = np.einsum("ij,ij->i", wl, wl)
        for k in range(len(x)):
            seen, frontier, found = x[k][None, :], x[k][None, :], False
            while len(frontier):
                d2 = (np.einsum("ij,ij->i", frontier, frontier)[:, None]
                      - 2.0 * frontier @ wl.T + wl2[None, :])
                q = np.argmin(d2, axis=1)
                known = d2[np.arange(len(frontier)), q] < half2
                far = np.einsum("ij,ij->i", frontier - x[k], frontier - x[k]) > r2
                if (known & ~reach[live[q]]).any() or (far & ~known).any():
                    found = True
                    break
                frontier = frontier[~known]
                nxt = []
                for b in range(self.n_primitives):
                    z = self._predicted(m, None, b, at=frontier) if len(frontier) else None
                    if z is None and len(frontier):
                        found = True
                        break
                    if z is not None:
                        nxt.append(z)
                if found or not nxt:
                    break
                z = np.vstack(nxt)
                new = []
                for y in z:                       # places not met yet, once each
                    dv = seen - y
                    if (np.einsum("ij,ij->i", dv, dv) >= half2).all():
                        seen = np.vstack([seen, y])
                        new.append(y)
                frontier = np.array(new).reshape(len(new), x.shape[1])
            out[k] = found
        return out

    def _turns(self, m: SensorimotorMap) -> list[int]:
        """The primitives that only turn the agent where it stands, as its own outcome
        memory and forward model tell: tried from some live node, never bumped (no live
        pair whose last try of it bumped), and its affine model (:meth:`_affine`),
        repeated, brings every live node's place back within half the shortest step of
        itself within ``2 P`` moves (P primitives); none while some such primitive has no
        affine model. A move through space never comes back by repeating itself."""
        n = m.n
        s2 = self._shortest_step2()
        live = m.alive[:n]
        if not s2 or not live.any():
            return []
        half2 = 0.25 * s2
        w = m.w[:n][live]
        out = []
        for b in range(self.n_primitives):
            tried = self.tried[:n, b] & live
            if not tried.any() or (tried & (self.bump_t[:n, b] >= 0)).any():
                continue
            B = self._affine(m, b)
            if B is None:
                return []
            x = w
            for _ in range(2 * self.n_primitives):
                x = x + x @ B[:-1] + B[-1]
                d = x - w
                if (np.einsum("ij,ij->i", d, d) < half2).all():
                    out.append(b)
                    break
        return out

    def _shut_places(self, m: SensorimotorMap) -> tuple[np.ndarray, np.ndarray]:
        """The places found shut since the route broke, and the clock of each: the
        successor (:meth:`_predicted`) of every pair whose last try bumped at or after
        ``break_t``, and every place a primitive that only turns the agent
        (:meth:`_turns`) leads to from one of them, again and again (the places of one
        location), each met once (within half the shortest step); only over primitives
        with an affine model (:meth:`_affine`), none without a turn:
        :meth:`_unplaced_options`, *A place shut from one side*."""
        n = m.n
        s2 = self._shortest_step2()
        none = np.zeros((0, m.w.shape[1])), np.zeros(0, dtype=np.int64)
        if self.break_t < 0 or not s2 or not m.alive[:n].any():
            return none
        free = self._turns(m)
        if not free:
            return none
        half2 = 0.25 * s2
        xs, ts = [], []
        for a in range(self.n_primitives):
            k = np.flatnonzero(m.alive[:n] & self.tried[:n, a]
                               & (self.bump_t[:n, a] >= self.break_t))
            x = self._predicted(m, k, a) if len(k) and self._affine(m, a) is not None \
                else None
            if x is not None:
                xs.append(x)
                ts.append(self.bump_t[k, a])
        if not xs:
            return none
        seen, when = np.vstack(xs), np.concatenate(ts)
        frontier, ft = seen, when
        for _ in range(4 * len(free)):
            nxt, nt = [], []
            for b in free:
                z = self._predicted(m, None, b, at=frontier)
                for y, t in zip(z, ft):
                    dv = seen - y
                    d2 = np.einsum("ij,ij->i", dv, dv)
                    if (d2 >= half2).all():
                        seen, when = np.vstack([seen, y]), np.append(when, t)
                        nxt.append(y)
                        nt.append(t)
                    else:
                        near = d2 < half2
                        when[near] = np.maximum(when[near], t)
            if not nxt:
                break
            frontier, ft = np.array(nxt), np.array(nt)
        return seen, when

    def _shut_since(self, m: SensorimotorMap, x: np.ndarray, seen: np.ndarray,
                    when: np.ndarray) -> np.ndarray:
        """For each place ``x[k]``: the clock at which a place within half the shortest
        step of it was found shut (:meth:`_shut_places`, the latest), else -1."""
        out = np.full(len(x), -1, dtype=np.int64)
        s2 = self._shortest_step2()
        if not len(seen) or not len(x) or not s2:
            return out
        half2 = 0.25 * s2
        d2 = (np.einsum("ij,ij->i", x, x)[:, None] - 2.0 * x @ seen.T
              + np.einsum("ij,ij->i", seen, seen)[None, :])
        near = d2 < half2
        return np.where(near.any(axis=1), np.where(near, when[None, :], -1).max(axis=1), -1)

    def _shortest_step2(self) -> float:
        """The squared length of the shortest step the primitives have sensed (the least
        positive ``delta_sq``), 0 before any move: half of it, the line between two places
        a step apart, is what tells a known place or a shut one (:meth:`_known_place`)."""
        moved = self.delta_sq[self.delta_sq > 0.0]
        return float(moved.min()) if len(moved) else 0.0

    def _known_extent(self, m: SensorimotorMap) -> tuple[np.ndarray, np.ndarray]:
        """The box the live nodes' places and the goal sensation span (lower, upper)."""
        w = m.w[:m.n][m.alive[:m.n]]
        pts = np.vstack([w, self.goal_x[None, :]]) if len(w) else self.goal_x[None, :]
        return pts.min(axis=0), pts.max(axis=0)

    def _outside(self, m: SensorimotorMap, n: int) -> np.ndarray:
        """The (node, primitive) pairs of rows ``[0, n)`` whose predicted successor lies
        outside the sensor's range, for the primitives that make lattice steps (n x P)."""
        if self.bounds is None or not self.delta.size or not self.lattice.any():
            return np.zeros((n, self.n_primitives), dtype=bool)
        lo, hi = self.bounds
        x = m.w[:n, None, :] + self.delta[None, :, :]
        return ((x < lo) | (x > hi)).any(axis=-1) & self.lattice

    def _moves(self, m: SensorimotorMap, a: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The moves the outcome memory holds, as pairs of nodes (k, j) in the order of k:
        k's last try of primitive ``a`` (of any primitive when None) moved it to another
        live node, j = ``succ[k, a]``; k live too."""
        n = m.n
        prims = slice(None) if a is None else slice(a, a + 1)
        k, b = np.nonzero(m.alive[:n, None] & self.tried[:n, prims]
                          & (self.bump_t[:n, prims] < 0))
        j = self.succ[k, b if a is None else a]
        ok = (j >= 0) & (j != k) & (j < n)
        k, j = k[ok], j[ok]
        live = m.alive[j]
        return k[live], j[live]

    def _predicted(self, m: SensorimotorMap, rows: np.ndarray | None, a: int,
                   at: np.ndarray | None = None) -> np.ndarray | None:
        """The successors of primitive a from the nodes ``rows`` as the local forward model
        predicts them: ``w_i + (w_j - w_k)``, k the node nearest i (in weights) whose last
        try of a moved it, to j = ``succ[k, a]`` (a move does from a place what it did from
        the place most like it); from the places ``at`` instead of the nodes' weights when
        given; None before a has moved from any live node.

        *After a break* (``broken``) the affine forward model of a instead, when its fit
        holds (:meth:`_affine`): ``w + [w, 1] B``. A move whose displacement depends on
        where it is taken through the sensation itself (MiniGrid's forward moves along the
        heading the sensation holds, its turns rotate it) is predicted from anywhere by
        one fit over all the agent's moves, where the nearest node whose try of a moved
        may face another way (at a new place, the nodes facing the same way are often
        further off): its forward was then predicted off its true direction, a turn
        looked like the way on, and the agent spun at the places it came to after a
        block. The fit is checked (the residuals within a quarter step), as the lattice
        is (frame.py), and a world whose moves it does not fit keeps the nearest node's
        prediction. In a training episode the nearest node's prediction stands, as the
        bounds of :meth:`_unplaced_options` do."""
        k, j = self._moves(m, a)
        if not len(k):
            return None
        wr, wk = (m.w[rows] if at is None else at), m.w[k]
        B = self._affine(m, a) if self.broken else None
        if B is not None:
            return wr + wr @ B[:-1] + B[-1]
        d2 = (np.einsum("ij,ij->i", wr, wr)[:, None] - 2.0 * wr @ wk.T
              + np.einsum("ij,ij->i", wk, wk)[None, :])
        near = np.argmin(d2, axis=1)
        return wr + (m.w[j[near]] - wk[near])

    def _affine(self, m: SensorimotorMap, a: int) -> np.ndarray | None:
        """The affine forward model of primitive a: ``B`` of the least-squares fit
        ``w_j - w_k = [w_k, 1] B`` over its moves (k, j) (:meth:`_moves`), when it has
        more moves than ``B`` has rows and the root mean square of the fit's residuals is
        within a quarter of the shortest step (well inside the half step that tells two
        places apart, :meth:`_known_place`); else None. Fitted once per step clock and
        map version: :meth:`_predicted`, *After a break*."""
        key = (m.version, self.clock)
        kept = self._affine_fit.get(a)
        if kept is not None and kept[0] == key:
            return kept[1]
        k, j = self._moves(m, a)
        s2 = self._shortest_step2()
        B = None
        if s2 and len(k) > m.w.shape[1] + 1:
            X = np.hstack([m.w[k], np.ones((len(k), 1))])
            Y = m.w[j] - m.w[k]
            fit = np.linalg.lstsq(X, Y, rcond=None)[0]
            miss = X @ fit - Y
            if math.sqrt(float(np.einsum("ij,ij->i", miss, miss).mean())) \
                    <= 0.25 * math.sqrt(s2):
                B = fit
        self._affine_fit[a] = (key, B)
        return B

    def open_prior(self, m: SensorimotorMap, n: int) -> float:
        """rho of a primitive never tried (Eq. 5'): ``untried_rho``, or when that is
        negative the chance that a move opens, estimated from the agent's own outcomes as
        the share of its tried pairs (of live nodes) whose last try moved it, (k + 1) /
        (t + 2) (Laplace's rule: 1/2 before any try). A pair never tried whose move the
        sensor's range closes (:meth:`outside_options`) counts as a tried pair that did
        not move: its outcome is known without the step, and leaving it out would count
        only the moves inside the arena, which open more often than moves in general."""
        if self.untried_rho >= 0.0:
            return self.untried_rho
        k = min(n, len(self.tried))
        tried = self.tried[:k] & m.alive[:k, None]
        t = int(np.count_nonzero(tried))
        opened = int(np.count_nonzero(tried & (self.bump_t[:k] < 0)))
        if self.bounds is not None:
            t += int(np.count_nonzero(self._outside(m, k) & ~tried & m.alive[:k, None]))
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
        :meth:`wall_prior` instead of ``stale_prior``; older bumps first). Searched from
        the agent's node (:func:`kernels.reaches_source_from`), what it learns kept per
        map version, goal node, terminal flags (and regions: ``_epoch``) and bump count,
        which fix the links and the outcome memory it reads (the terminal flags and the
        goal nodes as they were when that key changed)."""
        if self.goal_node < 0 or not 0 <= self._winner < n:
            return False
        absorbing = self._absorbing(m, n, closed=False)
        key = self._reach_key_for(m, self.goal_node)
        if key != self._reach_key:
            self._reach_key = key
            self._reach_abs, self._reach_src = absorbing.copy(), self.R >= GOAL_R
            if len(self._reach) < n:
                self._reach, self._reach_seen = (np.zeros(2 * n, np.int64) for _ in "ks")
                self._reach_stack = np.empty(2 * n, np.int64)
            self._reach_stamp += 1
        known = self.stuck_known(m, n, self.goal_node)
        if known is not None:
            return known
        self._reach_search += 1
        return not kernels.reaches_source_from(
            m.out, m.E, n, self._reach_abs, m.alive, self._reach_src, self.bump_t, self.succ,
            self.V, self._winner, self._reach, self._reach_stamp, self._reach_seen,
            self._reach_search, self._reach_stack)

    def _reach_key_for(self, m: SensorimotorMap, g: int) -> tuple:
        """What :meth:`stuck`'s search reads, for goal node ``g``: the map version, the
        goal node, the terminal flags (and regions: ``_epoch``) and the bump count."""
        return (m.version, g, self._abs_count, self._epoch, self._bumps)

    def stuck_known(self, m: SensorimotorMap, n: int, g: int) -> bool | None:
        """What :meth:`stuck` would answer for the goal node ``g`` when it needs no
        search (its key held and the agent's node was searched from, or no goal or
        node); None when it would search or start a new key."""
        if g < 0 or not 0 <= self._winner < n:
            return False
        if self._reach_key != self._reach_key_for(m, g):
            return None
        known = self._reach[self._winner]
        if known == self._reach_stamp or known == -self._reach_stamp:
            return bool(known < 0)
        return None

    def nodes_alive(self, m: SensorimotorMap, n: int) -> int:
        if self._alive_version != m.version:
            self._alive_version = m.version
            self._alive = int(m.alive[:n].sum())
        return self._alive
