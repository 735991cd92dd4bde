"""The composed graph (``tmgwr_agent composed``: the five nodes in one process on one
executor) is the same agent as the five processes: same names, topics and services, and the
same cells as the in-process TMGWRAgent loop step for step, a /set_goal change included.
"""

from __future__ import annotations

import pytest
from ros_helpers import ROOT, parse_json_line, ros2_run, spawn_python

pytestmark = pytest.mark.ros

MAZE = ROOT / "src" / "maze_sim" / "mazes" / "paper_13x17.txt"

# Lists the graph's nodes and services once they are all there, then asks /set_goal for
# goal 1 (row 2, col 15) when the simulator publishes observation argv[1]: the change
# lands on a step the test does not choose, the run records where (trajectory file).
OBSERVER = r"""
import sys, time
import rclpy
from geometry_msgs.msg import Point
from tmgwr_interfaces.msg import Observation
from tmgwr_interfaces.srv import SetGoal
from tmgwr_common import topics
from tmgwr_common.node import STEP_QOS
at = int(sys.argv[1])
rclpy.init()
node = rclpy.create_node("test_observer")
want = {"maze_sim", "sensory_preprocessor", "map_learner", "motivation_estimator",
        "action_selector"}
deadline = time.monotonic() + 60
while time.monotonic() < deadline and not want <= set(node.get_node_names()):
    rclpy.spin_once(node, timeout_sec=0.1)
print("NODES " + " ".join(sorted(set(node.get_node_names()) & want)), flush=True)
wanted = {"/set_goal", "/maze_sim/set_goal", "/maze_sim/set_cell", "/maze_sim/fire_event",
          "/maze_sim/reset", "/map_learner/save_map", "/map_learner/load_map"}
services = set()
while time.monotonic() < deadline and not wanted <= services:  # discovery may still run
    rclpy.spin_once(node, timeout_sec=0.1)
    services = {n for n, _ in node.get_service_names_and_types()}
print("SERVICES " + " ".join(sorted(services & wanted)), flush=True)
client = node.create_client(SetGoal, topics.SET_GOAL)
state = {"sent": None}
def on_obs(m):
    if state["sent"] is None and m.step_id >= at:
        state["sent"] = client.call_async(SetGoal.Request(goal=Point(x=15.0, y=2.0, z=0.0)))
node.create_subscription(Observation, topics.OBSERVATION, on_obs, STEP_QOS)
print("OBSERVER READY", flush=True)
while rclpy.ok():
    rclpy.spin_once(node, timeout_sec=0.1)
    fut = state["sent"]
    if fut is not None and fut.done():
        print("SET_GOAL " + str(fut.result().accepted) + " " + fut.result().message, flush=True)
        break
while rclpy.ok():
    rclpy.spin_once(node, timeout_sec=0.1)
"""


@pytest.mark.timeout(240)
def test_composed_graph_equals_in_process_step_for_step(ros_domain, tmp_path):
    from tmgwr_agent.experiments.lockstep import read_trajectory, run_reference

    steps, change_at = 3000, 1000
    traj = tmp_path / "trajectory.txt"
    observer = spawn_python(OBSERVER, str(change_at), domain=ros_domain, name="observer")
    # per-node seeds with rcl's node-qualified -p: the simulator 0, the selector 1
    graph = ros2_run("tmgwr_agent", "composed", "--ros-args",
                     "-p", "maze_sim:seed:=0", "-p", "action_selector:seed:=1",
                     "-p", "goal:=2", "-p", f"max_steps:={steps}", "-p", "exit_when_done:=true",
                     "-p", f"trajectory_path:={traj}", "-p", "start_delay:=1.0",
                     domain=ros_domain,     # the learner's map is saved under this HOME
                     env={"HOME": str(tmp_path), "ROS_HOME": str(tmp_path / ".ros")})
    with observer, graph:
        ready = graph.wait_for_line("composed ready", timeout=60)
        nodes = observer.wait_for_line("^NODES ", timeout=60).split()[1:]
        services = observer.wait_for_line("^SERVICES ", timeout=30).split()[1:]
        answer = observer.wait_for_line("^SET_GOAL ", timeout=120)
        out = graph.wait(timeout=180)
    assert "EventsExecutor" in ready or "SingleThreadedExecutor" in ready, ready
    assert nodes == sorted(["maze_sim", "sensory_preprocessor", "map_learner",
                            "motivation_estimator", "action_selector"]), nodes
    for srv in ("/set_goal", "/maze_sim/set_goal", "/maze_sim/set_cell",
                "/maze_sim/fire_event", "/maze_sim/reset", "/map_learner/save_map",
                "/map_learner/load_map"):
        assert srv in services, (srv, services)
    assert answer.startswith("SET_GOAL True"), answer
    summary = parse_json_line(out, "SUMMARY ")
    assert summary["steps"] == steps
    for name in ("maze_sim", "sensory_preprocessor", "map_learner", "motivation_estimator",
                 "action_selector"):                 # every node's shutdown hook ran
        assert f"{name}: {steps}" in out or f"{name}: {steps - 1}" in out, (name, out)
    cells, changes = read_trajectory(traj)
    assert len(cells) == steps and [c for _, c in changes] == [(2, 15)], changes
    assert changes[0][0] >= change_at
    ref, _ = run_reference(MAZE, steps, goal="2", world_seed=0, agent_seed=1,
                           goal_changes=changes)
    first = next((i for i, (a, b) in enumerate(zip(cells, ref)) if a != b), None)
    assert first is None, (f"composed and in-process differ from step {first}: "
                           f"{cells[first:first + 3]} vs {ref[first:first + 3]}")


def test_composed_refuses_an_invalid_parameter_naming_node_and_parameter(ros_domain):
    p = ros2_run("tmgwr_agent", "composed", "--ros-args", "-p", "gamma:=1.5",
                 domain=ros_domain)
    with p:
        out = p.wait(timeout=60, check=False)
    assert p.proc.returncode == 2, p.describe("composed did not exit with code 2")
    assert "cannot start motivation_estimator" in out and "'gamma'" in out, out
    assert "composed ready" not in out and "Traceback" not in out, out
