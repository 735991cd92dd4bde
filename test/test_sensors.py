"""``--sensor SPEC`` (maze_sim.sensors, tmgwr_agent.experiments.sensing): each wrapper by
hand and under Gymnasium's checker, the spec's errors through the real ``./tmgwr`` CLI
(exit 2 naming the part), the JSON's ``sensor`` and ``learning_steps``, identity sensing
unchanged, and the tabular agents' discretisation of what they sense."""

import json
import math
import subprocess
import warnings

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from ros_helpers import ROOT
from small_mazes import SMALL

from maze_sim.gym_env import MazeEnv
from maze_sim.maze import Maze, maze_file
from maze_sim.sensors import (
    NoiseSensor,
    SensorSpecError,
    goal_sensation,
    parse_sensor,
    sense,
    wrap,
)
from maze_sim.world import GridWorld
from tmgwr_agent.experiments.agent_factory import make_agent
from tmgwr_agent.experiments.env_change import trial as env_trial
from tmgwr_agent.experiments.runner import (
    Caps,
    make_world,
    set_goal,
    train_until_converged,
)
from tmgwr_agent.experiments.sensing import discretise, grid_step

SMALL_MAZE = Maze.from_text(SMALL, source="<small>")   # S (1, 1), G (5, 7)


def env_at(spec, cell=(3, 5), rng=None):
    """A wrapped MazeEnv of the small maze, reset with the agent at ``cell``."""
    env = wrap(MazeEnv(SMALL_MAZE), spec, rng)
    obs, _ = env.reset(seed=0, options={"start": cell})
    return env, obs


# ------------------------------------------------------------------ the spec
@pytest.mark.parametrize("text, normalised", [
    (None, "identity"), ("", "identity"), ("none", "identity"), ("identity", "identity"),
    ("noise=0", "identity"), ("rotate=360", "identity"), ("scale=1:1", "identity"),
    ("rotate=30,scale=1:2", "scale=1:2,rotate=30"), (" noise = 0.10 ", "noise=0.1"),
    ("rotate=-90", "rotate=270"), ("view=2", "view=2"),
])
def test_spec_is_normalised(text, normalised):
    assert parse_sensor(text).text == normalised


@pytest.mark.parametrize("text, part", [
    ("noise=abc", "noise=abc"), ("noise=-0.1", "noise=-0.1"), ("scale=1", "scale=1"),
    ("scale=0:1", "scale=0:1"), ("scale=1:x", "scale=1:x"), ("rotate=nan", "rotate=nan"),
    ("zoom=2", "zoom=2"), ("noise", "noise"), ("view=0", "view=0"), ("view=1.5", "view=1.5"),
    ("view=1,rotate=10", "view=1"), ("noise=0.1,noise=0.2", "noise=0.2"),
])
def test_bad_spec_names_the_part(text, part):
    with pytest.raises(SensorSpecError, match=f"'{part}'"):
        parse_sensor(text)


# ------------------------------------------------------------------ the wrappers by hand
def test_scale_and_rotate_by_hand():
    _, obs = env_at("scale=2:3")
    np.testing.assert_array_equal(obs, [6.0, 15.0])
    _, obs = env_at("rotate=90")                  # (row, col) -> (-col, row): axes swap
    np.testing.assert_array_equal(obs, [-5.0, 3.0])
    _, obs = env_at("rotate=90,scale=2:3")        # scale first, then rotate
    np.testing.assert_array_equal(obs, [-15.0, 6.0])
    _, obs = env_at("rotate=30")
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    np.testing.assert_allclose(obs, [c * 3 - s * 5, s * 3 + c * 5])
    env, obs = env_at("rotate=90")
    obs, *_ = env.step(0)                         # up: row - 1 -> second sensed axis - 1
    np.testing.assert_array_equal(obs, [-5.0, 2.0])


def test_goal_sensation_is_the_goal_through_the_same_transform():
    env, _ = env_at("noise=0.3,scale=2:3,rotate=90")
    np.testing.assert_array_equal(goal_sensation(env, (5, 7)), [-21.0, 10.0])


def test_noise_has_the_given_std_and_no_bias():
    env, _ = env_at("noise=0.2", rng=np.random.default_rng(7))
    draws = np.array([sense(env, np.array([3.0, 5.0])) for _ in range(20000)])
    np.testing.assert_allclose(draws.mean(axis=0), [3.0, 5.0], atol=0.01)
    np.testing.assert_allclose(draws.std(axis=0), [0.2, 0.2], rtol=0.03)
    a = NoiseSensor(MazeEnv(SMALL_MAZE), 0.2, np.random.default_rng(7))
    b = NoiseSensor(MazeEnv(SMALL_MAZE), 0.2, np.random.default_rng(7))
    x = np.array([3.0, 5.0])
    np.testing.assert_array_equal(a.sense(x), b.sense(x))     # seeded: reproducible


def test_view_window_at_a_corner():
    _, obs = env_at("view=1", cell=(1, 1))
    np.testing.assert_array_equal(obs[:9], [1, 1, 1,
                                            1, 0, 0,
                                            1, 0, 1])
    np.testing.assert_allclose(obs[9:], np.array([4.0, 6.0]) / math.hypot(4, 6))
    _, obs = env_at("view=2", cell=(1, 1))          # beyond the maze counts as wall
    window = obs[:25].reshape(5, 5)
    assert window[0].all() and window[:, 0].all()
    np.testing.assert_array_equal(window[2], [1, 1, 0, 0, 0])   # row 1: "##S.."


def test_view_sees_an_event_wall_and_the_goal_compass_is_zero():
    env, obs = env_at("view=1", cell=(5, 2))
    assert obs[5] == 0                                          # (5, 3) free: 'a'
    env.unwrapped.fire_event("a")
    obs, *_ = env.step(0)                                       # up: bump into (4, 2)
    assert obs[5] == 1
    goal = goal_sensation(env, (5, 7))
    np.testing.assert_array_equal(goal[9:], [0.0, 0.0])
    np.testing.assert_array_equal(goal[:9], [1, 0, 1, 0, 0, 1, 1, 1, 1])


@pytest.mark.parametrize("spec", ["noise=0.2", "scale=1:2", "rotate=30",
                                  "noise=0.1,scale=1:5,rotate=45", "view=1", "view=3"])
def test_wrappers_pass_the_gymnasium_checker(spec):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message=".*different from the unwrapped.*")
        check_env(wrap(MazeEnv(SMALL_MAZE), spec), skip_render_check=True)


# ------------------------------------------------------------------ the tabular reading
@pytest.mark.parametrize("spec", ["scale=1:2", "rotate=90,scale=3:1", "rotate=30",
                                  "rotate=45,scale=1:5", "scale=0.2:1,rotate=200"])
def test_no_two_cells_share_a_state(spec):
    spec = parse_sensor(spec)
    maze = Maze.from_file(maze_file())
    env = wrap(MazeEnv(maze), spec)
    keys = {discretise(sense(env, np.array(c, dtype=float)), spec) for c in maze.free_cells()}
    assert len(keys) == len(maze.free_cells())


def test_axis_aligned_grid_is_one_cell_centred():
    assert grid_step(parse_sensor("scale=2:5")) == (2.0, 5.0)
    assert grid_step(parse_sensor("scale=2:5,rotate=90")) == (5.0, 2.0)
    side = grid_step(parse_sensor("scale=2:5,rotate=30"))[0]
    assert side == pytest.approx(2 / math.sqrt(2))
    spec = parse_sensor("noise=0.1")       # noise well under half a cell: the cell's state
    assert discretise(np.array([3.3, 4.8]), spec) == (3, 5)


@pytest.mark.parametrize("name", ["q_learning", "dyna_q_plus", "rmax"])
def test_tabular_agent_under_scale_learns_the_same_states(name):
    """scale=1:2 keys every cell to one state: the table learns as many states as on cells,
    and since only the numbering differs, the very same episodes."""
    caps = Caps.for_maze(SMALL_MAZE)
    seed = np.random.SeedSequence(3)
    runs = {}
    for spec in ("identity", "scale=1:2"):
        world = make_world(SMALL_MAZE, "G", caps, spec, seed)
        agent = make_agent(name, SMALL_MAZE, np.random.default_rng(seed),
                           sensed=not world.identity)
        set_goal(world, agent, "G")
        conv = train_until_converged(world, agent, caps)
        runs[spec] = (agent.states_seen(), conv.curve, agent.sensed)
    assert runs["identity"][2] is None and runs["scale=1:2"][2]   # cells vs sensed keys
    assert runs["scale=1:2"][0] == runs["identity"][0] > 10
    assert runs["scale=1:2"][1] == runs["identity"][1]


@pytest.mark.parametrize("name", ["q_learning", "dyna_q_plus", "rmax", "tmgwr"])
def test_identity_world_runs_as_the_bare_world(name):
    """The experiments' world without --sensor gives the agents what the bare GridWorld
    gave them before --sensor existed: the same training, step for step."""
    caps = Caps.for_maze(SMALL_MAZE)
    seed = np.random.SeedSequence(5)
    curves = []
    for world in (GridWorld(SMALL_MAZE, "G", max_episode_steps=caps.episode_steps),
                  make_world(SMALL_MAZE, "G", caps, None, seed)):
        agent = make_agent(name, SMALL_MAZE, np.random.default_rng(seed))
        set_goal(world, agent, "G")
        curves.append(train_until_converged(world, agent, caps).curve)
    assert curves[0] == curves[1]


def test_learning_steps_is_the_mean_of_the_last_ten_training_episodes():
    caps = Caps.for_maze(SMALL_MAZE)
    seed = np.random.SeedSequence(11)
    world = make_world(SMALL_MAZE, "G", caps, "noise=0.1", seed)
    agent = make_agent("q_learning", SMALL_MAZE, np.random.default_rng(seed), sensed=True)
    set_goal(world, agent, "G")
    curve = train_until_converged(world, agent, caps).curve
    r = env_trial("q_learning", 0, seed, SMALL_MAZE, "a", "G", to_optimal=False,
                  sensor="noise=0.1")
    assert len(curve) > 10
    assert r["learning_steps"] == pytest.approx(sum(curve[-10:]) / 10)


# ------------------------------------------------------------------ the CLI and the JSON
def tmgwr(*args):
    return subprocess.run([str(ROOT / "tmgwr"), *map(str, args)], capture_output=True,
                          text=True, timeout=300)


@pytest.fixture(scope="module")
def small_maze(tmp_path_factory):
    path = tmp_path_factory.mktemp("maze") / "small.txt"
    path.write_text(SMALL)
    return path


@pytest.mark.parametrize("spec, message", [
    ("noise=abc", "'noise=abc': 'abc' is not a number"),
    ("noise=-1", "'noise=-1': sigma must be >= 0"),
    ("scale=1", "'scale=1': expected scale=SX:SY"),
    ("blur=2", "'blur=2': unknown key 'blur'"),
    ("view=1,noise=0.1", "sensor part 'view=1' takes no other part"),
])
def test_cli_refuses_a_bad_spec_with_exit_2(small_maze, spec, message):
    proc = tmgwr("experiment", "env-change", "--maze", small_maze, "--trials", 1,
                 "--agents", "tmgwr,q_learning", "--sensor", spec, "--quiet")
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_cli_refuses_an_agent_that_reads_cells(small_maze):
    proc = tmgwr("experiment", "goal-change", "--suite", "braided:1", "--trials", 1,
                 "--agents", "model_based", "--sensor", "rotate=10", "--quiet")
    assert proc.returncode == 2
    assert "'model_based' cannot run under --sensor rotate=10" in proc.stderr


def run_json(tmp_path, name, *args):
    out = tmp_path / f"{name}.json"
    proc = tmgwr("experiment", *args, "--json", out, "--quiet")
    assert proc.returncode == 0, proc.stderr
    return json.loads(out.read_text())


def assert_stat(s, n):
    assert set(s) - {"failed"} == {"mean", "std", "values"} and len(s["values"]) == n


def test_json_carries_sensor_and_learning_steps(tmp_path, small_maze):
    env = run_json(tmp_path, "env", "env-change", "--maze", small_maze, "--trials", 2,
                   "--agents", "tmgwr,q_learning,dyna_q_plus", "--sensor",
                   "rotate=30,scale=1:2,noise=0.05", "--jobs", 1)
    assert list(env)[:5] == ["scenario", "maze", "trials", "seed", "sensor"]
    assert env["sensor"] == "noise=0.05,scale=1:2,rotate=30"
    for a in ("tmgwr", "q_learning", "dyna_q_plus"):
        assert_stat(env["agents"][a]["learning_steps"], 2)
        assert all(v >= env["shortest_before"] for v in
                   env["agents"][a]["learning_steps"]["values"])
    goal = run_json(tmp_path, "goal", "goal-change", "--maze", small_maze, "--trials", 2,
                    "--agents", "q_learning", "--goals", "1,2,G", "--episodes", 12,
                    "--sensor", "view=1", "--jobs", 1)
    assert goal["sensor"] == "view=1"
    rows = goal["agents"]["q_learning"]["transitions"]
    assert [(r["from"], r["to"]) for r in rows] == [("1", "2"), ("2", "G")]
    for r in rows:
        assert_stat(r["learning_steps"], 2)


def test_identity_sensing_json_is_unchanged(tmp_path, small_maze):
    args = ("env-change", "--maze", small_maze, "--trials", 2, "--seed", 4,
            "--agents", "tmgwr,q_learning,dyna_q_plus,model_based", "--jobs", 1)
    plain = run_json(tmp_path, "plain", *args)
    assert plain["sensor"] == "identity"
    assert run_json(tmp_path, "empty", *args, "--sensor", "") == plain
    assert run_json(tmp_path, "identity", *args, "--sensor", "identity") == plain
    assert run_json(tmp_path, "zero", *args, "--sensor", "noise=0,rotate=0") == plain
