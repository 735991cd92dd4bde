"""The scaling rows of the bench alone (``python -m tmgwr_agent.experiments.bench``): a
small map gives a row with every field issue 27 names; bad arguments exit 2."""

import json
import subprocess
import sys

import pytest

from tmgwr_agent.experiments.bench import scaling_main


def test_scaling_alone_writes_the_rows(tmp_path):
    out = tmp_path / "scaling.json"
    assert scaling_main(["--families", "open", "--cells", "80", "--steps", "30",
                         "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["scaling_clock"] == "wall"
    rows = result["scaling"]
    assert len(rows) == 1 and rows[0]["family"] == "open"
    for key in ("cells", "nodes", "step_median_us", "step_p99_us", "step_mean_us",
                "goal_change_first_ms", "block_episode_ms", "episode_starts",
                "episode_start_median_ms", "episode_start_max_ms"):
        assert rows[0][key] > 0, key
    assert rows[0]["episode_start_max_ms"] >= rows[0]["episode_start_median_ms"]


def test_scaling_by_cpu_time(tmp_path):
    """--clock cpu times the rows by the thread's CPU time (a loaded machine)."""
    out = tmp_path / "scaling.json"
    assert scaling_main(["--families", "braided", "--cells", "80", "--steps", "20",
                         "--clock", "cpu", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["scaling_clock"] == "cpu"
    assert result["scaling"][0]["step_median_us"] > 0
    assert result["scaling"][0]["goal_change_first_ms"] > 0


def test_default_maze_alone_by_cpu_time(tmp_path):
    """--default N with no scaling rows: the default maze's converged core step alone,
    timed by --clock (the before/after figure of a change to the step)."""
    out = tmp_path / "default.json"
    assert scaling_main(["--cells", "", "--default", "40", "--clock", "cpu",
                         "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert "scaling" not in result
    d = result["step_default"]
    assert d["clock"] == "cpu" and d["steps"] == 40 and d["median_us"] > 0


@pytest.mark.parametrize("args", [["--families", "rooms"], ["--cells", "3x"],
                                  ["--steps", "0"], ["--clock", "sundial"],
                                  ["--default", "-1"], ["--cells", ""]])
def test_bad_arguments_exit_2_naming_them(args):
    p = subprocess.run([sys.executable, "-m", "tmgwr_agent.experiments.bench", *args],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 2
    assert args[0] in p.stderr
