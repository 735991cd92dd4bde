"""Reproduce, without this project, why a /features subscription made at ``activate`` took
~10 s to get a message in the composed graph (docs/graph.md, The map learner's lifecycle).

One process, one DDS participant (Fast DDS through rmw_fastrtps, as the Jazzy wheels ship
it), one SingleThreadedExecutor, std_msgs/UInt64 on a topic with the graph's per-step QoS
(reliable, volatile, keep-last DEPTH). A writer and a reader of another node exchange
SAMPLES messages in lockstep; then a new reader is created (from a timer callback while the
executor spins, as a lifecycle transition does) and the writer writes one message every
PERIOD s (as maze_sim's resends drive a waiting ring). Printed: how many writes the new
reader needed before it got one.

    source tools/env.sh
    python test/repro_late_reader.py --samples 1000     # below max_samples: 1 write
    python test/repro_late_reader.py --samples 6000     # above: about depth + 1 writes
    python test/repro_late_reader.py --samples 6000 --depth 3
    python test/repro_late_reader.py --samples 6000 --other-process   # not affected

Measured here (Fast DDS 2.14.5, rmw_fastrtps 8.4.3, rclpy 7.1.6): 1 write at 1000 and 4500
samples, 11 writes at 6000 (depth 10), 4 at 6000 with depth 3, the same with the project's
profile (tools/fastdds_localhost.xml) or none; 1 write at 6000 when the process
runs with a Fast DDS profile (FASTRTPS_DEFAULT_PROFILES_FILE) that either raises the
data_reader's resourceLimitsQos max_samples (default 5000) or sets the library's
intraprocess_delivery to OFF. The reader refuses the samples while it counts more than
max_samples changes it has not been told about (DataReaderHistory::can_change_be_added_nts).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=int, default=6000, help="written before the new reader")
    ap.add_argument("--depth", type=int, default=10, help="keep-last depth of both ends")
    ap.add_argument("--period", type=float, default=0.3, help="seconds between later writes")
    ap.add_argument("--other-process", action="store_true",
                    help="create the new reader in a child process (another participant)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        return late_reader_process(a.depth)

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import UInt64

    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=a.depth,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    rclpy.init()
    ex = SingleThreadedExecutor()
    writer, old, new = Node("repro_writer"), Node("repro_reader"), Node("repro_late_reader")
    for node in (writer, old, new):
        ex.add_node(node)
    pub = writer.create_publisher(UInt64, "repro_late_reader", qos)
    got_old: list[int] = []
    got_new: list[int] = []
    old.create_subscription(UInt64, "repro_late_reader", lambda m: got_old.append(m.data), qos)
    seq = 0
    for _ in range(a.samples):                 # lockstep: each taken before the next
        seq += 1
        pub.publish(UInt64(data=seq))
        n, deadline = len(got_old), time.monotonic() + 1.0
        while len(got_old) == n and time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.1)

    def subscribe():
        new.create_subscription(UInt64, "repro_late_reader",
                                lambda m: got_new.append(m.data), qos)
        timer.cancel()

    child = None
    if a.other_process:                        # matched once discovery is through
        child = subprocess.Popen([sys.executable, __file__, "--child", "--depth",
                                  str(a.depth)], stdout=subprocess.PIPE, text=True)
        while pub.get_subscription_count() < 2:
            ex.spin_once(timeout_sec=0.05)
    else:
        timer = new.create_timer(0.01, subscribe)
    for _ in range(5):
        ex.spin_once(timeout_sec=0.05)
    created, writes = time.monotonic(), 0
    while not got_new and writes < 3 * a.depth + 5:
        seq += 1
        writes += 1
        pub.publish(UInt64(data=seq))
        deadline = time.monotonic() + a.period
        while time.monotonic() < deadline:
            ex.spin_once(timeout_sec=0.02)
        if child is not None and child.poll() is not None:
            got_new.append(int(child.stdout.read().split()[-1]))
    profile = os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE", "none")
    where = "in another process" if a.other_process else "in this process"
    print(f"{a.samples} samples written (the old reader got {len(got_old)}), depth {a.depth}, "
          f"Fast DDS profile {profile}: the new reader ({where}) "
          + (f"got sample {got_new[0]} after {writes} writes "
             f"({time.monotonic() - created:.2f} s)" if got_new else
             f"got nothing in {writes} writes"), flush=True)
    if child is not None and child.poll() is None:
        child.kill()
    ex.shutdown()
    rclpy.try_shutdown()


def late_reader_process(depth: int) -> None:
    """--child: subscribe, print the first value received, exit."""
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import UInt64

    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    rclpy.init()
    node = Node("repro_late_reader_elsewhere")
    got: list[int] = []
    node.create_subscription(UInt64, "repro_late_reader", lambda m: got.append(m.data), qos)
    while not got:
        rclpy.spin_once(node, timeout_sec=0.1)
    print(got[0], flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
