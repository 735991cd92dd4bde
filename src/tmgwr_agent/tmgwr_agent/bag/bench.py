"""Recorder throughput for ``./tmgwr bench``: the highest lossless rate (msg/s).

Two real processes in a ROS domain of their own: the ``tmgwr_agent recorder`` node and a
publisher sending ``tmgwr_interfaces/Observation`` messages (reliable, keep-last 10, the
graph's per-step QoS) with consecutive step ids at a fixed target rate. After each run the
bag is read back and the step ids counted: a rate is *lossless* when every published
message is in the file. Rates double from ``start`` until a run loses messages (or the
publisher cannot reach the target); the result is the last lossless achieved rate, beside
the per-run figures (one bisection step refines the
first failing doubling). The graph's own rate (``graph`` part of bench.json) is the number to
compare it with: the graph publishes about six messages per step.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

PUBLISHER = r"""
import sys, time
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from tmgwr_interfaces.msg import Observation
n, rate = int(sys.argv[1]), float(sys.argv[2])
rclpy.init()
node = rclpy.create_node('bench_publisher')
pub = node.create_publisher(Observation, '/bench_observation',
                            QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
deadline = time.monotonic() + 20
while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
    time.sleep(0.02)
time.sleep(0.3)
m = Observation(sensors=[0.0] * 8, goal_sensors=[0.0] * 8)
t0 = time.perf_counter()
for i in range(n):
    m.step_id = i
    pub.publish(m)
    target = t0 + (i + 1) / rate
    while time.perf_counter() < target:
        pass
dt = time.perf_counter() - t0
print('PUBLISHED %d %.4f' % (n, dt), flush=True)
time.sleep(1.0)
node.destroy_node(); rclpy.shutdown()
"""


def _count(bag: Path) -> int:
    from rosbags.highlevel import AnyReader
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == "/bench_observation"]
        ids = {reader.deserialize(raw, c.msgtype).step_id
               for c, _t, raw in reader.messages(connections=conns)}
    return len(ids)


class RecorderBenchError(RuntimeError):
    """A run of the recorder bench that measured nothing; the message says why, with the
    recorder's exit code and output."""


READY_LINE = re.compile(r"\brecording\b.* to ")


def run_once(rate: float, seconds: float, domain: int, workdir: Path,
             compression: str = "zstd", ready_timeout: float = 60.0) -> dict:
    """One recorder + publisher run at ``rate`` msg/s for about ``seconds``.

    The publisher starts only once the recorder said it records (its writer is open): a
    SIGINT that reaches a recorder still starting up (rclpy not yet handling signals)
    kills it without a bag, which is how ``the recorder wrote no bag at .../rate_16000``
    came about when it started slowly. Its output is read while it runs (a full pipe
    would stall it mid-measure) and every way a run can fail raises
    :class:`RecorderBenchError` naming the rate, the exit code and the output."""
    n = max(100, int(rate * seconds))
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED="1")
    bag = workdir / f"rate_{int(rate)}"
    rec = subprocess.Popen([sys.executable, "-m", "tmgwr_agent.nodes.recorder", "--ros-args",
                            "-p", f"output_dir:={bag}", "-p", "topics:=[/bench_observation]",
                            "-p", f"compression:={compression}", "-p", "discovery_period:=0.1"],
                           env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                           start_new_session=True)
    lines: list[str] = []
    ready = threading.Event()

    def read() -> None:
        assert rec.stdout is not None
        for line in rec.stdout:
            lines.append(line.rstrip("\n"))
            if READY_LINE.search(line):
                ready.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()

    def fail(why: str) -> RecorderBenchError:
        reader.join(timeout=5)
        return RecorderBenchError(f"recorder bench at {rate:.0f} msg/s: {why} (recorder exit "
                                  f"code {rec.poll()}); its output:\n" + "\n".join(lines))

    pub = None
    try:
        deadline = time.monotonic() + ready_timeout
        while not ready.wait(0.1):
            if rec.poll() is not None:
                raise fail("the recorder exited during start-up")
            if time.monotonic() > deadline:
                raise fail(f"the recorder was not recording within {ready_timeout:.0f} s")
        pub = subprocess.run([sys.executable, "-c", PUBLISHER, str(n), str(rate)], env=env,
                             capture_output=True, text=True, timeout=60 + seconds * 3)
    finally:
        time.sleep(0.5)
        try:
            os.killpg(rec.pid, signal.SIGINT)
            rec.wait(timeout=30)
        except subprocess.TimeoutExpired:
            os.killpg(rec.pid, signal.SIGKILL)
            rec.wait()
            raise fail("the recorder did not finish within 30 s of SIGINT") from None
        except ProcessLookupError:
            pass
        reader.join(timeout=5)
    m = re.search(r"PUBLISHED (\d+) ([\d.]+)", pub.stdout)
    if not m:
        raise fail(f"the bench publisher failed:\n{pub.stdout}\n{pub.stderr}")
    published, dt = int(m.group(1)), float(m.group(2))
    if not (bag / "metadata.yaml").is_file():
        raise fail(f"the recorder wrote no bag at {bag}")
    recorded = _count(bag)
    return {"target_rate": rate, "published": published,
            "achieved_rate": round(published / dt, 1), "recorded": recorded,
            "lossless": recorded == published, "recorder_rc": rec.returncode}


def _reserve_domain() -> tuple[int, int]:
    """A ROS_DOMAIN_ID nobody else uses: the flock'ed files of test/ros_helpers.py
    (``$TMPDIR/tmgwr-ros-domains/<id>.lock``), so the bench and running tests never meet."""
    import fcntl
    lock_dir = Path(tempfile.gettempdir()) / "tmgwr-ros-domains"
    lock_dir.mkdir(parents=True, exist_ok=True)
    own = os.environ.get("ROS_DOMAIN_ID", "0")
    for domain in range(101, 0, -1):
        if str(domain) == own:
            continue
        fd = os.open(lock_dir / f"{domain}.lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return domain, fd
        except OSError:
            os.close(fd)
    raise RuntimeError("no free ROS_DOMAIN_ID in 1..101 for the recorder bench")


def run(args=None) -> dict:
    """The ``bag`` part of results/bench.json."""
    start = float(getattr(args, "bag_start_rate", None) or 1000)
    seconds = float(getattr(args, "bag_seconds", None) or 2.0)
    domain, lock = _reserve_domain()
    runs: list[dict] = []
    best = error = None
    try:
        best = _sweep(start, seconds, domain, runs)
    except RecorderBenchError as exc:    # kept with the runs measured so far, and said
        error = str(exc)
        print(f"bench: {exc}", file=sys.stderr, flush=True)
    finally:
        os.close(lock)
    return {
        **({"error": error} if error else {}),
        "recorder_lossless_msg_per_s": best,
        # to compare with graph.graph_steps_per_s: the recorder must take 5 messages a step
        "graph_messages_per_step": 5,
        "cpus": os.cpu_count(),
        "load_avg_1min": round(os.getloadavg()[0], 2),
        "method": f"one publisher process, reliable Observation messages, {seconds:g} s per "
                  f"rate, rates doubling from {start:g} (then one bisection step); "
                  f"lossless = every step id in the bag. The graph publishes 5 "
                  f"messages per lockstep step (observation, features, state, motivation, "
                  f"action) plus the pose and map topics at fixed rates",
        "runs": runs,
    }


def _sweep(start: float, seconds: float, domain: int, runs: list) -> float | None:
    best = None
    with tempfile.TemporaryDirectory(prefix="tmgwr-bag-bench-") as tmp:
        rate = start
        while rate <= 64000:
            print(f"bench: recorder at {rate:.0f} msg/s ...", file=sys.stderr, flush=True)
            r = run_once(rate, seconds, domain, Path(tmp))
            runs.append(r)
            if not r["lossless"]:
                break
            best = r["achieved_rate"]
            if r["achieved_rate"] < 0.9 * rate:      # the publisher is the limit now
                break
            rate *= 2
        if runs and not runs[-1]["lossless"] and best is not None:
            mid = (best + runs[-1]["target_rate"]) / 2  # one bisection step between the two
            print(f"bench: recorder at {mid:.0f} msg/s ...", file=sys.stderr, flush=True)
            r = run_once(mid, seconds, domain, Path(tmp))
            runs.append(r)
            if r["lossless"]:
                best = r["achieved_rate"]
    return best


if __name__ == "__main__":
    import json
    print(json.dumps(run(), indent=2))
