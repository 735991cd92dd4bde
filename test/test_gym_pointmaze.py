"""``--world gym:PointMaze_*`` (maze_sim.gym_adapter): the registered env's ``maze_map`` and
its own draw of the goal and reset cells at the layout seed become a PointMazeWorld; a
tiny sample-complexity run keeps the JSON contract; what cannot be mapped exits 2 naming
it."""

import json
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

from maze_sim.gym_adapter import AdapterError, make_gym_world, pointmaze_layout
from maze_sim.pointmaze_world import SUCCESS_RADIUS, PointMazeWorld

pytest.importorskip("gymnasium_robotics")

#: gymnasium_robotics.envs.maze.maps.U_MAZE (1 wall, 0 free).
U_MAZE = [[1, 1, 1, 1, 1],
          [1, 0, 0, 0, 1],
          [1, 1, 1, 0, 1],
          [1, 0, 0, 0, 1],
          [1, 1, 1, 1, 1]]


def envs_own_draw(env_id: str, seed: int) -> tuple[tuple[int, int], tuple[int, int]]:
    """(start, goal) cells of the env's own reset at ``seed``, read independently."""
    env = gym.make(env_id)
    try:
        u = env.unwrapped
        u.reset(seed=seed)
        cell = u.maze.cell_xy_to_rowcol
        return tuple(map(int, cell(u.reset_pos))), tuple(map(int, cell(u.goal)))
    finally:
        env.close()


@pytest.mark.parametrize("seed", [0, 3])
def test_umaze_layout_is_the_envs_map_and_draw(seed):
    walls, start, goal = pointmaze_layout("PointMaze_UMaze-v3", seed)
    np.testing.assert_array_equal(walls, np.array(U_MAZE, dtype=bool))
    assert (start, goal) == envs_own_draw("PointMaze_UMaze-v3", seed)
    assert start != goal and not walls[start] and not walls[goal]
    assert pointmaze_layout("PointMaze_UMaze-v3", seed) [1:] == (start, goal)  # fixed


def test_reset_and_goal_cells_of_the_map_are_honoured():
    """Medium_Diverse_G: one 'r' cell (1, 1), three 'g' cells."""
    for seed in range(3):
        _, start, goal = pointmaze_layout("PointMaze_Medium_Diverse_G-v3", seed)
        assert start == (1, 1)
        assert goal in {(2, 6), (5, 1), (6, 5)}


def test_the_world_is_a_pointmaze_world_with_a_finite_oracle():
    w = make_gym_world("PointMaze_UMazeDense-v3", max_episode_steps=50, layout_seed=3)
    assert isinstance(w, PointMazeWorld)
    assert w.name == "gym:PointMaze_UMazeDense-v3" and w.layout_seed == 3
    assert w.start_pose == w.maze.start and w.goal == w.maze.goals["G"]
    np.testing.assert_allclose(w.goal_observation(), w.xy(w.goal))
    assert w.goal_tolerance == SUCCESS_RADIUS
    d = w.shortest_path_length()
    assert 0 < d < 4 * w.per_cell * w.walls.size
    obs, _ = w.reset()
    np.testing.assert_allclose(obs, w.xy(w.start_pose))


@pytest.mark.parametrize("kwargs, message", [
    ({"reset_target": True}, "reset_target=true moves the goal"),
    ({"position_noise_range": 0.25}, "position_noise_range=0.25 cannot be mapped"),
    ({"render_mode": "human"}, "'render_mode' cannot be mapped"),
    ({"layout_seed": -1}, "layout_seed must be an integer >= 0"),
    ({"maze_map": [[1, 1, 1], [1, 0, 1], [1, 1, 1]]}, "maze_map has 1 free cell"),
])
def test_what_cannot_be_mapped_is_refused_naming_it(kwargs, message):
    with pytest.raises(AdapterError, match=message):
        make_gym_world("PointMaze_Open-v3", **kwargs)


def cli(*args):
    return subprocess.run([sys.executable, "-m", "tmgwr_agent.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=600)


def test_sample_complexity_runs_on_a_registered_pointmaze(tmp_path):
    out = tmp_path / "out.json"
    proc = cli("experiment", "sample-complexity", "--world", "gym:PointMaze_UMaze-v3",
               "--world-kwargs", '{"layout_seed": 3}', "--agents", "tmgwr",
               "--trials", "1", "--episodes", "3", "--jobs", "1", "--json", out, "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert "AdroitHand" not in proc.stderr      # gymnasium_robotics' import-time notice
    res = json.loads(out.read_text())
    assert res["world"] == "gym:PointMaze_UMaze-v3"
    assert res["maze"] == "gym:PointMaze_UMaze-v3 (layout seed 3)"
    assert res["scenario"] == "sample-complexity"
    assert "tmgwr" in res["agents"]


@pytest.mark.parametrize("args, message", [
    (["--world", "gym:PointMaze_Nope-v3"], "unknown Gymnasium env id 'PointMaze_Nope-v3'"),
    (["--world", "gym:PointMaze_UMaze-v3", "--world-kwargs", '{"reset_target": true}'],
     "gym:PointMaze_UMaze-v3: reset_target=true"),
])
def test_cli_refusals_exit_2_naming_it(args, message):
    proc = cli("experiment", "sample-complexity", "--trials", "1", *args)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr
