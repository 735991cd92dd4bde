"""``./tmgwr up | goal | cell | event | reset`` against a real graph of node processes.

One graph (``python -m tmgwr_agent.cli up``, i.e. what ``./tmgwr up`` runs) is started for
the module in a ROS_DOMAIN_ID of its own; the client commands run as separate processes
against it, and the last test stops it with SIGINT and checks that every node is gone.
"""

from __future__ import annotations

import os
import re
import signal
import time

import pytest
from ros_helpers import allocate_domain, graph_up_pids, release_domain, spawn_module

pytestmark = pytest.mark.ros


@pytest.fixture(scope="module")
def graph():
    domain = allocate_domain()
    proc = spawn_module("tmgwr_agent.cli", "up", "--no-record", "--seed", "1",
                        domain=domain, name="tmgwr up")
    try:
        pids = graph_up_pids(proc)
        yield proc, domain, pids
    finally:
        proc.stop()
        release_domain(domain)


def cli(domain: int, *args: str, timeout: float = 60.0):
    p = spawn_module("tmgwr_agent.cli", *args, domain=domain, name=" ".join(args[:1]))
    with p:
        try:
            p.proc.wait(timeout=timeout)
        except Exception:  # noqa: BLE001 -- the assertion below shows the output
            pass
        p.stop()
    return p.proc.returncode, p.output


def test_up_started_the_five_nodes(graph):
    proc, domain, pids = graph
    assert set(pids) == {"maze_sim", "sensory_preprocessor", "map_learner",
                         "motivation_estimator", "action_selector"}, proc.output
    assert "recording" not in proc.output.split("graph up")[1].splitlines()[0]


def test_goal_accepted_reaches_the_whole_graph(graph):
    proc, domain, _ = graph
    rc, out = cli(domain, "goal", "11", "1")
    assert rc == 0, out
    assert "goal (x=11, y=1): accepted" in out, out
    # the simulator applies it at its next observation and says so in the up output
    proc.wait_for_line(r"\[maze_sim\].*goal -> row 1, col 11", timeout=20)


@pytest.mark.parametrize("x, y, why", [
    ("0", "0", "a wall"),
    ("99", "3", "outside the maze"),
    ("nan", "3", "not finite"),
])
def test_goal_refused(graph, x, y, why):
    _, domain, _ = graph
    rc, out = cli(domain, "goal", x, y)
    assert rc == 1, f"{why}: {out}"
    assert "refused" in out, out


def test_event_and_cell(graph):
    proc, domain, _ = graph
    # the agent walks on: an event that would wall it in where it stands at that moment
    # is refused (world edits keep the task solvable) and is asked again a step later
    for _ in range(20):
        rc, out = cli(domain, "event", "a")
        if "would wall in the agent" not in out:
            break
        time.sleep(0.05)
    assert rc == 0 and "event 'a': accepted" in out, out
    rc, out = cli(domain, "event", "A1")
    assert rc == 1 and "refused" in out, out
    # (4, 1) is a wall of the paper maze: the agent can never stand there, so blocking it
    # (a no-op) and then opening it (a new passage) are always accepted
    rc, out = cli(domain, "cell", "4", "1", "--block")
    assert rc == 0 and "accepted" in out, out
    rc, out = cli(domain, "cell", "4", "1", "--open")
    assert rc == 0 and "accepted" in out, out
    proc.wait_for_line(r"\[maze_sim\].*cell \(row 4, col 1\) opened", timeout=10)
    rc, out = cli(domain, "cell", "40", "1", "--block")
    assert rc == 1 and "refused" in out and "outside" in out, out
    rc, out = cli(domain, "reset")
    assert rc == 0 and "reset: accepted" in out, out
    proc.wait_for_line(r"\[maze_sim\].*event 'a' fired", timeout=10)


def test_client_says_when_no_graph_runs():
    domain = allocate_domain()          # a domain where nothing runs
    try:
        rc, out = cli(domain, "goal", "15", "11", "--timeout", "1.5")
    finally:
        release_domain(domain)
    assert rc == 2, out
    assert "no service /set_goal" in out and "is the graph running" in out, out


def test_sigint_stops_every_node(graph):
    proc, _, pids = graph
    os.killpg(proc.proc.pid, signal.SIGINT)     # what Ctrl-C in the terminal does
    proc.proc.wait(timeout=60)
    proc._reader.join(timeout=5)
    out = proc.output
    assert proc.proc.returncode == 0, out
    stopped = re.search(r"^graph stopped: (.*)$", out, re.M)
    assert stopped, out
    # stopped in reverse start order, each cleanly (exit 0 after SIGINT)
    order = re.findall(r"(\w+) exit (-?\d+|None)", stopped.group(1))
    assert [n for n, _ in order] == ["action_selector", "motivation_estimator", "map_learner",
                                     "sensory_preprocessor", "maze_sim"], out
    assert all(code == "0" for _, code in order), out
    deadline = time.monotonic() + 5
    alive = [n for n, pid in pids.items() if os.path.exists(f"/proc/{pid}")]
    while alive and time.monotonic() < deadline:
        time.sleep(0.1)
        alive = [n for n, pid in pids.items() if os.path.exists(f"/proc/{pid}")]
    assert not alive, f"still running after up stopped: {alive}\n{out}"


def kill_under_up(proc, name: str, after: str | None = None) -> tuple[dict[str, int], str]:
    """SIGKILL node ``name`` of the graph ``./tmgwr up`` (``proc``) runs (once a line
    matching ``after`` is out) and wait for ``up`` to end: it exits 1 naming the node.
    Returns the graph's pids and the output."""
    with proc:
        pids = graph_up_pids(proc)
        if after is not None:
            proc.wait_for_line(after, timeout=120)
        os.kill(pids[name], signal.SIGKILL)
        proc.proc.wait(timeout=60)
        proc._reader.join(timeout=5)
    out = proc.output
    assert proc.proc.returncode == 1, out
    assert re.search(rf"node '{name}' died \(exit code -9\)", out), out
    return pids, out


def test_up_reports_a_node_that_dies_and_stops_the_rest(ros_domain):
    """With restarts off (``--respawn-limit 0``; test_respawn.py: with them on)."""
    proc = spawn_module("tmgwr_agent.cli", "up", "--no-record", "--quiet",
                        "--respawn-limit", "0", domain=ros_domain, name="tmgwr up")
    pids, out = kill_under_up(proc, "map_learner")
    # the others were stopped cleanly, in reverse order
    stopped = re.search(r"^graph stopped: (.*)$", out, re.M).group(1)
    assert "map_learner exit -9" in stopped, out
    for name in ("action_selector", "motivation_estimator", "sensory_preprocessor", "maze_sim"):
        assert f"{name} exit 0" in stopped, out
    time.sleep(0.5)
    assert not [n for n, pid in pids.items() if os.path.exists(f"/proc/{pid}")], out


def test_up_saves_the_map_when_another_node_dies(ros_domain, tmp_path):
    """Issue 10: after a node death under ``up`` the map was not saved. The action
    selector is SIGKILLed mid-run; ``up`` stops the others cleanly and the learner saves
    its map in the run's directory (and says so), beside its checkpoint."""
    run = tmp_path / "run"
    proc = spawn_module("tmgwr_agent.cli", "up", "--record-dir", str(run),
                        "--respawn-limit", "0", domain=ros_domain, name="tmgwr up")
    _, out = kill_under_up(proc, "action_selector",
                           after=r"^episode 1: \d+ steps")
    saved = re.search(r"map_learner: saved (\d+) nodes, \d+ links \(step (\d+)\) to (\S+)",
                      out)
    assert saved, out
    assert int(saved.group(1)) > 0 and int(saved.group(2)) > 0, out
    path = saved.group(3).rstrip(".")
    assert os.path.isfile(path) and os.path.dirname(os.path.realpath(path)).startswith(
        os.path.realpath(run)), (path, out)
    assert (run / "map_learner.ckpt.npz").is_file(), out


def test_up_refuses_a_bad_params_file_before_starting_nodes(ros_domain, tmp_path):
    """``up --params-file``: a malformed file (file:line), an old-layout file (how to
    convert it) and an unknown name (the nearest known one) are refused up front, exit 2."""
    files = {"broken.yaml": ("/**:\n  ros__parameters:\n    gamma: [0.9\n",
                             ["broken.yaml:4:", "malformed parameter file"]),
             "old.yaml": ("/**:\n  ros__parameters:\n    tmgwr:\n      gamma: 0.9\n",
                          ["old.yaml", "old layout", "'gamma: ...' directly under"]),
             "typo.yaml": ("action_selector:\n  ros__parameters:\n    eps_mn: 0.2\n",
                           ["typo.yaml [action_selector]", "unknown parameter 'eps_mn'",
                            "did you mean 'eps_min'"])}
    for name, (text, expected) in files.items():
        (tmp_path / name).write_text(text)
        p = spawn_module("tmgwr_agent.cli", "up", "--no-record", "--params-file",
                         str(tmp_path / name), domain=ros_domain, name=name)
        with p:
            p.proc.wait(timeout=60)
            p._reader.join(timeout=5)
        assert p.proc.returncode == 2, p.describe(name)
        assert "graph up" not in p.output and "Traceback" not in p.output, p.output
        for e in expected:
            assert e in p.output, (name, e, p.output)
