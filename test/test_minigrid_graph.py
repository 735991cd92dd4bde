"""The node graph on MiniGrid (``./tmgwr up --world minigrid``) over real DDS, recorded.

maze_sim hosts the MiniGrid env built from a small maze; the agent nodes take its senses by
name (``(row, col, cos h, sin h)``, three native actions). The test waits for goals reached
by the agent, fires an event, stops the graph and reads the bag back: the ring answered
every step, every sensation is a pose of the maze (a free cell, a heading along an axis),
the event walled its cell, and ``./tmgwr report`` rebuilds the map from the recording.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from ros_helpers import ROOT, RosProcess, ros_env
from test_recorder import mcap_files, tmgwr_cli

pytest.importorskip("minigrid")

pytestmark = [pytest.mark.ros, pytest.mark.slow]

MAZE = """\
#######
#S.a.G#
#.###.#
#.....#
#######
"""
GOAL = re.compile(r"\[maze_sim\].*episode (\d+): goal \((\d+), (\d+)\) reached in (\d+) steps")
PER_STEP = ("/observation", "/features", "/sensorimotor_state", "/motivation", "/action")


def test_the_graph_runs_on_minigrid_and_the_bag_reads_back(ros_domain, tmp_path):
    maze = tmp_path / "small.txt"
    maze.write_text(MAZE)
    bag = tmp_path / "run"
    up = RosProcess([str(ROOT / ".venv/bin/python"), "-m", "tmgwr_agent.cli", "up",
                     "--world", "minigrid", "--maze", str(maze), "--seed", "3",
                     "--record-dir", str(bag), "--domain-id", str(ros_domain)],
                    ros_env(ros_domain), name="up")
    with up:
        up.wait_for_line(r"world minigrid", timeout=90)
        up.wait_for_line(r"^recording to ", timeout=90)
        for _ in range(2):                                   # goals, by the agent
            up.wait_for_line(GOAL.pattern, timeout=240)
        for _ in range(20):                 # refused while the agent stands on the cell
            event = tmgwr_cli("event", "a", "--domain-id", str(ros_domain), domain=ros_domain)
            if "would wall in the agent" not in event.stdout:
                break
        assert event.returncode == 0 and "accepted" in event.stdout, \
            event.stdout + event.stderr
        up.wait_for_line(r"event 'a' fired", timeout=30)
        up.proc.send_signal(2)              # Ctrl-C: the nodes stop, the recorder last
        up.wait_for_line(r"^recording: ", timeout=60)
        up.wait(timeout=60, check=False)
    assert up.proc.returncode == 0, up.describe("./tmgwr up failed")
    errors = [line for line in up.lines if "Exception in" in line or "Traceback" in line]
    assert not errors, errors                # e.g. the simulator's checkpoint of the world

    from rosbags.highlevel import AnyReader
    steps: dict[str, list[int]] = {}
    sensed, grids = [], []
    with AnyReader(mcap_files(bag)) as reader:
        for conn, _t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic in PER_STEP:
                steps.setdefault(conn.topic, []).append(int(msg.step_id))
            if conn.topic == "/observation":
                sensed.append(np.array(msg.sensors, dtype=float))
            elif conn.topic == "/maze_grid":
                grids.append(msg)
    for topic in PER_STEP:
        ids = sorted(set(steps[topic]))
        assert ids[0] == 0 and ids == list(range(ids[-1] + 1)), topic
    poses = np.array(sensed)
    assert poses.shape[1] == 4
    free = ~np.array([[ch == "#" for ch in line] for line in MAZE.splitlines()])
    free[1, 3] = True                       # open until the event
    rows, cols = poses[:, 0].astype(int), poses[:, 1].astype(int)
    assert (poses[:, :2] == np.round(poses[:, :2])).all() and free[rows, cols].all()
    heading = poses[:, 2:]
    assert (np.abs(heading).sum(axis=1) == 1).all()          # a unit vector on an axis
    assert len({tuple(h) for h in heading}) > 1               # the agent turned
    g = grids[-1]
    walls = np.array(g.data).reshape(g.info.height, g.info.width) > 0   # y = row
    assert walls[1, 3] and not walls[1, 1]                    # event 'a' walled (1, 3)

    report = tmgwr_cli("report", str(bag))
    assert report.returncode == 0, report.stdout + report.stderr
