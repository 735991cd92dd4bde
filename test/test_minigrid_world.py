"""``--world minigrid`` and ``--world gym:ID`` (maze_sim.worlds, minigrid_world, gym_adapter):
the MiniGrid grid built from a maze file is that maze, the (cell, heading) oracle agrees
with a count by hand, an event edits the running grid, check_env passes on the wrapped
env, a short env-change run keeps the JSON contract, and bad names exit 2 naming them."""

import json
import subprocess
import sys

import numpy as np
import pytest
from small_mazes import SMALL

from maze_sim.maze import Maze
from maze_sim.minigrid_world import (
    FORWARD,
    LEFT,
    RIGHT,
    MiniGridWorld,
    discretise,
    event_oracle_steps,
)
from maze_sim.worlds import WorldError, make_world, parse_world, parse_world_kwargs

#: S at (1, 1) facing east; G at (1, 3): two forwards. Goal 1 at (3, 1): turn right, two
#: forwards. Event a blocks (1, 2).
TINY = ("#####\n"
        "#SaG#\n"
        "#.#.#\n"
        "#1..#\n"
        "#####\n")


def grid_objects(world):
    """(rows, cols) of MiniGrid object types inside the border (None: empty)."""
    g = world.base.grid
    rows, cols = world.maze.shape
    return [[(g.get(c + 1, r + 1).type if g.get(c + 1, r + 1) else None)
             for c in range(cols)] for r in range(rows)]


def test_minigrid_grid_is_the_maze():
    maze = Maze.from_text(SMALL)
    w = MiniGridWorld(maze, "G")
    objs = grid_objects(w)
    rows, cols = maze.shape
    for r in range(rows):
        for c in range(cols):
            want = "wall" if maze.walls[r, c] else "goal" if (r, c) == maze.goal_cell("G") \
                else None
            assert objs[r][c] == want, (r, c)
    g = w.base.grid                      # the border around the maze is wall
    assert all(g.get(x, 0).type == "wall" for x in range(cols + 2))
    obs, _ = w.reset()
    assert tuple(w.base.agent_pos) == (maze.start[1] + 1, maze.start[0] + 1)
    np.testing.assert_array_equal(obs, [maze.start[0], maze.start[1], 1.0, 0.0])
    np.testing.assert_array_equal(w.goal_observation(), [5, 7, 0.0, 0.0])
    assert w.goal_state == (5, 7, None)


def test_native_actions_turn_move_bump_and_reach_the_goal():
    w = MiniGridWorld(Maze.from_text(TINY), "1")
    w.reset()
    obs, _, term, _, info = w.step(LEFT)         # east -> north
    np.testing.assert_array_equal(obs, [1, 1, 0.0, -1.0])
    assert info.cell == (1, 1, 3) and not info.bumped
    _, _, _, _, info = w.step(FORWARD)           # into the wall above: a bump
    assert info.bumped and info.cell == (1, 1, 3)
    for a in (RIGHT, RIGHT, FORWARD):            # face south, move down
        obs, _, term, _, info = w.step(a)
    np.testing.assert_array_equal(obs, [2, 1, 0.0, 1.0])
    _, reward, term, _, info = w.step(FORWARD)   # onto goal 1: MiniGrid ends it
    assert term and info.reached_goal and reward == 1.0


def test_pose_bfs_oracle_by_hand():
    maze = Maze.from_text(TINY)
    w = MiniGridWorld(maze, "G")
    assert w.shortest_path_length() == 2                     # forward, forward
    assert MiniGridWorld(maze, "1").shortest_path_length() == 3   # right, fwd, fwd
    # After a: S (1,1) east -> right, fwd, fwd (3,1), left, fwd, fwd (3,3), left, fwd,
    # fwd (1,3) = 9. The oracle walks the old path: a forward bumps into (1, 2) (1 step),
    # then those 9: 10.
    assert w.shortest_steps(maze.walls_after(["a"])) == 9
    assert w.event_oracle_steps("a") == 10
    # Facing west at the start, the old path starts with two turns.
    west = MiniGridWorld(maze, "G", start_dir=2)
    assert west.shortest_path_length() == 4
    assert event_oracle_steps(maze.walls, maze.walls_after(["a"]), (1, 1, 2), (1, 3)) == \
        2 + 1 + 9


def test_event_edits_the_running_grid_and_the_agent_keeps_its_pose():
    maze = Maze.from_text(TINY)
    w = MiniGridWorld(maze, "G")
    w.reset()
    w.step(RIGHT)                                # south, at S
    w.fire_event("a")
    assert w.base.grid.get(3, 2).type == "wall"  # (row 1, col 2) -> x 3, y 2
    assert w.pose == (1, 1, 1)
    w.step(LEFT)                                 # east again: the new wall is ahead
    _, _, _, _, info = w.step(FORWARD)
    assert info.bumped
    w.reset()                                    # a new episode keeps the event
    assert w.base.grid.get(3, 2).type == "wall"


def test_goal_change_keeps_the_previous_goal_terminal():
    w = MiniGridWorld(Maze.from_text(TINY), "G")
    w.set_goal("1", keep_previous=True)
    assert grid_objects(w)[1][3] == "goal" and grid_objects(w)[3][1] == "goal"
    w.reset()
    w.step(FORWARD)                              # a: free until fired
    _, _, term, _, info = w.step(FORWARD)
    assert term and info.reached_previous_goal and not info.reached_goal


def test_discretisation_of_the_sensation():
    assert discretise(np.array([2.0, 3.0, 1.0, 0.0])) == (2, 3, 0)
    assert discretise(np.array([2.0, 3.0, 0.0, 1.0])) == (2, 3, 1)
    assert discretise(np.array([2.0, 3.0, -1.0, 0.0])) == (2, 3, 2)
    assert discretise(np.array([2.0, 3.0, 0.0, -1.0])) == (2, 3, 3)
    assert discretise(np.array([2.0, 3.0, 0.0, 0.0])) == (2, 3, None)


def test_check_env_passes_on_the_wrapped_env():
    from gymnasium.utils.env_checker import check_env
    w = MiniGridWorld(Maze.from_text(SMALL), "G")
    check_env(w.env, skip_render_check=True)
    from tmgwr_agent.world_senses import env_senses
    senses = env_senses(w.env)
    assert senses.dim == 4 and senses.n_actions == 3


def test_senses_from_spaces_takes_the_wrapped_env_and_refuses_the_raw_one():
    from tmgwr_agent.core.senses import Senses, SensesError
    w = MiniGridWorld(Maze.from_text(TINY), "G")
    senses = Senses.from_spaces(w.env.observation_space, w.env.action_space)
    np.testing.assert_array_equal(senses.primitives, np.eye(3))   # not told any geometry
    with pytest.raises(SensesError, match="1-D Box"):
        Senses.from_spaces(w.base.observation_space, w.base.action_space)  # MiniGrid's dict


def test_world_names_and_kwargs_are_checked():
    assert parse_world(None).name == "grid"
    assert parse_world("minigrid", '{"start_dir": 1}').kwargs == {"start_dir": 1}
    with pytest.raises(WorldError, match="unknown world 'minigird'"):
        parse_world("minigird")
    with pytest.raises(WorldError, match="not JSON"):
        parse_world_kwargs("{start_dir: 1}")
    with pytest.raises(WorldError, match="must be a JSON object"):
        parse_world_kwargs("[1]")
    with pytest.raises(WorldError, match="unknown Gymnasium env id 'MiniGrid-Nope-v0'"):
        parse_world("gym:MiniGrid-Nope-v0")
    with pytest.raises(WorldError, match="cannot map this env's observation"):
        parse_world("gym:CartPole-v1")
    with pytest.raises(WorldError, match="world 'minigrid'.*colour"):
        make_world("minigrid", Maze.from_text(TINY), colour="red")
    w = make_world("minigrid", Maze.from_text(TINY), "G", 100, 0, start_dir=2)
    assert w.start_pose == (1, 1, 2)


def test_pointmaze_is_refused_or_built():
    """This branch may lack maze_sim.pointmaze_world (the other #26 world): then the
    name is refused as not available, never a traceback."""
    try:
        import maze_sim.pointmaze_world  # noqa: F401
    except ModuleNotFoundError:
        with pytest.raises(WorldError, match="'pointmaze' is not available in this build"):
            parse_world("pointmaze")
    else:
        assert parse_world("pointmaze").name == "pointmaze"


def test_gym_minigrid_world_with_a_fixed_layout_seed():
    from maze_sim.gym_adapter import GymWorld
    a = GymWorld("MiniGrid-FourRooms-v0", layout_seed=3)
    b = GymWorld("MiniGrid-FourRooms-v0", layout_seed=3)
    assert a.goal == b.goal and a.start_pose == b.start_pose
    assert (a.walls == b.walls).all()
    d = a.shortest_path_length()
    assert d > 0
    obs1, _ = a.reset()
    a.step(FORWARD)
    obs2, _ = a.reset()                          # every episode: the same layout
    np.testing.assert_array_equal(obs1, obs2)
    assert a.goal_state == (a.goal[0], a.goal[1], None)


def cli(*args):
    return subprocess.run([sys.executable, "-m", "tmgwr_agent.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=240)


def test_env_change_in_minigrid_keeps_the_json_contract(tmp_path):
    maze = tmp_path / "tiny.txt"
    maze.write_text(TINY)
    out = tmp_path / "out.json"
    proc = cli("experiment", "env-change", "--world", "minigrid", "--maze", maze,
               "--agents", "tmgwr,q_learning,dyna_q_plus,rmax", "--trials", "2",
               "--jobs", "1", "--json", out, "--quiet")
    assert proc.returncode == 0, proc.stderr
    res = json.loads(out.read_text())
    assert res["world"] == "minigrid" and res["scenario"] == "env-change"
    assert res["oracle_steps"] == 10
    assert res["shortest_before"] == 2 and res["shortest_after"] == 9
    for a in ("tmgwr", "q_learning", "dyna_q_plus", "rmax"):
        steps = res["agents"][a]["steps"]
        assert len(steps["values"]) == 2
        assert all(v is None or v >= 10 for v in steps["values"])


@pytest.mark.parametrize("args, message", [
    (["--world", "minigird"], "unknown world 'minigird'"),
    (["--world", "gym:NoSuchEnv-v9"], "unknown Gymnasium env id 'NoSuchEnv-v9'"),
    (["--world", "gym:CartPole-v1"], "cannot map this env's observation"),
    (["--world", "minigrid", "--world-kwargs", "{bad"], "--world-kwargs '{bad' is not JSON"),
    (["--world", "minigrid", "--agents", "freespace"],
     "agent 'freespace' cannot run in --world"),
    (["--world", "gym:MiniGrid-FourRooms-v0"], "runs sample-complexity only"),
])
def test_world_cli_errors_exit_2_naming_it(args, message):
    proc = cli("experiment", "env-change", *args)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_tabular_goal_key_with_an_open_heading():
    from tmgwr_agent.baselines.q_learning import key_matches
    assert key_matches((5, 7, 2), (5, 7, None))
    assert not key_matches((5, 6, 2), (5, 7, None))
    assert key_matches((5, 7), (5, 7)) and not key_matches((0, 1, -1), (0, 1, 3))
    assert not key_matches((0, 1, 3), (0, 1, -1))   # -1 (a view's "at goal") is a value


def test_the_default_agent_converges_in_minigrid_and_detours_near_the_oracle():
    """Forward and turns make no lattice (core/frame.py): the default agent must still
    train to convergence and find the detour after the block (before the frame checked
    its lattice it never converged in MiniGrid)."""
    from tmgwr_agent.experiments.env_change import event_oracle, trial
    from tmgwr_agent.experiments.parallel import trial_seeds
    maze, spec = Maze.from_text(SMALL), parse_world("minigrid")
    oracle = event_oracle(spec, maze, "a", "G")["oracle_steps"]
    for t, seed in enumerate(trial_seeds(0, 3)):
        r = trial("tmgwr", t, seed, maze, "a", "G", world_spec=spec)
        assert r["train_episodes"] is not None, (t, r)
        assert r["steps"] is not None and r["steps"] <= 1.5 * oracle, (t, r, oracle)


def test_the_graph_knows_minigrid_senses_by_name():
    """The agent nodes host no world: the senses they take by name are the env's own."""
    from tmgwr_agent.world_senses import GRAPH_WORLDS, named_world_senses, world_senses
    assert "minigrid" in GRAPH_WORLDS
    named = named_world_senses("minigrid")
    built = world_senses(MiniGridWorld(Maze.from_text(SMALL), "G"))
    assert named.dim == built.dim == 4
    np.testing.assert_array_equal(named.primitives, built.primitives)
    assert named.goal_tolerance == built.goal_tolerance > 0.0
