"""World edits keep the task solvable or say no (issue 10, item 4).

``GridWorld.set_cell``, ``fire_event`` and ``set_goal`` refuse, with the reason and the world
unchanged, to wall in the start, the goal (or a goal requested for the next observation),
the agent during an episode, or the last route to the goal from the start or the agent.
The maze_sim node answers its services with those messages and stays up; a goal it accepted
is applied even when a cell or event edit comes before the next observation (the cause of
"goal change to (1, 11) dropped").
"""

from __future__ import annotations

import numpy as np
import pytest
from ros_helpers import ROOT, ros2_run, spawn_python, stop_all
from test_nodes import call

from maze_sim.maze import Maze, MazeError
from maze_sim.world import EditRefused, GridWorld

# S (1,1) and G (1,5) joined by the top corridor through event cell a (1,3) and by the
# bottom corridor through event cell b (3,3): each event alone leaves a detour, both cut G.
TWO_ROUTES = """\
#######
#S.a.G#
#.###.#
#..b..#
#######
"""
UP, DOWN, LEFT, RIGHT = range(4)


def world(**kw) -> GridWorld:
    w = GridWorld(Maze.from_text(TWO_ROUTES, "two_routes.txt"), "G", **kw)
    w.reset()
    return w


def refused(w: GridWorld, edit, *args, match: str):
    before = (w.walls.copy(), list(w.fired), w.goal, w.pending_goal)
    with pytest.raises(EditRefused, match=match) as exc:
        edit(*args)
    assert (w.walls == before[0]).all() and w.fired == before[1]    # unchanged
    assert (w.goal, w.pending_goal) == before[2:]
    assert "two_routes.txt" in str(exc.value)
    return str(exc.value)


def test_set_cell_refuses_to_wall_in_the_start_goal_or_agent():
    w = world()
    refused(w, w.set_cell, 1, 1, True, match=r"wall in the start at \(row 1, col 1\)")
    refused(w, w.set_cell, 1, 5, True, match=r"wall in the goal at \(row 1, col 5\)")
    w.step(RIGHT)                                        # the agent at (1, 2)
    refused(w, w.set_cell, 1, 2, True, match=r"wall in the agent at \(row 1, col 2\)")
    w.set_cell(3, 3, True)                               # a detour is left: accepted
    assert w.walls[3, 3]
    w.set_cell(3, 3, False)                              # opening is always accepted
    assert not w.walls[3, 3]


def test_set_cell_refuses_to_cut_the_last_route_from_the_start_or_the_agent():
    w = world()
    w.set_cell(1, 3, True)                               # the top route is gone
    msg = refused(w, w.set_cell, 3, 3, True, match="cut the last route from the start")
    assert "(row 1, col 1) to the goal (row 1, col 5)" in msg
    w = world()
    for a in (DOWN, DOWN, RIGHT):                        # the agent at (3, 2)
        w.step(a)
    w.set_cell(2, 1, True)          # the start keeps the top route, the agent the bottom one
    msg = refused(w, w.set_cell, 3, 3, True, match="cut the last route from the agent")
    assert "the agent (row 3, col 2) to the goal (row 1, col 5)" in msg


def test_the_agent_matters_only_during_an_episode():
    w = world(max_episode_steps=1)
    w.step(RIGHT)                                        # truncated at (1, 2)
    w.set_cell(1, 2, True)                               # the next reset starts at S
    w.set_cell(1, 2, False)
    w.reset()
    assert w.cell == (1, 1) and w.in_episode
    refused(w, w.set_cell, 1, 1, True, match="wall in the start")


def test_fire_event_leaves_the_world_unchanged_when_it_would_cut_the_goal_off():
    w = world()
    w.fire_event("a")
    assert w.walls[1, 3] and w.fired == ["a"]
    msg = refused(w, w.fire_event, "b", match=r"event 'b' refused: it would cut the last "
                                            r"route from the start \(row 1, col 1\)")
    assert "to the goal (row 1, col 5)" in msg
    with pytest.raises(MazeError, match="no event named 'z'"):
        w.fire_event("z")
    # the event applies on the current layout: a cell edit is not undone by it
    w2 = world()
    w2.set_cell(2, 1, True)
    w2.fire_event("b")
    assert w2.walls[2, 1] and w2.walls[3, 3]
    refused(w2, w2.fire_event, "a", match="wall in|cut the last route")


def test_fire_event_refuses_to_wall_in_the_agent():
    w = world()
    for a in (RIGHT, RIGHT):                             # the agent on a, (1, 3)
        w.step(a)
    refused(w, w.fire_event, "a", match=r"event 'a' refused: it would wall in the agent")
    w.end_episode()                    # an experimenter cut the episode: the cell is free
    w.fire_event("a")
    assert w.walls[1, 3]


def test_a_requested_goal_is_kept_free_until_it_applies():
    w = world()
    assert w.request_goal((3, 4)) == (3, 4)
    refused(w, w.set_cell, 3, 4, True, match=r"wall in the requested goal at \(row 3, col 4\)")
    w.fire_event("a")
    refused(w, w.fire_event, "b", match="requested goal|the goal")
    assert w.set_goal((3, 4)) == (3, 4) and w.pending_goal is None


def test_set_goal_refuses_walls_and_unreachable_cells():
    maze = Maze.from_text("#######\n#S..#.#\n#..G#.#\n#######\n", "pocket.txt")
    w = GridWorld(maze, "G")
    with pytest.raises(MazeError, match="is a wall"):
        w.set_goal((0, 0))
    with pytest.raises(EditRefused, match=r"goal \(row 1, col 5\) refused: it cannot be "
                                          r"reached from the start"):
        w.set_goal((1, 5))
    with pytest.raises(EditRefused, match="cannot be reached from the start"):
        GridWorld(maze, (2, 5))
    assert w.goal == (2, 3)


def test_the_paper_events_are_accepted_as_before():
    maze = Maze.from_file(ROOT / "src" / "maze_sim" / "mazes" / "paper_13x17.txt")
    w = GridWorld(maze, "G")
    for e in ("a", "b"):
        w.reset()
        w.fire_event(e)
        np.testing.assert_array_equal(w.walls, maze.walls_after(w.fired))

# Answers every observation with Action.NONE (the simulator restarts the episode at S),
# copying the lockstep identity fields the observation carries.
NONE_AGENT = r"""
import rclpy
from tmgwr_common import topics
from tmgwr_common.node import STEP_QOS
from tmgwr_interfaces.msg import Action, Observation
rclpy.init()
node = rclpy.create_node("none_agent")
pub = node.create_publisher(Action, topics.ACTION, STEP_QOS)
def answer(o):
    a = Action(step_id=o.step_id, action=Action.NONE)
    if hasattr(o, "run_id") and hasattr(a, "run_id"):
        a.run_id = o.run_id
    pub.publish(a)
node.create_subscription(Observation, topics.OBSERVATION, answer, STEP_QOS)
print("AGENT READY", flush=True)
rclpy.spin(node)
"""


@pytest.mark.ros
@pytest.mark.timeout(120)
def test_maze_sim_services_refuse_unsolvable_edits_and_apply_an_accepted_goal(ros_domain,
                                                                               tmp_path):
    maze = tmp_path / "two_routes.txt"
    maze.write_text(TWO_ROUTES)
    sim = ros2_run("maze_sim", "maze_sim", "--ros-args", "-p", f"maze:={maze}",
                   "-p", "resend_period:=30.0", domain=ros_domain)
    agent = None
    try:
        sim.wait_for_line("maze_sim ready", timeout=60)
        res = call(ros_domain, [
            ["/maze_sim/set_cell", "SetCell", {"row": 1, "col": 1, "blocked": True}],
            ["/maze_sim/fire_event", "FireEvent", {"event": "a"}],
            ["/maze_sim/fire_event", "FireEvent", {"event": "b"}],
            ["/maze_sim/set_cell", "SetCell", {"row": 2, "col": 1, "blocked": True}],
            ["/maze_sim/set_goal", "SetGoal", {"x": 4, "y": 3}],
            ["/maze_sim/set_cell", "SetCell", {"row": 3, "col": 4, "blocked": True}],
            ["/maze_sim/set_cell", "SetCell", {"row": 3, "col": 2, "blocked": True}]])
        assert [r["accepted"] for r in res] == [False, True, False, False, True, False,
                                                False], res
        assert "wall in the start at (row 1, col 1)" in res[0]["message"]
        assert "event 'b' refused: it would cut the last route from the start" \
            in res[2]["message"]
        assert "cut the last route" in res[3]["message"]
        assert "applies from step" in res[4]["message"]
        assert "wall in the requested goal at (row 3, col 4)" in res[5]["message"]
        assert "cut the last route" in res[6]["message"]
        assert sim.running(), sim.describe("maze_sim died on a refused edit")
        # the next observation applies the accepted goal: nothing walled it meanwhile
        agent = spawn_python(NONE_AGENT, domain=ros_domain, name="none_agent")
        agent.wait_for_line("AGENT READY", timeout=60)
        sim.wait_for_line(r"goal -> row 3, col 4", timeout=60)
        assert "dropped" not in sim.output
    finally:
        stop_all([p for p in (agent, sim) if p is not None])
