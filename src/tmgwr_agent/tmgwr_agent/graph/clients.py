"""Talking to a running graph: one-shot service calls and the episode monitor.

* :func:`call` -- wait (a bounded time) for a service, call it once, return the response;
  :class:`NoGraph` when nothing answers, so the CLI can say "no graph is running".
  Futures are completed with ``executor.spin_once`` in a loop, not
  ``spin_until_future_complete`` (rclpy 7 slows down on repeated calls: ros2/rclpy#1374).
* :class:`EpisodeMonitor` -- follows the Observation topic and turns it into episodes:
  how many steps each took and whether it ended at the goal, the previous goal, or was cut
  short. ``./tmgwr up`` prints it, the demo decides with it, the bench times steps with it.

rclpy is imported inside the functions so that importing this module stays cheap.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from tmgwr_common import topics


class NoGraph(RuntimeError):
    """No node offers the service: the graph is not running (in this ROS_DOMAIN_ID)."""


def _domain() -> str:
    import os
    return os.environ.get("ROS_DOMAIN_ID", "0")


def call(node, srv_type, name: str, request, timeout: float = 10.0, executor=None):
    """Call service ``name`` once from ``node``; raises NoGraph or TimeoutError."""
    client = node.create_client(srv_type, name)
    try:
        if not client.wait_for_service(timeout_sec=timeout):
            raise NoGraph(f"no service {name} within {timeout:.0f} s: is the graph running "
                          f"(./tmgwr up) in ROS_DOMAIN_ID={_domain()}?")
        future = client.call_async(request)
        own = executor is None
        if own:
            from rclpy.executors import SingleThreadedExecutor
            executor = SingleThreadedExecutor()
            executor.add_node(node)
        try:
            deadline = time.monotonic() + timeout
            while not future.done():
                if time.monotonic() > deadline:
                    raise TimeoutError(f"service {name} did not answer within {timeout:.0f} s")
                executor.spin_once(timeout_sec=0.05)
        finally:
            if own:
                executor.remove_node(node)
                executor.shutdown()
        if future.exception() is not None:
            raise RuntimeError(f"service {name} failed: {future.exception()}")
        return future.result()
    finally:
        node.destroy_client(client)


def call_once(srv_type, name: str, request, timeout: float = 10.0):
    """:func:`call` in a process of its own: init rclpy, make a node, call, shut down."""
    import rclpy
    rclpy.init()
    try:
        node = rclpy.create_node("tmgwr_cli")
        try:
            return call(node, srv_type, name, request, timeout)
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown()


# ----------------------------------------------------------------------- requests
def set_goal_request(x: float, y: float):
    """SetGoal request: x = column, y = row (maze cell coordinates, DESIGN.md section 2)."""
    from geometry_msgs.msg import Point
    from tmgwr_interfaces.srv import SetGoal
    return SetGoal, SetGoal.Request(goal=Point(x=float(x), y=float(y), z=0.0))


def set_cell_request(row: int, col: int, blocked: bool):
    from tmgwr_interfaces.srv import SetCell
    return SetCell, SetCell.Request(row=int(row), col=int(col), blocked=bool(blocked))


def fire_event_request(event: str):
    from tmgwr_interfaces.srv import FireEvent
    return FireEvent, FireEvent.Request(event=str(event))


def reset_request():
    from std_srvs.srv import Trigger
    return Trigger, Trigger.Request()


# ----------------------------------------------------------------------- episodes
MONITOR_DEPTH = 10000
"""Observations the monitor's reader keeps before the oldest is dropped: 20 s of the
lockstep graph at 500 steps/s. The ring's own STEP_QOS depth (10) is enough for a node that
answers every step, but the observer is a bystander that can fall behind by hundreds of
steps while it prints or waits for a service (measured: 266 lost at 510 steps/s on 2 cores
with depth 10). A reliable keep-last reader never slows the publisher down, so a deep
history costs only memory (about 1 MB here)."""


def monitor_qos():
    """STEP_QOS (reliable, volatile) with a :data:`MONITOR_DEPTH` history."""
    from rclpy.qos import QoSProfile
    from tmgwr_common.node import STEP_QOS
    return QoSProfile(history=STEP_QOS.history, depth=MONITOR_DEPTH,
                      reliability=STEP_QOS.reliability, durability=STEP_QOS.durability)


@dataclass
class EpisodeRecord:
    episode: int
    steps: int                 # actions taken in the episode
    outcome: str               # "goal", "previous_goal", "cut" (truncated / reset)
    end_step: int              # step_id of the episode's last observation
    start_cell: tuple[int, int] = (-1, -1)
    end_cell: tuple[int, int] = (-1, -1)


@dataclass
class EpisodeMonitor:
    """Episodes from the stream of Observations (one per lockstep step).

    Attach with :meth:`subscribe`; every Observation goes through :meth:`on_observation`.
    ``steps`` counts actions (observations that are not an episode's first). An episode
    ends with a ``terminal`` observation; one whose end was never seen (a reset, the
    monitor joining late) is closed as ``cut`` when the next episode starts.
    """

    episodes: list[EpisodeRecord] = field(default_factory=list)
    last_step_id: int = -1
    first_step_id: int = -1
    first_time: float = 0.0
    last_time: float = 0.0
    seen: int = 0
    missed: int = 0            # gaps in step_id after the first message
    _episode: int = -1
    _steps: int = 0
    _start_cell: tuple[int, int] = (-1, -1)
    _closed: bool = True
    on_episode: object = None  # callable(EpisodeRecord) or None

    def subscribe(self, node, qos=None):
        """Follow the Observation topic from ``node`` (default QoS: :func:`monitor_qos`)."""
        from tmgwr_interfaces.msg import Observation
        return node.create_subscription(Observation, topics.OBSERVATION,
                                        self.on_observation, qos or monitor_qos())

    def on_observation(self, msg) -> None:
        now = time.perf_counter()
        sid = int(msg.step_id)
        if sid <= self.last_step_id:
            return          # the simulator resent an observation nobody answered yet
        if self.first_step_id < 0:
            self.first_step_id, self.first_time = sid, now
        elif sid > self.last_step_id + 1:
            self.missed += sid - self.last_step_id - 1
        self.last_step_id, self.last_time = sid, now
        self.seen += 1
        cell = (int(msg.row), int(msg.col))
        if msg.episode_start or int(msg.episode) != self._episode:
            if not self._closed and self._episode >= 0:
                self._close("cut", sid - 1, cell)
            self._episode, self._steps, self._start_cell = int(msg.episode), 0, cell
            self._closed = False
        if not msg.episode_start:
            self._steps += 1
        if msg.terminal and not self._closed:
            outcome = ("goal" if msg.goal_reached else
                       "previous_goal" if msg.previous_goal_reached else "cut")
            self._close(outcome, sid, cell)

    def _close(self, outcome: str, end_step: int, cell: tuple[int, int]) -> None:
        rec = EpisodeRecord(self._episode, self._steps, outcome, end_step, self._start_cell, cell)
        self.episodes.append(rec)
        self._closed = True
        if callable(self.on_episode):
            self.on_episode(rec)

    # -------------------------------------------------------------- summaries
    def rate(self) -> float:
        """Steps per second over what this monitor saw."""
        dt = self.last_time - self.first_time
        return (self.last_step_id - self.first_step_id) / dt if dt > 0 else 0.0

    def since(self, step_id: int) -> list[EpisodeRecord]:
        """Episodes that ended after ``step_id``."""
        return [e for e in self.episodes if e.end_step > step_id]

    def reliable(self, optimal: int, streak: int = 3, slack: float = 1.5,
                 after_step: int = -1) -> bool:
        """The last ``streak`` episodes (ended after ``after_step``) all reached the goal
        within ``slack`` times the shortest path."""
        eps = self.since(after_step)
        last = eps[-streak:]
        return len(last) == streak and all(
            e.outcome == "goal" and e.steps <= slack * optimal for e in last)
