"""``./tmgwr tune AGENT --world minigrid`` (docs/tuning.md): the objective's suite runs in
that world, the study and its parameter file say so, a study of another world is not
re-opened, worlds and agents tuning cannot run are refused with exit 2; and
``experiment --params AGENT=tuned`` picks the world's own tuned file."""

import json
from pathlib import Path

import pytest
from test_experiments import cli
from test_minigrid_world import TINY
from test_tune import tune as tune_on

from maze_sim.worlds import parse_world
from tmgwr_agent.experiments.parallel import trial_seeds
from tmgwr_agent.experiments.tune import (
    TUNED,
    evaluate,
    load_tuned,
    resolve_tuned,
    tasks,
)

SPLIT = ["--suite", "open:1", "--open-weight", "0", "--seeds", "1"]


def tune(tmp_path, *args, check=True):
    return tune_on(tmp_path, *args, check=check, split=SPLIT)


def test_a_minigrid_study_runs_its_suite_in_minigrid(tmp_path):
    tune(tmp_path, "--world", "minigrid", "--trials", "2")
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["objective"]["world"] == "minigrid"
    assert summary["trials"]["counted"] == 2
    # the defaults' trial is the objective of the same runs in MiniGrid, by hand
    world = parse_world("minigrid", None)
    task_list, _ = tasks("open:1", 0, 0, world=world)
    grid_tasks, _ = tasks("open:1", 0, 0)
    assert task_list[0].oracle != grid_tasks[0].oracle     # turns are primitive steps
    by_hand = evaluate("q_learning", {}, task_list, trial_seeds(0, 1))
    assert summary["defaults"]["value"] == pytest.approx(by_hand["objective"])
    assert summary["defaults"]["geo_mean_ratio"] == pytest.approx(by_hand["geo_mean_ratio"])
    text = (tmp_path / "best.yaml").read_text()
    assert "--world minigrid --suite open:1" in text       # the header says where
    assert load_tuned(tmp_path / "best.yaml", "q_learning") == pytest.approx(
        summary["best"]["params"])
    # the same study is not re-opened for the grid
    proc = tune(tmp_path, "--trials", "2", check=False)
    assert proc.returncode == 2
    assert "was made with other options: world 'minigrid' (now 'grid')" in proc.stderr


@pytest.mark.parametrize("args, message", [
    (["--world", "gym:MiniGrid-Empty-5x5-v0"], "a registered env has neither"),
    (["--world", "minigird"], "unknown world 'minigird'"),
    (["--world", "minigrid", "--world-kwargs", "{bad"], "is not JSON"),
])
def test_worlds_tuning_cannot_run_exit_2(tmp_path, args, message):
    proc = tune(tmp_path, *args, "--trials", "1", check=False)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "study.journal").exists()


def test_an_agent_given_the_grid_cells_is_not_tuned_in_minigrid(tmp_path):
    proc = cli("tune", "model_based", "--world", "minigrid", "--storage",
               tmp_path / "study.journal", "--trials", "1", check=False)
    assert proc.returncode == 2
    assert "agent 'model_based' cannot run in --world minigrid" in proc.stderr


def test_params_agent_tuned_is_the_worlds_own_file():
    rel = Path(TUNED).relative_to(Path.cwd()) if Path(TUNED).is_relative_to(Path.cwd()) \
        else Path(TUNED)
    assert resolve_tuned(["q_learning=tuned", "x.yaml"], None) == [
        f"q_learning={rel / 'q_learning.yaml'}", "x.yaml"]
    assert resolve_tuned(["dyna_q_plus=tuned"], "minigrid") == [
        f"dyna_q_plus={rel / 'minigrid' / 'dyna_q_plus.yaml'}"]


@pytest.mark.parametrize("args, message", [
    (["--world", "pointmaze", "--params", "q_learning=tuned"],
     "no tuned file for q_learning in --world pointmaze: "),
    (["--world", "minigrid", "--params", "tuned"], "--params tuned: name the agent"),
])
def test_params_tuned_refusals_exit_2(args, message):
    proc = cli("experiment", "env-change", "--agents", "q_learning", *args, check=False)
    assert proc.returncode == 2, proc.stderr
    assert message in proc.stderr and "Traceback" not in proc.stderr


def test_a_minigrid_experiment_runs_with_the_minigrid_tuned_file(tmp_path):
    maze = tmp_path / "tiny.txt"
    maze.write_text(TINY)
    out = tmp_path / "out.json"
    cli("experiment", "env-change", "--world", "minigrid", "--maze", maze, "--agents",
        "q_learning", "--trials", "1", "--jobs", "1", "--params", "q_learning=tuned",
        "--json", out, "--quiet")
    res = json.loads(out.read_text())
    (used,) = res["params"]["files"]
    name, _, path = used.partition("=")
    assert name == "q_learning"
    assert Path(path).resolve() == (TUNED / "minigrid" / "q_learning.yaml").resolve()
    assert res["params"]["agents"]["q_learning"] == load_tuned(path, "q_learning")
