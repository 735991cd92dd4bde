"""The recorder node and the bag tools against real rclpy publishers (own ROS_DOMAIN_ID).

A test publisher process publishes, like the graph does: a latched (transient local)
``/goal`` before the recorder exists, then ``N`` ``tmgwr_interfaces/Observation`` messages
with consecutive step ids on a reliable ``/observation`` at a few hundred per second, and a
best-effort ``/agent_pose`` stream. The recording is read back by rosbags (AnyReader and the
rosbag2 directory reader), by the ``mcap`` reader, and by Foxglove's own JavaScript readers
(``@mcap/core``, ``@foxglove/rosmsg``, ``@foxglove/rosmsg2-serialization``, pinned in
test/js/package-lock.json, installed with ``npm ci``, run with the machine's Node.js).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest
import yaml
from ros_helpers import ROOT, RosProcess, base_env, ros2_run, ros_env, spawn_python, stop_all

pytestmark = [pytest.mark.ros, pytest.mark.slow]

JS_DIR = ROOT / "test" / "js"
NODE = os.environ.get("TMGWR_NODE", "/usr/bin/node")

PUBLISHER = r"""
import sys, time
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy, DurabilityPolicy
from tmgwr_interfaces.msg import Observation
from geometry_msgs.msg import PointStamped, PoseStamped
n, rate = int(sys.argv[1]), float(sys.argv[2])
rclpy.init()
node = rclpy.create_node('test_publisher')
step_qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
sensor = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
obs_pub = node.create_publisher(Observation, '/observation', step_qos)
goal_pub = node.create_publisher(PointStamped, '/goal', latched)
pose_pub = node.create_publisher(PoseStamped, '/agent_pose', sensor)
goal = PointStamped(); goal.header.frame_id = 'maze'; goal.point.x = 15.0; goal.point.y = 11.0
goal_pub.publish(goal)                      # latched: published before anyone listens
print('LATCHED', flush=True)
while obs_pub.get_subscription_count() < 1:  # the recorder discovered /observation
    time.sleep(0.02)
time.sleep(0.3)
t0 = time.perf_counter()
for i in range(n):
    m = Observation(step_id=i, episode=i // 100, sensors=[0.5 * i, -1.0, 2.0],
                    episode_start=(i % 100 == 0), goal_reached=(i % 100 == 99),
                    terminal=(i % 100 == 99), row=i % 13, col=i % 17)
    m.header.stamp = node.get_clock().now().to_msg()
    obs_pub.publish(m)
    if i % 50 == 0:
        p = PoseStamped(); p.pose.position.x = float(i % 17); pose_pub.publish(p)
        print('PUBLISHED %d' % i, flush=True)      # step ids 0..i-1 are out
    target = t0 + (i + 1) / rate
    while time.perf_counter() < target:
        time.sleep(min(0.0005, max(0.0, target - time.perf_counter())))
print('DONE %d %.3f' % (n, time.perf_counter() - t0), flush=True)
sys.stdin.readline() if len(sys.argv) > 3 else time.sleep(1.0)
node.destroy_node(); rclpy.shutdown()
"""


# ----------------------------------------------------------------------------- helpers
def start_recorder(domain: int, out: Path, *params: str, name: str = "recorder") -> RosProcess:
    args = ["--ros-args", "-p", f"output_dir:={out}"]
    for p in params:
        args += ["-p", p]
    return ros2_run("tmgwr_agent", "recorder", *args, domain=domain, name=name)


def record(domain: int, out: Path, n: int, rate: float, *params: str,
           stop_signal=signal.SIGINT) -> str:
    """Record ``n`` test messages; the recorder is stopped with ``stop_signal``."""
    rec = start_recorder(domain, out, *params)
    pub = spawn_python(PUBLISHER, str(n), str(rate), domain=domain, name="publisher")
    with rec, pub:
        rec.wait_for_line(r"recording .* to ", timeout=30)
        pub.wait_for_line(r"^DONE", timeout=30 + n / rate)
        pub.wait(timeout=20)
        time.sleep(0.3)
        os.killpg(rec.proc.pid, stop_signal)
        rec.wait_for_line(r"recorded: received", timeout=20)
        rec.wait(timeout=20, check=False)
    assert rec.proc.returncode == 0, rec.describe("recorder did not exit cleanly")
    return rec.output


def mcap_files(bag: Path) -> list[Path]:
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return [bag / p for p in meta["relative_file_paths"]]


def read_step_ids(paths: list[Path], topic: str = "/observation") -> list[int]:
    from rosbags.highlevel import AnyReader
    with AnyReader(paths) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        return [reader.deserialize(raw, c.msgtype).step_id
                for c, _t, raw in reader.messages(connections=conns)]


@pytest.fixture(scope="session")
def foxglove_decoder():
    """``node test/js/decode.js FILES`` with the pinned npm packages installed by ``npm ci``."""
    lock = JS_DIR / "package-lock.json"
    stamp = JS_DIR / "node_modules" / ".package-lock.json"
    if not stamp.is_file() or stamp.stat().st_mtime < lock.stat().st_mtime:
        proc = subprocess.run(["npm", "ci", "--no-audit", "--no-fund"], cwd=JS_DIR,
                              capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, f"npm ci failed in {JS_DIR}:\n{proc.stdout}\n{proc.stderr}"

    def decode(paths: list[Path]) -> dict:
        proc = subprocess.run([NODE, str(JS_DIR / "decode.js"), *map(str, paths)],
                              capture_output=True, text=True, timeout=120)
        assert proc.stdout, f"decode.js printed nothing:\n{proc.stderr}"
        result = json.loads(proc.stdout)
        assert proc.returncode == 0, \
            f"Foxglove readers failed:\n{json.dumps(result)[:4000]}\n{proc.stderr}"
        return result
    return decode


def tmgwr_cli(*args: str, domain: int | None = None,
              timeout: float = 120) -> subprocess.CompletedProcess:
    """``./tmgwr ARGS`` (python -m tmgwr_agent.cli) in ``domain`` when it talks ROS."""
    env = ros_env(domain) if domain is not None else base_env()
    return subprocess.run([str(ROOT / ".venv/bin/python"), "-m", "tmgwr_agent.cli", *args],
                          env=env, capture_output=True, text=True, timeout=timeout)


# ----------------------------------------------------------------------------- tests
N = 1500
RATE = 500.0


def test_recording_opens_everywhere_and_counts_match(ros_domain, tmp_path, foxglove_decoder):
    bag = tmp_path / "run"
    # lz4 chunks of 16 KiB, split every 64 KiB: several complete files; stopped by SIGTERM
    out = record(ros_domain, bag, N, RATE, "compression:=lz4", "chunk_size:=16384",
                 "max_bag_size:=65536", "flush_period:=0.2", stop_signal=signal.SIGTERM)
    assert f"/observation: received {N}, written {N}" in out, out

    files = mcap_files(bag)
    assert len(files) >= 2, f"expected a split bag, got {files}"
    # rosbag2 directory (metadata.yaml version 9) read by rosbags' rosbag2 reader
    from rosbags.rosbag2 import Reader
    with Reader(bag) as r2:
        counts = {c.topic: c.msgcount for c in r2.connections}
        assert counts["/observation"] == N
        assert counts["/goal"] == 1                   # latched before the recorder started
        qos_goal = next(c for c in r2.connections if c.topic == "/goal").ext.offered_qos_profiles
        assert qos_goal[0].durability.name == "TRANSIENT_LOCAL"
    # every message through AnyReader, from the directory and file by file
    assert read_step_ids([bag]) == list(range(N))
    assert read_step_ids(files) == list(range(N))

    # the mcap library: ros2 profile, schemas, channel metadata, statistics, rosbag2 record
    from mcap.reader import make_reader
    total = 0
    for path in files:
        with open(path, "rb") as f:
            reader = make_reader(f)
            assert reader.get_header().profile == "ros2"
            summary = reader.get_summary()
            assert summary.statistics is not None and summary.chunk_indexes
            total += summary.statistics.message_count
            for ch in summary.channels.values():
                schema = summary.schemas[ch.schema_id]
                assert schema.encoding == "ros2msg" and ch.message_encoding == "cdr"
                text = schema.data.decode()
                assert "MSG: std_msgs/msg/" not in text
                if ch.topic == "/observation":
                    assert "\nMSG: std_msgs/Header\n" in text
                    assert "\nMSG: builtin_interfaces/Time\n" in text
                    qos = yaml.safe_load(ch.metadata["offered_qos_profiles"])
                    assert qos[0]["reliability"] == "reliable"
                    assert qos[0]["durability"] == "volatile"
                    expected_hash = json.loads(
                        (ROOT / "install/tmgwr_interfaces/share/tmgwr_interfaces/msg/"
                                "Observation.json").read_text())["type_hashes"][0]["hash_string"]
                    assert ch.metadata["topic_type_hash"] == expected_hash
                if ch.topic == "/agent_pose":
                    qos = yaml.safe_load(ch.metadata["offered_qos_profiles"])
                    assert qos[0]["reliability"] == "best_effort"
            meta = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
            assert len(meta) == 1
            info = yaml.safe_load(meta[0].metadata["serialized_metadata"])
            assert info["version"] == 9 and info["storage_identifier"] == "mcap"
            assert info["message_count"] == summary.statistics.message_count
            assert info["relative_file_paths"] == [path.name]
            for key in ("duration", "starting_time", "topics_with_message_count", "files",
                        "compression_format", "compression_mode", "custom_data", "ros_distro"):
                assert key in info
            for _s, _c, m in reader.iter_messages(topics=["/observation"]):
                assert 0 < m.publish_time <= m.log_time < m.publish_time + 5 * 10**9
    top = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert top["message_count"] == total

    # Foxglove's own readers decode every message of every file
    result = foxglove_decoder(files)
    steps, fox_counts = [], {}
    for path in files:
        res = result["files"][str(path)]
        assert res["profile"] == "ros2"
        for topic, t in res["topics"].items():
            assert not t["errors"], (path, topic, t["errors"])
            assert t["trailing"] == 0, (path, topic)
            fox_counts[topic] = fox_counts.get(topic, 0) + t["count"]
        steps += res["topics"].get("/observation", {}).get("step_ids", [])
    assert steps == list(range(N))
    assert fox_counts["/goal"] == 1
    assert fox_counts["/observation"] == N


def test_bad_parameters_are_refused_by_name(ros_domain, tmp_path):
    for param, word in (("compression:=brotli", "compression"), ("chunk_size:=10", "chunk_size"),
                        ("max_bag_duration:=-1.0", "max_bag_duration"),
                        ("exclude:='(('", "exclude")):
        rec = start_recorder(ros_domain, tmp_path / "x", param)
        with rec:
            out = rec.wait(timeout=30, check=False)
        assert rec.proc.returncode != 0, out
        assert word in out and "cannot start" in out, out


def test_kill9_mid_run_then_recover_saves_what_was_written(ros_domain, tmp_path):
    bag = tmp_path / "killed"
    # flush the open chunk every 10 ms: what a kill -9 can lose is bounded by that
    rec = start_recorder(ros_domain, bag, "flush_period:=0.01")
    pub = spawn_python(PUBLISHER, str(N), "250", "hold", domain=ros_domain, name="publisher")
    with rec, pub:
        rec.wait_for_line(r"recording .* to ", timeout=30)
        line = pub.wait_for_line(r"^PUBLISHED (6\d\d|[7-9]\d\d)", timeout=60)
        published = int(line.split()[1])     # at least this many were out before the kill
        time.sleep(0.05)
        os.killpg(rec.proc.pid, signal.SIGKILL)      # mid-run: the publisher goes on
        rec.proc.wait(timeout=10)
        assert "DONE" not in pub.output
    path = bag / f"{bag.name}_0.mcap"
    from mcap.reader import make_reader
    with pytest.raises(Exception):            # the indexed reader refuses the broken file
        with open(path, "rb") as f:
            make_reader(f).get_summary()

    proc = tmgwr_cli("recover", str(path))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    fixed = bag / f"{bag.name}_0.recovered.mcap"
    assert str(fixed) in proc.stdout
    steps = read_step_ids([fixed])
    print(f"kill -9 after >= {published} published: {len(steps)} recovered")
    assert len(steps) >= 0.99 * published, proc.stdout
    assert steps == list(range(len(steps)))
    with open(fixed, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary.statistics.message_count == int(proc.stdout.split(" messages saved")[0]
                                                   .rsplit(" ", 1)[-1])


def test_replay_rerecorded_is_byte_identical_with_timing(ros_domain, tmp_path):
    first = tmp_path / "first"
    record(ros_domain, first, 600, 300.0, "compression:=zstd")
    second = tmp_path / "second"
    rec = start_recorder(ros_domain, second, "topics:=[/observation,/goal]",
                         "discovery_period:=0.1", name="rerecorder")
    with rec:
        rec.wait_for_line(r"recording .* to ", timeout=30)
        proc = tmgwr_cli("replay", str(first), "--topics", "/observation", "/goal",
                         "--wait-subscribers", "1", "--delay", "0.5", domain=ros_domain,
                         timeout=60)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        rec.stop()
    assert rec.proc.returncode == 0, rec.output

    from mcap.reader import make_reader

    def messages(bag):
        out = {}
        for path in mcap_files(bag):
            with open(path, "rb") as f:
                for _s, ch, m in make_reader(f).iter_messages(log_time_order=True):
                    out.setdefault(ch.topic, []).append((m.log_time, bytes(m.data)))
        return out

    a, b = messages(first), messages(second)
    assert len(b["/observation"]) == len(a["/observation"]) == 600
    assert [d for _t, d in b["/observation"]] == [d for _t, d in a["/observation"]]
    assert [d for _t, d in b["/goal"]] == [d for _t, d in a["/goal"]]
    ta = [t for t, _d in a["/observation"]]
    tb = [t for t, _d in b["/observation"]]
    offsets = [(y - tb[0]) - (x - ta[0]) for x, y in zip(ta, tb)]
    # Both recordings carry the reception jitter of a shared 2-core machine (a median of
    # 0.2 ms on a quiet one, 2.4 ms at load 6), so this checks that replay keeps the
    # recorded timing, not how precisely: a replay that ignored it would put the 600
    # messages of 2 s into a few ms (errors up to 2 s, median about 1 s). The precision is
    # a benchmark figure; the test prints it.
    err = sorted(abs(o) / 1e6 for o in offsets)
    median, p95, worst = err[len(err) // 2], err[int(0.95 * (len(err) - 1))], err[-1]
    print(f"replay timing error (ms): median {median:.3f}, p95 {p95:.3f}, max {worst:.3f}")
    span_a, span_b = (ta[-1] - ta[0]) / 1e9, (tb[-1] - tb[0]) / 1e9
    assert 0.9 < span_b / span_a < 1.1, (span_a, span_b)
    assert median < 50.0, (median, p95, worst)

    # --rate 4 --loop: the same bytes again and again, four times faster
    third = tmp_path / "third"
    rec = start_recorder(ros_domain, third, "topics:=[/observation]", "discovery_period:=0.1",
                         name="looprecorder")
    with rec:
        rec.wait_for_line(r"recording .* to ", timeout=30)
        player = RosProcess([str(ROOT / ".venv/bin/python"), "-m", "tmgwr_agent.cli", "replay",
                             str(first), "--topics", "/observation", "--rate", "4", "--loop",
                             "--wait-subscribers", "1", "--delay", "0.2"],
                            ros_env(ros_domain), name="replay-loop")
        with player:
            player.wait_for_line(r"^replay: 1 topics", timeout=30)
            time.sleep(0.2 + 1.0 + 2 * 2.0 / 4)    # delay, matching, two passes at 4x
            player.stop()
        rec.stop()
    c = messages(third)["/observation"]
    passes = len(c) // 600
    assert passes >= 2, len(c)
    data = [d for _t, d in c]
    assert data[:600 * passes] == [d for _t, d in a["/observation"]] * passes
    orig = (ta[-1] - ta[0]) / 1e9
    fast = (c[599][0] - c[0][0]) / 1e9
    assert fast == pytest.approx(orig / 4, rel=0.1), (orig, fast)



# Publishes argv[1] Observations of run 7 (steps 0..n-1) with a deep reliable history, once
# the recorder matched and after argv[2] seconds; then waits until they are acknowledged.
QUEUED_PUBLISHER = r"""
import sys, time
import rclpy
from rclpy.duration import Duration
from rclpy.qos import QoSProfile, ReliabilityPolicy
from tmgwr_interfaces.msg import Observation
n, pause = int(sys.argv[1]), float(sys.argv[2])
rclpy.init()
node = rclpy.create_node("queued_publisher")
pub = node.create_publisher(Observation, "/observation",
                            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
while pub.get_subscription_count() < 1:
    time.sleep(0.02)
print("MATCHED", flush=True)
time.sleep(pause)
for i in range(n):
    pub.publish(Observation(run_id=7, step_id=i))
print("PUBLISHED", flush=True)
print("ACKED", pub.wait_for_all_acked(Duration(seconds=30)), flush=True)
node.destroy_node(); rclpy.shutdown()
"""


def test_a_stop_with_messages_still_queued_writes_them_all(ros_domain, tmp_path):
    """The cause of the CI flake '/action step 646 missing against /observation step 647 at
    the stop': the recorder, stopped last, closed the bag with the nodes' last messages still
    queued on its subscriptions. Here 300 messages arrive while the recorder is paused and
    its stop request is already pending: it writes every one (it drains its subscriptions
    before closing), and says there is no gap."""
    bag = tmp_path / "queued"
    rec = start_recorder(ros_domain, bag, "topics:=[/observation]", "drain_max:=0")
    pub = spawn_python(QUEUED_PUBLISHER, "300", "1.0", domain=ros_domain, name="publisher")
    with rec, pub:
        rec.wait_for_line(r"recording .* to ", timeout=30)
        pub.wait_for_line("^MATCHED", timeout=30)
        os.kill(rec.proc.pid, signal.SIGSTOP)
        pub.wait_for_line("^PUBLISHED", timeout=30)
        time.sleep(0.5)
        os.kill(rec.proc.pid, signal.SIGINT)       # pending until the recorder runs again
        os.kill(rec.proc.pid, signal.SIGCONT)
        rec.wait_for_line(r"recorded: received", timeout=30)
        out = rec.wait(timeout=30)
        assert "ACKED True" in pub.wait(timeout=60)
    assert "/observation: received 300, written 300" in out, out
    assert "run 7: steps 0-299, no gap" in out and "step gaps: none" in out, out
    assert read_step_ids([bag]) == list(range(300))
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    gaps = json.loads(meta["custom_data"]["step_gaps"])
    assert gaps["/observation"]["7"]["missing"] == 0


def test_a_ring_told_to_await_the_recorder_starts_only_when_it_has_every_topic(
        ros_domain, tmp_path):
    """A graph started before its recorder (``up --no-record``, maze_sim's ``await_recorder``
    on) takes no step until the recorder, started seconds later, has matched a publisher on
    every ring topic: the bag then holds step 0 on all five. (Without the wait a reliable
    volatile reader matched late gets nothing of what went before: a recorder discovering
    the last-started node after the ring turned lost its first steps.)"""
    from tmgwr_common import topics
    params = tmp_path / "await.yaml"
    params.write_text("maze_sim:\n  ros__parameters:\n    await_recorder: true\n")
    up = RosProcess([str(ROOT / ".venv/bin/python"), "-m", "tmgwr_agent.cli", "up",
                     "--seed", "1", "--max-steps", "200", "--params-file", str(params),
                     "--no-record", "--domain-id", str(ros_domain)],
                    ros_env(ros_domain), name="up")
    bag = tmp_path / "late"
    with up:
        up.wait_for_line(r"waiting for a recorder on '/recorder_ready'", timeout=120)
        recorder = start_recorder(ros_domain, bag)
        with recorder:
            recorder.wait_for_line(r"matched a publisher on every expected topic \(5\)",
                                   timeout=60)
            up.wait_for_line(r"the recorder is ready", timeout=60)
            up.wait(timeout=240)
            recorder.stop()
    for name in topics.STEP_TOPICS:
        steps = read_step_ids(mcap_files(bag), "/" + name)
        assert steps and min(steps) == 0 and set(range(150)) <= set(steps), \
            (name, sorted(set(steps))[:5])


def test_a_ring_awaiting_the_recorder_holds_its_first_step_until_the_bag_has_it_all(
        ros_domain, tmp_path):
    """A recorder's matched reader does not prove that the publisher has matched it: under
    load a node's first messages can go out before its publisher knows the recorder (CI:
    a MiniGrid graph's bag lacked an /action step). Played here by an /action publisher
    that the recorder takes only after it said ready: it does not ``expect`` /action and
    the action selector starts once the recorder said ready, so the recorder subscribes to
    /action at its next discovery (2 s later) while the ring answers at once. The simulator
    holds the run's first step, resending it, until the recorder says on ``recorder_run``
    that it has the run on every ring topic, so the bag holds step 0 on all five."""
    from tmgwr_agent.nodes.recorder import GRAPH_STEP_TOPICS
    from tmgwr_common import topics
    early = [e for e in GRAPH_STEP_TOPICS if not e.startswith(f"{topics.ACTION}=")]
    bag = tmp_path / "late_action"
    procs = [start_recorder(ros_domain, bag, "discovery_period:=2.0",
                            "expect:=[" + ",".join(f"'{e}'" for e in early) + "]")]
    procs.append(ros2_run("maze_sim", "maze_sim", "--ros-args", "-p", "await_recorder:=true",
                          "-p", "max_steps:=100", "-p", "exit_when_done:=true",
                          domain=ros_domain))
    for name in ("sensory_preprocessor", "map_learner", "motivation_estimator"):
        procs.append(ros2_run("tmgwr_agent", name, domain=ros_domain))
    recorder, sim = procs[0], procs[1]
    try:
        recorder.wait_for_line(r"matched a publisher on every expected topic \(4\)",
                               timeout=120)
        sim.wait_for_line(r"the recorder is ready", timeout=60)
        procs.append(ros2_run("tmgwr_agent", "action_selector", domain=ros_domain))
        line = recorder.wait_for_line(r"run \d+ is in the bag on every ring topic \(5\)",
                                      timeout=120)
        assert "from step 0" in line, line
        sim.wait(timeout=120)
        recorder.stop()
    finally:
        stop_all(reversed(procs))
    assert "step 0 answered: held until the recorder has run" in sim.output, sim.output
    for name in topics.STEP_TOPICS:
        steps = read_step_ids(mcap_files(bag), "/" + name)
        assert steps and min(steps) == 0 and set(range(90)) <= set(steps), \
            (name, sorted(set(steps))[:5])
