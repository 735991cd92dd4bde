"""``ros2 run tmgwr_agent map_learner``: the TMGWR sensorimotor map (section 3.1, Eq. 1-2).

Per step (lockstep): ``Features`` in, :meth:`SensorimotorMap.experience` with the step's
:class:`~tmgwr_agent.core.outcome.Outcome`, the call :class:`~tmgwr_agent.core.agent.TMGWRAgent`
makes in-process; ``SensorimotorState`` out. The state carries this step's *change* of
the map arrays the motivation estimator needs to run Eq. 4-5 on the map of *this* step
(alive mask, terminal flags, weights, link targets and reliabilities E: only the rows that
changed, :mod:`tmgwr_agent.map_replica`) and the winner's link action vectors. The first
state of a map (created, loaded) carries the whole map. The whole map also goes out latched
on ``/sensorimotor_snapshot`` every ``snapshot_period`` steps, when the learner starts from
or loads a map, and on request (``/map_learner/request_snapshot``, std_srvs/Trigger): what a
replica that missed a change starts again from.

At ``publish_rate`` Hz (when the map changed) the whole map is published latched, as
``tmgwr_interfaces/SensorimotorMap`` and as ``visualization_msgs/MarkerArray`` (nodes at
their sensed position, coloured by the motivation potentials of the last
``/potentials``; links coloured by reliability E). These whole-map messages are for
inspection and cost the map's size to build, so they take at most ``map_publish_share`` of
the learner's wall time: after a publication that took ``t`` seconds the next one waits
``t / map_publish_share`` (and at least ``1 / publish_rate``). On a small map that is the
rate; on a growing big map the inspection messages thin out instead of capping the steps.
On the timer each of the two is built only while something subscribes to it (the
recorder, RViz): a new subscriber gets the last one at once and a fresh one within
``1 / publish_rate`` s. A map the learner starts from or loads is published at once.

Persistence (:mod:`tmgwr_agent.map_store`; docs/graph.md, Maps on disk): maps live in one
directory, ``map_dir`` (``./tmgwr up`` passes the run's directory; default
``$ROS_HOME/tmgwr/domain<ID>[_<namespace>]``), held by this learner alone. The private
``~/save_map`` and ``~/load_map`` services take a map *name* (``NAME`` -> ``NAME.npz`` in
that directory), never a path; a refused name, file or content leaves the node running
and the response says why. The map is saved as ``map_name`` on deactivate and on shutdown
(SIGINT/SIGTERM) and ``initial_map`` (a name in ``map_dir``, or a path given by whoever
starts the node) starts the learner from a saved map, so a restarted learner continues
with the same map (the file also records the last step it learnt and its run, so a resent
step is answered, not learnt twice). A map saved in another run brings that run's id
along: the learner follows the simulator's current run from its first step
(``tmgwr_common.lockstep``), learning on with the loaded map. A loaded map is validated
completely before it replaces the live one.

Lifecycle (a managed node, ``rclpy.lifecycle.LifecycleNode`` as in ros2/demos
``lifecycle_py``; :mod:`tmgwr_common.lifecycle`; ``ros2 lifecycle get/set /map_learner``):

* ``configure``: hold the map directory, load the map (``initial_map``, else the checkpoint
  with ``resume``, else none until the first features), create the publishers (lifecycle
  publishers: silent unless active) and the services (they answer while configured);
* ``activate``: join the lockstep (learn and answer ``/features``, to which the node
  subscribes once, when it is built, and which it drops unless active: see
  :meth:`MapLearnerNode.__init__`; the simulator resends the step the ring waits for,
  within ``resend_period``) and publish the map;
* ``deactivate``: stop stepping (the ring waits, nothing is lost) and save the map and the
  checkpoint; ``activate`` goes on from the same map and step;
* ``cleanup``: drop the map, the publishers and services, release the directory;
* ``shutdown`` (from any state; Ctrl-C and SIGTERM take it too): save as on deactivate
  (atomic), release everything, and end the process (a finalized learner never steps
  again: ``./tmgwr up`` then stops the graph naming it, never a silent stall).

``autostart`` (default true) configures and activates the node as soon as it is built, so
``ros2 run``, ``ros2 launch``, ``./tmgwr up`` and the composed graph step by themselves; a
configure that fails then stops the learner at start (exit code 2, saying why). With
``autostart:=false`` it waits unconfigured for ``ros2 lifecycle set`` or a lifecycle manager.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
from geometry_msgs.msg import Point
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.lifecycle.publisher import LifecyclePublisher
from std_msgs.msg import ColorRGBA
from std_srvs.srv import Trigger
from visualization_msgs.msg import Marker, MarkerArray

from tmgwr_agent.core.sensorimotor_map import MapConfig, SensorimotorMap
from tmgwr_agent.map_replica import ChangeEncoder
from tmgwr_agent.map_store import (
    MapStore,
    MapStoreError,
    default_map_dir,
    read_map,
    validate_state,
)
from tmgwr_agent.nodes.step_messages import fill_change, outcome_of
from tmgwr_agent.world_senses import drawn_at, node_senses
from tmgwr_common import topics
from tmgwr_common.cdr import codec
from tmgwr_common.checkpoint import CHECKPOINT_SPECS, Checkpoint, Checkpointer, CheckpointError
from tmgwr_common.lifecycle import LIFECYCLE_SPECS, autostart, refuse_invalid_transitions
from tmgwr_common.lockstep import Lockstep
from tmgwr_common.node import (
    LATCHED_QOS,
    NODE_OPTIONS,
    SENSOR_QOS,
    STEP_QOS,
    declare_parameters,
    f64,
    np_f64,
    run,
    subscribe_decoded,
    wait_for_acknowledgments,
)
from tmgwr_common.params import WORLD_PARAM, Param
from tmgwr_interfaces.msg import (
    Features,
    MapLink,
    MapNode,
    Potentials,
    SensorimotorSnapshot,
    SensorimotorState,
)
from tmgwr_interfaces.msg import SensorimotorMap as MapMsg
from tmgwr_interfaces.srv import LoadMap, SaveMap

# the per-step state and the snapshots go serialized (tmgwr_common.cdr)
STATE, SNAPSHOT = codec(SensorimotorState), codec(SensorimotorSnapshot)

NODE_SPECS = (
    WORLD_PARAM,
    Param("map_dir", "", "directory of this learner's maps (empty = "
          "$ROS_HOME/tmgwr/domain<ROS_DOMAIN_ID>[_<namespace>], ROS_HOME defaulting to "
          "~/.ros); one learner per directory"),
    Param("map_name", "map", "name of the map saved on shutdown and by save_map with an "
          "empty name (file NAME.npz in map_dir; empty = do not save on shutdown)"),
    Param("initial_map", "", "start from this saved map: a name in map_dir, or a path "
          "(empty = an empty map)"),
    Param("map_path", "", "the old form of map_dir + map_name: DIR/NAME.npz sets both "
          "(empty = use map_dir and map_name)"),
    Param("publish_rate", 2.0, "rate (Hz) of the latched map and marker publications",
          low=0.01, high=100.0),
    Param("map_publish_share", 0.05, "largest share of wall time spent building the "
          "whole-map /map and /map_markers messages (they thin out on big maps)",
          low=0.001, high=1.0),
    Param("snapshot_period", 500, "steps between two latched whole-map snapshots "
          "(/sensorimotor_snapshot; also sent on request and for a new map)", low=1,
          high=1e9, integer=True),
    *CHECKPOINT_SPECS,
    *LIFECYCLE_SPECS,
)


class MapLearnerNode(LifecycleNode):
    """A managed node (module docstring, Lifecycle): the map exists from ``configure`` to
    ``cleanup``/``shutdown``; the learner steps only while ``active``."""

    def __init__(self):
        super().__init__("map_learner", **NODE_OPTIONS)
        self.config, self.p = declare_parameters(self, MapConfig, NODE_SPECS)
        self.primitives = node_senses(self.p["world"]).primitives   # the world's motor vectors
        if self.p["map_path"]:                              # the old form: DIR/NAME.npz
            old = Path(self.p["map_path"])
            self.p["map_dir"], self.p["map_name"] = str(old.parent), old.name
        refuse_invalid_transitions(self)
        self.map: SensorimotorMap | None = None
        self.store: MapStore | None = None
        self.checkpoints: Checkpointer | None = None
        self.lockstep: Lockstep | None = None
        self.stepping = False              # active: features are learnt and answered
        # /features: subscribed here, once, for the node's life, and dropped unless active
        # (on_features), never made again at configure or activate. Why: with Fast DDS 2.14
        # (rmw_fastrtps, Jazzy), a reliable volatile reader created in a process where the
        # topic's writer has already written more samples than the reader's max_samples
        # (Fast DDS's default resource limit: 5000) gets no sample until the writer has
        # written about `depth` more (STEP_QOS: 10). It has not had the writer's heartbeat
        # yet, so it counts every earlier sequence number as a change still to come and
        # refuses each sample while that count is >= max_samples
        # (DataReaderHistory::can_change_be_added_nts). That happens through intraprocess
        # delivery, i.e. in the composed graph (one participant), once the preprocessor's
        # writer is past 5000 samples; while the ring waits it writes one sample per
        # resend_period (1 s): a subscription made at activate waited ~10 s. Separate
        # processes are not affected. docs/graph.md, The map learner's lifecycle;
        # test/repro_late_reader.py reproduces it with std_msgs alone.
        self.features_sub = subscribe_decoded(self, Features, topics.FEATURES,
                                              self.on_features, STEP_QOS)
        self.map_timer = None
        self.refusal = ""                  # why the last transition failed ("" = none)
        self.exit_code = 0
        self.finished = False              # finalized: the process ends (tmgwr_common.node)
        self.motivation_raw: bytes | None = None
        if self.p["autostart"]:
            autostart(self)                 # ValueError: exit code 2 with the reason
            self.get_logger().info(f"map_learner ready: {self.config.as_dict()}")
        else:
            self.get_logger().info(
                "map_learner ready, unconfigured (autostart false): waiting for `ros2 "
                f"lifecycle set {self.get_fully_qualified_name()} configure`, then activate")

    # ------------------------------------------------------------------ lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """The map directory (held), the map (``initial_map``, else the checkpoint with
        ``resume``, else empty until the first features), publishers and services."""
        try:
            self.configure()
        except (MapStoreError, CheckpointError, ValueError, OSError) as exc:
            self.refusal = str(exc)
            self.get_logger().error(f"configure failed: {exc}")
            self.release()
            return TransitionCallbackReturn.FAILURE
        self.refusal = ""
        return TransitionCallbackReturn.SUCCESS

    def configure(self) -> None:
        self.map, last_step, run_id = None, -1, 0
        self.gain = 1.0
        self.prev_winner = -1
        self.store = MapStore(self.p["map_dir"] or default_map_dir(
            os.environ.get("ROS_DOMAIN_ID") or 0, self.get_namespace()))
        self.store.lock()
        if self.p["map_name"]:
            self.store.path(self.p["map_name"])          # a bad name stops us now, not later
        if self.p["initial_map"]:
            self.map, last_step, run_id = self.read_initial_map(self.p["initial_map"])
            self.map.primitives = self.primitives         # the world's motor primitives
            self.get_logger().info(f"started from {self.p['initial_map']}: {self.map.size} nodes, "
                                   f"{self.map.link_count()} links, step {last_step} "
                                   f"(run {run_id or 'unknown'})")
        # the map and its step survive any stop (tmgwr_common.checkpoint; before initial_map)
        self.checkpoints = Checkpointer("map_learner", self.p, self.get_logger(),
                                        default_dir=self.store.directory)
        ck = self.checkpoints.resume(check=self.map_of_checkpoint)
        if ck is not None:
            self.map, last_step, run_id = self.map_of_checkpoint(ck), ck.step_id, ck.run_id
        elif self.p["map_name"]:
            self.keep_previous_map()
        self.V = np.zeros(0)
        self.published = (-1, -1, ())    # (step, version, wanted) of the last /map, markers

        state_pub = self.create_lifecycle_publisher(SensorimotorState,
                                                    topics.SENSORIMOTOR_STATE, STEP_QOS)
        self.lockstep = Lockstep(state_pub, last_step=last_step, run_id=run_id,
                                 logger=self.get_logger(), what="features")
        self.map_pub = self.create_lifecycle_publisher(MapMsg, topics.MAP, LATCHED_QOS)
        self.marker_pub = self.create_lifecycle_publisher(MarkerArray, topics.MAP_MARKERS,
                                                          LATCHED_QOS)
        # Marker colours only: the newest field is enough (best effort, depth 1, never
        # stalls its publisher), kept serialized and decoded only when markers are drawn.
        self.potentials_sub = self.create_subscription(
            Potentials, topics.POTENTIALS, self.on_motivation, SENSOR_QOS, raw=True)
        self.motivation_raw = None
        self.own_services = [self.create_service(SaveMap, topics.SAVE_MAP, self.on_save),
                         self.create_service(LoadMap, topics.LOAD_MAP, self.on_load)]
        # the map as consumers replicate it: per-step changes, latched whole-map snapshots
        self.encoder: ChangeEncoder | None = None
        self.encoder_of: SensorimotorMap | None = None       # the map it encodes
        self.snapshot_pub = self.create_lifecycle_publisher(
            SensorimotorSnapshot, topics.MAP_SNAPSHOT, LATCHED_QOS)
        self.own_services.append(self.create_service(Trigger, topics.REQUEST_SNAPSHOT,
                                                 self.on_request_snapshot))
        self.next_map_time = 0.0        # time.monotonic() before which publish_map waits

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Join the lockstep: answer the features again (the simulator's next resend
        brings the step the ring waits for) and publish the map."""
        super().on_activate(state)                   # the lifecycle publishers
        self.stepping = True
        self.map_timer = self.create_timer(1.0 / self.p["publish_rate"], self.publish_map)
        self.published = (-1, -1, ())
        if self.map is not None:
            self.publish_map(always=True)
        ls = self.lockstep
        self.get_logger().info(
            "active: stepping " + (f"on from step {ls.last_step} of run {ls.run_id}"
                                   if ls.run_id else "from the simulator's next step")
            + (f" with {self.map.size} nodes" if self.map is not None else ""))
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop stepping (the ring waits; the simulator resends until we are back) and save
        the map and the checkpoint."""
        self.stop_stepping()
        super().on_deactivate(state)
        self.get_logger().info(f"inactive: stepping stopped after step "
                               f"{self.lockstep.last_step}; {self.save_all(print_=False)}")
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Drop the map and everything configure made; the map directory is released."""
        self.release()
        self.get_logger().info("unconfigured: map dropped, map directory released")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """The end (Ctrl-C, SIGTERM, ``ros2 lifecycle set ... shutdown``): save the map and
        the checkpoint (atomic), release everything. FAILURE when the map was not saved."""
        if self.lockstep is not None:
            print(f"map_learner: {self.lockstep.timer.summary()}", flush=True)
        ok = True
        if state.label == "active":
            self.stop_stepping()
        if self.store is not None:
            try:
                self.save_all(print_=True, strict=True)
            except MapStoreError as exc:
                self.refusal = f"map NOT saved: {exc}"
                print(f"map_learner: {self.refusal}", flush=True)
                ok = False
        wait_for_acknowledgments(self)       # subscribers get our last messages first
        self.release(final=True)
        # A finalized learner never steps again: its process ends, so that whoever runs the
        # graph sees it go (./tmgwr up stops the graph naming it) instead of a ring that
        # waits for ever on a node that is still there (issue 24).
        if not self.finished:
            self.finished = True
            print("map_learner: finalized: the process ends", flush=True)
        if not ok:
            self.exit_code = 1
        return TransitionCallbackReturn.SUCCESS if ok else TransitionCallbackReturn.FAILURE

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.get_logger().error(f"error while leaving {state.label}: back to unconfigured")
        self.stop_stepping()
        self.release()
        return TransitionCallbackReturn.SUCCESS

    def stop_stepping(self) -> None:
        self.stepping = False
        if self.map_timer is not None:
            self.destroy_timer(self.map_timer)
            self.map_timer = None

    def release(self, final: bool = False) -> None:
        """Undo configure: publishers, services, the map, the directory lock; ``final``
        (shutdown): the /features subscription too."""
        self.stop_stepping()
        for pub in [p for p in self.publishers if isinstance(p, LifecyclePublisher)]:
            self.destroy_lifecycle_publisher(pub)
        for srv in getattr(self, "own_services", []):
            self.destroy_service(srv)
        self.own_services = []
        for name in ("potentials_sub", "features_sub") if final else ("potentials_sub",):
            if getattr(self, name, None) is not None:
                self.destroy_subscription(getattr(self, name))
                setattr(self, name, None)
        if self.checkpoints is not None:
            self.checkpoints.close()
        if self.store is not None:
            self.store.close()
        self.map, self.store, self.checkpoints, self.lockstep = None, None, None, None
        self.encoder = self.encoder_of = None

    def keep_previous_map(self) -> None:
        """A fresh start: the map an earlier run saved as ``map_name`` is renamed, not
        overwritten by this run's saves (map_store.MapStore.keep_previous)."""
        try:
            kept = self.store.keep_previous(self.p["map_name"])
        except MapStoreError as exc:
            self.get_logger().warning(f"{exc}; this run's saves will replace it")
            return
        if kept is not None:
            self.get_logger().info(f"an earlier run's map {self.store.path(self.p['map_name'])} "
                                   f"kept as {kept.name} (this run saves its own)")

    def save_all(self, print_: bool, strict: bool = False) -> str:
        """Write the checkpoint and save the map as ``map_name`` (both atomic); what was
        done, in words. ``strict``: a refused map save raises MapStoreError."""
        step, run_id = self.lockstep.last_step, self.lockstep.run_id
        if self.map is None:
            return "no map yet: nothing saved"
        if print_:                       # the end: rclpy's logging may be gone
            self.checkpoints.stop(step, run_id, self.checkpoint_state)
        elif step >= 0 and self.checkpoints.store is not None:
            self.checkpoints.save(step, run_id, self.checkpoint_state,
                                  self.get_logger().warning)
        if not self.p["map_name"]:
            return "map not saved (map_name empty)"
        try:
            path = self.store.save(self.map, self.p["map_name"], step, run_id)
        except MapStoreError as exc:
            if strict:
                raise
            self.get_logger().warning(f"map NOT saved: {exc}")
            return f"map NOT saved: {exc}"
        text = (f"saved {self.map.size} nodes, {self.map.link_count()} links (step {step}) "
                f"to {path}")
        if print_:
            print(f"map_learner: {text}", flush=True)
        return text

    # ------------------------------------------------------------------ per step
    def on_features(self, f):
        """A Features message (its fields, read by tmgwr_common.cdr)."""
        if not self.stepping:            # inactive: the ring waits, the simulator resends
            return
        dim = self.map.dim if self.map is not None else len(f.features) or -1
        if f.run_id and len(f.features) != dim:     # a malformed stray must not crash us
            self.get_logger().warning(
                f"ignored features of step {f.step_id} (run {f.run_id}): {len(f.features)} "
                f"values, the map has dimension {dim}", throttle_duration_sec=10.0)
            return
        self.lockstep.on_step(f.run_id, f.step_id, lambda: self.learn(f),
                              answer_again=lambda: self.make_state(f))
        self.checkpoints.step(self.lockstep.last_step, self.lockstep.run_id,
                              self.checkpoint_state)

    def learn(self, f) -> bytes:
        x = np_f64(f.features)
        if self.map is None:
            self.map = SensorimotorMap(dim=len(x), action_dim=self.primitives.shape[1],
                                       config=self.config, primitives=self.primitives)
        self.gain = f.gain or 1.0
        outcome = outcome_of(f)
        self.prev_winner = -1 if outcome.episode_start else int(self.map.prev)
        self.map.experience(x, outcome)              # what TMGWRAgent.step does here
        if self.map.bump_from is not None:           # a bump taken at another place
            self.prev_winner = self.map.bump_from
        state = self.make_state(f)
        if f.step_id % self.p["snapshot_period"] == 0:
            self.publish_snapshot()
        return state

    def make_state(self, f) -> bytes:
        """The SensorimotorState of this step (Features ``f``), serialized."""
        m = self.map
        s = STATE.new()
        s.header = f.header
        s.run_id = f.run_id
        s.step_id = f.step_id
        s.winner = int(m.winner)
        s.previous_winner = self.prev_winner
        s.map_version = int(m.version)
        goal_x = np_f64(f.goal_features)
        s.goal_node = int(m.nearest_by_weight(goal_x)) if len(goal_x) == m.dim else -1
        s.inserted = bool(m.inserted)
        fill_change(s.map_change, self.changes().encode(m, f.run_id, f.step_id))
        s.action_dim = m.action_dim
        if m.winner >= 0:
            s.winner_link_actions = m.a[m.winner].ravel()
        s.goal_features = f.goal_features
        s.episode_start = f.episode_start
        s.action = f.action
        s.bumped = f.bumped
        s.goal_reached = f.goal_reached
        s.terminal = f.terminal
        return STATE.encode(s)

    def on_motivation(self, raw: bytes):
        self.motivation_raw = raw

    def potentials(self) -> np.ndarray:
        """V of the newest /potentials (zeros before the first one)."""
        if self.motivation_raw is not None:
            from rclpy.serialization import deserialize_message
            self.V = np_f64(deserialize_message(self.motivation_raw, Potentials).potentials)
            self.motivation_raw = None
        return self.V

    # ------------------------------------------------------------------ replicated map
    def changes(self) -> ChangeEncoder:
        """The change encoder of the current map: a new one (new map id, whole map first)
        when the map was created or replaced."""
        if self.encoder_of is not self.map:
            self.encoder, self.encoder_of = ChangeEncoder(time.time_ns()), self.map
        return self.encoder

    def publish_snapshot(self) -> str:
        """The whole map, latched, as last sent (encoded now if nothing was sent yet)."""
        enc = self.changes()
        if enc.sequence < 0:
            enc.encode(self.map, self.lockstep.run_id, max(self.lockstep.last_step, 0))
        c = enc.snapshot()
        msg = SNAPSHOT.new()
        msg.header.stamp, msg.header.frame_id = self.get_clock().now().to_msg(), "maze"
        msg.run_id, msg.step_id, msg.map_version = c.run_id, max(c.step_id, 0), c.version
        fill_change(msg.map, c)
        self.snapshot_pub.publish(SNAPSHOT.encode(msg))
        return (f"map {c.map_id} state {c.sequence} (step {c.step_id} of run {c.run_id}): "
                f"{c.n} slots")

    def on_request_snapshot(self, _req, resp):
        if self.map is None:
            resp.success, resp.message = False, "no map yet: nothing learnt"
        elif not self.stepping:
            resp.success, resp.message = False, "inactive: the map is not published"
        else:
            resp.success, resp.message = True, "published " + self.publish_snapshot()
        return resp

    # ------------------------------------------------------------------ latched map
    def publish_map(self, always: bool = False):
        """The whole map on /map and /map_markers (latched). On the timer only for their
        subscribers; ``always`` (a map started from or loaded): whoever subscribes later
        gets it at once, before the ring moves on."""
        m = self.map
        if m is None or self.lockstep is None:
            # nothing to publish; also a map_timer event that rclpy 7.1.6's EventsExecutor
            # had queued before stop_stepping destroyed the timer, run after a cleanup
            # released the map (a deactivate and a cleanup without spinning in between)
            return
        if self.encoder_of is not m:                          # started from / loaded a map
            self.publish_snapshot()
        step = self.lockstep.last_step
        # built only for a subscriber (the recorder, RViz, a test): they cost the map's
        # size in the learner's step loop; a new subscriber gets one within 1/publish_rate s
        wanted = (always or self.map_pub.get_subscription_count() > 0,
                  always or self.marker_pub.get_subscription_count() > 0)
        if not any(wanted) or self.published == (step, m.version, wanted) and step >= 0:
            return
        if time.monotonic() < self.next_map_time and not always:
            return
        started = time.monotonic()
        self.published = (step, m.version, wanted)
        stamp = self.get_clock().now().to_msg()
        ids = m.node_ids()
        src, tgt, act, E, age = m.links()
        if wanted[0]:
            msg = MapMsg()
            msg.header.stamp, msg.header.frame_id = stamp, "maze"
            msg.map_version, msg.step_id = int(m.version), max(step, 0)
            msg.run_id = self.lockstep.run_id
            msg.nodes = [MapNode(id=int(i), weight=f64(m.w[i]), context=f64(m.c[i]),
                                 habituation=float(m.h[i]), terminal=bool(m.terminal[i]))
                         for i in ids]
            msg.links = [MapLink(source=int(s), target=int(t), action=f64(a),
                                 reliability=float(e), age=int(g))
                         for s, t, a, e, g in zip(src, tgt, act, E, age)]
            self.map_pub.publish(msg)
        if wanted[1]:
            self.marker_pub.publish(self.markers(stamp, ids, src, tgt, E))
        took = time.monotonic() - started
        self.next_map_time = started + took / self.p["map_publish_share"]

    def position(self, i: int) -> Point:
        """A node drawn where it is sensed (weight / gain), in the simulator's frame."""
        x, y = drawn_at(self.p["world"], self.map.w[i] / self.gain)
        return Point(x=x, y=y, z=0.0)

    def markers(self, stamp, ids, src, tgt, E) -> MarkerArray:
        nodes = Marker(ns="nodes", id=0, type=Marker.SPHERE_LIST, action=Marker.ADD)
        nodes.header.stamp, nodes.header.frame_id = stamp, "maze"
        nodes.pose.orientation.w = 1.0
        nodes.scale.x = nodes.scale.y = nodes.scale.z = 0.35
        V = self.potentials()
        V = V if len(V) >= self.map.n else np.zeros(self.map.n)
        vmax = float(V[ids].max()) if len(ids) and V[ids].max() > 0 else 1.0
        for i in ids:
            nodes.points.append(self.position(i))
            v = float(V[i]) / vmax          # blue (no motivation) -> red (the goal)
            nodes.colors.append(ColorRGBA(r=v, g=0.2, b=1.0 - v, a=1.0))
        links = Marker(ns="links", id=1, type=Marker.LINE_LIST, action=Marker.ADD)
        links.header.stamp, links.header.frame_id = stamp, "maze"
        links.pose.orientation.w = 1.0
        links.scale.x = 0.05
        for s, t, e in zip(src, tgt, E):
            c = ColorRGBA(r=1.0 - float(e), g=float(e), b=0.0, a=0.8)   # red -> green with E
            links.points += [self.position(s), self.position(t)]
            links.colors += [c, c]
        return MarkerArray(markers=[nodes, links])

    # ------------------------------------------------------------------ persistence
    def read_initial_map(self, where: str) -> tuple[SensorimotorMap, int, int]:
        """``initial_map``: a name in the map directory, or a path (the operator's)."""
        if "/" not in where and not where.startswith("~"):
            return self.store.load(where, self.config)
        try:
            path = Path(where).expanduser().resolve()
        except RuntimeError as exc:                     # ~nosuchuser
            raise MapStoreError(f"initial_map {where!r}: {exc}") from None
        try:
            return read_map(path, self.config)
        except MapStoreError as exc:
            raise MapStoreError(f"initial_map: {exc}") from None

    def on_save(self, req, resp):
        """``req.name``: a map NAME in the map directory (empty: map_name)."""
        if self.map is None:
            resp.success, resp.message = False, "the map is empty: nothing learnt yet"
            return resp
        step = self.lockstep.last_step
        try:
            path = self.store.save(self.map, req.name or self.p["map_name"], step,
                                   self.lockstep.run_id)
        except MapStoreError as exc:
            resp.success, resp.message = False, f"save_map refused: {exc}"
            self.get_logger().warning(resp.message)
            return resp
        resp.success, resp.path = True, str(path)
        resp.message = (f"saved {self.map.size} nodes, {self.map.link_count()} links "
                        f"(step {step}) to {path}")
        self.get_logger().info(resp.message)
        return resp

    def on_load(self, req, resp):
        """``req.name`` is a map NAME in the map directory; the file is validated
        completely before it replaces the live map."""
        try:
            m, _, _ = self.store.load(req.name or self.p["map_name"], self.config)
            if self.map is not None and (m.dim, m.action_dim) != (self.map.dim,
                                                                 self.map.action_dim):
                raise MapStoreError(f"the file's map has dimension {m.dim}/{m.action_dim}, "
                                    f"the live one {self.map.dim}/{self.map.action_dim}")
        except MapStoreError as exc:
            resp.success, resp.message = False, f"load_map refused: {exc}"
            self.get_logger().warning(resp.message)
            return resp
        self.map = m
        self.map.primitives = self.primitives
        self.lockstep.forget(self.lockstep.last_step)   # the cached state is of the old map
        resp.success = True
        resp.message = (f"loaded {self.map.size} nodes, {self.map.link_count()} links from "
                        f"{self.store.path(req.name or self.p['map_name'])}")
        self.get_logger().info(resp.message)
        self.publish_map(always=True)
        return resp

    def checkpoint_state(self):
        return {"gain": self.gain}, self.map.state_dict()

    def map_of_checkpoint(self, ck: Checkpoint) -> SensorimotorMap:
        """The checkpoint's map, validated as completely as a loaded map file."""
        try:
            validate_state({**ck.arrays, "step_id": np.array(ck.step_id),
                            "run_id": np.array(ck.run_id, dtype=np.uint64)}, str(ck.path))
            m = SensorimotorMap(dim=ck.arrays["w"].shape[1],
                                action_dim=ck.arrays["a"].shape[2], config=self.config,
                                primitives=self.primitives)
            m.load_state_dict(ck.arrays)
        except (MapStoreError, KeyError, ValueError, IndexError) as exc:
            raise CheckpointError(str(exc)) from None
        self.gain = float(ck.state.get("gain", 1.0))
        return m


def main(args=None):
    raise SystemExit(run(MapLearnerNode, "map_learner", args))


if __name__ == "__main__":
    main()
