"""``experiment env-change --event-delay K[,K...]``: the event K learning episodes after
convergence, for every agent alike. The CLI refuses a bad value (exit 2, naming the
option); ``--event-delay 0`` is today's protocol, JSON for JSON; several delays keep each
delay's run whole under ``delays`` (each equal to the run at that delay alone), with
``settled_steps`` (the mean steps of the K episodes) when K > 0; the results tables read
the layout back with a delay column and the settled table, the figure one panel per
delay."""

import json

import pytest
from small_mazes import SMALL
from test_experiments import cli

from tmgwr_agent.experiments import results
from tmgwr_agent.experiments.env_change import delay_views, parse_delays
from tmgwr_agent.experiments.plots import plot

AGENTS = "tmgwr,q_learning"
SUITE = "blocking:1"


@pytest.fixture(scope="module")
def small_maze(tmp_path_factory):
    path = tmp_path_factory.mktemp("maze") / "small.txt"
    path.write_text(SMALL)
    return path


def run(tmp_path, name, *args):
    out = tmp_path / f"{name}.json"
    cli("experiment", "env-change", *args, "--agents", AGENTS, "--trials", 2, "--jobs", 1,
        "--json", out, "--quiet")
    return json.loads(out.read_text())


@pytest.mark.parametrize("value, named", [
    ("4,x", "'x' is not a whole number"),
    ("-1", "'-1' is not a whole number"),
    ("0,,4", "'' is not a whole number"),
    ("4,4", "delay 4 given twice"),
])
def test_a_bad_delay_exits_2_naming_the_option(small_maze, value, named):
    proc = cli("experiment", "env-change", "--maze", small_maze, "--trials", 1,
               "--event-delay", value, check=False)
    assert proc.returncode == 2
    assert "--event-delay" in proc.stderr and named in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr


def test_a_delay_for_another_scenario_exits_2(small_maze):
    proc = cli("experiment", "goal-change", "--maze", small_maze, "--trials", 1,
               "--event-delay", "4", check=False)
    assert proc.returncode == 2
    assert "--event-delay applies to env-change only, not goal-change" in proc.stderr


def test_parse_delays():
    assert parse_delays(None) == (0,)
    assert parse_delays("0, 4,8") == (0, 4, 8)
    assert parse_delays([8, 0]) == (8, 0)


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_delay_zero_is_todays_protocol_and_several_delays_keep_each_run(small_maze,
                                                                         tmp_path):
    today = run(tmp_path, "today", "--maze", small_maze)
    assert run(tmp_path, "zero", "--maze", small_maze, "--event-delay", "0") == today
    assert "event_delay" not in today and "delays" not in today
    three = run(tmp_path, "three", "--maze", small_maze, "--event-delay", "3")
    assert three["event_delay"] == 3
    both = run(tmp_path, "both", "--maze", small_maze, "--event-delay", "0,3")
    assert both["event_delays"] == [0, 3] and "agents" not in both
    assert [d["event_delay"] for d in both["delays"]] == [0, 3]
    (k0, v0), (k3, v3) = delay_views(both)
    assert (k0, v0) == (0, today)                  # each delay's run, whole
    assert (k3, v3) == (3, {k: v for k, v in three.items() if k != "event_delay"})
    for a in AGENTS.split(","):
        assert "settled_steps" not in v0["agents"][a]
        settled = v3["agents"][a]["settled_steps"]["values"]
        assert len(settled) == 2 and all(s >= today["shortest_before"] for s in settled)
        # the same training to convergence at every delay (the same trial seeds)
        assert v3["agents"][a]["train_episodes"] == v0["agents"][a]["train_episodes"]
        assert v3["agents"][a]["learning_steps"] == v0["agents"][a]["learning_steps"]
    text = cli("experiment", "env-change", "--maze", small_maze, "--agents", AGENTS,
               "--trials", 2, "--jobs", 1, "--event-delay", "0,3", "--json",
               tmp_path / "again.json", "--quiet").stdout
    assert "event delay 3: event a" in text and "settled_steps" in text
    plot(both, tmp_path / "both.png")              # one panel per delay
    assert (tmp_path / "both.png").stat().st_size > 0


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_suite_delays_layout_and_tables(tmp_path):
    today = run(tmp_path, "today", "--suite", SUITE)
    both = run(tmp_path, "both", "--suite", SUITE, "--event-delay", "0,2")
    views = delay_views(both)
    assert [k for k, _ in views] == [0, 2]
    assert views[0][1] == today
    assert set(both["delays"][1]) == {"event_delay", "agents", "suite"}
    s2 = views[1][1]["suite"]
    for a in AGENTS.split(","):
        m = s2["mazes"][0]
        assert len(m["agents"][a]["settled_steps"]["values"]) == 2
        ratio = s2["overall"]["settled_ratio"][a]
        assert ratio["values"][0] == pytest.approx(
            sorted(m["agents"][a]["settled_steps"]["values"])[0] / 2 / m["shortest_before"]
            + sorted(m["agents"][a]["settled_steps"]["values"])[1] / 2
            / m["shortest_before"])
    assert "settled_ratio" not in views[0][1]["suite"]["overall"]
    plot(both, tmp_path / "both.png")
    assert (tmp_path / "both.png").stat().st_size > 0
    # the results tables read the layout back: a delay column, one row set per delay
    (tmp_path / "results").mkdir()
    doc = {"name": "x", "command": "./tmgwr experiment env-change ...", "commit": "0" * 40,
           "dirty": False, "machine": {"cores": 2, "load_start": [0.0], "load_end": [0.0]},
           "result": both}
    (tmp_path / "results" / "x.json").write_text(json.dumps(doc))
    blocks = results.table_suite(tmp_path, "x")
    assert blocks.splitlines()[0].startswith("| event delay K | family (mazes) |")
    assert [r.split(" | ")[0] for r in blocks.splitlines()[2:6]] == ["| 0", "| 0", "| 2",
                                                                    "| 2"]
    assert "Event delay K:" in blocks
    settled = results.table_settled(tmp_path, "x")
    rows = settled.splitlines()[2:4]
    assert [r.split(" | ")[0] for r in rows] == ["| 2", "| 2"]
    assert f"{s2['overall']['settled_ratio']['tmgwr']['median']:.2f}" in rows[1]
    doc["result"] = today                          # one delay of 0: today's table
    (tmp_path / "results" / "x.json").write_text(json.dumps(doc))
    assert "event delay" not in results.table_suite(tmp_path, "x")
    with pytest.raises(results.ResultsError, match="no event delay > 0"):
        results.table_settled(tmp_path, "x")
