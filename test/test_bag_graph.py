"""A recording of the real node graph, read back and reported (own ROS_DOMAIN_ID).

``./tmgwr up`` starts the five nodes and the recorder as separate processes on a small maze;
the test changes the goal with ``./tmgwr goal`` and fires an event with ``./tmgwr event``
while the graph runs, and keeps every episode the simulator logged live (its own
``episode N: goal ... reached in S steps (step E)`` lines, forwarded by ``up``). Then:

* the bag is complete: each per-step topic holds every step id from 0 to the last without
  a gap, the recorder wrote everything it received, and rosbags and Foxglove's own readers
  decode every message of every topic (custom tmgwr_interfaces types, OccupancyGrid,
  MarkerArray, ...);
* ``./tmgwr report`` rebuilds the map from the per-step changes without a gap and states
  the run's own figures: the same episodes (steps, end step)
  as logged live, the goal change at the step the simulator logged, the steps to the
  goal after the goal change and after the event as computed from the live episodes.
"""

from __future__ import annotations

import json
import re
import time

import pytest
import yaml
from ros_helpers import ROOT, RosProcess, graph_up_pids, ros_env
from test_recorder import foxglove_decoder, mcap_files, tmgwr_cli  # noqa: F401, F811 (fixtures)
from world_graph import PER_STEP, assert_every_step_answered

pytestmark = [pytest.mark.ros, pytest.mark.slow]

MAZE = """\
#######
#S.a.G#
#.###.#
#.1...#
#######
"""
# The simulator's own log line for every episode that reaches the goal (forwarded by up);
# on this maze every episode ends at the goal (no step cap, no kept previous goal).
EPISODE = re.compile(r"\[maze_sim\].*episode (\d+): goal \(\d+, \d+\) reached in (\d+) steps "
                     r"\(step (\d+)\)")


def live_episodes(up: RosProcess) -> list[tuple[int, int, str, int]]:
    """(episode, steps, outcome, end step) as the simulator logged them while running."""
    out = []
    for line in up.lines:
        m = EPISODE.search(line)
        if m:
            out.append((int(m.group(1)), int(m.group(2)), "goal", int(m.group(3))))
    return out


def wait_episodes(up: RosProcess, n: int, timeout: float) -> None:
    deadline = time.monotonic() + timeout
    while len(live_episodes(up)) < n:
        if not up.running() or time.monotonic() > deadline:
            raise AssertionError(up.describe(f"fewer than {n} episodes within {timeout} s"))
        time.sleep(0.2)


@pytest.fixture(scope="module")
def graph_run(tmp_path_factory):
    """Run the graph once for the module: (bag directory, live episodes, goal step)."""
    from ros_helpers import allocate_domain, release_domain
    domain = allocate_domain()
    tmp = tmp_path_factory.mktemp("graph")
    maze = tmp / "small.txt"
    maze.write_text(MAZE)
    bag = tmp / "run"
    up = RosProcess([str(ROOT / ".venv/bin/python"), "-m", "tmgwr_agent.cli", "up", "--maze",
                     str(maze), "--seed", "3", "--record-dir", str(bag),
                     "--domain-id", str(domain)], ros_env(domain), name="up")
    try:
        with up:
            up.wait_for_line(r"^recording to ", timeout=90)
            wait_episodes(up, 4, timeout=90)
            goal = tmgwr_cli("goal", "2", "3", "--domain-id", str(domain), domain=domain)
            assert goal.returncode == 0 and "accepted" in goal.stdout, goal.stdout + goal.stderr
            # the simulator's own log line (forwarded by up) says where the change landed
            line = up.wait_for_line(r"step \d+: goal -> row 3, col 2", timeout=30)
            goal_step = int(re.search(r"step (\d+): goal ->", line).group(1))
            n = len(live_episodes(up))
            wait_episodes(up, n + 4, timeout=90)
            event = tmgwr_cli("event", "a", "--domain-id", str(domain), domain=domain)
            assert event.returncode == 0 and "accepted" in event.stdout, \
                event.stdout + event.stderr
            n = len(live_episodes(up))
            wait_episodes(up, n + 3, timeout=90)
            up.proc.send_signal(2)             # Ctrl-C: the nodes stop, the recorder last
            up.wait_for_line(r"^recording: ", timeout=60)
            up.wait(timeout=60, check=False)
        assert up.proc.returncode == 0, up.describe("./tmgwr up failed")
        yield bag, live_episodes(up), goal_step, up.output
    finally:
        release_domain(domain)


def test_graph_recording_is_complete_and_decodes_everywhere(graph_run, foxglove_decoder):
    bag, _live, _goal_step, _out = graph_run
    files = mcap_files(bag)
    from rosbags.highlevel import AnyReader
    steps: dict[str, list[int]] = {}
    counts: dict[str, int] = {}
    with AnyReader([bag]) as reader:
        for conn, _t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)      # every message decodes
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
            if conn.topic in PER_STEP:
                steps.setdefault(conn.topic, []).append(int(msg.step_id))
        meta_counts = {c.topic: c.msgcount for c in reader.connections}
    assert counts == {t: n for t, n in meta_counts.items() if n}
    assert max(steps["/observation"]) > 100
    assert_every_step_answered(steps)
    for topic in ("/maze_grid", "/goal", "/map", "/map_markers", "/maze_events",
                  "/sensorimotor_snapshot", "/potentials", "/world_senses",
                  "/feature_senses"):
        assert counts.get(topic, 0) >= 1, topic

    result = foxglove_decoder(files)
    fox: dict[str, int] = {}
    for path in files:
        for topic, t in result["files"][str(path)]["topics"].items():
            assert not t["errors"], (topic, t["errors"])
            fox[topic] = fox.get(topic, 0) + t["count"]
    assert {t: n for t, n in fox.items() if n} == counts


def test_the_foxglove_report_survives_a_late_reader(graph_run, foxglove_decoder, tmp_path):
    """decode.js prints more than a pipe holds (64 KiB); a reader that comes late gets it all.

    CI once read the first 65536 characters only: decode.js ended with process.exit(), which
    drops what a pipe could not take at once. It now sets process.exitCode instead. The
    report grows with the run, so the bag's files are given under enough names to fill a pipe.
    """
    import math
    import subprocess

    from test_recorder import JS_DIR, NODE
    files = mcap_files(graph_run[0])
    one = len(json.dumps(foxglove_decoder(files)))
    names = []
    for k in range(math.ceil(2 * 65536 / one)):
        for f in files:
            names.append(tmp_path / f"{k}_{f.name}")
            names[-1].symlink_to(f)
    proc = subprocess.Popen([NODE, str(JS_DIR / "decode.js"), *map(str, names)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(2.0)                      # the pipe fills and node has to wait for us
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert len(out) > 65536, len(out)
    assert set(json.loads(out)["files"]) == set(map(str, names))


def test_recorder_lost_nothing(graph_run):
    bag, _live, _goal_step, out = graph_run
    m = re.search(r"recorded: received (\d+), written (\d+) messages", out)
    assert m, out[-3000:]
    assert m.group(1) == m.group(2)
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["message_count"] == int(m.group(2))
    # and it counted the step ids live: no gap on any per-step topic, and said so
    assert "step gaps: none on 5 per-step topics" in out, out[-3000:]
    gaps = json.loads(info["custom_data"]["step_gaps"])
    assert sorted(gaps) == sorted(PER_STEP)
    assert all(r["missing"] == 0 for runs in gaps.values() for r in runs.values()), gaps


def recorded_missing(bag) -> dict[str, list[list[int]]]:
    """The step ids each per-step topic lacks between its first and last, as ranges, read
    from the bag itself."""
    from rosbags.highlevel import AnyReader
    ids: dict[str, set[int]] = {}
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in PER_STEP]
        for conn, _t, raw in reader.messages(connections=conns):
            ids.setdefault(conn.topic, set()).add(int(reader.deserialize(raw, conn.msgtype)
                                                      .step_id))
    out = {}
    for topic, have in ids.items():
        ranges, lo = [], None
        for k in range(min(have), max(have) + 2):
            if k not in have and k <= max(have) and lo is None:
                lo = k
            elif (k in have or k > max(have)) and lo is not None:
                ranges.append([lo, k - 1])
                lo = None
        out[topic] = ranges
    return out


@pytest.mark.timeout(240)
def test_a_paused_recorder_says_exactly_what_it_lost(ros_domain, tmp_path):
    """Issue 10: a recorder paused for 10 s lost 1711 consecutive steps on every step topic,
    yet ended with 'received 25421, written 25421'. The ring does not wait for the recorder
    (keep-last STEP_DEPTH per-step publishers), so a paused recorder loses what their
    history no longer holds; now it says exactly which steps, live and at the end, and the
    bag's metadata holds the same ranges as the bag itself lacks. The pause (25 s) outlasts
    that history even at a loaded machine's rate."""
    import os
    import signal
    bag = tmp_path / "paused"
    up = RosProcess([str(ROOT / ".venv/bin/python"), "-m", "tmgwr_agent.cli", "up",
                     "--seed", "1", "--record-dir", str(bag), "--domain-id", str(ros_domain)],
                    ros_env(ros_domain), name="up")
    with up:
        pid = graph_up_pids(up, timeout=90)["recorder"]
        up.wait_for_line(r"\[maze_sim\].*goal \(\d+, \d+\) reached", timeout=90)
        os.kill(pid, signal.SIGSTOP)
        time.sleep(25.0)
        os.kill(pid, signal.SIGCONT)
        up.wait_for_line(r"\[recorder\].*GAP on /", timeout=30)     # said at once
        time.sleep(3.0)
        up.proc.send_signal(signal.SIGINT)
        up.wait_for_line(r"^recording: ", timeout=60)
        out = up.wait(timeout=60, check=False)
    assert up.proc.returncode == 0, up.describe("./tmgwr up failed")
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    stated = json.loads(info["custom_data"]["step_gaps"])
    actual = recorded_missing(bag)
    figures = {}
    for topic in PER_STEP:
        [(run, r)] = stated[topic].items()
        assert r["ranges"] == actual[topic] and not r["ranges_cut"], (topic, r, actual[topic])
        assert r["missing"] == sum(b - a + 1 for a, b in actual[topic]) > 0, (topic, r)
        assert f"{r['missing']} MISSING" in out, out[-4000:]
        figures[topic] = (r["missing"], r["last"] - r["first"] + 1)
    m = re.search(r"step gaps: (\d+) steps MISSING on 5 per-step topics", out)
    assert m and int(m[1]) == sum(v[0] for v in figures.values()), out[-3000:]
    print("paused 25 s: missing / steps per topic: "
          + ", ".join(f"{t} {a}/{b}" for t, (a, b) in figures.items()))


def test_report_states_the_runs_own_figures(graph_run, tmp_path):
    bag, live, goal_step, _out = graph_run
    maze = tmp_path / "small.txt"
    maze.write_text(MAZE)
    proc = tmgwr_cli("report", str(bag), "-o", str(tmp_path / "report"), "--maze", str(maze))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rep = json.loads((tmp_path / "report" / "report.json").read_text())
    for name in ("steps_per_episode", "goal_change_visits", "steps_to_goal", "map_over_time",
                 "final_map"):
        png = tmp_path / "report" / f"{name}.png"
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # the same episodes as logged live (the bag may hold more: the simulator's last lines
    # can be cut off by the stop)
    n = len(live)
    assert n >= 11
    assert rep["episodes"]["steps_per_episode"][:n] == [s for _e, s, _o, _end in live]
    assert rep["episodes"]["end_steps"][:n] == [end for _e, _s, _o, end in live]
    assert rep["episodes"]["outcomes"] == {"goal": rep["episodes"]["count"]}
    assert rep["steps"]["missed"] == 0

    # the goal change at the step the simulator announced, with the live figures
    (change,) = rep["goal_changes"]
    assert change["step"] == goal_step
    assert change["to"] == [3, 2] and change["from"] == [1, 5]
    assert (change["from_name"], change["to_name"]) == ("G", "1")
    assert f"goal change at step {goal_step} [1, 5] -> [3, 2]" in proc.stdout
    after = [e for e in live if e[3] > goal_step - 1]
    first = next(e for e in after if e[2] == "goal")
    assert change["first_goal_steps_after"] == first[3] - (goal_step - 1)
    (event,) = rep["events"]
    assert "event 'a'" in event["what"]
    in_phase = [e for e in after if e[3] <= event["step"]]
    assert change["episodes"] == len(in_phase)
    assert change["previous_pct"] <= change["previous_visit_pct"] <= 100.0
    assert change["current_pct"] == pytest.approx(
        100.0 * sum(e[2] == "goal" for e in in_phase) / len(in_phase))
    first = next(e for e in live if e[3] > event["step"] and e[2] == "goal")
    assert event["first_goal_steps_after"] == first[3] - event["step"]
    assert rep["map"]["nodes"] > 0 and 0.0 <= rep["map"]["mean_reliability"] <= 1.0
    # the map rebuilt from the per-step changes, every one of them applied
    rebuilt = rep["map"]["rebuilt"]
    assert rep["map"]["source"] == "/sensorimotor_state" and rebuilt["gaps"] == 0, rebuilt
    assert rebuilt["step_id"] >= rep["steps"]["last"] - 1
    # shortest paths of the maze in force (from /maze_grid): G 4 steps from S, goal 1 3 steps
    # (before and after event a, which only blocks the top corridor)
    assert rep["start_cell"] == [1, 1]
    assert rep["learning"]["optimal_steps"] == 4
    assert change["optimal_steps"] == 3 and event["optimal_steps"] == 3
    k = change["episodes_to_optimal"]
    assert k is None or change["steps_per_episode"][k - 1] == 3


@pytest.mark.timeout(300)
def test_a_root_recorder_checks_gaps_per_namespace(ros_domain, tmp_path):
    """Issue 24: a recorder in the root namespace recorded two namespaced graphs but checked
    the step ids of neither. Now each namespace's per-step topics are checked on their own."""
    import signal

    from ros_helpers import ros2_run, spawn_module
    graphs = [spawn_module("tmgwr_agent.cli", "up", "--no-record", "--quiet", "--seed", str(i),
                           "--namespace", ns, domain=ros_domain, name=f"up {ns}")
              for i, ns in enumerate("ab")]
    bag = tmp_path / "root_bag"
    rec = ros2_run("tmgwr_agent", "recorder", "--ros-args", "-p", f"output_dir:={bag}",
                   domain=ros_domain, name="recorder")
    with rec, graphs[0], graphs[1]:
        for g in graphs:
            graph_up_pids(g, timeout=120)
        for g in graphs:
            g.wait_for_line(r"^episode \d+: \d+ steps", timeout=120)
        time.sleep(2.0)
        rec.proc.send_signal(signal.SIGINT)
        out = rec.wait(timeout=60, check=False)
    assert rec.proc.returncode == 0, rec.describe("the recorder did not stop cleanly")
    assert "step gaps: none on 10 per-step topics" in out, out[-3000:]
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    stated = json.loads(info["custom_data"]["step_gaps"])
    assert set(stated) == {f"/{ns}{t}" for ns in "ab" for t in PER_STEP}, stated
    for topic, runs in stated.items():
        assert sum(r["received"] for r in runs.values()) > 50, (topic, runs)
