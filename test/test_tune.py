"""``./tmgwr tune`` (docs/tuning.md): two worker processes on one Optuna journal study, the
parameter file it writes, the search space read from the Config declarations, the
objective by hand, and clear errors for a bad agent, space or storage."""

import json
import math

import numpy as np
import optuna
import pytest
from optuna.storages import JournalStorage
from optuna.storages.journal import JournalFileBackend
from test_experiments import cli

from maze_sim.suite import generate
from tmgwr_agent.experiments.agent_factory import make_agent
from tmgwr_agent.experiments.parallel import trial_seeds
from tmgwr_agent.experiments.tune import (
    OPEN_WITHIN,
    PENALTY,
    SEARCH,
    Task,
    block_run,
    interleaved,
    load_tuned,
    open_run,
    parse_space,
    score,
    search_space,
    tasks,
    write_params,
)
from tmgwr_common.params import ParamError, check_params_file, params_for, read_params_file

SPLIT = ["--suite", "blocking:1,open:1", "--open-suite", "shortcut:1", "--seeds", "1"]


def tune(tmp_path, *args, check=True, split=SPLIT):
    """``./tmgwr tune q_learning`` on the training ``split``, its study and outputs in
    ``tmp_path``."""
    return cli("tune", "q_learning", *split, "--storage", tmp_path / "study.journal",
               "--study", "s", "--params-out", tmp_path / "best.yaml", "--json",
               tmp_path / "summary.json", "--quiet", *args, check=check)


def trials_in(journal, study="s"):
    storage = JournalStorage(JournalFileBackend(str(journal)))
    return optuna.load_study(study_name=study, storage=storage).get_trials()


@pytest.mark.slow
def test_two_workers_share_one_journal_study_and_the_file_loads(tmp_path):
    tune(tmp_path, "--trials", "4", "--workers", "2", "--evaluate", "--eval-trials", "1")
    trials = trials_in(tmp_path / "study.journal")
    assert len(trials) == 4
    assert all(t.state.name == "COMPLETE" for t in trials)
    workers = {t.user_attrs["worker"] for t in trials}
    assert len(workers) == 2, workers                     # both processes' trials
    assert {w.rsplit(":", 1)[1] for w in workers} == {"0", "1"}
    defaults = [t for t in trials if t.user_attrs.get("defaults")]
    assert len(defaults) == 1 and defaults[0].params["gamma"] == 0.86   # Table 2

    summary = json.loads((tmp_path / "summary.json").read_text())
    best = min(trials, key=lambda t: t.value)
    assert summary["best"]["number"] == best.number
    assert summary["best"]["value"] == pytest.approx(best.value)
    assert sorted(summary["trials"]["by_worker"].values()) == [2, 2]
    held = summary["held_out"]
    assert held["first"] == 1 and held["mazes"] == ["blocking-01", "open-01"]
    assert set(held) >= {"tuned", "defaults", "tuned_wins"}
    assert held["open_suite"] == "shortcut:1" and held["tuned"]["open_runs"] == 1
    assert summary["objective"]["open_suite"] == "shortcut:1"
    assert all(h["open_found"] is not None for h in summary["history"])

    # the parameter file: ROS 2 layout, the baseline's own section, every searched name
    entries = read_params_file(tmp_path / "best.yaml")
    assert list(entries) == ["q_learning"]
    values = entries["q_learning"]
    assert set(values) == set(SEARCH["q_learning"])
    assert values == pytest.approx(best.params)
    assert load_tuned(tmp_path / "best.yaml", "q_learning") == values
    maze = generate("blocking", 0).maze()
    agent = make_agent("q_learning", maze, np.random.default_rng(0), values)
    assert (agent.gamma, agent.beta, agent.r_wall) == pytest.approx(
        (values["gamma"], values["beta"], values["r_wall"]))

    # the study is complete: running again adds no trial, also with its space named in
    # another order (bare names: their search intervals); other options are refused
    tune(tmp_path, "--trials", "4")
    tune(tmp_path, "--trials", "4", "--space", ",".join(reversed(SEARCH["q_learning"])))
    assert len(trials_in(tmp_path / "study.journal")) == 4
    assert "# searched: " + ", ".join(sorted(SEARCH["q_learning"])) + "; the rest" in \
        (tmp_path / "best.yaml").read_text()
    proc = tune(tmp_path, "--trials", "4", "--seed", "3", check=False)
    assert proc.returncode == 2
    assert "made with other options" in proc.stderr and "seed" in proc.stderr


def test_tmgwr_file_is_what_the_nodes_read(tmp_path):
    values = {d.name: d.default for d in search_space("tmgwr")}
    path = write_params(tmp_path / "tmgwr.yaml", "tmgwr", values, "test")
    check_params_file(path)                      # what `./tmgwr up` checks before the nodes
    assert params_for(path, "motivation_estimator") == values   # the /** section
    assert load_tuned(path, "tmgwr") == values
    (tmp_path / "bad.yaml").write_text("/**:\n  ros__parameters:\n    gama: 0.9\n")
    with pytest.raises(ParamError, match="did you mean 'gamma'"):
        load_tuned(tmp_path / "bad.yaml", "tmgwr")


@pytest.mark.slow
def test_tune_runs_are_the_experiment_runs(tmp_path):
    """block_run is env_change.trial (steps 1-3): with the tuned file, the runs tune
    scores are the steps `experiment env-change --suite ... --params` reports."""
    from test_experiments import TUNED_QL
    out = tmp_path / "suite.json"
    cli("experiment", "env-change", "--suite", "blocking:1,open:1", "--agents",
        "q_learning", "--trials", "2", "--jobs", "1", "--params", TUNED_QL, "--json", out,
        "--quiet")
    mazes = json.loads(out.read_text())["suite"]["mazes"]
    task_list, _ = tasks("blocking:1,open:1", 0, 0)
    values = load_tuned(TUNED_QL, "q_learning")
    for task, m in zip(task_list, mazes, strict=True):
        runs = [block_run("q_learning", values, task, s) for s in trial_seeds(0, 2)]
        assert [r["steps"] for r in runs] == m["agents"]["q_learning"]["steps"]["values"]
        assert [r["train_episodes"] for r in runs] == \
            m["agents"]["q_learning"]["train_episodes"]["values"]


@pytest.mark.parametrize("agent", sorted(SEARCH))
def test_search_space_lies_inside_the_declared_ranges(agent):
    dims = search_space(agent)           # raises on a name or interval the Config refuses
    assert [d.name for d in dims] == list(SEARCH[agent])
    for d in dims:
        assert d.low < d.high


def test_space_names_take_their_search_interval_and_fix_holds_some_back():
    # a bare name: the interval SEARCH gives it (a_T's declared range (0, 1) is open)
    dims = {d.name: d for d in search_space("tmgwr", parse_space("a_T,E_min,eps_b"))}
    assert (dims["a_T"].low, dims["a_T"].high) == (SEARCH["tmgwr"]["a_T"].low,
                                                  SEARCH["tmgwr"]["a_T"].high)
    assert dims["E_min"].log
    assert (dims["eps_b"].low, dims["eps_b"].high) == (0.0, 1.0)   # not in SEARCH: declared
    # --fix: the default space without these (they keep their defaults)
    fixed = search_space("tmgwr", fix=["eps_min", "p_turn"])
    assert [d.name for d in fixed] == [n for n in SEARCH["tmgwr"]
                                       if n not in ("eps_min", "p_turn")]


def test_objective_by_hand():
    tasks = [Task("m1", "f", "", "a", 10, 50.0), Task("m2", "f", "", "a", 20, 40.0)]
    runs = [[{"steps": 20, "train_episodes": 3}, {"steps": 40, "train_episodes": 3},
             {"steps": None, "train_episodes": 3}],            # failed: cap ratio 50
            [{"steps": 20, "train_episodes": None},            # train failure, ratio 1
             {"steps": 80, "train_episodes": 2}, {"steps": 20, "train_episodes": 2}]]
    s = score(tasks, runs)
    assert s["per_maze"] == {"m1": 4.0, "m2": 1.0}
    assert s["failed_runs"] == 2 and s["runs"] == 6 and s["worst_ratio"] == 50.0
    assert s["objective"] == pytest.approx(math.sqrt(4.0 * 1.0) + PENALTY * 2 / 6)
    assert s["open_found"] is None
    # with an opening: found within the cap in 1 of its 3 runs (one run's training failed)
    o = Task("o1", "g", "", "b", 8, 30.0, "open")
    opened = [{"episodes": 4, "train_episodes": 2}, {"episodes": None, "train_episodes": 2},
              {"episodes": None, "train_episodes": None}]
    s = score(tasks + [o], runs + [opened], open_weight=1.5)
    assert s["per_maze"] == {"m1": 4.0, "m2": 1.0}
    assert s["failed_runs"] == 3 and s["runs"] == 9
    assert s["open_found"] == pytest.approx(1 / 3) and s["open_per_maze"] == {"o1": 1 / 3}
    assert s["objective"] == pytest.approx(2.0 + PENALTY * 3 / 9 + 1.5 * 2 / 3)
    # a trial runs them alternately (what the pruner compares mixes both kinds)
    o2 = Task("o2", "g", "", "b", 8, 30.0, "open")
    assert [t.name for t in interleaved(tasks + [o, o2])] == ["m1", "o1", "m2", "o2"]


@pytest.mark.slow
def test_opening_runs_are_the_experiment_runs(tmp_path):
    """open_run is env_change.trial with step 4 capped at OPEN_WITHIN episodes: found
    exactly when `experiment env-change --event open` reports the greedy path on the
    shortcut within that many episodes."""
    out = tmp_path / "open.json"
    cli("experiment", "env-change", "--suite", "shortcut:2", "--event", "open", "--agents",
        "tmgwr", "--trials", "2", "--jobs", "1", "--json", out, "--quiet")
    mazes = json.loads(out.read_text())["suite"]["mazes"]
    task_list, _ = tasks("shortcut:2", 0, 0, "open")
    for task, m in zip(task_list, mazes, strict=True):
        runs = [open_run("tmgwr", {}, task, s) for s in trial_seeds(0, 2)]
        expected = [e if e is not None and e <= OPEN_WITHIN else None
                    for e in m["agents"]["tmgwr"]["episodes_to_optimal"]["values"]]
        assert [r["episodes"] for r in runs] == expected


@pytest.mark.parametrize("args, message", [
    (["tune", "q_leaning"], "unknown agent 'q_leaning'"),
    (["tune", "dyna_q_plus", "--space", "kapa"], "did you mean 'kappa'"),
    (["tune", "q_learning", "--space", "gamma=0.5:1.5"], "leaves its declared range"),
    (["tune", "tmgwr", "--space", "goal_sigma"], "give --space goal_sigma=LOW:HIGH inside"),
    (["tune", "q_learning", "--fix", "gama"], "did you mean 'gamma'"),
    (["tune", "q_learning", "--fix", "eps_start"], "--fix 'eps_start': it is not searched"),
    (["tune", "q_learning", "--space", "gamma", "--fix", "gamma"], "leaves no parameter"),
    (["tune", "q_learning", "--suite", "shortcut:1"], "no maze with a block event"),
    (["tune", "q_learning", "--open-suite", "blocking:1"], "no maze with an opening"),
    (["tune", "q_learning", "--open-weight", "-1"], "--open-weight must be >= 0"),
    (["tune", "q_learning", "--storage", "nosuchdb://x/y"], "cannot open the RDB storage"),
])
def test_bad_requests_exit_2_with_a_clear_message(args, message):
    proc = cli(*args, "--trials", "1", check=False)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr, proc.stderr


def test_a_journal_path_that_cannot_be_a_file_is_refused(tmp_path):
    (tmp_path / "plain").write_text("x")
    for where in (tmp_path, tmp_path / "plain" / "study.journal"):
        proc = cli("tune", "q_learning", "--storage", where, "--trials", "1", check=False)
        assert proc.returncode == 2
        assert f"--storage {where}: cannot use it as an Optuna journal file" in proc.stderr
