"""``ros2 run tmgwr_agent recorder``: record the graph's topics to a rosbag2/MCAP bag.

rosbag2 is not installable from the registries here, so the project records itself.
The node subscribes to every topic (or the ``topics`` list) with
*raw* subscriptions, which hand over the CDR bytes as they came off the wire, and writes
those bytes unchanged with :class:`tmgwr_agent.bag.writer.BagWriter` (no second
serialization). New topics are discovered every ``discovery_period`` seconds; the ring's
per-step topics (``expect``) are subscribed at start, before their publishers exist, so the
first step of a starting graph is recorded on every topic.

Throughput: the executor's per-message round trip (wait set, task) is what limits an rclpy
recorder; each callback therefore also takes whatever else is queued on its subscription
(``drain_max``), which raises the rate it records without loss (``./tmgwr bench``, part
``bag``).

QoS: each topic is subscribed with a profile compatible with all its publishers
(:func:`tmgwr_agent.bag.qos.subscription_qos`): reliable when they all are, transient local
when they all are (so latched messages published before the recorder joined are recorded),
and a history of at least ``queue_depth`` so a momentarily busy recorder loses nothing.
The latched whole-map snapshots (``/sensorimotor_snapshot``) and potentials
(``/potentials``) are therefore left to discovery, not ``expect``ed: subscribed transient
local, a recorder that joins late still records the newest whole map, which the per-step
map changes of ``/sensorimotor_state`` build on (``./tmgwr report`` rebuilds the map).

Ready: once every expected topic it records has a matched publisher, the recorder says so,
latched, on ``recorder_ready`` (std_msgs/String: the bag's directory; not recorded itself).
A simulator started with ``await_recorder`` publishes its first observation only then:
``./tmgwr up`` and the launch file set it whenever they record, so no step of the ring
goes by before the recorder could take it (a reliable volatile reader matched late gets
nothing of what was published before). A graph node that starts after the recorder's
discovery of the others is the race this closes.

Run recorded: a matched reader does not prove that the publisher has matched it (each side
of discovery runs at its own pace: under load a publisher's first messages can go out
before it knows the recorder, and a volatile reader never gets them). Once every ring topic
it records (``gap_topics`` in its own namespace) has a message of a run, the recorder says
so, latched, on ``recorder_run`` (std_msgs/UInt64: the run id; 0 at start when it records
none of them). A simulator with ``await_recorder`` holds its run's first step, resending
it, until then; the ring answers a resend from its cache, so what was missed is recorded.

Gaps: on the per-step topics (``gap_topics``: the ring's five, and the same names and types
in any namespace below the recorder's, each topic on its own) every message's (run_id,
step_id) is read from its bytes (:mod:`tmgwr_agent.bag.gaps`); a step id that jumps ahead
is logged at once as a gap naming the missing steps, and at the end each topic's steps,
resends and gaps are logged and stored in the bag's metadata (``custom_data.step_gaps``,
JSON). A recorder that falls behind (paused, starved of CPU) loses what its publishers'
keep-last history no longer holds, and says exactly which steps.

Shutdown: SIGINT and SIGTERM stop the loop (tmgwr_common.node.run); whatever is still
queued on the subscriptions is taken and written, then the bag is finished (summary,
indexes, metadata.yaml) and the received and written counts and the gaps are logged per
topic. A recorder killed outright leaves at most ``flush_period`` seconds unflushed;
``./tmgwr recover`` makes such a file valid again.
"""

from __future__ import annotations

import json
import re
import time
from datetime import datetime, timezone
from pathlib import Path

from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String, UInt64

from tmgwr_agent.bag import definitions
from tmgwr_agent.bag import qos as bag_qos
from tmgwr_agent.bag.gaps import StepGaps
from tmgwr_agent.bag.writer import COMPRESSIONS, BagWriter, TopicInfo
from tmgwr_common import topics
from tmgwr_common.node import LATCHED_QOS, NODE_OPTIONS, declare_parameters, run
from tmgwr_common.params import Param

_BIG = 2 ** 62

# The per-step topics of the lockstep ring (tmgwr_common.topics, all reliable volatile: STEP_QOS of
# tmgwr_common.node). A node publishes its first message as soon as the ring turns, possibly before
# periodic discovery has seen its publisher; subscribing to these at start (the ``expect``
# parameter) means the recorder is matched as soon as DDS discovers the publisher, so step 0 is
# recorded on every topic.
GRAPH_STEP_TOPICS = (
    f"{topics.OBSERVATION}=tmgwr_interfaces/msg/Observation",
    f"{topics.FEATURES}=tmgwr_interfaces/msg/Features",
    f"{topics.SENSORIMOTOR_STATE}=tmgwr_interfaces/msg/SensorimotorState",
    f"{topics.MOTIVATION}=tmgwr_interfaces/msg/MotivationField",
    f"{topics.ACTION}=tmgwr_interfaces/msg/Action",
)


#: The recorder's parameters (read-only ROS parameters, declared like every node's).
SPECS = (
    Param("output_dir", "", "bag directory; empty: runs/<UTC timestamp>/"),
    Param("topics", ("",), "topics to record (relative names resolve in the recorder's "
          "namespace); empty: all of its namespace (discovered periodically)"),
    Param("exclude", "", "regular expression of topics not to record"),
    Param("compression", "zstd", "chunk compression", choices=tuple(COMPRESSIONS)),
    Param("chunk_size", 1 << 20, "uncompressed chunk size in bytes", low=1024, high=1 << 30,
          integer=True),
    Param("max_bag_size", 0, "split into a new file at this size in bytes (0: never)",
          low=0, high=_BIG, integer=True),
    Param("max_bag_duration", 0.0, "split into a new file after this many seconds "
          "(0: never)", low=0.0, high=1e9),
    Param("discovery_period", 0.2, "seconds between topic discoveries", low=0.05,
          high=60.0),
    Param("flush_period", 0.2, "seconds between flushes of the open chunk to disk (bounds "
          "what a kill -9 loses; 0: only full chunks)", low=0.0, high=3600.0),
    Param("queue_depth", 1000, "minimum subscription history depth", low=1, high=1000000,
          integer=True),
    Param("expect", GRAPH_STEP_TOPICS, "topics (NAME=pkg/msg/Type) subscribed at start, "
          "reliable and volatile, before any publisher is seen, so their first messages "
          "are not missed (only those the topics/exclude parameters record)"),
    Param("drain_max", 100, "messages taken directly after each callback before returning "
          "to the executor (0: one per callback)", low=0, high=100000, integer=True),
    Param("gap_topics", tuple(name for name, _ in (e.split("=") for e in GRAPH_STEP_TOPICS)),
          "per-step topics (Header, run_id, step_id first) whose step ids are checked for "
          "gaps as they arrive (relative names resolve in the recorder's namespace)"),
)
GAP_WARN_PERIOD = 2.0       # seconds between two gap warnings of one topic


def default_output_dir(now: datetime | None = None) -> Path:
    """``runs/<UTC timestamp>/`` relative to the working directory."""
    now = now or datetime.now(timezone.utc)
    return Path("runs") / now.strftime("%Y%m%dT%H%M%SZ")


class Recorder(Node):
    """Raw-bytes recorder: discovery timer, one raw subscription per topic, a BagWriter."""

    def __init__(self):
        # No /rosout publisher: the recorder would otherwise record its own log lines, and
        # its final counts are logged after the context has shut down (on SIGINT/SIGTERM).
        super().__init__("recorder", enable_rosout=False, **NODE_OPTIONS)
        p = self._declare_parameters()
        # names resolve in the recorder's namespace, like every node's (relative names)
        self.topic_list: list[str] = [self.resolve_topic_name(t) for t in p["topics"]]
        ns = self.get_namespace()
        self.namespace_prefix = "" if ns == "/" else ns + "/"
        self.exclude = re.compile(p["exclude"]) if p["exclude"] else None
        self.queue_depth = p["queue_depth"]
        self.drain_max = p["drain_max"]
        out = Path(p["output_dir"]) if p["output_dir"] else default_output_dir()
        self.writer = BagWriter(
            out, compression=p["compression"], chunk_size=p["chunk_size"],
            max_file_size=p["max_bag_size"],
            max_file_duration_ns=int(p["max_bag_duration"] * 1e9),
            library="tmgwr_agent recorder (mcap-python)",
            custom_data={"recorder": "tmgwr_agent recorder"})
        self.received: dict[str, int] = {}
        self.failed: dict[str, int] = {}
        self.subscriptions_by_topic: dict[str, object] = {}
        self.early: set[str] = set()          # subscribed before a publisher was seen
        self.early_types: dict[str, str] = {}
        self._warned: set[str] = set()
        self.gaps = StepGaps()
        self.ready_pub = self.create_publisher(String, topics.RECORDER_READY, LATCHED_QOS)
        self.ready_topic = self.resolve_topic_name(topics.RECORDER_READY)
        self.ready = False
        self.run_pub = self.create_publisher(UInt64, topics.RECORDER_RUN, LATCHED_QOS)
        self.run_topic = self.resolve_topic_name(topics.RECORDER_RUN)
        self.runs_said: set[int] = set()
        self.gap_topics = {self.resolve_topic_name(t) for t in p["gap_topics"] if t}
        # the ring's topics that this recorder records: a run is in the bag once each has
        # a message of it (recorder_run)
        self.ring_topics = {t for t in self.gap_topics if self._wanted(t)}
        # their types (from ``expect``): the same name in a nested namespace is checked too
        self.gap_types = {t: type_name for t, type_name in p["expect"].items()
                          if t in self.gap_topics}
        self._gap_warned: dict[str, float] = {}      # topic -> time of its last warning
        self._drains: dict[str, tuple[object, type, object]] = {}   # for the final drain
        for topic, type_name in p["expect"].items():
            if self._wanted(topic):
                try:
                    self._subscribe(topic, type_name, infos=None)
                except definitions.DefinitionError as exc:
                    self._warn_once(topic, f"{topic} not recorded: {exc}")
        if not self.ring_topics:
            self.run_pub.publish(UInt64(data=0))       # no run to wait for
        self.discover()
        # The line the graph supervisor waits for: the writer is open and the expected
        # topics are subscribed.
        self.get_logger().info(
            f'recording {"all topics" if not self.topic_list else ", ".join(self.topic_list)} '
            f'to {self.writer.directory.resolve()} (compression {p["compression"]})')
        # Discovery and flushing run on timers in the same single-threaded executor as the
        # subscriptions, so the writer is never used by two threads at once.
        self.create_timer(p["discovery_period"], self.discover)
        if p["flush_period"] > 0:
            self.create_timer(p["flush_period"], self.writer.flush)

    # ------------------------------------------------------------------ parameters
    def _declare_parameters(self) -> dict:
        values = declare_parameters(self, SPECS)
        values["topics"] = [t for t in values["topics"] if t]
        if values["exclude"]:
            try:
                re.compile(values["exclude"])
            except re.error as exc:
                raise ValueError(f"parameter 'exclude': invalid regular expression "
                                 f"{values['exclude']!r}: {exc}") from None
        for t in values["topics"]:
            if not re.fullmatch(r"/?[A-Za-z~][\w/~{}]*", t):
                raise ValueError(f"parameter 'topics': {t!r} is not a valid topic name")
        expect = {}
        for entry in values["expect"]:
            if not entry:
                continue
            name, _, type_name = entry.partition("=")
            if not (name and type_name.count("/") == 2):
                raise ValueError(f"parameter 'expect': {entry!r} is not NAME=pkg/msg/Type")
            expect[self.resolve_topic_name(name)] = type_name
        values["expect"] = expect
        return values

    # ------------------------------------------------------------------ discovery
    def _wanted(self, topic: str) -> bool:
        if topic in (self.ready_topic, self.run_topic):    # the recorder's own word
            return False
        if self.topic_list:
            return topic in self.topic_list
        if any(part.startswith("_") for part in topic.split("/")):   # hidden topics
            return False
        if not topic.startswith(self.namespace_prefix):   # another graph's namespace
            return False
        return not (self.exclude and self.exclude.search(topic))

    def discover(self) -> None:
        self._say_ready()
        for topic, types in self.get_topic_names_and_types():
            if topic in self.early and self.received[topic] == 0:
                self._check_early(topic, types)
            if topic in self.subscriptions_by_topic or not self._wanted(topic):
                continue
            if len(types) != 1:
                self._warn_once(topic, f"{topic} has several types {types}: not recorded")
                continue
            infos = self.get_publishers_info_by_topic(topic)
            if not infos:           # only subscribers so far: wait for a publisher's QoS
                continue
            try:
                self._subscribe(topic, types[0], infos)
            except definitions.DefinitionError as exc:
                self._warn_once(topic, f"{topic} not recorded: {exc}")

    def _say_ready(self) -> None:
        """Once every expected topic subscribed early has a matched publisher: publish the
        bag's directory on ``recorder_ready`` (latched) and log it."""
        if self.ready or any(self.subscriptions_by_topic[t].get_publisher_count() == 0
                             for t in self.early):
            return
        self.ready = True
        where = str(self.writer.directory.resolve())
        self.ready_pub.publish(String(data=where))
        self.get_logger().info(f"matched a publisher on every expected topic "
                               f"({len(self.early)}): said so on {self.ready_topic}")

    def _say_run(self, run_id: int | None) -> None:
        """Once every ring topic recorded has a message of ``run_id`` (the run the gap
        check read from the newest message; None: unreadable): publish it on
        ``recorder_run`` (latched) and log it."""
        if run_id is None or run_id in self.runs_said or not all(
                run_id in self.gaps.topics.get(t, ()) for t in self.ring_topics):
            return
        self.runs_said.add(run_id)
        self.run_pub.publish(UInt64(data=run_id))
        first = min(self.gaps.topics[t][run_id].first for t in self.ring_topics)
        self.get_logger().info(f"run {run_id} is in the bag on every ring topic "
                               f"({len(self.ring_topics)}) from step {first}: said so on "
                               f"{self.run_topic}")

    def _checks_gaps(self, topic: str, type_name: str) -> bool:
        """Whether ``topic``'s step ids are checked: a ``gap_topics`` name, or the same
        name and type in a namespace below the recorder's (a recorder in the root namespace
        checks ``/a/observation`` and ``/b/observation``, each on its own)."""
        if topic in self.gap_topics:
            return True
        own = self.get_namespace().rstrip("/") + "/"
        if not topic.startswith(own):
            return False
        for gap_topic, gap_type in self.gap_types.items():
            base = gap_topic[len(own):] if gap_topic.startswith(own) else ""
            if base and topic.endswith("/" + base) and type_name == gap_type:
                return True
        return False

    def _warn_once(self, topic: str, text: str) -> None:
        if topic not in self._warned:
            self._warned.add(topic)
            self.get_logger().warning(text)

    def _topic_info(self, topic: str, type_name: str, infos) -> TopicInfo:
        """What the bag stores about ``topic``: definition, offered QoS, type hash."""
        offered = [bag_qos.profile_to_dict(i.qos_profile) for i in infos]
        hashes = {str(i.topic_type_hash) for i in infos}
        type_hash = sorted(hashes)[0] if len(hashes) == 1 else ""
        if not type_hash.startswith("RIHS"):
            type_hash = definitions.type_hash(type_name)
        return TopicInfo(name=topic, type=type_name,
                         definition=definitions.ros2msg_definition(type_name),
                         offered_qos=offered, type_hash=type_hash)

    def _check_early(self, topic: str, types: list[str]) -> None:
        """An expected topic whose publisher is not reliable, or of another type, would never
        match the early subscription: subscribe again the ordinary way."""
        infos = self.get_publishers_info_by_topic(topic)
        if not infos:
            return
        unreliable = any(bag_qos.profile_to_dict(i.qos_profile)["reliability"] != "reliable"
                         for i in infos)
        if unreliable or types != [self.early_types[topic]]:
            why = "a publisher is not reliable" if unreliable else f"types {types}"
            self.get_logger().info(f"{topic}: {why}: the early subscription does not match, "
                                   f"subscribing again")
            self.destroy_subscription(self.subscriptions_by_topic.pop(topic))
            self.early.discard(topic)
            del self.received[topic]

    def _subscribe(self, topic: str, type_name: str, infos) -> None:
        """Raw subscription to ``topic``. ``infos`` (the publishers) None: an expected topic,
        subscribed before any publisher exists; the topic is added to the bag with its
        publishers' QoS when its first message arrives."""
        msg_class = definitions.import_message(type_name)
        definitions.ros2msg_definition(type_name)          # fail now if it is unknown
        if infos is None:
            self.early.add(topic)
            self.early_types[topic] = type_name
            sub_qos = bag_qos.subscription_qos([{"reliability": "reliable",
                                                 "durability": "volatile"}], self.queue_depth)
        else:
            info = self._topic_info(topic, type_name, infos)
            self.writer.add_topic(info)
            sub_qos = bag_qos.subscription_qos(info.offered_qos, self.queue_depth)
        self.received[topic] = 0
        write = self.writer.write
        received = self.received
        count_gaps = self._checks_gaps(topic, type_name)
        on_ring = topic in self.ring_topics

        def store(data: bytes, msg_info: dict) -> None:
            if topic not in self.writer.topics:             # first message of an early one
                self.writer.add_topic(self._topic_info(
                    topic, type_name, self.get_publishers_info_by_topic(topic)))
            received[topic] += 1
            if count_gaps:
                gap = self.gaps.add(topic, data)
                if gap is not None:
                    self._warn_gap(topic, *gap)
            if on_ring:                                     # a ring topic's gaps are counted
                self._say_run(self.gaps.newest_run[topic])
            try:
                write(topic, data, msg_info["received_timestamp"],
                      msg_info["source_timestamp"], msg_info["publication_sequence_number"])
            except Exception as exc:  # noqa: BLE001 -- count it, keep recording the rest
                self.failed[topic] = self.failed.get(topic, 0) + 1
                self._warn_once("write:" + topic, f"writing a message of {topic} failed: {exc}")

        def on_message(data: bytes, msg_info: dict) -> None:
            store(data, msg_info)
            # Drain what else is queued on this subscription right here: one executor
            # round trip (wait set, task) per message is what limits an rclpy recorder;
            # taking the backlog directly roughly doubles the lossless rate.
            for _ in range(self.drain_max):
                with handle:
                    taken = handle.take_message(msg_class, True)
                if taken is None:
                    break
                store(*taken)

        sub = self.create_subscription(msg_class, topic, on_message, sub_qos, raw=True)
        handle = sub.handle
        self.subscriptions_by_topic[topic] = sub
        self._drains[topic] = (handle, msg_class, store)
        self.get_logger().info(
            f"subscribed to {topic} [{type_name}] ({sub_qos.reliability.name.lower()}, "
            f"{sub_qos.durability.name.lower()}, depth {sub_qos.depth})"
            + (" before its publisher appeared" if infos is None else ""))

    def _warn_gap(self, topic: str, run_id: int, first: int, last: int) -> None:
        """A gap on a per-step topic: at once for the first one of a topic, then at most
        every GAP_WARN_PERIOD s with the count since (all of them are in the summary)."""
        now = time.monotonic()
        if now - self._gap_warned.get(topic, -GAP_WARN_PERIOD) < GAP_WARN_PERIOD:
            return
        self._gap_warned[topic] = now
        total = sum(r.missing for r in self.gaps.topics[topic].values())
        steps = f"steps {first}-{last}" if last > first else f"step {first}"
        self.get_logger().warning(
            f"GAP on {topic} (run {run_id}): {steps} not recorded ({last - first + 1} "
            f"messages; {total} missing on {topic} so far): the recorder fell behind what "
            "its publishers keep")

    # ------------------------------------------------------------------ end
    def drain(self, quiet: float = 0.2, limit: float = 2.0) -> int:
        """Take and write what is still queued on every subscription, until nothing more
        arrives for ``quiet`` seconds (at most ``limit``): the graph's nodes stop before
        the recorder, and their last messages may still be on their way or waiting here
        when the recorder is told to stop. Returns how many were written."""
        n = 0
        start = last = time.monotonic()
        while time.monotonic() - last < quiet and time.monotonic() - start < limit:
            took = 0
            for handle, msg_class, store in self._drains.values():
                while True:
                    with handle:
                        taken = handle.take_message(msg_class, True)
                    if taken is None:
                        break
                    store(*taken)
                    took += 1
            if took:
                n += took
                last = time.monotonic()
            else:
                time.sleep(0.01)
        return n

    def on_shutdown(self) -> None:
        """Finish the bag (summary, indexes, metadata.yaml) and log what was recorded and
        every gap of the per-step topics."""
        try:
            drained = self.drain()
        except Exception as exc:  # noqa: BLE001 -- the bag must still be finished
            drained = 0
            self.get_logger().warning(f"could not take the last queued messages: {exc}")
        self.writer.custom_data["step_gaps"] = json.dumps(self.gaps.as_dict())
        meta = self.writer.close()
        written = {t["topic_metadata"]["name"]: t["message_count"]
                   for t in meta["topics_with_message_count"]}
        total_r, total_w = sum(self.received.values()), sum(written.values())
        for topic in sorted(self.received):
            failed = self.failed.get(topic, 0)
            self.get_logger().info(f"  {topic}: received {self.received[topic]}, written "
                                   f"{written.get(topic, 0)}"
                                   + (f", {failed} FAILED to write" if failed else ""))
            for line in self.gaps.topic_lines(topic):
                self.get_logger().info(f"    {line}")
        if drained:
            self.get_logger().info(f"{drained} messages still queued at the stop were written")
        (self.get_logger().warning if self.gaps.missing else self.get_logger().info)(
            self.gaps.summary())
        files = ", ".join(str(p) for p in self.writer.file_paths())
        self.get_logger().info(
            f'recorded: received {total_r}, written {total_w} messages on '
            f'{len(self.received)} topics'
            f'{"" if total_r == total_w else " (MESSAGES LOST IN WRITING)"} -> {files}')


def main(args=None):
    # One single-threaded executor runs the subscriptions, discovery and flushing, so the
    # writer is never used by two threads at once.
    raise SystemExit(run(Recorder, "recorder", args, executor_factory=SingleThreadedExecutor))


if __name__ == "__main__":
    main()
