"""Stray messages on the per-step topics (issue 24, point 1), shared by
``test_stray_fuzz.py`` (the liveness floor) and ``measure_strays.py`` (rate after / before).

A stray is what a careless or hostile user on the same domain publishes with the real
``ros2 topic pub``: huge, zero and other-run ids on each of the five per-step topics, once
or repeated. ``STEP_MONITOR`` is a subscriber of ``/observation`` that prints the newest
(run, step) the simulator published, so a test can count the ring's steps from outside.
"""

from __future__ import annotations

import json
import re
import time
from dataclasses import dataclass

from ros_helpers import RosProcess, ros2_cli

U64_MAX = 2 ** 64 - 1

# Prints "STEP <run_id> <step_id>" for the newest observation, at most every 0.1 s.
STEP_MONITOR = r"""
import time
import rclpy
from tmgwr_common.node import STEP_QOS
from tmgwr_interfaces.msg import Observation
rclpy.init()
node = rclpy.create_node("step_monitor")
newest = [None, 0.0]
def on_obs(m):
    newest[0] = (m.run_id, m.step_id)
node.create_subscription(Observation, "/observation", on_obs, STEP_QOS)
print("MONITOR READY", flush=True)
while rclpy.ok():
    rclpy.spin_once(node, timeout_sec=0.05)
    if newest[0] is not None and time.monotonic() - newest[1] >= 0.1:
        print("STEP %d %d" % newest[0], flush=True)
        newest[1] = time.monotonic()
"""

STEP_LINE = re.compile(r"^STEP (\d+) (\d+)$")


@dataclass(frozen=True)
class Stray:
    topic: str
    type: str
    fields: dict
    times: int = 1                  # published this many times in a row (10 Hz)
    subscribers: int = 1            # ring subscribers to wait for (`ros2 topic pub -w`)
    latched: bool = False           # offered transient-local, as its subscribers request

    def __str__(self) -> str:
        return f"{self.topic} {json.dumps(self.fields)} x{self.times}"


def strays(run: int) -> list[Stray]:
    """The fuzz cases for a ring whose simulator runs ``run``. Subscribers: /observation
    has the preprocessor and the step monitor, /action the simulator and the estimator."""
    topics = (("/observation", "Observation", 2), ("/features", "Features", 1),
              ("/sensorimotor_state", "SensorimotorState", 1),
              ("/motivation", "MotivationField", 1), ("/action", "Action", 2))
    out = []
    for topic, name, subs in topics:
        t = f"tmgwr_interfaces/msg/{name}"
        out += [Stray(topic, t, {"run_id": U64_MAX, "step_id": 1}, subscribers=subs),
                Stray(topic, t, {"run_id": run, "step_id": 999999999}, subscribers=subs),
                Stray(topic, t, {"run_id": U64_MAX, "step_id": U64_MAX}, subscribers=subs)]
    out += [Stray("/action", "tmgwr_interfaces/msg/Action", {"run_id": 0, "step_id": 0},
                  subscribers=2),
            Stray("/features", "tmgwr_interfaces/msg/Features",
                  {"run_id": run - 1, "step_id": 5}),
            # well-formed (the paper maze's 2-d features): the learner learns it, and the
            # ring answers it down to an action of step 999999999 (test_lockstep_graph's)
            Stray("/features", "tmgwr_interfaces/msg/Features",
                  {"run_id": run, "step_id": 999999999, "features": [0.1, 0.1],
                   "goal_features": [0.1, 1.1], "gain": 0.1, "episode_start": True}),
            Stray("/observation", "tmgwr_interfaces/msg/Observation",
                  {"run_id": run, "step_id": 0}, subscribers=2),
            Stray("/action", "tmgwr_interfaces/msg/Action",
                  {"run_id": U64_MAX, "step_id": 1}, times=5, subscribers=2),
            Stray("/motivation", "tmgwr_interfaces/msg/MotivationField",
                  {"run_id": run, "step_id": 999999999}, times=5)]
    # the world's sensor declaration (latched): another run's, on both legs, and a second
    # one of the current run; the one the ring was started with stays in force
    info = "tmgwr_interfaces/msg/SensorInfo"
    out += [Stray("/world_senses", info, {"run_id": U64_MAX, "gain": 1.0,
                                          "goal_tolerance": 3.0}, latched=True),
            Stray("/feature_senses", info, {"run_id": U64_MAX, "gain": 1.0,
                                            "goal_tolerance": 3.0}, latched=True),
            Stray("/feature_senses", info, {"run_id": run, "gain": 1.0,
                                            "goal_tolerance": 3.0}, latched=True)]
    return out


def publish(domain: int, stray: Stray) -> str:
    """``ros2 topic pub`` the stray (after its subscribers matched); its output."""
    args = ["topic", "pub", "-w", str(stray.subscribers)]
    args += ["--once"] if stray.times == 1 else ["--times", str(stray.times), "-r", "10"]
    args += ["--qos-durability", "transient_local"] if stray.latched else []
    p = ros2_cli(*args, stray.topic, stray.type, json.dumps(stray.fields), domain=domain,
                 name=f"ros2 topic pub {stray.topic}")
    with p:
        return p.wait(timeout=90)


def newest_step(monitor: RosProcess, run: int, since: int = 0) -> int | None:
    """The newest step of run ``run`` the monitor saw, from step ``since`` on. Strays on
    /observation reach the monitor too: a step of another run, or 10**6 steps or more ahead
    of ``since`` (no test runs that long), is not the simulator's."""
    for line in reversed(monitor.lines):
        m = STEP_LINE.match(line)
        if m and int(m[1]) == run and since <= int(m[2]) < since + 10 ** 6:
            return int(m[2])
    return None


def seconds_to(monitor: RosProcess, run: int, step: int, timeout: float,
               since: int = 0) -> float | None:
    """Seconds until the monitor saw step ``step`` of run ``run`` (None: not within
    ``timeout``)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        now = newest_step(monitor, run, since)
        if now is not None and now >= step:
            return time.monotonic() - t0
        time.sleep(0.1)
    return None
