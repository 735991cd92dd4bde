"""The node graph on MiniGrid (``./tmgwr up --world minigrid``) over real DDS, recorded.

maze_sim hosts the MiniGrid env built from a small maze; the agent nodes take its senses by
name (``(row, col, cos h, sin h)``, three native actions). The test waits for goals reached
by the agent, fires an event, stops the graph and reads the bag back: the ring answered
every step, every sensation is a pose of the maze (a free cell, a heading along an axis),
the event walled its cell, and ``./tmgwr report`` rebuilds the map from the recording.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_recorder import tmgwr_cli
from world_graph import GOAL, ctrl_c, fire_event, read_bag, up_world

pytest.importorskip("minigrid")

pytestmark = [pytest.mark.ros, pytest.mark.slow]

MAZE = """\
#######
#S.a.G#
#.###.#
#.....#
#######
"""


def test_the_graph_runs_on_minigrid_and_the_bag_reads_back(ros_domain, tmp_path):
    up, bag = up_world("minigrid", MAZE, tmp_path, ros_domain)
    with up:
        up.wait_for_line(r"world minigrid", timeout=90)
        up.wait_for_line(r"^recording to ", timeout=90)
        for _ in range(2):                                   # goals, by the agent
            up.wait_for_line(GOAL.pattern, timeout=240)
        fire_event(up, ros_domain)
        ctrl_c(up)
    assert up.proc.returncode == 0, up.describe("./tmgwr up failed")
    errors = [line for line in up.lines if "Exception in" in line or "Traceback" in line]
    assert not errors, errors                # e.g. the simulator's checkpoint of the world

    msgs = read_bag(bag, ("/observation", "/maze_grid"), up.output)
    poses = np.array([np.array(m.sensors, dtype=float) for m in msgs["/observation"]])
    assert poses.shape[1] == 4
    free = ~np.array([[ch == "#" for ch in line] for line in MAZE.splitlines()])
    free[1, 3] = True                       # open until the event
    rows, cols = poses[:, 0].astype(int), poses[:, 1].astype(int)
    assert (poses[:, :2] == np.round(poses[:, :2])).all() and free[rows, cols].all()
    heading = poses[:, 2:]
    assert (np.abs(heading).sum(axis=1) == 1).all()          # a unit vector on an axis
    assert len({tuple(h) for h in heading}) > 1               # the agent turned
    g = msgs["/maze_grid"][-1]
    walls = np.array(g.data).reshape(g.info.height, g.info.width) > 0   # y = row
    assert walls[1, 3] and not walls[1, 1]                    # event 'a' walled (1, 3)

    report = tmgwr_cli("report", str(bag))
    assert report.returncode == 0, report.stdout + report.stderr
