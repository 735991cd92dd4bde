"""The graph's agent is told what the in-process agent is told of the world's sensor.

The in-process agent builds its motivation estimator with the world's goal region
(``Senses.goal_tolerance``) and sensor's range (``Senses.low``, ``high``: PointMaze's
depends on the maze file), both scaled into feature units by its preprocessor's gain. Over
real DDS (``./tmgwr up --world W``, own ROS_DOMAIN_ID) maze_sim declares them
(``SensorInfo`` on ``/world_senses``), the preprocessor scales them (``/feature_senses``)
and the motivation estimator sets them on its core before it solves a step: the estimator
then holds exactly the in-process agent's goal tolerance and bounds, for each world the
graph hosts and the same maze. Both declarations are recorded, so a replay carries them.
Told the same, the composed graph walks the in-process agent's cells step for step in
MiniGrid and PointMaze (it parted from them within a few steps when it was not told).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from test_recorder import mcap_files
from world_graph import ctrl_c, up_world

from maze_sim.maze import Maze
from maze_sim.worlds import make_world
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.world_senses import world_senses

pytestmark = [pytest.mark.ros, pytest.mark.slow]

MAZE = """\
#######
#S.a.G#
#.###.#
#.1...#
#######
"""
STEPS = {"minigrid": 2000, "pointmaze": 2000}
# the estimator's line when it sets the world's declaration on its core
SET = (r"\[motivation_estimator\].*step 0 \(run \d+\): the world's senses set: goal "
       r"tolerance (\S+), sensor's range \[(.*)\] \.\. \[(.*)\] \(feature units\)")


def values(text: str) -> np.ndarray:
    return np.array([float(v) for v in text.split(",") if v.strip()])


@pytest.mark.parametrize("world", ["grid", "minigrid", "pointmaze"])
@pytest.mark.timeout(300)
def test_the_graphs_estimator_has_the_in_process_goal_region_and_range(world, ros_domain,
                                                                      tmp_path):
    if world == "minigrid":
        pytest.importorskip("minigrid")
    if world == "pointmaze":
        pytest.importorskip("gymnasium_robotics")
        pytest.importorskip("mujoco")
    agent = TMGWRAgent(world_senses(make_world(world, Maze.from_text(MAZE))),
                       np.random.default_rng(0))
    want = agent.motivation
    up, bag = up_world(world, MAZE, tmp_path, ros_domain)
    with up:
        line = up.wait_for_line(SET, timeout=150)
        ctrl_c(up)
    assert up.proc.returncode == 0, up.describe("./tmgwr up failed")
    tol, low, high = re.search(SET, line).groups()
    assert float(tol) == want.goal_tolerance
    if want.bounds is None:
        assert low == high == ""
    else:
        assert np.array_equal(values(low), want.bounds[0])
        assert np.array_equal(values(high), want.bounds[1])
    if world != "grid":                  # the worlds the graph lacked them in before
        assert want.goal_tolerance > 0.0 and want.bounds is not None

    from rosbags.highlevel import AnyReader
    with AnyReader(mcap_files(bag)) as reader:
        got = {c.topic: [reader.deserialize(raw, c.msgtype)
                         for c2, _t, raw in reader.messages(connections=[c])]
               for c in reader.connections if c.topic in ("/world_senses", "/feature_senses")}
    assert set(got) == {"/world_senses", "/feature_senses"}
    feature = got["/feature_senses"][-1]
    assert feature.goal_tolerance == want.goal_tolerance
    assert feature.gain == agent.preprocessor.gain
    assert got["/world_senses"][-1].gain == 1.0


@pytest.mark.parametrize("world", ["minigrid", "pointmaze"])
@pytest.mark.timeout(400)
def test_the_graph_walks_the_in_process_agents_cells(world, ros_domain, tmp_path):
    """Told the same, the graph's agent (the composed graph) is the in-process agent step
    for step in a world whose goal region and sensor's range the rules read."""
    if world == "minigrid":
        pytest.importorskip("minigrid")
    else:
        pytest.importorskip("gymnasium_robotics")
        pytest.importorskip("mujoco")
    from ros_helpers import ros2_run

    from tmgwr_agent.experiments.lockstep import read_trajectory, run_reference
    steps = STEPS[world]
    maze = tmp_path / "small.txt"
    maze.write_text(MAZE)
    traj = tmp_path / "trajectory.txt"
    graph = ros2_run("tmgwr_agent", "composed", "--ros-args", "-p", f"world:={world}",
                     "-p", f"maze:={maze}", "-p", "maze_sim:seed:=0",
                     "-p", "action_selector:seed:=1", "-p", f"max_steps:={steps}",
                     "-p", "exit_when_done:=true", "-p", f"trajectory_path:={traj}",
                     "-p", "start_delay:=1.0", domain=ros_domain,
                     env={"HOME": str(tmp_path), "ROS_HOME": str(tmp_path / ".ros")})
    with graph:
        graph.wait(timeout=360)
    cells, _ = read_trajectory(traj)
    assert len(cells) == steps
    ref, _ = run_reference(maze, steps, world_seed=0, agent_seed=1, world_name=world)
    first = next((i for i, (a, b) in enumerate(zip(cells, ref)) if a != b), None)
    assert first is None, (f"graph and in-process differ from step {first}: "
                           f"{cells[first:first + 3]} vs {ref[first:first + 3]}")
    assert cells[-1][1] >= 3                # episodes ended at the goal: its region acted


# A motivation_estimator node told a world's declaration, then handed a checkpoint its core
# cannot take, then declarations it cannot take: prints the refusals, what it kept and what
# the core holds after them.
REFUSED = r"""
import numpy as np
import rclpy
from tmgwr_agent.nodes.motivation_estimator import MotivationEstimatorNode
from tmgwr_common.checkpoint import Checkpoint, CheckpointError
from tmgwr_interfaces.msg import SensorInfo
rclpy.init(args=["--ros-args", "-p", "world:=pointmaze", "-p", "checkpoint_period:=0"])
node = MotivationEstimatorNode()
node.core.set_senses(0.05, (np.array([-0.4, -0.2]), np.array([0.4, 0.2])))
try:
    node.restore(Checkpoint("motivation_estimator", 3, 1, 0.0, {"bogus": 1}))
except CheckpointError as exc:
    print("REFUSED", exc, flush=True)
for bad in (dict(low=[0.0], high=[1.0]), dict(low=[0.0, 1.0], high=[1.0, 0.0]),
            dict(goal_tolerance=float("nan"))):
    node.on_senses(SensorInfo(run_id=1, gain=1.0, **bad))
print("DECLARATIONS KEPT", node.senses, flush=True)
c = node.core
print("CORE", len(c.primitives), c.goal_tolerance, c.bounds[0].tolist(), c.bounds[1].tolist(),
      flush=True)
node.destroy_node()
rclpy.shutdown()
"""


@pytest.mark.timeout(120)
def test_a_refused_checkpoint_leaves_the_estimator_told_the_world(ros_domain, tmp_path):
    """The core a refused checkpoint leaves behind keeps the world's primitives, goal
    region and sensor's range (it was rebuilt from the configuration alone, and failed);
    a declaration the core cannot take is refused, named, and not kept."""
    pytest.importorskip("gymnasium_robotics")
    from ros_helpers import spawn_python
    p = spawn_python(REFUSED, domain=ros_domain, name="refused",
                     env={"HOME": str(tmp_path), "ROS_HOME": str(tmp_path / ".ros")})
    out = p.wait(timeout=100)
    assert "REFUSED" in out and "refused" in out, out
    assert "CORE 4 0.05 [-0.4, -0.2] [0.4, 0.2]" in out, out
    assert "DECLARATIONS KEPT {}" in out, out       # a range of 1 value, low > high, NaN
    assert out.count("refused a declaration of run 1") == 3, out


# what a recording made before the declarations existed lacks: both of them
OLD_RECORDING = r"exclude:=^/(world|feature)_senses$"
# the simulator waits for the recorder (started apart): its first step waits for the word that
# the recorder has matched every ring publisher
LATE_START = "maze_sim:\n  ros__parameters:\n    await_recorder: true\n"
STATES = 300


@pytest.mark.timeout(900)
def test_a_recording_without_the_declarations_replays_on_the_grid(ros_domain, tmp_path):
    """A grid run recorded without ``/world_senses`` and ``/feature_senses`` (a recording
    made before they existed), its states and actions replayed (``./tmgwr replay``) into a
    motivation estimator (``ros2 run``, real DDS): the estimator takes the grid's
    declaration, which the world's name says in full, and answers the replayed states (it
    held every one of them for good before, waiting for a declaration the recording cannot
    bring)."""
    from ros_helpers import ROOT, RosProcess, ros2_run, ros_env
    from test_recorder import start_recorder, tmgwr_cli
    params = tmp_path / "late.yaml"
    params.write_text(LATE_START)
    bag = tmp_path / "old"
    recorder = start_recorder(ros_domain, bag, OLD_RECORDING, "discovery_period:=0.1")
    with recorder:
        recorder.wait_for_line(r"recording .* to ", timeout=60)
        up = RosProcess([str(ROOT / ".venv/bin/python"), "-m", "tmgwr_agent.cli", "up",
                         "--seed", "1", "--max-steps", str(STATES), "--params-file",
                         str(params), "--no-record", "--quiet", "--domain-id",
                         str(ros_domain)], ros_env(ros_domain), name="up")
        with up:
            up.wait(timeout=240)
        recorder.stop()
    from rosbags.highlevel import AnyReader
    with AnyReader(mcap_files(bag)) as reader:
        recorded = {c.topic for c in reader.connections}
        states = [reader.deserialize(raw, c.msgtype).step_id for c, _t, raw in
                  reader.messages([c for c in reader.connections
                                   if c.topic == "/sensorimotor_state"])]
    assert "/sensorimotor_state" in recorded and len(set(states)) >= STATES - 1, recorded
    assert not recorded & {"/world_senses", "/feature_senses"}, recorded

    home = {"HOME": str(tmp_path), "ROS_HOME": str(tmp_path / ".ros")}
    estimator = ros2_run("tmgwr_agent", "motivation_estimator", "--ros-args", "-p",
                         "checkpoint_period:=0", domain=ros_domain, env=home)
    with estimator:
        estimator.wait_for_line(r"motivation_estimator ready", timeout=90)
        # in the ring's causal order (the estimator holds a state until the previous
        # step's action; the recorder may receive an action before its state), at half
        # the recorded pace: the replay is not lockstep, and a reader of the ring's
        # keep-last history loses states when starved of CPU for STEP_DEPTH of them (a
        # loaded machine's recording may last a minute or more: its ring was slow too)
        replay = tmgwr_cli("replay", str(bag), "--topics", "/sensorimotor_state", "/action",
                           "--wait-subscribers", "1", "--delay", "0.5", "--rate", "0.5",
                           "--message-order", "sent", domain=ros_domain, timeout=600)
        assert replay.returncode == 0, replay.stdout + replay.stderr
        line = estimator.wait_for_line(r"the world's senses set", timeout=30)
        estimator.stop()
    assert "goal tolerance 0.0, sensor's range [] .. []" in line, line
    assert "the grid world's, which its name says in full" in line, line
    solved = re.search(r"motivation_estimator: (\d+) step callbacks", estimator.output)
    assert solved, estimator.describe("no summary at the stop")
    assert int(solved[1]) >= 0.9 * len(set(states)), estimator.describe(
        f"{solved[1]} of {len(set(states))} replayed states answered")


# A pointmaze motivation_estimator handed states of a run whose declaration never comes:
# prints what it logged (its patience shortened for the test).
UNDECLARED = r"""
import time
import rclpy
import tmgwr_agent.nodes.motivation_estimator as me
from tmgwr_interfaces.msg import SensorimotorState
me.SENSES_PATIENCE = 0.5
rclpy.init(args=["--ros-args", "-p", "world:=pointmaze", "-p", "checkpoint_period:=0"])
node = me.MotivationEstimatorNode()
for step in range(4):
    node.on_state(SensorimotorState(run_id=5, step_id=step))
    time.sleep(0.3)
print("WAITING", node.unsensed.step_id, flush=True)
node.destroy_node()
rclpy.shutdown()
"""


@pytest.mark.timeout(120)
def test_an_estimator_without_a_declaration_says_which_topic_lacks_it(ros_domain, tmp_path):
    """In a world whose range lies in the maze file (PointMaze) the estimator cannot take a
    default: a run whose declaration does not come is reported once, as an error naming
    the missing topics, and its newest state keeps waiting."""
    pytest.importorskip("gymnasium_robotics")
    from ros_helpers import spawn_python
    p = spawn_python(UNDECLARED, domain=ros_domain, name="undeclared",
                     env={"HOME": str(tmp_path), "ROS_HOME": str(tmp_path / ".ros")})
    out = p.wait(timeout=100)
    assert "WAITING 3" in out, out
    assert out.count("no sensor declaration of this run on feature_senses") == 1, out
    assert "pointmaze world's range lies in its maze file" in out, out
    assert "maze_sim publishes it on world_senses" in out, out
