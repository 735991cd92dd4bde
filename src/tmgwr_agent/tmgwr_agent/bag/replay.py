"""``./tmgwr replay BAG [--rate R] [--topics ...] [--loop]``: play a recording back live.

The recorded CDR bytes are published unchanged (``Publisher.publish(bytes)``, no
deserialization), each on a publisher with the QoS its original publisher offered
(``offered_qos_profiles`` of the channel, so latched topics are latched again), at the
original pace: message ``k`` goes out ``(log_time_k - log_time_0) / R`` seconds after the
first. Nodes, the recorder and Foxglove see the run again.

Message order (``--message-order``, as rosbag2's ``ros2 bag play`` names it): ``received``
(default) plays in the order the recorder received the messages (log time); ``sent`` in
the order their publishers sent them (publish time, the writer's source timestamp), paced
by it. Across topics the two differ: the recorder takes its subscriptions one after the
other, so it may receive a step's ``/action`` before the ``/sensorimotor_state`` that caused
it. A node that follows the lockstep ring (the motivation estimator holds a state until the
previous step's action) needs the causal order: ``sent``, exact when the graph ran on one
host (one clock) and no message reached the recorder more than ``SENT_WINDOW`` seconds after
it was sent.

The map travels as per-step changes (``/sensorimotor_state``) that a consumer applies to a
replica starting from a whole map (:mod:`tmgwr_agent.map_replica`): a replay that selects
``/sensorimotor_state`` also plays ``/sensorimotor_snapshot`` (latched again), so a
consumer rebuilds the map from the recording as it did live.

The offered QoS recorded from DDS discovery carries no history depth (``history: unknown``,
``depth: 0``, as rosbag2 records it too); we publish latched topics with depth 1 (a late
joiner gets the newest sample, as from the original latched publisher) and the others with
depth 100 (enough for bursts).
"""

from __future__ import annotations

import heapq
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import yaml
from mcap.reader import make_reader

from tmgwr_agent.bag import definitions
from tmgwr_agent.bag import qos as bag_qos
from tmgwr_agent.bag.recover import require_finished
from tmgwr_common.topics import GraphNames

LATCHED_DEPTH = 1
STREAM_DEPTH = 100
ORDERS = ("received", "sent")
SENT_WINDOW = 10.0   # s: how long after its sending a message may arrive and stay in order


@dataclass
class Channel:
    topic: str
    type: str
    offered_qos: list[dict]


def bag_files(bag: str | Path) -> list[Path]:
    """The ``.mcap`` files of a bag: the file itself, or a directory's files in order."""
    bag = Path(bag)
    if bag.is_file():
        return [bag]
    if not bag.is_dir():
        raise FileNotFoundError(f"{bag} does not exist")
    meta = bag / "metadata.yaml"
    if meta.is_file():
        info = yaml.safe_load(meta.read_text())["rosbag2_bagfile_information"]
        files = [bag / p for p in info.get("relative_file_paths", [])]
        missing = [str(f) for f in files if not f.is_file()]
        if missing:
            raise FileNotFoundError(f'{meta} lists missing files: {", ".join(missing)}')
        return files
    files = sorted(bag.glob("*.mcap"))
    if not files:
        raise FileNotFoundError(f"{bag} holds no .mcap file")
    return files


def read_channels(files: list[Path]) -> dict[str, Channel]:
    channels: dict[str, Channel] = {}
    for path in files:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        if summary is None:
            raise ValueError(f"{path} has no summary (unfinished recording?): "
                             f"run ./tmgwr recover {path} first")
        for ch in summary.channels.values():
            if ch.topic not in channels:
                schema = summary.schemas[ch.schema_id]
                channels[ch.topic] = Channel(
                    ch.topic, schema.name,
                    bag_qos.load_profiles(ch.metadata.get("offered_qos_profiles", "")))
    return channels


def iter_messages(files: list[Path], topics: set[str] | None,
                  order: str = "received") -> Iterator[tuple[str, int, bytes]]:
    """``(topic, time, data)``, file after file: ``received``, the log time in log-time
    order; ``sent``, the publish time in publish-time order (read in log-time order and
    held back ``SENT_WINDOW`` s: a message sent before the log time of what was read
    minus the window comes out, smallest publish time first)."""
    if order not in ORDERS:
        raise ValueError(f"message order {order!r}: one of {', '.join(ORDERS)}")
    window = int(SENT_WINDOW * 1e9)
    for path in files:
        held: list[tuple[int, int, str, bytes]] = []     # (publish_time, n, topic, data)
        with open(path, "rb") as f:
            reader = make_reader(f)
            for n, (_schema, channel, message) in enumerate(reader.iter_messages(
                    topics=sorted(topics) if topics else None, log_time_order=True)):
                if order == "received":
                    yield channel.topic, message.log_time, bytes(message.data)
                    continue
                heapq.heappush(held, (message.publish_time, n, channel.topic,
                                      bytes(message.data)))
                while held and held[0][0] < message.log_time - window:
                    sent, _, topic, data = heapq.heappop(held)
                    yield topic, sent, data
        while held:
            sent, _, topic, data = heapq.heappop(held)
            yield topic, sent, data


def replay_qos(offered: list[dict]):
    """Publisher QoS for a replayed topic from the recorded offered profiles."""
    profile = dict(offered[0]) if offered else {"reliability": "reliable",
                                                 "durability": "volatile"}
    latched = profile.get("durability") == "transient_local"
    if not profile.get("depth") or profile.get("history") in (None, "unknown",
                                                              "system_default"):
        profile["history"] = "keep_last"
        profile["depth"] = LATCHED_DEPTH if latched else STREAM_DEPTH
    return bag_qos.dict_to_profile(profile)


def replay(bag: str | Path, rate: float = 1.0, topics: list[str] | None = None,
           loop: bool = False, delay: float = 1.0, wait_subscribers: int = 0,
           wait_timeout: float = 10.0, linger: float = 1.0, order: str = "received",
           log=print) -> dict:
    """Publish the recording in ``order`` (:data:`ORDERS`); returns ``{"published": n,
    "loops": k, "seconds": s}``."""
    import rclpy
    from rclpy.executors import ExternalShutdownException

    if not rate > 0:
        raise ValueError(f"--rate must be > 0 (got {rate})")
    if order not in ORDERS:
        raise ValueError(f"--message-order {order!r}: one of {', '.join(ORDERS)}")
    files = bag_files(bag)
    require_finished(bag, files)             # a killed recorder's bag: recover it first
    channels = read_channels(files)
    wanted = None
    if topics:
        wanted = {t if t.startswith("/") else "/" + t for t in topics}
        unknown = sorted(wanted - set(channels))
        if unknown:
            raise ValueError(f'topics not in {bag}: {", ".join(unknown)} '
                             f'(recorded: {", ".join(sorted(channels))})')
        T = GraphNames.of_bag(channels)     # the recorded graph's names (its namespace)
        if T.SENSORIMOTOR_STATE in wanted and T.MAP_SNAPSHOT in channels \
                and T.MAP_SNAPSHOT not in wanted:
            wanted.add(T.MAP_SNAPSHOT)      # what the map changes start from
            log(f"replay: also {T.MAP_SNAPSHOT}: the map changes of "
                f"{T.SENSORIMOTOR_STATE} start from its whole maps")
    selected = {t: c for t, c in channels.items() if wanted is None or t in wanted}
    published, loops = 0, 0
    rclpy.init()
    node = rclpy.create_node("replay", enable_rosout=False)
    try:
        pubs = {t: node.create_publisher(definitions.import_message(c.type), t,
                                         replay_qos(c.offered_qos))
                for t, c in selected.items()}
        log(f'replay: {len(pubs)} topics from {", ".join(str(f) for f in files)} at rate {rate}, '
            f'in the order {order}')
        time.sleep(delay)
        if wait_subscribers > 0:
            deadline = time.monotonic() + wait_timeout
            while any(p.get_subscription_count() < wait_subscribers for p in pubs.values()):
                if time.monotonic() > deadline:
                    short = [t for t, p in pubs.items()
                             if p.get_subscription_count() < wait_subscribers]
                    raise TimeoutError(f'no {wait_subscribers} subscriber(s) within '
                                       f'{wait_timeout} s on {", ".join(short)}')
                time.sleep(0.05)
        started = time.monotonic()
        while True:
            t0_bag = None
            t0_wall = time.monotonic()
            for topic, bag_time, data in iter_messages(files, set(selected), order):
                if t0_bag is None:
                    t0_bag = bag_time
                target = t0_wall + (bag_time - t0_bag) / 1e9 / rate
                while True:
                    left = target - time.monotonic()
                    if left <= 0:
                        break
                    # sleep most of the wait, spin the last 0.5 ms for a precise send time
                    time.sleep(left - 0.0005 if left > 0.001 else 0)
                pubs[topic].publish(data)
                published += 1
            loops += 1
            if not loop or t0_bag is None:
                break
        seconds = time.monotonic() - started
        log(f"replay: published {published} messages in {seconds:.3f} s ({loops} pass(es))")
        time.sleep(linger)           # let reliable / latched samples reach late readers
    except (KeyboardInterrupt, ExternalShutdownException):
        seconds = time.monotonic() - started if "started" in locals() else 0.0
        log(f"replay: interrupted after {published} messages")
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return {"published": published, "loops": loops, "seconds": seconds}
