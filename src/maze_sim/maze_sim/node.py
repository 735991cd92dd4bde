"""``ros2 run maze_sim maze_sim``: the grid world as a ROS 2 node (docs/graph.md).

Hosts a world by name (parameter ``world``, :mod:`maze_sim.worlds`: ``grid``, our
:class:`~maze_sim.world.GridWorld`, ``minigrid``, :mod:`maze_sim.minigrid_world`, or
``pointmaze``, MuJoCo's PointMaze built from the maze file,
:mod:`maze_sim.pointmaze_world`) and drives the lockstep ring: it publishes one
``Observation`` per step and steps the world only when the ``Action`` carrying that
observation's ``run_id`` and ``step_id`` arrives. The answer to a terminal observation is
``Action.NONE``; the simulator then starts the next episode. While it waits it resends the
current observation every ``resend_period`` seconds, and every 0.25 s while its run has
had no action yet or a node has just joined the ring (a subscriber of ``/observation`` or
a publisher of a ring topic appeared: its endpoints are being matched), so the ring
recovers from a node that started late or was restarted (every node answers a repeated
step with its cached output, so a resend never changes what is learnt).
Its warning says which step of which run it waits for, when the last action came, and
which ring topics have no publisher.

Run identity (``tmgwr_common.lockstep``): at start the simulator picks ``run_id`` (the
wall clock in ns: nonzero, larger for a later start) and stamps it on every observation;
step ids count from 0 within the run. The agent nodes follow the newest run, so a
restarted simulator is followed from its first observation. An action of another run
(a simulator that was replaced, a stray ``ros2 topic pub`` with run_id 0) is ignored.

Goal changes (``/set_goal``, the graph's, and ``/maze_sim/set_goal``: one service under
two names) are validated at once (inside, free, reachable: the answer says so, so
"accepted" means applied) and applied at the next observation the simulator publishes: that
observation already carries the new goal sensation, which is how the goal reaches the
agent (the agent never receives the goal's cell); until then cell and event edits keep the
requested goal free. Cell and event changes apply at once. Every edit keeps the task
solvable or is refused with the reason (:class:`~maze_sim.world.EditRefused`): nothing may
wall in the start, the goal, the agent or the last route to the goal.

Also published: the maze as ``nav_msgs/OccupancyGrid`` (latched, republished on change;
cell (row, col) is centred at x = col, y = row, resolution 1), the current goal as
``geometry_msgs/PointStamped`` (latched, x = col, y = row), the agent pose at
``pose_rate`` Hz, and a line per goal/cell/event change on ``/maze_events``. In a
continuous world (PointMaze) the frame is the world's own: the grid's cells centred where
the env puts them (x, y in metres, row 0 at the top), the goal at its cell's centre, the
pose where the point is, and ``/set_goal`` takes a position in that frame (the goal is the
cell it lies in).
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from pathlib import Path

import numpy as np
from geometry_msgs.msg import PointStamped, PoseStamped
from nav_msgs.msg import OccupancyGrid
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from std_msgs.msg import String, UInt64
from std_srvs.srv import Trigger

from maze_sim.maze import DEFAULT_MAZE, N_ACTIONS, Maze, MazeError, maze_file
from maze_sim.worlds import WorldError, declared_sensor, make_world
from tmgwr_common import topics
from tmgwr_common.cdr import codec
from tmgwr_common.checkpoint import CHECKPOINT_SPECS, Checkpoint, Checkpointer, CheckpointError
from tmgwr_common.lockstep import WARN_PERIOD
from tmgwr_common.node import (
    LATCHED_QOS,
    NODE_OPTIONS,
    SENSOR_QOS,
    STEP_QOS,
    CallbackTimer,
    declare_parameters,
    run,
    subscribe_decoded,
)
from tmgwr_common.params import WORLD_PARAM, Param, ParamError
from tmgwr_common.share import DataFileError
from tmgwr_common.text import shown
from tmgwr_interfaces.msg import Action, Observation, SensorInfo
from tmgwr_interfaces.srv import FireEvent, SetCell, SetGoal

FRAME = "maze"
OBSERVATION = codec(Observation)      # the per-step messages go serialized (tmgwr_common.cdr)
WARMUP_STEPS = 200    # the SUMMARY's steady rate leaves out discovery and the first steps
RECORDER_WAIT_LOG = 5.0  # seconds between two "waiting for a recorder" lines
JOIN_RESEND = 0.25    # resend period while a run starts or a node joins (matching settles)
# Who publishes each ring topic (named in the warning when nobody does).
RING = ((topics.FEATURES, "sensory_preprocessor"), (topics.SENSORIMOTOR_STATE, "map_learner"),
        (topics.MOTIVATION, "motivation_estimator"), (topics.ACTION, "action_selector"))


def new_run_id() -> int:
    """A run id: the wall clock in ns (nonzero; a simulator started later has a larger
    one, which is how the nodes tell the newer run)."""
    return max(time.time_ns(), 1)

SPECS = (
    WORLD_PARAM,
    Param("maze", DEFAULT_MAZE, "maze file (docs/mazes.md, Maze format): absolute, relative to "
          "the working directory, or a file name shipped in share/maze_sim/mazes"),
    Param("goal", "G", "initial goal: a goal name of the maze ('G', '1'..'9') or 'row,col'"),
    Param("seed", 0, "seed of the world's sensor-noise generator", low=0, high=2 ** 63 - 1,
          integer=True),
    Param("sensor_noise", 0.0, "std of the Gaussian noise on the sensed coordinates (cells)",
          low=0.0, high=100.0),
    Param("max_episode_steps", 0, "truncate an episode after this many steps (0 = never)",
          low=0, high=2 ** 62, integer=True),
    Param("max_steps", 0, "stop after this many observations (0 = run until shut down)",
          low=0, high=2 ** 62, integer=True),
    Param("exit_when_done", False, "exit (code 0) after max_steps, printing a SUMMARY line"),
    Param("resend_period", 1.0, "resend the current observation after this many seconds "
          "without its action (recovers from late or restarted nodes)", low=0.01,
          high=3600.0),
    Param("pose_rate", 10.0, "agent pose publication rate (Hz)", low=0.1, high=1000.0),
    Param("trajectory_path", "", "write 'step_id episode row col' per observation and the "
          "goal changes to this file at exit (empty = do not write)"),
    Param("start_delay", 0.0, "seconds to wait after start before the first observation",
          low=0.0, high=3600.0),
    Param("await_recorder", False, "publish the first observation only once a recorder said "
          "on 'recorder_ready' that it has matched every per-step publisher (and start_delay "
          "has passed), and go past it only once the recorder said on 'recorder_run' that "
          "it has this run on every per-step topic, so the bag holds the run's first step "
          "on every topic"),
    *CHECKPOINT_SPECS,
)


def parse_goal(maze: Maze, goal: str):
    goal = goal.strip()
    if "," in goal:
        try:
            r, c = (int(v) for v in goal.split(","))
        except ValueError:
            raise ParamError(f"parameter 'goal' = {goal!r}: expected a goal name or "
                             "'row,col'") from None
        return (r, c)
    return goal


class MazeSimNode(Node):
    def __init__(self):
        super().__init__("maze_sim", **NODE_OPTIONS)
        p = declare_parameters(self, SPECS)
        self.p = p
        try:
            path = maze_file(p["maze"])
        except DataFileError as exc:
            raise ParamError(f"parameter 'maze': {exc}") from None
        maze = Maze.from_file(path)
        noise = {"sensor_noise": p["sensor_noise"]} if p["sensor_noise"] else {}
        try:
            self.world = make_world(p["world"], maze, parse_goal(maze, p["goal"]),
                                    p["max_episode_steps"] or None, seed=p["seed"], **noise)
        except WorldError as exc:
            raise ParamError(f"parameter 'world' = {p['world']!r}: {exc}") from None
        except MazeError as exc:
            raise ParamError(f"parameter 'goal' = {p['goal']!r}: {exc}") from None
        # where the world's cells, goal and agent are drawn: the grid's (x = col, y = row)
        # or the world's own continuous frame (PointMaze: the env's x, y in metres)
        self.continuous = hasattr(self.world, "xy")
        self.maze_path = path

        self.obs_pub = self.create_publisher(Observation, topics.OBSERVATION, STEP_QOS)
        self.grid_pub = self.create_publisher(OccupancyGrid, topics.GRID, LATCHED_QOS)
        self.goal_pub = self.create_publisher(PointStamped, topics.GOAL, LATCHED_QOS)
        self.pose_pub = self.create_publisher(PoseStamped, topics.AGENT_POSE, SENSOR_QOS)
        self.event_pub = self.create_publisher(String, topics.EVENTS, LATCHED_QOS)
        self.senses_pub = self.create_publisher(SensorInfo, topics.WORLD_SENSES, LATCHED_QOS)
        subscribe_decoded(self, Action, topics.ACTION, self.on_action, STEP_QOS)
        services = MutuallyExclusiveCallbackGroup()
        for name in (topics.SET_GOAL, topics.SIM_SET_GOAL):   # the graph's goal, and ours
            self.create_service(SetGoal, name, self.on_set_goal, callback_group=services)
        self.create_service(SetCell, topics.SET_CELL, self.on_set_cell, callback_group=services)
        self.create_service(FireEvent, topics.FIRE_EVENT, self.on_fire_event,
                            callback_group=services)
        self.create_service(Trigger, topics.RESET, self.on_reset, callback_group=services)

        self.run_id = new_run_id()         # this run's identity (tmgwr_common.lockstep)
        self.step_id = -1                  # id of the observation awaiting its action
        self.resends = 0                   # of the current observation
        self.last_action: tuple[int, float] | None = None   # (step, time) of the last one
        self.foreign = (0.0, 0)            # (time, count) of ignored actions of other runs
        self.ring_size = 0                 # subscribers + ring publishers last counted
        self.joined_at = -math.inf         # when that count last grew (a node joined)
        self.logged_at = -math.inf         # of the last 'no action' line
        self.current: bytes | None = None  # the observation awaiting its action, serialized
        self.sent_at = 0.0
        self.first_sent = 0.0              # first publication of the current step
        self.pending_goal = None           # (row, col) applied at the next observation
        self.pending_reset = False
        self.finished = False
        self.exit_code = 0
        self.trajectory: list[tuple[int, int, int, int]] = []
        self.goal_changes: list[tuple[int, tuple[int, int]]] = []
        self.goals_reached = 0
        self.episode_len = 0
        self.t_start = None
        self.t_warm = None
        self.timer = CallbackTimer()
        self.world_timer = CallbackTimer()   # the world's own step (physics) within it
        # the counters, goal and layout survive any stop (tmgwr_common.checkpoint)
        self.checkpoints = Checkpointer("maze_sim", p, self.get_logger(),
                                        {"maze": maze_fingerprint(maze)}, self.get_namespace())
        self.restore(self.checkpoints.resume({"walls": ("b", 2)}, self.check_checkpoint))

        self.publish_senses()
        self.publish_grid()
        self.publish_goal()
        self.create_timer(1.0 / p["pose_rate"], self.publish_pose)
        self.create_timer(min(0.1, p["resend_period"]), self.check_resend)
        # the first observation waits for start_delay and, when asked, for the recorder
        self.delay_over = False
        self.recorder_ready = not p["await_recorder"]
        # ... and the first step is held (resent) until the recorder has it on every topic
        self.run_recorded = not p["await_recorder"]
        self.held: Action | None = None      # the first step's action, while held
        if p["await_recorder"]:
            self.create_subscription(String, topics.RECORDER_READY, self.on_recorder_ready,
                                     LATCHED_QOS)
            self.create_subscription(UInt64, topics.RECORDER_RUN, self.on_recorder_run,
                                     LATCHED_QOS)
            self._waiting_timer = self.create_timer(RECORDER_WAIT_LOG, self.say_waiting)
        self._start_timer = self.create_timer(max(p["start_delay"], 0.01), self.on_delay_over)
        self.t_ready = time.monotonic()
        self.get_logger().info(
            f"maze_sim ready: run {self.run_id}, world {p['world']}, maze {path} "
            f"({maze.walls.shape[0]}x{maze.walls.shape[1]}), goal {self.world.goal}, "
            f"seed {p['seed']}, max_steps {p['max_steps'] or 'none'}")

    # ------------------------------------------------------------------ the ring
    def on_delay_over(self):
        self._start_timer.cancel()
        self.delay_over = True
        self.start()

    def on_recorder_ready(self, msg: String):
        if not self.recorder_ready:
            self.recorder_ready = True
            self._waiting_timer.cancel()
            self.get_logger().info(f"the recorder is ready ({shown(msg.data)})")
            self.start()

    def on_recorder_run(self, msg: UInt64):
        """The recorder has a run on every ring topic (0: it records none of them): a held
        first step goes on."""
        if self.run_recorded or msg.data not in (0, self.run_id):
            return
        self.run_recorded = True
        self.get_logger().info(f"the recorder has run {self.run_id} on every ring topic"
                               if msg.data else "the recorder records no ring topic")
        held, self.held = self.held, None
        if held is not None:
            self.on_action(held)

    def say_waiting(self):
        self.get_logger().warning(
            f"waiting for a recorder on '{self.resolve_topic_name(topics.RECORDER_READY)}' "
            f"before the first observation (await_recorder is true; "
            f"{time.monotonic() - self.t_ready:.0f} s so far)")

    def start(self):
        """The ring's first observation, once start_delay passed and the recorder (when
        awaited) is ready; once."""
        if self.t_start is not None or not (self.delay_over and self.recorder_ready):
            return
        self.t_start = time.perf_counter()
        self.start_episode(first=True)

    def start_episode(self, first: bool = False):
        obs, _ = self.world.reset()
        if not first:
            self.pending_reset = False
        self.episode_len = 0
        self.publish_observation(obs, episode_start=True)

    def on_action(self, msg):
        """An Action (its fields, read by tmgwr_common.cdr)."""
        if msg.run_id != self.run_id:
            self.foreign_action(msg)
            return
        if msg.step_id != self.step_id or self.current is None or self.finished:
            return                          # a duplicate answer to a resent observation
        if not self.run_recorded:           # resent until the recorder has every topic
            if self.held is None:
                self.get_logger().info(
                    f"step {msg.step_id} answered: held until the recorder has run "
                    f"{self.run_id} on every ring topic (the observation is resent)")
            self.held = msg
            return
        self.answered(msg.step_id)
        with self.timer:
            if self.pending_reset or msg.action == Action.NONE:
                self.start_episode()
                return
            if msg.action >= N_ACTIONS:
                self.get_logger().error(f"step {msg.step_id}: invalid action {msg.action}")
                return
            with self.world_timer:
                obs, _, terminated, truncated, info = self.world.step(msg.action)
            self.episode_len += 1
            if info.reached_goal:
                self.goals_reached += 1
                self.get_logger().info(
                    f"episode {info.episode}: goal {self.world.goal} reached in "
                    f"{self.episode_len} steps (step {self.step_id + 1})")
            self.publish_observation(obs, action=msg.action, motor=msg.motor,
                                     bumped=info.bumped, goal_reached=info.reached_goal,
                                     previous_goal_reached=info.reached_previous_goal,
                                     terminal=terminated or truncated,
                                     truncated=truncated and not terminated)

    def publish_observation(self, obs, episode_start=False, action=Action.NONE, motor=(),
                            bumped=False, goal_reached=False, previous_goal_reached=False,
                            terminal=False, truncated=False):
        if self.p["max_steps"] and self.step_id + 1 >= self.p["max_steps"]:
            self.finish()
            return
        self.step_id += 1
        if self.step_id == WARMUP_STEPS:
            self.t_warm = time.perf_counter()
        if self.pending_goal is not None:   # a goal change lands on this observation
            self.apply_goal(self.pending_goal)
            self.pending_goal = None
        m = OBSERVATION.new()
        m.header.stamp.sec, m.header.stamp.nanosec = divmod(
            self.get_clock().now().nanoseconds, 10 ** 9)       # what Time.to_msg() gives
        m.header.frame_id = FRAME
        m.run_id = self.run_id
        m.step_id = self.step_id
        m.episode = self.world.episode
        m.sensors = obs
        m.goal_sensors = self.world.goal_observation()
        m.episode_start = episode_start
        m.action = int(action)
        m.motor = motor
        m.bumped = bool(bumped)
        m.goal_reached = bool(goal_reached)
        m.previous_goal_reached = bool(previous_goal_reached)
        m.terminal = bool(terminal)
        m.truncated = bool(truncated)
        m.row, m.col = (int(v) for v in self.world.cell)
        self.current = OBSERVATION.encode(m)
        if self.p["trajectory_path"]:       # kept only when asked for (runs may be long)
            self.trajectory.append((self.step_id, self.world.episode, m.row, m.col))
        self.timer.publish(self.obs_pub, self.current)
        self.sent_at = time.monotonic()
        self.first_sent = self.sent_at
        self.checkpoints.step(self.step_id, self.run_id, self.checkpoint_state)

    def answered(self, step: int):
        """Book-keeping of an accepted action: say when the ring resumed after resends, and
        how long the first step of this run took from ready."""
        now = time.monotonic()
        if step == 0:
            self.get_logger().info(
                f"run {self.run_id}: the ring answered step 0 {now - self.t_ready:.2f} s after "
                f"this simulator was ready (start_delay {self.p['start_delay']} s)")
        elif self.resends:
            self.get_logger().info(f"step {step} answered after {self.resends} resends "
                                   f"({now - self.first_sent:.2f} s): the ring resumed")
        self.resends = 0
        self.last_action = (step, now)

    def foreign_action(self, msg: Action):
        """An action that is not of this run: ignored, said at most every WARN_PERIOD s."""
        now = time.monotonic()
        last, count = self.foreign
        if now - last < WARN_PERIOD:
            self.foreign = (last, count + 1)
            return
        self.foreign = (now, 0)
        whose = ("no run (run_id 0: a stray publisher?)" if msg.run_id == 0 else
                 f"run {msg.run_id}, not this simulator's run {self.run_id}")
        more = f" ({count} more in the last {now - last:.0f} s)" if count else ""
        self.get_logger().warning(f"ignored an action for step {msg.step_id} of {whose}{more}")

    def check_resend(self):
        """Resend the current observation after ``resend_period`` without its action, or
        every JOIN_RESEND s while this run has had no action yet or a node has just joined
        the ring (its endpoints are being matched; a duplicate is answered from cache)."""
        now = time.monotonic()
        size = self.obs_pub.get_subscription_count() + sum(
            self.count_publishers(t) for t, _ in RING)
        if size > self.ring_size:
            self.joined_at = now
        self.ring_size = size
        if self.current is None or self.finished:
            return
        period = self.p["resend_period"]
        if self.last_action is None or now - self.joined_at < period:
            period = min(period, JOIN_RESEND)
        if now - self.sent_at > period:
            self.resends += 1
            if now - self.logged_at >= self.p["resend_period"]:
                self.logged_at = now
                self.get_logger().info(
                    f"step {self.step_id} of run {self.run_id} held for the recorder "
                    f"{now - self.first_sent:.1f} s: resending the observation"
                    if self.held is not None else
                    f"no action for step {self.step_id} of run {self.run_id} within "
                    f"{now - self.first_sent:.1f} s: resending the observation "
                    f"({self.ring_status(now)})")
            self.obs_pub.publish(self.current)
            self.sent_at = now

    def ring_status(self, now: float) -> str:
        """The last action heard and the ring topics nobody publishes (cheap: the local
        graph cache)."""
        parts = [f"last action: step {self.last_action[0]}, {now - self.last_action[1]:.1f} s "
                 "ago" if self.last_action else "no action yet from this run"]
        if not self.obs_pub.get_subscription_count():
            parts.append(f"nobody subscribes to {topics.OBSERVATION} (sensory_preprocessor)")
        missing = [f"{t} ({who})" for t, who in RING if not self.count_publishers(t)]
        if missing:
            parts.append("no publisher on " + ", ".join(missing))
        if self.foreign[0]:
            parts.append(f"last action of another run {now - self.foreign[0]:.1f} s ago")
        return "; ".join(parts)

    def finish(self):
        self.finished = True
        elapsed = time.perf_counter() - (self.t_start or time.perf_counter())
        steps = self.step_id + 1
        summary = {"steps": steps, "seconds": round(elapsed, 3),
                   "steps_per_s": round(steps / elapsed, 1) if elapsed > 0 else None,
                   "steady_steps_per_s": (
                       round((steps - WARMUP_STEPS) / (time.perf_counter() - self.t_warm), 1)
                       if self.t_warm and steps > WARMUP_STEPS else None),
                   "goals_reached": self.goals_reached, "episode": self.world.episode,
                   "goal_changes": [[s, list(c)] for s, c in self.goal_changes],
                   "sim_callback": self.timer.summary()}
        self.get_logger().info(f"finished {steps} steps in {elapsed:.2f} s")
        print("SUMMARY " + json.dumps(summary), flush=True)
        self.write_trajectory()
        if not self.p["exit_when_done"]:
            self.finished = False           # keep serving topics/services, stop stepping
            self.current = None

    def write_trajectory(self):
        path = self.p["trajectory_path"]
        if not path:
            return
        lines = [f"# maze {self.maze_path}"]
        lines += [f"goal {s} {c[0]} {c[1]}" for s, c in self.goal_changes]
        lines += [f"{s} {e} {r} {c}" for s, e, r, c in self.trajectory]
        Path(path).write_text("\n".join(lines) + "\n")

    def on_shutdown(self):
        if self.p["trajectory_path"] and self.current is not None:
            self.write_trajectory()
        print(f"maze_sim: {self.timer.summary()}", flush=True)
        w = self.world_timer
        k = 1e6 / w.n if w.n else 0.0
        print(f"maze_sim world {self.p['world']}: {w.n} world steps, mean {k * w.total:.0f} "
              f"us, cpu mean {k * w.cpu:.0f} us", flush=True)
        self.checkpoints.stop(self.step_id, self.run_id, self.checkpoint_state)

    # ------------------------------------------------------------------ checkpoint
    def checkpoint_state(self):
        """(state, arrays) that continue this run: counters, goal, layout, noise generator.
        A resumed simulator starts a new episode (the one cut by the stop is not resumed)."""
        w = self.world
        cell = lambda c: [int(v) for v in c] if c is not None else None   # noqa: E731
        return ({"episode": w.episode, "total_steps": w.total_steps, "goal": cell(w.goal),
                 "pending_goal": cell(self.pending_goal), "fired": list(w.fired),
                 "goals_reached": self.goals_reached,
                 "goal_changes": [[int(s), cell(c)] for s, c in self.goal_changes],
                 "rng": w.rng.bit_generator.state},
                {"walls": w.walls})

    def check_checkpoint(self, ck: Checkpoint) -> None:
        walls = ck.arrays["walls"]
        if walls.shape != self.world.walls.shape:
            raise CheckpointError(f"{ck.path}: a {walls.shape} layout, the maze is "
                                  f"{self.world.walls.shape}: refused")
        try:
            episode, total = int(ck.state["episode"]), int(ck.state["total_steps"])
            goal = tuple(int(v) for v in ck.state["goal"])
            if episode < 0 or total < 0 or len(goal) != 2:
                raise ValueError("negative counters or a goal that is not (row, col)")
            if walls[self.world.maze.start] or walls[goal]:
                raise ValueError("the start or the goal is a wall")
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise CheckpointError(f"{ck.path}: {exc}: refused") from None

    def restore(self, ck: Checkpoint | None) -> None:
        if ck is None:
            return
        w, s = getattr(self.world, "grid", self.world), ck.state   # the book-keeper
        w.walls, w.fired = ck.arrays["walls"].astype(bool), [str(e) for e in s["fired"]]
        w.set_goal(tuple(int(v) for v in s["goal"]))
        w.episode, w.total_steps = int(s["episode"]), int(s["total_steps"])
        try:
            w.rng.bit_generator.state = s["rng"]
        except (KeyError, TypeError, ValueError) as exc:
            self.get_logger().warning(f"noise generator not restored ({exc})")
        if s.get("pending_goal"):
            self.pending_goal = w.request_goal(tuple(int(v) for v in s["pending_goal"]))
        if w is not self.world:                # the hosted world follows its book-keeper
            self.world.sync()
        self.step_id = ck.step_id              # the next observation is step_id + 1
        self.goals_reached = int(s.get("goals_reached", 0))
        self.goal_changes = [(int(a), tuple(c)) for a, c in s.get("goal_changes", [])]
        self.get_logger().info(
            f"resumed at step {ck.step_id + 1} (new run {self.run_id}; the checkpoint's run "
            f"{ck.run_id}): episode {w.episode + 1} starts, goal {w.goal}, "
            f"{self.goals_reached} goals reached so far, events {w.fired or 'none'}")

    # ------------------------------------------------------------------ goal and layout
    def apply_goal(self, cell):
        try:
            self.world.set_goal(cell)
        except MazeError as exc:            # the cell became a wall since the request
            self.get_logger().error(f"goal change to {cell} dropped: {exc}")
            return
        self.goal_changes.append((self.step_id, self.world.goal))
        self.publish_goal()
        self.event(f"step {self.step_id}: goal -> row {cell[0]}, col {cell[1]}")

    def on_set_goal(self, req, resp):
        """``/set_goal`` (the graph's goal) and ``/maze_sim/set_goal``: the answer is this
        simulator's own check (inside, free, reachable: :meth:`GridWorld.check_goal`), so
        "accepted" means the goal applies from the next observation."""
        x, y = req.goal.x, req.goal.y
        asked = f"goal (x={x:.6g}, y={y:.6g})"      # never 301 digits for x = 1e300
        rows, cols = self.world.walls.shape
        replaced, refusal = self.pending_goal, None
        x0, y0 = self.frame_origin()
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(req.goal.z)):
            refusal = "not finite"
        elif self.continuous and not (x0 <= x < x0 + cols and y0 <= y < y0 + rows):
            refusal = (f"outside the {rows}x{cols} maze (x in [{x0:g}, {x0 + cols:g}), "
                       f"y in [{y0:g}, {y0 + rows:g}))")
        elif not self.continuous and not (-0.5 <= x < cols - 0.5 and -0.5 <= y < rows - 0.5):
            refusal = (f"outside the {rows}x{cols} maze (x in 0..{cols - 1}, "
                       f"y in 0..{rows - 1})")
        else:
            row, col = self.world.cell_of((x, y)) if self.continuous else \
                (int(math.floor(y + 0.5)), int(math.floor(x + 0.5)))
            try:
                # checked now and kept free by cell and event edits until it applies
                self.pending_goal = self.world.request_goal((row, col))
            except MazeError as exc:
                refusal = str(exc)
        if refusal is not None:
            resp.accepted, resp.message = False, f"{asked} refused: {refusal}"
            self.get_logger().warning(resp.message)
            return resp
        resp.accepted = True
        gx, gy = self.cell_position((row, col))
        resp.message = (f"goal set to row {row}, col {col} (x={gx:g}, y={gy:g}); it applies "
                        f"from step {self.step_id + 1}")
        if replaced is not None and replaced != self.pending_goal:
            resp.message += (f" (replaces the change to row {replaced[0]}, col {replaced[1]}"
                             " requested in the same step)")
        self.get_logger().info(resp.message)
        return resp

    def on_set_cell(self, req, resp):
        try:
            self.world.set_cell(req.row, req.col, req.blocked)
        except MazeError as exc:        # outside, or it would make the task unsolvable
            resp.accepted, resp.message = False, str(exc)
            self.get_logger().warning(f"set_cell refused: {exc}")
            return resp
        what = "blocked" if req.blocked else "opened"
        resp.accepted, resp.message = True, f"cell (row {req.row}, col {req.col}) {what}"
        self.publish_grid()
        self.event(f"step {self.step_id}: {resp.message}")
        return resp

    def on_fire_event(self, req, resp):
        name = req.event.strip()
        if len(name) != 1 or not name.islower():
            resp.accepted = False
            resp.message = f"event {shown(req.event)}: expected one lowercase letter a-z"
            return resp
        try:
            self.world.fire_event(name)
        except MazeError as exc:        # unknown, or it would make the task unsolvable
            resp.accepted, resp.message = False, str(exc)
            self.get_logger().warning(f"fire_event refused: {exc}")
            return resp
        resp.accepted, resp.message = True, f"event {name!r} fired"
        self.publish_grid()
        self.event(f"step {self.step_id}: {resp.message}")
        return resp

    def on_reset(self, req, resp):
        self.pending_reset = True
        resp.success = True
        resp.message = f"a new episode starts after step {self.step_id}"
        return resp

    # ------------------------------------------------------------------ inspection
    def event(self, text: str):
        self.get_logger().info(text)
        self.event_pub.publish(String(data=text))

    def publish_senses(self):
        """What the world declares of its sensor (goal region, sensor's range), in sensation
        units, latched: the agent nodes are told them as the in-process agent is
        (``Senses``), for this run."""
        tol, low, high = declared_sensor(self.world)
        m = SensorInfo()
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = FRAME
        m.run_id, m.gain, m.goal_tolerance = self.run_id, 1.0, tol
        if low is not None:
            m.low = np.asarray(low, dtype=float).ravel().tolist()
            m.high = np.asarray(high, dtype=float).ravel().tolist()
        self.senses_pub.publish(m)

    def publish_grid(self):
        rows, cols = self.world.walls.shape
        g = OccupancyGrid()
        g.header.stamp = self.get_clock().now().to_msg()
        g.header.frame_id = FRAME
        g.info.resolution = 1.0
        g.info.width, g.info.height = cols, rows
        g.info.origin.position.x, g.info.origin.position.y = self.frame_origin()
        g.info.origin.orientation.w = 1.0
        walls = self.world.walls[::-1] if self.continuous else self.world.walls  # y up: last row
        g.data = (walls.astype(np.int8) * 100).ravel().tolist()
        self.grid_pub.publish(g)

    def publish_goal(self):
        m = PointStamped()
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = FRAME
        m.point.x, m.point.y = self.cell_position(self.world.goal)
        self.goal_pub.publish(m)

    def publish_pose(self):
        if not self.pose_pub.get_subscription_count():
            return                          # a stream for viewers: nobody looks, nothing made
        m = PoseStamped()
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = FRAME
        if self.continuous:             # where the point is, not its cell
            m.pose.position.x, m.pose.position.y = (float(v) for v in self.world.data.qpos[:2])
        else:
            m.pose.position.x, m.pose.position.y = self.cell_position(self.world.cell)
        m.pose.orientation.w = 1.0
        self.pose_pub.publish(m)

    def frame_origin(self) -> tuple[float, float]:
        """The (x, y) of the maze's lower-left corner in the ``maze`` frame: the grid's
        (-0.5, -0.5) (cell (row, col) centred at x = col, y = row), or the continuous
        world's (the env's frame, row 0 at the top: cell centres at :meth:`cell_position`)."""
        if not self.continuous:
            return -0.5, -0.5
        rows, cols = self.world.walls.shape
        x, y = self.world.xy((rows - 1, 0))
        return float(x) - 0.5, float(y) - 0.5

    def cell_position(self, cell) -> tuple[float, float]:
        """The centre of ``cell`` (row, col) in the ``maze`` frame."""
        if self.continuous:
            x, y = self.world.xy(cell)
            return float(x), float(y)
        return float(cell[1]), float(cell[0])


def maze_fingerprint(maze: Maze) -> str:
    """What a checkpoint's maze must match: the layout and start as loaded from the file."""
    h = hashlib.sha256(maze.walls.astype(bool).tobytes())
    h.update(repr((maze.walls.shape, tuple(maze.start))).encode())
    return h.hexdigest()[:16]


def main(args=None):
    raise SystemExit(run(MazeSimNode, "maze_sim", args))


if __name__ == "__main__":
    main()
