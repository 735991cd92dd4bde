"""Per-message decode and encode time of the ring's messages: ``tmgwr_common.cdr`` against
rosbags' serde (a pinned dependency) and rclpy's own (de)serialization, with the bytes
compared both ways (what docs/graph.md, Topics and services, says about the choice). Run it from
the repository root on a recording (any ``./tmgwr up`` run directory, or one ``.mcap``)::

    source tools/env.sh && python test/measure_cdr.py runs/<stamp> [--rounds 9]

The samples are the recorded bytes of each per-step topic (the last 500) and of the
snapshots (all). Each round times every codec on every type (the order reversed every
other round, so a change of the machine's load falls on all of them); the figure is the
median over the rounds of one pass over the samples divided by their number, in µs.
``mcap_ros2_support_fast`` is timed as well when it can be imported (it is not a
dependency: GPL-3.0). Not collected by pytest (test_cdr.py checks the bytes).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import timeit
from collections import defaultdict
from pathlib import Path

from mcap.reader import make_reader
from rclpy.serialization import deserialize_message, serialize_message
from test_cdr import rosbags_typestore

from tmgwr_common.cdr import codec
from tmgwr_interfaces.msg import (
    Action,
    Features,
    MotivationField,
    Observation,
    SensorimotorSnapshot,
    SensorimotorState,
)

TOPICS = {"/observation": Observation, "/features": Features,
          "/sensorimotor_state": SensorimotorState, "/motivation": MotivationField,
          "/action": Action, "/sensorimotor_snapshot": SensorimotorSnapshot}


def recorded(path: Path):
    """Per topic the recorded bytes (the last 500) and the channel's schema."""
    samples, schemas = defaultdict(list), {}
    for bag in sorted(path.glob("*.mcap")) if path.is_dir() else [path]:
        with open(bag, "rb") as f:
            for schema, channel, message in make_reader(f).iter_messages(topics=list(TOPICS)):
                samples[channel.topic].append(message.data)
                schemas[channel.topic] = schema
    return {t: b[-500:] for t, b in samples.items()}, schemas


def codecs(store, topic: str, msg_type, data: list[bytes], schema) -> dict:
    """(what, codec) -> a function doing it for every sample."""
    name = f"tmgwr_interfaces/msg/{msg_type.__name__}"
    c = codec(msg_type)
    ours = [c.decode(b) for b in data]
    theirs = [store.deserialize_cdr(b, name) for b in data]
    rclpy_msgs = [deserialize_message(b, msg_type) for b in data]
    ops = {
        ("decode", "cdr.py"): lambda: [c.read(b) for b in data],
        ("decode", "rosbags"): lambda: [store.deserialize_cdr(b, name) for b in data],
        ("decode", "rclpy"): lambda: [deserialize_message(b, msg_type) for b in data],
        ("encode", "cdr.py"): lambda: [c.encode(m) for m in ours],
        ("encode", "rosbags"): lambda: [bytes(store.serialize_cdr(m, name)) for m in theirs],
        ("encode", "rclpy"): lambda: [serialize_message(m) for m in rclpy_msgs],
    }
    try:
        from mcap_ros2_support_fast.decoder import DecoderFactory
        from mcap_ros2_support_fast.writer import ROS2EncoderFactory
    except ImportError:
        return ops
    dec = DecoderFactory().decoder_for("cdr", schema)
    enc = ROS2EncoderFactory().encoder_for(schema)
    ops[("decode", "mcap_ros2_support_fast")] = lambda: [dec(b) for b in data]
    ops[("encode", "mcap_ros2_support_fast")] = lambda: [bytes(enc(m)) for m in theirs]
    return ops


def mismatches(store, msg_type, data: list[bytes]) -> int:
    """Samples on which rosbags and cdr.py / rclpy disagree: rosbags' bytes equal cdr.py's
    and read back with rclpy as the same message; rclpy's bytes read with rosbags give
    the same bytes again."""
    name = f"tmgwr_interfaces/msg/{msg_type.__name__}"
    c, msgdef = codec(msg_type), store.get_msgdef(name)
    bad = 0
    for b in data:
        out = bytes(store.serialize_cdr(store.deserialize_cdr(b, name), name))
        bad += out != c.encode(c.decode(b))
        bad += deserialize_message(out, msg_type) != deserialize_message(b, msg_type)
        # serialize_message leaves up to 12 unused bytes after the last field (its size
        # estimate), which deserialize_cdr refuses as a size mismatch: read them directly
        theirs = serialize_message(deserialize_message(b, msg_type))
        m, _ = msgdef.deserialize_cdr_le(memoryview(theirs)[4:], 0, msgdef.cls, store)
        bad += bytes(store.serialize_cdr(m, name)) != out
    return bad


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recording", type=Path, help="a run directory or an .mcap file")
    ap.add_argument("--rounds", type=int, default=9)
    args = ap.parse_args()
    samples, schemas = recorded(args.recording)
    if not samples:
        print(f"no per-step topic in {args.recording}", file=sys.stderr)
        return 1
    store = rosbags_typestore()
    ops = {t: codecs(store, t, TOPICS[t], samples[t], schemas[t]) for t in samples}
    print("mismatches:", {t: mismatches(store, TOPICS[t], samples[t]) for t in samples})
    times = defaultdict(list)
    for r in range(args.rounds):
        for topic in (list(ops) if r % 2 == 0 else list(reversed(ops))):
            items = list(ops[topic].items())
            for key, fn in (items if r % 2 == 0 else reversed(items)):
                n = len(samples[topic])
                reps = max(1, 2000 // n)
                times[(topic, *key)].append(timeit.timeit(fn, number=reps) / reps / n * 1e6)
    load = os.getloadavg()
    print(f"load {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} after {args.rounds} rounds; "
          "median us a message (x cdr.py)")
    for topic in ops:
        size = statistics.median(len(b) for b in samples[topic])
        print(f"{topic} ({len(samples[topic])} messages, median {size:.0f} B)")
        for what in ("decode", "encode"):
            base = statistics.median(times[(topic, what, "cdr.py")])
            cells = [f"{lib} {statistics.median(v):.2f} (x{statistics.median(v) / base:.2f})"
                     for (t, w, lib), v in times.items() if (t, w) == (topic, what)]
            print(f"    {what}: " + ", ".join(cells))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
