"""Shared steps of the graph tests on other worlds (test_minigrid_graph, test_pointmaze_graph):
``./tmgwr up --world W`` on a small maze, recorded; an event asked until the agent is off
its cell; the Ctrl-C stop; the bag read back with every per-step topic's step ids."""

from __future__ import annotations

import re
from pathlib import Path

from ros_helpers import ROOT, RosProcess, ros_env
from test_recorder import mcap_files, tmgwr_cli

from tmgwr_common.topics import STEP_TOPICS

GOAL = re.compile(r"\[maze_sim\].*episode (\d+): goal \((\d+), (\d+)\) reached in (\d+) steps")
PER_STEP = tuple("/" + name for name in STEP_TOPICS)      # the ring's topics, in its order


def up_world(world: str, maze: str, tmp_path: Path, domain: int) -> tuple[RosProcess, Path]:
    """``./tmgwr up --world WORLD`` on the maze text, recording to ``tmp_path/run``; (the
    process, not yet entered, and the bag's folder)."""
    path = tmp_path / "small.txt"
    path.write_text(maze)
    bag = tmp_path / "run"
    up = RosProcess([str(ROOT / ".venv/bin/python"), "-m", "tmgwr_agent.cli", "up",
                     "--world", world, "--maze", str(path), "--seed", "3",
                     "--record-dir", str(bag), "--domain-id", str(domain)],
                    ros_env(domain), name="up")
    return up, bag


def fire_event(up: RosProcess, domain: int, name: str = "a") -> None:
    """Fire an event, asked again while it is refused because the agent stands on its
    cell, and wait for the simulator's line."""
    for _ in range(20):
        event = tmgwr_cli("event", name, "--domain-id", str(domain), domain=domain)
        if "would wall in the agent" not in event.stdout:
            break
    assert event.returncode == 0 and "accepted" in event.stdout, event.stdout + event.stderr
    up.wait_for_line(rf"event '{name}' fired", timeout=30)


def ctrl_c(up: RosProcess) -> None:
    """Ctrl-C: the nodes stop, the recorder last."""
    up.proc.send_signal(2)
    up.wait_for_line(r"^recording: ", timeout=60)
    up.wait(timeout=60, check=False)


def read_bag(bag: Path, topics: tuple[str, ...], log: str = "") -> dict[str, list]:
    """Every message of ``topics`` in the bag, in order; asserts that the ring answered
    every step (each per-step topic's step ids run 0, 1, ... without a gap). ``log``: the
    run's output, whose recorder and simulator lines a failure quotes."""
    from rosbags.highlevel import AnyReader
    steps: dict[str, list[int]] = {}
    msgs: dict[str, list] = {t: [] for t in topics}
    with AnyReader(mcap_files(bag)) as reader:
        for conn, _t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic in PER_STEP:
                steps.setdefault(conn.topic, []).append(int(msg.step_id))
            if conn.topic in msgs:
                msgs[conn.topic].append(msg)
    assert_every_step_answered(steps, log)
    return msgs


def assert_every_step_answered(steps: dict[str, list[int]], log: str = "") -> None:
    """Each per-step topic's step ids (as recorded) run 0, 1, ... without a gap, up to the
    newest observation but one: the newest step may still be in flight at the stop. A
    failure names the missing ids and quotes ``log``'s recorder, gap, resend and event
    lines (where a step was lost: at the start, at an event, mid-run)."""
    last = max(steps["/observation"])
    for topic in PER_STEP:
        ids = sorted(set(steps[topic]))
        missing = sorted(set(range(ids[-1] + 1)) - set(ids))
        assert ids[0] == 0 and not missing, _lost_steps(topic, ids, missing, steps, log)
        assert ids[-1] >= last - 1, (topic, ids[-1], last)


def _lost_steps(topic: str, ids: list[int], missing: list[int],
                steps: dict[str, list[int]], log: str) -> str:
    """The message of a topic whose recorded step ids do not run 0, 1, ...: its range and
    missing ids, the first ids of every topic, and ``log``'s recorder, gap, resend and
    event lines (read only when the check fails)."""
    said = [ln for ln in log.splitlines()
            if re.search(r"recorder|recording|gap|resend|event|ready", ln)]
    first = {t: sorted(set(v))[:3] for t, v in steps.items()}
    return (f"{topic}: {len(ids)} step ids from {ids[0]} to {ids[-1]}, missing "
            f"{missing[:20]}; the first ids of every topic: {first}\n" + "\n".join(said[-60:]))
