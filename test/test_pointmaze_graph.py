"""The node graph on PointMaze (``./tmgwr up --world pointmaze``) over real DDS, recorded.

``./tmgwr up`` starts the five nodes and the recorder as separate processes with
``--world pointmaze`` on a small maze: maze_sim hosts MuJoCo's PointMaze built from it, the
agent nodes take its senses (a 2-D position, four force primitives). The test waits for the
first goal, changes the goal by a position in the world's frame and fires an event, then
stops the graph and reads the bag back: the ring answered every step, the sensations are
continuous positions inside the maze, the pose, grid and markers are in the world's frame,
and ``./tmgwr report`` rebuilds the map from the recording.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_recorder import tmgwr_cli
from world_graph import GOAL, ctrl_c, fire_event, read_bag, up_world

from maze_sim.pointmaze_world import step_length

pytest.importorskip("gymnasium_robotics")
pytest.importorskip("mujoco")

pytestmark = [pytest.mark.ros, pytest.mark.slow]

# 5 x 7: cell (row, col) centred at x = col - 3, y = 2 - row (PointMaze's frame, metres)
MAZE = """\
#######
#S.a.G#
#.###.#
#.1...#
#######
"""


def test_the_graph_runs_on_pointmaze_and_the_bag_reads_back(ros_domain, tmp_path):
    up, bag = up_world("pointmaze", MAZE, tmp_path, ros_domain)
    with up:
        up.wait_for_line(r"world pointmaze", timeout=90)
        up.wait_for_line(r"^recording to ", timeout=90)
        up.wait_for_line(GOAL.pattern, timeout=240)          # a first goal, by the agent
        # goal (row 3, col 2) by its centre in the world's frame: x = -1, y = -1
        goal = tmgwr_cli("goal", "-1.2", "-0.9", "--domain-id", str(ros_domain),
                         domain=ros_domain)
        assert goal.returncode == 0 and "accepted" in goal.stdout, goal.stdout + goal.stderr
        up.wait_for_line(r"goal -> row 3, col 2", timeout=30)
        refused = tmgwr_cli("goal", "40", "0", "--domain-id", str(ros_domain),
                            domain=ros_domain)
        assert refused.returncode == 1 and "outside" in refused.stdout, refused.stdout
        fire_event(up, ros_domain)
        ctrl_c(up)
    assert up.proc.returncode == 0, up.describe("./tmgwr up failed")

    msgs = read_bag(bag, ("/observation", "/features", "/agent_pose", "/maze_grid",
                          "/map_markers"), up.output)
    sensed = [np.array(m.sensors, dtype=float) for m in msgs["/observation"]]
    poses = [(m.pose.position.x, m.pose.position.y) for m in msgs["/agent_pose"]]
    grids, markers = msgs["/maze_grid"], msgs["/map_markers"]
    xy = np.array(sensed)
    assert xy.shape[1] == 2
    # inside the free cells of the maze (x in [-2.5, 2.5], y in [-1.5, 1.5]), metres about
    # the maze's centre (not the grid world's (row, col)), on PointMaze's move lattice (the
    # cells' centres, a move apart)
    assert (xy[:, 0] > -2.5).all() and (xy[:, 0] < 2.5).all()
    assert (xy[:, 1] > -1.5).all() and (xy[:, 1] < 1.5).all()
    assert (xy < 0).any()
    step = step_length()
    assert step == 1.0 and np.abs(xy - np.round(xy)).max() < 5e-3
    # the preprocessor node was told the world's resolution: one move, one feature step
    assert {m.gain for m in msgs["/features"]} == {0.1 / step}
    g = grids[-1]
    assert (g.info.origin.position.x, g.info.origin.position.y) == (-3.5, -2.5)
    walls = np.array(g.data).reshape(g.info.height, g.info.width)[::-1] > 0
    assert walls[1, 3]                      # event 'a' walled (row 1, col 3)
    assert not walls[1, 1] and walls[0].all()
    if poses:                               # /agent_pose is made only while someone listens
        p = np.array(poses)
        assert (np.abs(p[:, 0]) < 2.5).all() and (np.abs(p[:, 1]) < 1.5).all()
    nodes = [pt for m in markers for mk in m.markers if mk.ns == "nodes" for pt in mk.points]
    assert nodes and all(-2.5 < pt.x < 2.5 and -1.5 < pt.y < 1.5 for pt in nodes)

    report = tmgwr_cli("report", str(bag))
    assert report.returncode == 0, report.stdout + report.stderr


def test_up_refuses_an_unknown_world_before_starting_nodes():
    out = tmgwr_cli("up", "--world", "mars", "--no-record")
    assert out.returncode == 2, out.stdout + out.stderr
    assert "unknown world 'mars'" in out.stderr and "Traceback" not in out.stderr
