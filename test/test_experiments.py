"""The experiments CLI end to end (``python -m tmgwr_agent.cli experiment ...`` in a
subprocess, on a small maze with few trials): the JSON shape of every scenario
(docs/experiments.md), identical JSON for the same seed whatever ``--jobs``, ``null`` and
``"failed"`` for trials that never reach the goal, ``oracle_steps`` computed by hand, the
figures, and exit code 2 with a clear message for bad names."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from small_mazes import SMALL

from maze_sim import Maze
from maze_sim.maze import maze_file
from tmgwr_agent.experiments.env_change import oracle_steps
from tmgwr_agent.experiments.runner import Caps
from tmgwr_agent.experiments.stats import stat

DEFAULT_MAZE = maze_file()


@pytest.fixture(scope="module")
def small_maze(tmp_path_factory):
    path = tmp_path_factory.mktemp("maze") / "small.txt"
    path.write_text(SMALL)
    return path


def cli(*args, check=True):
    proc = subprocess.run([sys.executable, "-m", "tmgwr_agent.cli", *map(str, args)],
                          capture_output=True, text=True, timeout=240)
    if check:
        assert proc.returncode == 0, proc.stderr
    return proc


def experiment(tmp_path, maze, *args, name="out"):
    out = tmp_path / f"{name}.json"
    cli("experiment", *args, "--maze", maze, "--json", out, "--quiet")
    return json.loads(out.read_text()), out


def assert_stat(s, trials):
    assert set(s) - {"failed"} == {"mean", "std", "values"}
    assert len(s["values"]) == trials
    failed = sum(v is None for v in s["values"])
    assert s.get("failed", 0) == failed
    ok = [v for v in s["values"] if v is not None]
    if ok:
        assert s["mean"] == pytest.approx(sum(ok) / len(ok))
    else:
        assert s["mean"] is None and s["std"] is None


def assert_header(res, scenario, maze, trials, seed, agents):
    assert res["scenario"] == scenario
    assert res["maze"] == str(maze)
    assert res["trials"] == trials and res["seed"] == seed
    assert list(res["agents"]) == agents


# ------------------------------------------------------------------ JSON shape, per scenario
def test_goal_change_json_and_plot(tmp_path, small_maze):
    png = tmp_path / "gc.png"
    res, _ = experiment(tmp_path, small_maze, "goal-change", "--goals", "1,2,G",
                        "--episodes", "15", "--trials", "2", "--seed", "5",
                        "--agents", "tmgwr,q_learning,model_based,dyna_q_plus",
                        "--plot", png)
    assert_header(res, "goal-change", small_maze, 2, 5,
                  ["tmgwr", "q_learning", "model_based", "dyna_q_plus"])
    assert res["episodes"] == 15
    for name, a in res["agents"].items():
        assert [(t["from"], t["to"]) for t in a["transitions"]] == [("1", "2"), ("2", "G")]
        for t in a["transitions"]:
            assert_stat(t["previous_pct"], 2)
            assert_stat(t["current_pct"], 2)
            for p, c in zip(t["previous_pct"]["values"], t["current_pct"]["values"]):
                assert 0 <= p and 0 <= c and p + c <= 100.0 + 1e-9
    # the model-based agent replans at once with its (still valid) model
    mb = res["agents"]["model_based"]["transitions"]
    assert mb[0]["current_pct"]["mean"] > 50        # 1 -> 2
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_env_change_json_nulls_and_oracle(tmp_path, small_maze):
    png = tmp_path / "ec.png"
    res, _ = experiment(tmp_path, small_maze, "env-change", "--event", "a", "--trials", "2",
                        "--agents", "tmgwr:literal,q_learning,model_based", "--plot", png)
    assert_header(res, "env-change", small_maze, 2, 0,
                  ["tmgwr:literal", "q_learning", "model_based"])
    # oracle by hand: 5 steps S->(5,2), 1 bump at (5,3), then back to S (5) and over the
    # top (14): 5 + 1 + 19 = 25
    assert res["oracle_steps"] == 25
    assert (res["shortest_before"], res["shortest_after"]) == (10, 14)
    for name, a in res["agents"].items():
        for key in ("steps", "episodes_to_optimal"):
            assert_stat(a[key], 2)
    # the model-based agent never recovers: every trial is null, reported, not dropped
    mb = res["agents"]["model_based"]
    assert mb["steps"]["values"] == [None, None] and mb["steps"]["failed"] == 2
    assert mb["episodes_to_optimal"]["failed"] == 2
    # Q-learning does find the detour, never faster than the oracle
    ql = res["agents"]["q_learning"]["steps"]["values"]
    assert all(v is not None and v >= 25 for v in ql)
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_sample_complexity_json(tmp_path, small_maze):
    res, _ = experiment(tmp_path, small_maze, "sample-complexity", "--goals", "G,1",
                        "--episodes", "12", "--trials", "2",
                        "--agents", "q_learning,model_based")
    assert_header(res, "sample-complexity", small_maze, 2, 0, ["q_learning", "model_based"])
    for name, a in res["agents"].items():
        assert list(a["goals"]) == ["G", "1"]
        for g in a["goals"].values():
            assert len(g["curve"]) == 2             # episodes 5 and 10
            assert all(isinstance(v, float) and v >= 10 for v in g["curve"])
            assert_stat(g["episodes_to_converge"], 2)
    # the model-based agent knows the maze: its first greedy rollout is optimal
    assert res["agents"]["model_based"]["goals"]["G"]["episodes_to_converge"]["values"] \
        == [1, 1]


def test_timing_json(tmp_path, small_maze):
    res, _ = experiment(tmp_path, small_maze, "timing", "--goals", "G,2", "--trials", "2",
                        "--agents", "q_learning,model_based")
    assert_header(res, "timing", small_maze, 2, 0, ["q_learning", "model_based"])
    for name, a in res["agents"].items():
        for key in ("train_s", "goal_adapt_s", "event_recover_s"):
            assert_stat(a[key], 2)
            assert all(v is None or v >= 0 for v in a[key]["values"])
    assert res["agents"]["model_based"]["event_recover_s"]["failed"] == 2
    assert res["agents"]["q_learning"]["train_s"]["mean"] > 0


# ------------------------------------------------------------------ determinism
def test_same_seed_same_json_whatever_jobs(tmp_path, small_maze):
    args = ("goal-change", "--goals", "G,1,2", "--episodes", "10", "--trials", "3",
            "--agents", "tmgwr,q_learning,model_based,dyna_q_plus")
    outs = []
    for jobs in (1, 2):
        _, path = experiment(tmp_path, small_maze, *args, "--seed", "7", "--jobs", jobs,
                             name=f"j{jobs}")
        outs.append(path.read_bytes())
    assert outs[0] == outs[1]
    # a different seed gives different trials
    res2, _ = experiment(tmp_path, small_maze, *args, "--seed", "8", "--jobs", "2",
                         name="s8")
    assert res2["agents"] != json.loads(outs[0])["agents"]


# ------------------------------------------------------------------ statistics, oracle
def test_stat_reports_failed_trials_as_null():
    s = stat([3, None, 5, float("inf")])
    assert s == {"mean": 4.0, "std": 1.0, "values": [3, None, 5, None], "failed": 2}
    assert stat([None, None]) == {"mean": None, "std": None, "values": [None, None],
                                  "failed": 2}
    assert "failed" not in stat([1.5])


def test_oracle_steps_on_the_default_maze():
    maze = Maze.from_file(DEFAULT_MAZE)
    # By hand from src/maze_sim/mazes/paper_13x17.txt: the only 44-step path runs
    # S(1,1) down, right, up to (1,5), down to (5,5) [12 steps], left to (5,3) [14],
    # through a=(6,3) to row 7, along it to (7,7) [20], up to (3,7) [24], right to (3,9),
    # down to (5,9), right to (5,10) [29], through b=(5,11) down column 11 to (11,11)
    # [36] and on to G(11,15) [44].
    # Event a: 14 steps to (5,3), 1 bump, then from (5,3) the new shortest path west and
    # down the left side, along row 11 and up column 5, east along row 9, up to (7,9)
    # and west to (7,7) [22], plus the old 24 from (7,7) to G: 14 + 1 + 46 = 61.
    assert oracle_steps(maze, "a") == 14 + 1 + 46 == 61
    # Event b: 29 steps to (5,10), 1 bump, then back to (3,7) [5], up to row 1, east to
    # goal 2 (1,11), down to (3,11) [13], east to (3,15), down to (5,15), west to (5,13),
    # down to (7,13), west to (7,11) [25], down to (11,11) [29], on to G [37]:
    # 29 + 1 + 37 = 67.
    assert oracle_steps(maze, "b") == 29 + 1 + 37 == 67
    assert maze.shortest_path_length(maze.start, maze.goals["G"]) == 44
    assert maze.shortest_path_length(maze.start, maze.goals["G"],
                                     walls=maze.walls_after(["a"])) == 60
    assert maze.shortest_path_length(maze.start, maze.goals["G"],
                                     walls=maze.walls_after(["b"])) == 56


def test_oracle_is_the_plain_shortest_path_when_an_optimal_path_avoids_the_block():
    # two equally short routes; the event blocks only one of them
    maze = Maze.from_text("#####\n#S..#\n#.#.#\n#a.G#\n#####\n")
    assert oracle_steps(maze, "a") == 4


def test_caps_follow_the_maze_size():
    maze = Maze.from_file(DEFAULT_MAZE)
    assert len(maze.free_cells()) == 99
    assert Caps.for_maze(maze) == Caps(episode_steps=19800, max_episodes=1980,
                                       budget_steps=99000)


def test_agent_options_combine():
    from tmgwr_agent.experiments.agent_factory import make_agent
    ag = make_agent("tmgwr:literal+paper", Maze.from_text(SMALL), np.random.default_rng(0))
    assert ag.map.link_rule == "literal"
    assert not (ag.motivation.absorbing_terminals or ag.selector.goal_search
                or ag.selector.try_untried or ag.selector.config.walk_while_novel)
    assert ag.selector.policy.hold is None
    default = make_agent("tmgwr", Maze.from_text(SMALL), np.random.default_rng(0))
    assert default.selector.try_untried and default.motivation.absorbing_terminals
    assert default.selector.policy.hold is not None
    assert default.motivation.retest_rate == "fixed"
    settle = make_agent("tmgwr:settle+grid", Maze.from_text(SMALL), np.random.default_rng(0))
    assert settle.motivation.retest_rate == "learnt"
    assert settle.motivation.config.unknown == "grid"


# ------------------------------------------------------------------ errors
@pytest.mark.parametrize("args, message", [
    (["experiment", "env-change", "--agents", "tmgwr,sarsa"], "unknown agent 'sarsa'"),
    (["experiment", "env-change", "--agents", "q_learning:credit"], "takes no option"),
    (["experiment", "env-change", "--agents", "tmgwr:credit+fast"],
     "unknown tmgwr option 'fast'"),
    (["experiment", "env-change", "--event", "z"], "no event named 'z'"),
    (["experiment", "goal-change", "--goals", "1,9"], "no goal named '9'"),
    (["experiment", "timing", "--goals", "1,2,3"], "two goals"),
    (["experiment", "env-change", "--maze", "/nonexistent/maze.txt"],
     "maze file '/nonexistent/maze.txt' not found"),
    (["experiment", "warp-speed"], "invalid choice: 'warp-speed'"),
])
def test_cli_errors_exit_2_with_a_clear_message(args, message):
    proc = cli(*args, check=False)
    assert proc.returncode == 2
    assert message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_malformed_maze_names_line_and_column(tmp_path):
    bad = tmp_path / "bad.txt"
    bad.write_text("#####\n#S.G#\n###\n")
    proc = cli("experiment", "env-change", "--maze", bad, check=False)
    assert proc.returncode == 2
    assert f"{bad}:3:" in proc.stderr


# ------------------------------------------------------------------ --params
REPO = Path(__file__).resolve().parents[1]
TUNED_QL = str(REPO / "config/tuned/q_learning.yaml")


def test_tuned_file_changes_the_baseline_and_the_json_records_it(tmp_path, small_maze):
    args = ("env-change", "--event", "a", "--trials", "2", "--agents",
            "q_learning,model_based", "--jobs", "1")
    plain, _ = experiment(tmp_path, small_maze, *args, name="plain")
    assert "params" not in plain                         # no --params: the old JSON
    tuned, _ = experiment(tmp_path, small_maze, *args, "--params", TUNED_QL, name="tuned")
    from tmgwr_agent.experiments.tune import load_tuned
    values = load_tuned(TUNED_QL, "q_learning")
    assert values["gamma"] != 0.86                       # not the defaults (Table 2)
    assert list(tuned) == list(plain)[:-1] + ["params", "agents"]
    assert tuned["params"] == {"files": [TUNED_QL],
                               "agents": {"q_learning": values, "model_based": {}}}
    # the tuned values reach the agent: another run; the untouched agent is unchanged
    assert tuned["agents"]["q_learning"] != plain["agents"]["q_learning"]
    assert tuned["agents"]["model_based"] == plain["agents"]["model_based"]
    # the same file given to q_learning only, and a later file's value winning
    later = tmp_path / "later.yaml"
    later.write_text("q_learning:\n  ros__parameters:\n    gamma: 0.9\n")
    again, _ = experiment(tmp_path, small_maze, *args, "--params", f"q_learning={TUNED_QL}",
                          "--params", later, name="again")
    assert again["params"]["files"] == [f"q_learning={TUNED_QL}", str(later)]
    assert again["params"]["agents"]["q_learning"] == {**values, "gamma": 0.9}


def test_params_per_agent_spec(tmp_path):
    from tmgwr_agent.experiments.scenarios import UsageError
    from tmgwr_agent.experiments.tune import experiment_params
    agents = ["tmgwr:credit", "tmgwr:literal", "q_learning"]
    with pytest.raises(UsageError, match="values for none of the agents"):
        experiment_params(agents, [str(REPO / "config/tuned/dyna_q_plus.yaml")])
    # one file with a section per agent serves them all; AGENT=FILE narrows it
    f = tmp_path / "all.yaml"
    f.write_text("/**:\n  ros__parameters:\n    gamma: 0.9\n"
                 "q_learning:\n  ros__parameters:\n    gamma: 0.5\n"
                 "dyna_q_plus:\n  ros__parameters:\n    kappa: 0.01\n")
    assert experiment_params(agents, [str(f)]) == {
        "tmgwr:credit": {"gamma": 0.9}, "tmgwr:literal": {"gamma": 0.9},
        "q_learning": {"gamma": 0.5}}
    assert experiment_params(agents, [f"tmgwr:credit={f}"]) == {
        "tmgwr:credit": {"gamma": 0.9}, "tmgwr:literal": {}, "q_learning": {}}
    assert experiment_params(agents, [f"tmgwr={f}"])["tmgwr:literal"] == {"gamma": 0.9}


@pytest.mark.parametrize("body, arg, message", [
    ("q_learning:\n  ros__parameters:\n    gama: 0.9\n", "{f}",
     "[q_learning]: unknown parameter 'gama' (did you mean 'gamma'?)"),
    ("q_leaning:\n  ros__parameters:\n    gamma: 0.9\n", "{f}",
     "section 'q_leaning' is read by no agent (did you mean 'q_learning'?)"),
    ("q_learning:\n  ros__parameters:\n    gamma: 1.5\n", "{f}", "out of range"),
    ("q_learning:\n  ros__parameters:\n    gamma: 0.9\n", "sarsa={f}",
     "unknown agent 'sarsa'"),
    ("q_learning:\n  ros__parameters:\n    gamma: 0.9\n", "dyna_q_plus={f}",
     "not among the agents run"),
    ("/**:\n  ros__parameters:\n    gamma: 0.9\n", "q_learning={f}",
     "has no section 'q_learning' for q_learning"),
])
def test_bad_params_exit_2_naming_the_key_and_the_file(tmp_path, body, arg, message):
    f = tmp_path / "p.yaml"
    f.write_text(body)
    for extra in ((), ("--suite", "blocking:1")):
        proc = cli("experiment", "env-change", "--agents", "tmgwr,q_learning", "--params",
                   arg.format(f=f), *extra, check=False)
        assert proc.returncode == 2, proc.stderr
        assert message in proc.stderr, proc.stderr
        assert "Traceback" not in proc.stderr
        if "sarsa" not in arg and "not among" not in message:
            assert str(f) in proc.stderr


# ------------------------------------------------------------------ bench
def test_bench_times_core_steps_after_convergence():
    from tmgwr_agent.experiments.bench import bench_default
    r = bench_default(seed=0, steps=300)
    assert r["steps"] == 300 and r["free_cells"] == 99
    assert r["trained_episodes"] is not None          # converged before timing
    assert 0 < r["p10_us"] <= r["median_us"] <= r["p90_us"] <= r["p99_us"] <= r["max_us"]
    assert 0 < r["nodes"] <= 2 * 99
