"""maze_sim.gym_env.MazeEnv: Gymnasium's own checker, wrappers, seeding, and the maze rules
(goal, bump, events) seen through the Gymnasium API."""

import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.wrappers import RecordEpisodeStatistics, TimeLimit

from maze_sim.gym_env import ENV_ID, MazeEnv
from maze_sim.maze import ACTIONS, Maze, bfs_distances, maze_file, move

UP, DOWN, LEFT, RIGHT = (ACTIONS.index(a) for a in ("up", "down", "left", "right"))


def shortest_actions(env: MazeEnv) -> list[int]:
    """Actions of a shortest path from the current cell to the goal (BFS distance descent)."""
    walls, cell = env.world.walls, env.world.cell
    dist = bfs_distances(walls, env.world.goal)
    actions = []
    while cell != env.world.goal:
        a = next(a for a in range(len(ACTIONS))
                 if dist[move(walls, cell, a)[0]] == dist[cell] - 1)
        actions.append(a)
        cell = move(walls, cell, a)[0]
    return actions


@pytest.mark.parametrize("noise", [0.0, 0.3])
def test_check_env_passes_without_warnings(noise):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gymnasium.make(ENV_ID, sensor_noise=noise)
        check_env(env.unwrapped)   # with a spec: also the "ansi" render mode and close()
        env.close()


def test_spaces_follow_the_maze_and_the_noise():
    env = MazeEnv(sensor_noise=0.5)
    assert env.action_space == gymnasium.spaces.Discrete(4)
    np.testing.assert_allclose(env.observation_space.low, [-3.0, -3.0])
    np.testing.assert_allclose(env.observation_space.high, [12 + 3.0, 16 + 3.0])
    exact = MazeEnv()
    np.testing.assert_array_equal(exact.observation_space.low, [0, 0])
    np.testing.assert_array_equal(exact.observation_space.high, [12, 16])


def test_make_by_id_with_wrappers_truncates_and_records():
    env = RecordEpisodeStatistics(
        gymnasium.make("maze_sim.gym_env:maze_sim/Maze-v0", max_episode_steps=5))
    assert any(isinstance(w, TimeLimit) for w in _wrappers(env))
    obs, info = env.reset(seed=0)
    np.testing.assert_array_equal(obs, [1.0, 1.0])
    assert info["cell"] == (1, 1)
    for k in range(5):
        obs, reward, terminated, truncated, info = env.step(DOWN if k % 2 == 0 else UP)
        assert not terminated and reward == 0.0
    assert truncated and info["episode"]["l"] == 5 and info["episode"]["r"] == 0.0


def _wrappers(env):
    while isinstance(env, gymnasium.Wrapper):
        yield env
        env = env.env


def test_the_world_truncates_with_max_episode_steps():
    env = MazeEnv(max_episode_steps=3)
    env.reset(seed=0)
    flags = [env.step(UP)[3] for _ in range(3)]
    assert flags == [False, False, True]


def test_same_seed_same_trajectory_with_noise():
    env = MazeEnv(sensor_noise=0.4)
    actions = np.random.default_rng(1).integers(0, 4, size=50)

    def run(seed):
        obs, info = env.reset(seed=seed)
        out = [(obs, info)]
        for a in actions:
            out.append(env.step(a))
        return out

    first, second, other = run(7), run(7), run(8)
    for a, b in zip(first, second):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)
    assert not np.array_equal(first[0][0], other[0][0])
    assert set(first[1][-1]) == {"cell", "bumped", "reached_goal", "reached_previous_goal"}


def test_shortest_path_on_the_default_maze_reaches_the_goal():
    env = MazeEnv()
    env.reset(seed=0)
    actions = shortest_actions(env)
    assert len(actions) == 44   # docs/mazes.md: the unique shortest S-G path
    for a in actions[:-1]:
        obs, reward, terminated, truncated, info = env.step(a)
        assert (reward, terminated, truncated) == (0.0, False, False)
    obs, reward, terminated, truncated, info = env.step(actions[-1])
    assert terminated and not truncated and reward == 1.0 and info["reached_goal"]
    np.testing.assert_array_equal(obs, [11.0, 15.0])
    assert info["cell"] == (11, 15)


def test_a_bump_leaves_the_agent_in_place():
    env = MazeEnv()
    env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(UP)   # (0, 1) is the outer wall
    assert info["bumped"] and info["cell"] == (1, 1)
    np.testing.assert_array_equal(obs, [1.0, 1.0])
    assert not env.step(DOWN)[4]["bumped"]


def test_reset_options_move_the_goal_and_the_start():
    env = MazeEnv()
    obs, info = env.reset(seed=0, options={"goal": "2", "start": (1, 9)})
    assert info == {"cell": (1, 9), "goal": (1, 11)}
    env.step(RIGHT)
    obs, reward, terminated, _, info = env.step(RIGHT)
    assert terminated and reward == 1.0 and info["cell"] == (1, 11)
    _, info = env.reset()                    # the goal stays, the start does not
    assert info == {"cell": (1, 1), "goal": (1, 11)}
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(options={"goals": "2"})


def test_fire_event_blocks_a_cell_and_ansi_render_shows_it():
    env = MazeEnv(render_mode="ansi")
    env.reset(seed=0, options={"start": (5, 3)})
    assert not env.step(DOWN)[4]["bumped"]  # (6, 3) is free before event a
    env.reset(options={"start": (5, 3)})
    env.unwrapped.fire_event("a")
    assert env.step(DOWN)[4]["bumped"]
    rows = env.render().splitlines()
    assert rows[6][3] == "#" and rows[5][3] == "@" and rows[11][15] == "G"
    assert len(rows) == 13 and {len(r) for r in rows} == {17}


def test_maze_given_as_object_or_path():
    small = Maze.from_text("#####\n#S.G#\n#####\n")
    env = MazeEnv(small)
    env.reset(seed=0)
    assert env.step(RIGHT)[2] is False and env.step(RIGHT)[2] is True
    assert MazeEnv(str(maze_file())).world.maze.shape == (13, 17)
