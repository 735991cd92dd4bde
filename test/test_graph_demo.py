"""The ROS demo scenario end to end, the ring benchmark, and the launch file.

* The demo (``python -m tmgwr_agent.graph.demo``, what ``make demo`` runs after its
  in-process part) starts the real graph recorded to MCAP, learns G, changes the goal with
  a real ``/set_goal`` call, fires event ``a``, and must report each goal reached, every
  node stopped with exit code 0 and a recording whose Observation count covers the run.
* The ring of the bench (real rclpy processes) returns sane laps/s for 2 and 5 processes.
* ``launch/agent.launch.py`` (the launch packages are not on PyPI, so it cannot run here)
  compiles and starts exactly the contract's executables.
"""

from __future__ import annotations

import ast

import pytest
from ros_helpers import ROOT, parse_json_line, spawn_module, spawn_python

pytestmark = pytest.mark.ros


def test_demo_scenario_end_to_end(ros_domain, tmp_path):
    out_dir = tmp_path / "run"
    demo = spawn_module("tmgwr_agent.graph.demo", "--record-dir", str(out_dir),
                        domain=ros_domain, name="demo")
    with demo:
        output = demo.wait(timeout=240)
    report = parse_json_line(output, "DEMO ")
    phases = report["phases"]
    # learnt G reliably, then the new goal and the detour after the event were found
    assert phases["learn"]["reliable"], output
    assert report["set_goal"]["accepted"] and report["event"]["accepted"], output
    for name in ("goal", "event"):
        assert phases[name]["first_goal_steps_after"] is not None, output
        assert phases[name]["goal_reached_episodes"] >= 1, output
    # the detour is longer than the old route: the event really changed the maze
    assert report["optimal"]["event"] > report["optimal"]["goal"]
    assert set(report["exit_codes"]) == {"recorder", "maze_sim", "sensory_preprocessor",
                                         "map_learner", "motivation_estimator",
                                         "action_selector"}
    assert all(code == 0 for code in report["exit_codes"].values()), output
    assert report["missed_observations"] == 0, output
    assert f"recording: {out_dir}" in output

    # the recording holds every observation the demo saw (read with the mcap library)
    from mcap.reader import make_reader
    files = sorted(out_dir.glob("*.mcap"))
    assert files, f"no .mcap in {out_dir}: {list(out_dir.iterdir())}"
    count = 0
    for f in files:
        with open(f, "rb") as fh:
            for _, channel, _ in make_reader(fh).iter_messages(topics=["/observation"]):
                count += 1
    assert count >= report["steps"], (count, report["steps"])


def test_ring_bench_returns_sane_numbers(ros_domain):
    code = r"""
import json
from tmgwr_agent.graph.bench import ring
rings = {"2": ring(2, laps=300, warmup=20), "5": ring(5, laps=200, warmup=20)}
print("RESULT " + json.dumps(rings))
"""
    proc = spawn_python(code, domain=ros_domain, name="ring bench")
    with proc:
        output = proc.wait(timeout=150)
    res = parse_json_line(output, "RESULT ")
    for size, laps in (("2", 300), ("5", 200)):
        r = res[size]
        assert r["processes"] == int(size) and r["laps"] == laps
        # a lap is at least a few hops of tens of microseconds and well under a second
        assert 5 < r["laps_per_s"] < 50000, r
        assert abs(r["hop_ms"] - 1000 / r["laps_per_s"] / int(size)) < 0.01, r
        assert 0 < r["lap_ms_p50"] <= r["lap_ms_p99"], r


def test_launch_file_starts_the_contract_executables():
    path = ROOT / "src/tmgwr_agent/launch/agent.launch.py"
    source = path.read_text()
    tree = ast.parse(source, str(path))
    compile(tree, str(path), "exec")
    funcs = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert "generate_launch_description" in funcs
    # the launch file and the pip-only supervisor start the same executables: the launch
    # file takes the node list from the supervisor (one place)
    imported = {(n.module, a.name) for n in tree.body if isinstance(n, ast.ImportFrom)
                for a in n.names}
    assert ("tmgwr_agent.graph.supervisor", "GRAPH_NODES") in imported
    from tmgwr_agent.graph.supervisor import GRAPH_NODES
    pairs = GRAPH_NODES
    assert list(pairs) == [("maze_sim", "maze_sim"), ("tmgwr_agent", "sensory_preprocessor"),
                           ("tmgwr_agent", "map_learner"), ("tmgwr_agent", "motivation_estimator"),
                           ("tmgwr_agent", "action_selector")]
    assert 'executable="recorder"' in source
    for package, exe in pairs:   # and each is what `ros2 run` would find
        assert (ROOT / "install" / package / "lib" / package / exe).is_file(), (package, exe)
