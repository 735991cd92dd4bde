"""``ros2 run tmgwr_agent motivation_estimator``: Eq. 4-5 on this step's map.

Per step (lockstep): ``SensorimotorState`` in (it carries this step's change of the map),
applied to this node's replica of the map (:mod:`tmgwr_agent.map_replica`),
:meth:`MotivationEstimator.update` on that map, ``MotivationField`` out (the winner's
outgoing links and the potentials V of their targets, what Eq. 6 ranks); the potentials of
every node go out latched on ``/potentials`` every ``field_period`` steps. A state whose
change does not follow the replica (this node started late, or a message was missed) is
held, logged, and the learner asked for a whole map (``/map_learner/request_snapshot``);
the replica starts again from the latched ``/sensorimotor_snapshot`` and the held step is
computed then (a resent step is answered from the replica as it is). The goal is the goal
*sensation* that came with the observation (through the preprocessor and the map learner):
when it changes the potentials restart from 0 (Algorithm 1 line 5), exactly as
:meth:`TMGWRAgent.set_goal` does in-process.

When the selector's epsilon draw for its next action, made ahead, chose the random walk
(``Action.walk_next``; every step while epsilon is 1), Eq. 4-5 are not solved for that
step, as :meth:`TMGWRAgent.step` does in-process: this node hears the selector's
``Action`` of the previous step and holds a state until that action has arrived (the
simulator made the state after it, so it was sent first; a resent state with the action
still missing is solved in full, with a warning, and provisionally: the core as it was
before the solve is kept, and when the late action arrives and says the draw chose the
walk, the core goes back to it and skips the solve as the in-process agent did, so the
warm start of the next solve is the same either way). The first state of a run has no action
before it: solved, as the in-process agent solves its first step. A field not solved
carries the winner's links without options, potentials 0, goal node -1 and 0 sweeps, and
no ``/potentials`` goes out for it.

What the world declares of its sensor, its goal region (``goal_tolerance``) and its
sensor's range (the bounds no option leads outside), reaches this node in feature units as
``SensorInfo`` on ``/feature_senses`` (latched; maze_sim declares them, the preprocessor
scales them), and is set on the core (:meth:`MotivationEstimator.set_senses`) as the
in-process agent's estimator is built with them. A state of a run whose declaration has not
arrived is held (logged) and computed when it does: no step is solved without them. The one
exception is a world whose name says its declaration in full, the grid (no goal tolerance,
no range: :func:`~tmgwr_agent.world_senses.named_declaration`): its states are solved with
that until the run's own declaration comes, so a recording made before the declarations
existed (it lacks ``/world_senses`` and ``/feature_senses``) replays on the grid as it ran.
For MiniGrid or PointMaze such a recording cannot be solved (the range lies in the maze
file): after ``SENSES_PATIENCE`` seconds of waiting the node says so, once per run, naming
the missing topic, and keeps waiting.

The goal reaches this node only as the goal sensation of the observations: ``/set_goal``
is the simulator's (``maze_sim``), which answers from its own check, so "accepted" means
applied (issue 24; this node hosted it once and answered before the simulator had
checked reachability).
"""

from __future__ import annotations

import copy
import math

import numpy as np
from rclpy.node import Node
from std_srvs.srv import Trigger

from tmgwr_agent.core.motivation import MotivationConfig, MotivationEstimator
from tmgwr_agent.core.sensorimotor_map import Links, survivor
from tmgwr_agent.map_replica import APPLIED, GAP, Replica
from tmgwr_agent.nodes.preload import load_cached_kernels
from tmgwr_agent.nodes.step_messages import change_of, outcome_of
from tmgwr_agent.world_senses import named_declaration, node_senses
from tmgwr_common import topics
from tmgwr_common.cdr import codec
from tmgwr_common.checkpoint import (
    CHECKPOINT_SPECS,
    Checkpoint,
    Checkpointer,
    CheckpointError,
    joined_state,
    split_state,
)
from tmgwr_common.lockstep import Lockstep
from tmgwr_common.node import (
    LATCHED_QOS,
    NODE_OPTIONS,
    STEP_QOS,
    declare_parameters,
    f64,
    i32,
    np_f64,
    run,
    subscribe_decoded,
)
from tmgwr_common.params import WORLD_PARAM, Param
from tmgwr_common.text import shown
from tmgwr_interfaces.msg import (
    Action,
    MotivationField,
    Potentials,
    SensorimotorSnapshot,
    SensorimotorState,
    SensorInfo,
)

#: Runs whose sensor declarations are kept (see ``on_senses``).
SENSES_RUNS = 8
#: Seconds a run's states wait for its declaration before the node reports it missing.
SENSES_PATIENCE = 10.0
FIELD = codec(MotivationField)        # the per-step messages go serialized (tmgwr_common.cdr)

NODE_SPECS = (
    WORLD_PARAM,
    Param("field_period", 100, "steps between two latched publications of every node's "
          "potential (/potentials, for inspection)", low=1, high=1e9, integer=True),
    *CHECKPOINT_SPECS,
)


class MotivationEstimatorNode(Node):
    def __init__(self):
        super().__init__("motivation_estimator", **NODE_OPTIONS)
        config, self.p = declare_parameters(self, MotivationConfig, NODE_SPECS)
        senses = node_senses(self.p["world"])
        self.dim = senses.dim               # the sensation's (a declared range gives as many)
        self.core = MotivationEstimator(config, primitives=senses.primitives)
        # the world's sensor declaration in feature units (run id, goal tolerance, bounds):
        # no state is solved before the one of its run has come (a state waits for it)
        # per run id, the newest SENSES_RUNS runs and the one being stepped (a declaration
        # of another run, a stray included, never evicts the current run's: the latched
        # original does not come again)
        self.senses: dict[int, tuple[float, tuple[np.ndarray, np.ndarray] | None]] = {}
        self.unsensed = None                # a state waiting for it
        # what this world's name says of its declaration (the grid's: all of it), used
        # until a run's own declaration comes; the run waiting for one and since when
        self.named = named_declaration(self.p["world"])
        self.missing: tuple[int, float] | None = None
        self.applied = None                 # the declaration last set on the core
        self.create_subscription(SensorInfo, topics.FEATURE_SENSES, self.on_senses,
                                 LATCHED_QOS)
        self._ids = np.zeros(0, dtype=np.int32)
        pub = self.create_publisher(MotivationField, topics.MOTIVATION, STEP_QOS)
        self.lockstep = Lockstep(pub, logger=self.get_logger(), what="state")
        # the selector's last action (run, step, walk_next): when its draw for the next
        # action chose the random walk, Eq. 4-5 need not be solved for it
        self.heard: tuple[int, int, bool] | None = None
        self.waiting = None                 # a state awaiting that action
        # a state solved without that action: ((run, step), the core before the solve)
        self.provisional: tuple[tuple[int, int], MotivationEstimator] | None = None
        # Action, SensorimotorState and SensorimotorSnapshot arrive as their fields (read by
        # tmgwr_common.cdr from the serialized message), MotivationField leaves serialized
        subscribe_decoded(self, Action, topics.ACTION, self.on_action, STEP_QOS)
        subscribe_decoded(self, SensorimotorState, topics.SENSORIMOTOR_STATE, self.on_state,
                          STEP_QOS)
        # the map of this step: a replica of the learner's, kept by its per-step changes
        self.replica = Replica()
        self.held = None                    # a state waiting for a whole map
        subscribe_decoded(self, SensorimotorSnapshot, topics.MAP_SNAPSHOT, self.on_snapshot,
                          LATCHED_QOS)
        self.snapshot_client = self.create_client(
            Trigger, topics.of_node(topics.LEARNER, topics.REQUEST_SNAPSHOT))
        self.asked = False                  # a snapshot request is under way
        self.potentials_pub = self.create_publisher(Potentials, topics.POTENTIALS, LATCHED_QOS)
        # the outcome memory of Eq. 5' survives any stop (tmgwr_common.checkpoint)
        self.checkpoints = Checkpointer("motivation_estimator", self.p, self.get_logger(),
                                        namespace=self.get_namespace())
        self.checkpoints.resume(check=self.restore)
        load_cached_kernels()               # Eq. 4-5' kernels: not on the first step
        self.get_logger().info(f"motivation_estimator ready: {config.as_dict()}")

    # ------------------------------------------------------------------ per step
    def on_action(self, a):
        """The selector's answer to a step: news only when it answers the newest step this
        node computed (a state may wait for it) or the one before (a state solved without
        it, provisional). Anything else is a resent answer, or a stray (another run, a
        step this node never computed): kept, it would hold every state of the real ring
        until the simulator's resend, for good (issue 24)."""
        ls = self.lockstep
        if a.run_id != ls.run_id or a.step_id not in (ls.last_step, ls.last_step - 1) or (
                self.heard is not None and (a.run_id, a.step_id) < self.heard[:2]
                and self.heard[0] == ls.run_id and self.heard[1] <= ls.last_step):
            return
        self.heard = (a.run_id, a.step_id, a.walk_next)
        self.settle(a)
        w = self.waiting
        if w is not None and (w.run_id, w.step_id - 1) == (a.run_id, a.step_id):
            self.waiting = None
            self.on_state(w)

    def settle(self, a) -> None:
        """The late action ``a`` of a step solved without it: when its draw chose the walk,
        undo the solve (the in-process agent skipped it) and skip it."""
        p, self.provisional = self.provisional, None
        if p is None or p[0] != (a.run_id, a.step_id + 1):
            return
        if a.walk_next:
            self.core = p[1]
            self.core.update(self.replica.snapshot(), skip=True)
            self.get_logger().info(f"step {a.step_id + 1} (run {a.run_id}): the late action "
                                   "chose the walk: the solve made without it undone")

    def awaits_action(self, s) -> bool:
        """Whether state ``s`` waits for the selector's action of the step before (this
        node computed that step, so the selector answered it: the action is on its way)."""
        if (s.run_id, s.step_id - 1) != (self.lockstep.run_id, self.lockstep.last_step) or (
                self.heard is not None and self.heard[:2] == (s.run_id, s.step_id - 1)):
            return False
        w, self.waiting = self.waiting, s
        if w is not None and (w.run_id, w.step_id) == (s.run_id, s.step_id):
            self.waiting = None             # resent and the action still missing
            self.get_logger().warning(
                f"step {s.step_id} (run {s.run_id}): no action of step {s.step_id - 1} "
                "heard from the selector: Eq. 4-5 solved without its draw",
                throttle_duration_sec=5.0)
            return False
        return True

    def on_senses(self, m):
        """The world's sensor declaration (feature units) of a run: kept, set on the core
        before the next solve; a state that waited for it is computed now."""
        low, high = np_f64(m.low), np_f64(m.high)
        tol = float(m.goal_tolerance)
        if len(low) != len(high) or len(low) not in (0, self.dim) or np.isnan(low).any() \
                or np.isnan(high).any() or (low > high).any() or \
                not (math.isfinite(tol) and tol >= 0.0):
            self.get_logger().error(
                f"{topics.FEATURE_SENSES}: refused a declaration of run {m.run_id}: goal "
                f"tolerance {tol}, range {shown(str(low.tolist()))} .. "
                f"{shown(str(high.tolist()))} (a finite "
                f"tolerance >= 0; no range, or {self.dim} low and {self.dim} high values, "
                "low <= high)")
            return
        kept = self.senses.get(m.run_id)
        if kept is not None:                    # a run's first declaration stands
            if kept[0] != tol or (kept[1] is None) != (not len(low)) or (
                    kept[1] is not None and not (np.array_equal(kept[1][0], low)
                                                 and np.array_equal(kept[1][1], high))):
                self.get_logger().warning(
                    f"{topics.FEATURE_SENSES}: ignored another declaration of run "
                    f"{m.run_id} (its first stands)", throttle_duration_sec=5.0)
            return
        self.senses[m.run_id] = (tol, (low, high) if len(low) else None)
        for old in [r for r, d in self.senses.items() if d is not self.applied][
                :max(0, len(self.senses) - SENSES_RUNS)]:
            del self.senses[old]                # the oldest, never the one being stepped
        w, self.unsensed = self.unsensed, None
        if w is not None:
            self.on_state(w)

    def sensed(self, s) -> bool:
        """Whether the world's declaration of the run of state ``s`` has come (set on the
        core); else ``s`` waits for it (the newest state waiting)."""
        declared = self.senses.get(s.run_id, self.named)
        if declared is not None:
            if self.applied is not declared:        # its first state: set on the core
                self.applied = declared
                self.core.set_senses(*declared)
                c = self.core
                lo, hi = ([], []) if c.bounds is None else (b.tolist() for b in c.bounds)
                self.get_logger().info(
                    f"step {s.step_id} (run {s.run_id}): the world's senses set: goal "
                    f"tolerance {c.goal_tolerance!r}, sensor's range {lo} .. {hi} "
                    "(feature units)" + ("" if s.run_id in self.senses else
                                         f"; the {self.p['world']} world's, which its name "
                                         f"says in full (none came on "
                                         f"{topics.FEATURE_SENSES} yet)"))
            return True
        self.report_missing(s)
        if self.unsensed is None or (self.unsensed.run_id, self.unsensed.step_id) != \
                (s.run_id, s.step_id):
            self.get_logger().warning(
                f"step {s.step_id} (run {s.run_id}): waiting for the world's sensor "
                f"declaration on {topics.FEATURE_SENSES} (from maze_sim through the "
                "sensory_preprocessor)", throttle_duration_sec=5.0)
        self.unsensed = s
        return False

    def report_missing(self, s) -> None:
        """Say once per run, after ``SENSES_PATIENCE`` seconds of waiting, that the run's
        declaration has not come: why no step is solved, and which topic lacks it."""
        now = self.get_clock().now().nanoseconds * 1e-9
        if self.missing is None or self.missing[0] != s.run_id:
            self.missing = (s.run_id, now)
        elif now - self.missing[1] >= SENSES_PATIENCE:
            self.missing = (s.run_id, math.inf)     # said for this run
            self.get_logger().error(
                f"step {s.step_id} (run {s.run_id}): no sensor declaration of this run on "
                f"{topics.FEATURE_SENSES} in {SENSES_PATIENCE:g} s: no step is solved "
                f"without it (the {self.p['world']} world's range lies in its maze file). "
                f"maze_sim publishes it on {topics.WORLD_SENSES} at the start of a run; a "
                "recording made before the declarations existed lacks both topics and "
                "cannot drive this world's agent")

    def on_state(self, s):
        if s.run_id and not self.sensed(s):
            return                          # held until the world's declaration came
        resent = (s.run_id, s.step_id) == (self.lockstep.run_id, self.lockstep.last_step)
        if s.run_id and not resent and self.awaits_action(s):
            return                          # held until the previous step's action came
        if s.run_id and not resent and not self.follow(s):
            return                          # held until the replica has this step's map
        self.lockstep.on_step(s.run_id, s.step_id, lambda: self.motivate(s))
        self.checkpoints.step(self.lockstep.last_step, self.lockstep.run_id,
                              lambda: split_state(self.core.state_dict()))

    def follow(self, s) -> bool:
        """Bring the replica to the map of state ``s``; False (``s`` held, a whole map
        asked for) when its change does not follow the replica; False (``s`` dropped) when
        ``s`` cannot be a learner's (a stray message must not wipe the replica or crash the
        node: the simulator's resend brings the real step)."""
        try:
            c = change_of(s)
            why = c.problem()
        except ValueError as exc:           # array lengths that do not fit the sizes
            why = str(exc)
        if why is None and self.replica.status(c) != GAP and not (
                -1 <= s.winner < max(c.n, self.replica.n)):
            why = f"winner {s.winner}"
        if why is not None:
            self.get_logger().warning(
                f"dropped a state of step {s.step_id} (run {s.run_id}) that no learner sent: "
                f"{why}", throttle_duration_sec=5.0)
            return False
        if self.replica.apply(c) != GAP:
            return True
        r = self.replica
        self.get_logger().warning(
            f"step {s.step_id} (run {s.run_id}): map change {c.base} -> {c.sequence} of map "
            f"{c.map_id} does not follow the replica ("
            + (f"map {r.map_id} state {r.sequence}" if r.synced else "empty")
            + "): waiting for a whole map", throttle_duration_sec=5.0)
        self.held = s
        if not self.asked and self.snapshot_client.service_is_ready():
            self.asked = True
            self.snapshot_client.call_async(Trigger.Request()).add_done_callback(
                self.on_snapshot_answer)
        return False

    def on_snapshot_answer(self, _future):
        self.asked = False

    def on_snapshot(self, msg):
        c = change_of(msg)
        if self.replica.apply(c) == APPLIED:
            self.get_logger().info(f"map replica (re)synchronised: map {c.map_id} state "
                                   f"{c.sequence} (step {c.step_id} of run {c.run_id}), "
                                   f"{c.n} slots")
        held, self.held = self.held, None
        if held is not None and self.replica.status(change_of(held)) != GAP:
            self.on_state(held)

    def motivate(self, s) -> bytes:
        """The MotivationField of state ``s``, serialized."""
        goal_x = np_f64(s.goal_features)
        if self.core.follow_goal(goal_x):       # a new goal: V restarts from 0 (Algorithm 1)
            self.get_logger().info(f"step {s.step_id}: goal sensation {goal_x.tolist()}")
        m = self.replica.snapshot()
        # what TMGWRAgent.step does here: note what the last action did (Eq. 5' options),
        # then re-solve Eq. 4-5 on this step's map
        merges = self.replica.take_merges()     # nodes the map merged this step
        if len(merges):
            self.core.merge(merges)
        self.core.record(survivor(s.previous_winner, merges), s.winner, s.inserted,
                         outcome_of(s), m.w)
        heard = self.heard if self.heard and self.heard[:2] == (s.run_id, s.step_id - 1) \
            else None               # the selector's action of the step before
        # solved without the draw (a resend, the action missing; a run's first step; a
        # restart): provisional until that action turns up, if ever
        self.provisional = None if heard is not None else \
            ((s.run_id, s.step_id), copy.deepcopy(self.core))
        V = self.core.update(m, skip=heard is not None and heard[2])
        out = FIELD.new()
        out.header = s.header
        out.run_id = s.run_id
        out.step_id = s.step_id
        out.map_version = s.map_version
        out.goal_node = int(self.core.goal_node)
        out.sweeps = int(self.core.sweeps)
        out.winner = s.winner
        out.action_dim = s.action_dim
        if s.winner >= 0:          # what Eq. 6 ranks: the winner's links and its options
            actions = np_f64(s.winner_link_actions).reshape(-1, s.action_dim or 1)
            links = Links(m.out[s.winner], m.E[s.winner], actions)
            if V is not None:
                links = self.core.options_of(s.winner, links)
                potentials = self.core.V[links.targets]              # V[-1] = V[n] = 0
            else:                  # not solved: the next action walks
                potentials = np.zeros(len(links.targets))
            out.winner_link_targets = links.targets
            out.winner_link_reliability = links.E
            out.winner_link_potentials = potentials
            out.winner_link_actions = links.actions.ravel()
        else:
            out.winner_link_actions = s.winner_link_actions
        out.episode_start = s.episode_start
        out.action = s.action
        out.bumped = s.bumped
        out.goal_reached = s.goal_reached
        out.terminal = s.terminal
        if s.step_id % self.p["field_period"] == 0 and V is not None:
            self.publish_potentials(s, V)
        return FIELD.encode(out)

    def publish_potentials(self, s, V: np.ndarray) -> None:
        """Every node's potential, latched (for inspection: markers, report)."""
        p = Potentials()
        p.header = s.header
        p.run_id, p.step_id = s.run_id, s.step_id
        p.map_id, p.map_sequence = self.replica.map_id, self.replica.sequence
        p.map_version = s.map_version
        p.goal_node, p.sweeps = int(self.core.goal_node), int(self.core.sweeps)
        if len(self._ids) != len(V):
            self._ids = np.arange(len(V), dtype=np.int32)
        p.node_ids = i32(self._ids)
        p.potentials = f64(V)
        self.potentials_pub.publish(p)

    def restore(self, ck: Checkpoint) -> None:
        """The core's state from checkpoint ``ck`` (the core refuses what it cannot take)."""
        try:
            self.core.load_state_dict(joined_state(ck))
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            core = self.core                                  # nothing half loaded
            self.core = type(core)(core.config, primitives=core.primitives,
                                   goal_tolerance=core.goal_tolerance, bounds=core.bounds)
            raise CheckpointError(f"{ck.path}: {exc!r}: refused") from None

    def on_shutdown(self):
        print(f"motivation_estimator: {self.lockstep.timer.summary()}", flush=True)
        self.checkpoints.stop(self.lockstep.last_step, self.lockstep.run_id,
                              lambda: split_state(self.core.state_dict()))


def main(args=None):
    raise SystemExit(run(MotivationEstimatorNode, "motivation_estimator", args))


if __name__ == "__main__":
    main()
