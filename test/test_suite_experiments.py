"""``experiment env-change | goal-change --suite SPEC`` end to end (a subprocess, tiny
runs): the documented JSON keys, every maze's ``oracle_steps`` against an independent BFS
computation, skipped mazes listed, the maze files written beside the JSON, the figure,
the same JSON for the same seed whatever ``--jobs``, one maze's entry equal to the plain
``--maze`` run of its file, and exit code 2 for bad requests."""

import json

import pytest
from test_experiments import cli

from maze_sim import Maze
from maze_sim.suite import suite

SPEC = "blocking:2,shortcut:1"          # shortcut mazes have no block: one skipped
AGENTS = "tmgwr,q_learning"
TRIALS = 2

SUMMARY_KEYS = {"mazes", "skipped", "trials", "oracle_ratio", "steps",
                "episodes_to_optimal", "win_rate", "failures", "train_failures",
                "worst_trial_ratio", "optimal_within_10", "optimal_found",
                "episodes_win_rate"}


def run(tmp_path, name, *args):
    out = tmp_path / f"{name}.json"
    cli("experiment", *args, "--json", out, "--quiet")
    return json.loads(out.read_text()), out


@pytest.fixture(scope="module")
def block_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("suite")
    res, out = run(tmp, "out", "env-change", "--suite", SPEC, "--agents", AGENTS,
                   "--trials", TRIALS, "--jobs", 2, "--plot", tmp / "out.png")
    return res, out


def independent_oracle(maze: Maze, event: str, goal: str = "G") -> int:
    """The oracle of env_change's docstring, by plain BFS lengths: walk an old shortest
    path that stays clear of the blocked cells as far as it can, bump once into a blocked
    cell of an old shortest path, then take the new shortest path from there."""
    s, g = maze.start, maze.goal_cell(goal)
    old, new = maze.walls, maze.walls_after([event])
    blocked = new & ~old
    d = maze.shortest_path_length(s, g)
    clear = old | blocked                # old layout, blocked cells avoided
    if maze.shortest_path_length(s, g, walls=clear) == d:
        return d                         # an old shortest path avoids the block

    def ds(c, walls=old):
        return maze.shortest_path_length(s, c, walls=walls)

    def on_old_path(c):
        a, b = ds(c), maze.shortest_path_length(c, g)
        return a >= 0 and b >= 0 and a + b == d

    best = None
    for c in maze.free_cells(clear):
        if not on_old_path(c) or ds(c, clear) != ds(c):
            continue                     # not reached along a clear old shortest path
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            n = (c[0] + dr, c[1] + dc)
            if blocked[n] and on_old_path(n) and ds(n) == ds(c) + 1:
                rest = maze.shortest_path_length(c, g, walls=new)
                if rest >= 0:
                    total = ds(c) + 1 + rest
                    best = total if best is None else min(best, total)
    assert best is not None
    return best


@pytest.mark.slow
def test_suite_json_keys_oracle_and_skipped(block_run):
    res, out = block_run
    agents = AGENTS.split(",")
    assert res["scenario"] == "env-change" and res["trials"] == TRIALS
    assert res["seed"] == 0 and res["maze"] is None and res["event"] == "block"
    assert res["sensor"] == "identity"
    assert list(res["agents"]) == agents
    s = res["suite"]
    assert {"spec", "seed", "first", "event", "mazes", "skipped", "families",
            "overall"} <= set(s)
    assert s["spec"] == SPEC and s["seed"] == 0 and s["first"] == 0
    generated = {sm.name: sm for sm in suite(SPEC, 0)}
    assert [m["name"] for m in s["mazes"]] == ["blocking-00", "blocking-01"]
    assert s["skipped"] == [{"name": "shortcut-00", "family": "shortcut",
                             "reason": "no block event"}]
    maze_dir = out.with_name("out_mazes")
    for sm in generated.values():                 # every maze written, skipped ones too
        assert (maze_dir / f"{sm.name}.txt").read_text() == sm.text
    for m in s["mazes"]:
        sm = generated[m["name"]]
        maze = Maze.from_file(maze_dir / m["file"])
        assert m["family"] == sm.family and m["free_cells"] == sm.free_cells
        assert m["event"] == sm.block_event
        assert m["oracle_steps"] == independent_oracle(maze, m["event"])
        assert m["shortest_after"] == maze.shortest_path_length(
            maze.start, maze.goal_cell("G"), walls=maze.walls_after([m["event"]]))
        assert list(m["agents"]) == agents
        for a in agents:
            mapped = {"nodes"} if a.startswith("tmgwr") else set()   # a learnt map's size
            assert set(m["agents"][a]) == {"steps", "episodes_to_optimal",
                                           "train_episodes", "learning_steps"} | mapped
            for v in m["agents"][a].get("nodes", {"values": []})["values"]:
                assert 1 <= v <= 3 * m["free_cells"]
            assert len(m["agents"][a]["steps"]["values"]) == TRIALS
            assert len(m["agents"][a]["learning_steps"]["values"]) == TRIALS
    # top-level agents: every trial of every maze, maze by maze
    for a in agents:
        for key in ("steps", "learning_steps"):
            flat = [v for m in s["mazes"] for v in m["agents"][a][key]["values"]]
            assert res["agents"][a][key]["values"] == flat
        ratios = [None if v is None else v / m["oracle_steps"] for m in s["mazes"]
                  for v in m["agents"][a]["steps"]["values"]]
        assert res["agents"][a]["oracle_ratio"]["values"] == pytest.approx(ratios)
    assert set(s["families"]) == {"blocking", "shortcut"}
    assert s["families"]["shortcut"]["mazes"] == 0
    assert s["families"]["shortcut"]["skipped"] == 1
    fam = s["families"]["blocking"]
    assert set(fam) == SUMMARY_KEYS | {"max_nodes_per_cell"} and fam["mazes"] == 2
    assert set(fam["max_nodes_per_cell"]) == {a for a in agents if a.startswith("tmgwr")}
    assert fam["max_nodes_per_cell"]["tmgwr"] == max(
        v / m["free_cells"] for m in s["mazes"] for v in m["agents"]["tmgwr"]["nodes"]["values"])
    for a in agents:
        steps = [m["agents"][a]["steps"]["values"] for m in s["mazes"]]
        if all(None not in v for v in steps):
            medians = [sorted(v)[0] / 2 + sorted(v)[1] / 2 for v in steps]   # 2 trials
            assert fam["steps"][a]["values"] == pytest.approx(medians)
            assert fam["oracle_ratio"][a]["values"] == pytest.approx(
                [x / m["oracle_steps"] for x, m in zip(medians, s["mazes"])])
        assert fam["failures"][a] == sum(v.count(None) for v in steps)
        other = [b for b in agents if b != a][0]
        assert 0.0 <= fam["win_rate"][a][other] <= 1.0
    assert out.with_name("out.png").stat().st_size > 0


@pytest.mark.slow
def test_suite_same_seed_same_json_whatever_jobs(block_run, tmp_path):
    res, _ = block_run
    again, _ = run(tmp_path, "again", "env-change", "--suite", SPEC, "--agents", AGENTS,
                   "--trials", TRIALS, "--jobs", 1)
    assert again == res


@pytest.mark.slow
def test_suite_maze_entry_is_the_plain_maze_run(block_run, tmp_path):
    res, out = block_run
    m = res["suite"]["mazes"][1]
    plain, _ = run(tmp_path, "plain", "env-change", "--maze",
                   out.with_name("out_mazes") / m["file"], "--event", m["event"],
                   "--agents", "q_learning", "--trials", TRIALS, "--jobs", 1)
    assert plain["oracle_steps"] == m["oracle_steps"]
    assert plain["agents"]["q_learning"] == m["agents"]["q_learning"]


@pytest.mark.slow
def test_suite_openings_skip_mazes_without_one(tmp_path):
    res, _ = run(tmp_path, "open", "env-change", "--suite", "blocking:1,shortcut:1",
                 "--event", "open", "--agents", "q_learning", "--trials", 1, "--jobs", 1)
    s = res["suite"]
    assert res["event"] == "open" and s["event"] == "open"
    assert [k["name"] for k in s["skipped"]] == ["blocking-00"]
    (m,) = s["mazes"]
    assert m["name"] == "shortcut-00" and m["event"] == "b"
    # nothing blocks the old path: the oracle walks it; the new path is strictly shorter
    assert m["oracle_steps"] == m["shortest_before"] > m["shortest_after"]


@pytest.mark.slow
def test_suite_with_tuned_params(block_run, tmp_path):
    """--params reaches every maze's trials, is recorded, and one maze's entry is again
    the plain --maze run with the same file."""
    from test_experiments import TUNED_QL
    res, out = block_run
    tuned, _ = run(tmp_path, "tuned", "env-change", "--suite", "blocking:1",
                   "--agents", "q_learning", "--trials", TRIALS, "--jobs", 2,
                   "--params", TUNED_QL)
    from tmgwr_agent.experiments.tune import load_tuned
    assert tuned["params"] == {"files": [TUNED_QL],
                               "agents": {"q_learning": load_tuned(TUNED_QL, "q_learning")}}
    assert list(tuned)[-3:] == ["params", "agents", "suite"]
    (m,) = tuned["suite"]["mazes"]
    default = res["suite"]["mazes"][0]
    assert m["name"] == default["name"] == "blocking-00"
    assert m["agents"]["q_learning"] != default["agents"]["q_learning"]
    plain, _ = run(tmp_path, "plain", "env-change", "--maze",
                   out.with_name("out_mazes") / m["file"], "--event", m["event"],
                   "--agents", "q_learning", "--trials", TRIALS, "--jobs", 1,
                   "--params", TUNED_QL)
    assert plain["agents"]["q_learning"] == m["agents"]["q_learning"]
    assert plain["params"] == tuned["params"]


def test_suite_goal_change(tmp_path):
    res, _ = run(tmp_path, "goals", "goal-change", "--suite", "shortcut:1",
                 "--agents", "q_learning", "--trials", 1, "--episodes", 3, "--jobs", 1)
    assert res["goals"] == ["1", "2", "3", "4", "1"] and res["episodes"] == 3
    (m,) = res["suite"]["mazes"]
    assert m["goals"] == res["goals"]
    tr = m["agents"]["q_learning"]["transitions"]
    assert [(t["from"], t["to"]) for t in tr] == [("1", "2"), ("2", "3"), ("3", "4"),
                                                 ("4", "1")]
    assert res["agents"]["q_learning"]["transitions"] == tr      # one maze, one trial
    fam = res["suite"]["families"]["shortcut"]
    assert {"mazes", "skipped", "trials", "current_pct", "worst_pct", "perfect_trials",
            "win_rate"} == set(fam)


@pytest.mark.parametrize("args, message", [
    (["sample-complexity", "--suite", "blocking:1"], "--suite runs env-change"),
    (["env-change", "--suite", "mazy:2"], "unknown maze family 'mazy'"),
    (["env-change", "--suite", "blocking:0"], "positive integer"),
    (["env-change", "--suite", "blocking:1", "--maze", "x.txt"], "exclude each other"),
    (["env-change", "--suite", "blocking:1", "--event", "c"], "block or open"),
    (["env-change", "--suite", "blocking:1", "--agents", "nobody"], "unknown agent"),
])
def test_suite_usage_errors_exit_2(args, message):
    proc = cli("experiment", *args, "--quiet", check=False)
    assert proc.returncode == 2
    assert message in proc.stderr
