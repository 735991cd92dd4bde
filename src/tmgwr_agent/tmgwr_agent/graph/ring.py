"""One member of an empty lockstep ring: the ceiling of the node graph's design.

The graph passes one message per step once around five processes (maze_sim ->
sensory_preprocessor -> map_learner -> motivation_estimator -> action_selector -> maze_sim).
A ring of N processes that only relay a step id, over the same middleware (Fast DDS, the
same profile and discovery range from tools/env.sh) with the same QoS as the graph's
per-step topics, bounds what any lockstep graph of N processes can reach here:
the graph's rate divided by the ring's rate is the share left to the algorithm.

Run one process per member (``python -m tmgwr_agent.graph.ring --index I --size N``);
member ``i`` subscribes to ``/ring/hop_i`` and publishes to ``/ring/hop_{(i+1) % N}``.
Every member prints ``ring member I ready`` once both ends of its hop have matched.
Member 0 drives: it sends probes until one comes back (the whole ring is matched), drains
stray probes, then runs ``--warmup`` laps and times ``--laps`` laps, and prints one line
``RING {json}`` (laps/s, hop time, lap-time percentiles) and exits; the relays run until
SIGINT. The spin loop is a persistent SingleThreadedExecutor, like the graph's nodes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

PROBE_BASE = 1 << 62       # probe ids live far above any lap id


def step_qos():
    """The QoS of the graph's per-step topics: the nodes' own ``STEP_QOS``
    (:mod:`tmgwr_common.node`), so the ring and the graph can never drift apart."""
    from tmgwr_common.node import STEP_QOS
    return STEP_QOS


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tmgwr_agent.graph.ring", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--index", type=int, required=True, help="member index 0..size-1")
    ap.add_argument("--size", type=int, required=True, help="number of processes in the ring")
    ap.add_argument("--laps", type=int, default=2000, help="timed laps (member 0)")
    ap.add_argument("--warmup", type=int, default=100, help="untimed laps first (member 0)")
    ap.add_argument("--timeout", type=float, default=60.0,
                    help="member 0 gives up after this many seconds")
    args = ap.parse_args(argv)
    if args.size < 2 or not 0 <= args.index < args.size:
        ap.error(f"need size >= 2 and 0 <= index < size "
                 f"(got index {args.index}, size {args.size})")
    if args.laps < 1 or args.warmup < 0:
        ap.error("--laps must be >= 1 and --warmup >= 0")

    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from std_msgs.msg import UInt64

    rclpy.init()
    node = rclpy.create_node(f"ring_{args.index}")
    qos = step_qos()
    pub = node.create_publisher(UInt64, f"/ring/hop_{(args.index + 1) % args.size}", qos)
    out = UInt64()
    state = {"expect": None, "count": 0, "t0": 0.0, "laps": [], "t_last": 0.0,
             "returned_probe": False, "done": False}

    if args.index == 0:
        total = args.warmup + args.laps

        def on_msg(msg: UInt64) -> None:
            if msg.data >= PROBE_BASE:          # a probe made it round: the ring is matched
                state["returned_probe"] = True
                return
            if state["expect"] is None or msg.data != state["expect"]:
                return                          # a stray (should not happen after draining)
            now = time.perf_counter()
            k = msg.data
            if k == args.warmup:                # end of warm-up: the timed part starts
                state["t0"] = now
            elif k > args.warmup:
                state["laps"].append(now - state["t_last"])
            state["t_last"] = now
            if k >= total:
                state["done"] = True
                return
            state["expect"] = k + 1
            out.data = k + 1
            pub.publish(out)
    else:
        def on_msg(msg: UInt64) -> None:        # relay: forward the step id unchanged
            pub.publish(msg)

    sub = node.create_subscription(UInt64, f"/ring/hop_{args.index}", on_msg, qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    rc = 0
    try:
        announced = False
        deadline = time.monotonic() + args.timeout
        probe = PROBE_BASE
        next_probe = 0.0
        while rclpy.ok():
            matched = pub.get_subscription_count() > 0 and sub.get_publisher_count() > 0
            if not announced and matched:
                print(f"ring member {args.index} ready", flush=True)
                announced = True
            if args.index == 0:
                if time.monotonic() > deadline:
                    print(f"ring member 0: no result within {args.timeout} s "
                          f"(probe back: {state['returned_probe']}, laps: {len(state['laps'])})",
                          file=sys.stderr, flush=True)
                    rc = 1
                    break
                if state["expect"] is None and announced:
                    if not state["returned_probe"]:
                        if time.monotonic() >= next_probe:
                            probe += 1
                            out.data = probe
                            pub.publish(out)
                            next_probe = time.monotonic() + 0.2
                    else:                       # drain probes still travelling, then start
                        end = time.monotonic() + 0.5
                        while time.monotonic() < end:
                            executor.spin_once(timeout_sec=0.05)
                        state["expect"] = 1
                        state["t_last"] = time.perf_counter()
                        out.data = 1
                        pub.publish(out)
                if state["done"]:
                    elapsed = state["t_last"] - state["t0"]
                    laps = sorted(state["laps"])
                    pct = lambda q: laps[min(len(laps) - 1, int(q * len(laps)))] * 1e3  # noqa: E731
                    print("RING " + json.dumps({
                        "processes": args.size, "laps": args.laps,
                        "seconds": round(elapsed, 4),
                        "laps_per_s": round(args.laps / elapsed, 1),
                        "hop_ms": round(elapsed / args.laps / args.size * 1e3, 4),
                        "lap_ms_p50": round(pct(0.5), 4), "lap_ms_p99": round(pct(0.99), 4),
                    }), flush=True)
                    break
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return rc


if __name__ == "__main__":
    sys.exit(main())
