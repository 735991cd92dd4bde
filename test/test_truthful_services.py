"""Services tell the truth (issue 24, points 3 and 7): ``/set_goal`` answers from the
simulator's own check, reachability included, so "accepted" means applied, and
``./tmgwr goal`` exits 1 on a refusal; echoed input is cut to a readable length.

Before, the motivation estimator hosted ``/set_goal``: it checked the cell against the
latched grid only (inside, not a wall), answered "accepted" for a free cell that cannot be
reached, and the simulator then refused it and only logged an error (``./tmgwr goal``
exited 0). A goal of x = 1e300 was echoed as a 301-digit number, a 10 kB event name in
full.
"""

from __future__ import annotations

import re

import pytest
from ros_helpers import SERVICE_ANSWERED, graph_up_pids, ros2_cli, spawn_module
from test_graph import cli

pytestmark = [pytest.mark.ros]

# S and G on the left; (1, 5) and (2, 5) free, walled off from both.
POCKET = "#######\n#S..#.#\n#..G#.#\n#######\n"


@pytest.mark.timeout(240)
def test_set_goal_refuses_an_unreachable_cell_and_the_cli_says_so(ros_domain, tmp_path):
    maze = tmp_path / "pocket.txt"
    maze.write_text(POCKET)
    up = spawn_module("tmgwr_agent.cli", "up", "--no-record", "--maze", str(maze),
                      domain=ros_domain, name="tmgwr up")
    with up:
        graph_up_pids(up)
        rc, out = cli(ros_domain, "goal", "5", "1")
        assert rc == 1, out
        assert "refused" in out and "cannot be reached from the start" in out, out
        # what a ROS user types gets the same answer
        p = ros2_cli("service", "call", "/set_goal", "tmgwr_interfaces/srv/SetGoal",
                     "{goal: {x: 5.0, y: 2.0}}", domain=ros_domain)
        with p:
            answer = p.wait(timeout=60, done=SERVICE_ANSWERED)
        assert re.search(r"accepted=False, message='goal \(x=5, y=2\) refused: .*cannot be "
                         r"reached", answer), answer
        # echoed input stays readable
        rc, out = cli(ros_domain, "goal", "1e300", "1")
        assert rc == 1 and "outside" in out and not re.search(r"\d{20}", out), out
        rc, out = cli(ros_domain, "event", "x" * 10_000)
        assert rc == 1 and "expected one lowercase letter" in out, out
        assert "(10000 characters)" in out and len(out) < 2000, out
        # an accepted goal is applied: the simulator moves it at its next observation
        rc, out = cli(ros_domain, "goal", "2", "2")
        assert rc == 0 and "accepted" in out, out
        up.wait_for_line(r"\[maze_sim\].*goal -> row 2, col 2", timeout=30)
        assert up.running(), up.output
