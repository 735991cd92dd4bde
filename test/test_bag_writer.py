"""The bag writer, definitions and recovery without DDS (fast): split by duration and
size, every compression, schema text in the short ``MSG:`` form, recovery of a directory
whose last file was cut off mid-chunk."""

from __future__ import annotations

import shutil

import pytest
import yaml
from mcap.reader import make_reader

from tmgwr_agent.bag import definitions
from tmgwr_agent.bag.recover import recover
from tmgwr_agent.bag.writer import BagWriter, TopicInfo


def observation_bytes(step: int) -> bytes:
    # A fixed-size type: rclpy's serialize_message may append 4 bytes of padding after some
    # variable-length messages, and rosbags refuses more than 3 (the recorder tests check
    # the real messages of the graph, which decode everywhere).
    from geometry_msgs.msg import Point
    from rclpy.serialization import serialize_message
    return serialize_message(Point(x=float(step), y=1.0, z=2.0))


def topic() -> TopicInfo:
    t = "geometry_msgs/msg/Point"
    return TopicInfo("/observation", t, definitions.ros2msg_definition(t),
                     [{"history": "unknown", "depth": 0, "reliability": "reliable",
                       "durability": "volatile"}], definitions.type_hash(t))


def test_definition_uses_the_short_msg_form_and_each_dependency_once():
    text = definitions.ros2msg_definition("visualization_msgs/msg/MarkerArray")
    names = [line[5:] for line in text.splitlines() if line.startswith("MSG: ")]
    assert names[0] == "visualization_msgs/Marker"
    assert "std_msgs/Header" in names and "builtin_interfaces/Time" in names
    assert len(names) == len(set(names))
    assert all("/msg/" not in n for n in names)
    assert definitions.type_hash("std_msgs/msg/Header").startswith("RIHS01_")
    with pytest.raises(definitions.DefinitionError, match="no_such_pkg"):
        definitions.ros2msg_definition("no_such_pkg/msg/Thing")


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_split_by_duration_every_file_complete(tmp_path, compression):
    bag = tmp_path / "b"
    w = BagWriter(bag, compression=compression, chunk_size=4096,
                  max_file_duration_ns=10**9)
    w.add_topic(topic())
    t0 = 1_700_000_000 * 10**9
    for i in range(300):                          # 3 s of log time at 100 msg/s
        w.write("/observation", observation_bytes(i), t0 + i * 10**7, t0 + i * 10**7 - 1000, i)
    meta = w.close()
    assert len(meta["files"]) == 3 and meta["message_count"] == 300
    total = 0
    for f in meta["files"]:
        with open(bag / f["path"], "rb") as fh:
            reader = make_reader(fh)
            s = reader.get_summary()
            assert s.statistics.message_count == f["message_count"] == 100
            rec = next(m for m in reader.iter_metadata() if m.name == "rosbag2")
            assert yaml.safe_load(rec.metadata["serialized_metadata"])["message_count"] == 100
            total += s.statistics.message_count
    assert total == 300
    on_disk = yaml.safe_load((bag / "metadata.yaml").read_text())
    assert on_disk["rosbag2_bagfile_information"]["relative_file_paths"] == \
        [f["path"] for f in meta["files"]]
    with pytest.raises(FileExistsError):          # never overwrite a bag
        BagWriter(bag)


def test_recover_a_directory_whose_last_file_was_cut(tmp_path):
    bag = tmp_path / "cut"
    w = BagWriter(bag, compression="none", chunk_size=2048, max_file_size=20000)
    w.add_topic(topic())
    for i in range(1000):
        w.write("/observation", observation_bytes(i), 10**18 + i * 10**6, 10**18 + i * 10**6, i)
    meta = w.close()
    files = [bag / f["path"] for f in meta["files"]]
    assert len(files) >= 3
    last = files[-1]
    data = last.read_bytes()
    last.write_bytes(data[:len(data) // 2])        # the writer "died" in the last file
    with pytest.raises(Exception):
        with open(last, "rb") as fh:
            make_reader(fh).get_summary()
    results = recover(bag)
    out = bag.with_name("cut.recovered")
    assert [r.complete for r in results] == [True] * (len(files) - 1) + [False]
    saved = sum(r.messages for r in results)
    assert sum(f["message_count"] for f in meta["files"][:-1]) < saved < 1000
    from rosbags.highlevel import AnyReader
    with AnyReader([out]) as reader:
        ids = [int(reader.deserialize(raw, c.msgtype).x) for c, _t, raw in reader.messages()]
    assert ids == list(range(saved))
    shutil.rmtree(out)


def test_replay_plays_in_the_order_received_or_in_the_order_sent(tmp_path):
    """``./tmgwr replay --message-order sent`` (rosbag2's name): the recorder may receive a
    step's action before the state that caused it (it takes its subscriptions one after the
    other); played in publish-time order the ring's causal order comes back, and a message
    that arrived later than SENT_WINDOW after its sending still comes out."""
    from dataclasses import replace

    from tmgwr_agent.bag.replay import SENT_WINDOW, iter_messages
    bag = tmp_path / "b"
    w = BagWriter(bag, compression="none")
    w.add_topic(replace(topic(), name="/state"))
    w.add_topic(replace(topic(), name="/action"))
    ms, late = 10 ** 6, int(SENT_WINDOW * 1e9) + 5 * 10 ** 9
    t0 = 1_700_000_000 * 10 ** 9
    # (topic, step, sent, received): each step's action received before its state
    sent = [("/state", 0, 0, 3), ("/action", 0, 1, 2), ("/state", 1, 10, 13),
            ("/action", 1, 11, 12), ("/state", 2, 20, 20 + late // ms)]
    for name, step, at, got in sent:
        w.write(name, observation_bytes(step), t0 + got * ms, t0 + at * ms, step)
    w.close()
    files = sorted(bag.glob("*.mcap"))
    got = {order: [(name, t - t0) for name, t, _ in iter_messages(files, None, order)]
           for order in ("received", "sent")}
    assert got["received"] == [("/action", 2 * ms), ("/state", 3 * ms), ("/action", 12 * ms),
                               ("/state", 13 * ms), ("/state", 20 * ms + late)]
    assert got["sent"] == [("/state", 0), ("/action", ms), ("/state", 10 * ms),
                           ("/action", 11 * ms), ("/state", 20 * ms)]
    with pytest.raises(ValueError, match="one of received, sent"):
        list(iter_messages(files, None, "arrival"))
