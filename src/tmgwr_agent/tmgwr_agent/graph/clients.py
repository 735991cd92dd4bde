"""Talking to a running graph: one-shot service calls and the episode monitor.

* :func:`call` -- wait (a bounded time) for a service, call it once, return the response;
  :class:`NoGraph` when nothing answers, so the CLI can say "no graph is running".
  Futures are completed with ``executor.spin_once`` in a loop, not
  ``spin_until_future_complete`` (rclpy 7 slows down on repeated calls: ros2/rclpy#1374).
* :func:`subscribe_monitor` -- feeds an :class:`~tmgwr_agent.episodes.EpisodeMonitor`
  (ROS-free: it turns Observations into episodes) from the Observation topic.

rclpy is imported inside the functions so that importing this module stays cheap.
"""

from __future__ import annotations

import time

from tmgwr_agent.episodes import EpisodeMonitor
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
    """SetGoal request: x = column, y = row (cell coordinates; docs/graph.md)."""
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
"""Observations the monitor's reader keeps before the oldest is dropped: many seconds of
the lockstep graph. The ring's own STEP_QOS depth is enough for a node that answers
every step, but the observer is a bystander that can fall behind by many steps
while it prints or waits for a service, and with a depth of 10 it lost observations (so
episodes). A reliable keep-last reader never slows the publisher down, so a deep history
costs only memory."""


def monitor_qos():
    """STEP_QOS (reliable, volatile) with a :data:`MONITOR_DEPTH` history."""
    from rclpy.qos import QoSProfile

    from tmgwr_common.node import STEP_QOS
    return QoSProfile(history=STEP_QOS.history, depth=MONITOR_DEPTH,
                      reliability=STEP_QOS.reliability, durability=STEP_QOS.durability)


def subscribe_monitor(node, monitor: EpisodeMonitor, qos=None):
    """Feed ``monitor`` the Observation topic from ``node`` (default QoS:
    :func:`monitor_qos`); returns the subscription."""
    from tmgwr_interfaces.msg import Observation
    return node.create_subscription(Observation, topics.OBSERVATION,
                                    monitor.on_observation, qos or monitor_qos())
