"""A rosbag2-compatible MCAP bag writer for already serialized (CDR) messages. ROS-free.

A bag is a directory (rosbag2 layout) holding ``<name>_0.mcap``, ``<name>_1.mcap``, ... and
``metadata.yaml`` (rosbag2 metadata version 9). Every ``.mcap`` file is complete on its own:

* header profile ``ros2``; one ``ros2msg`` schema per type with the full definition
  (:mod:`.definitions`); one ``cdr`` channel per topic carrying the metadata
  ``offered_qos_profiles`` (YAML, :mod:`.qos`) and ``topic_type_hash`` (RIHS01);
* messages in chunks compressed with zstd, lz4 or nothing; log time = reception time,
  publish time = the publisher's source timestamp, sequence = publication sequence number;
* a summary with a Statistics record and indexes (what rosbag2 requires to open a bare
  ``.mcap``), and a metadata record ``rosbag2`` whose ``serialized_metadata`` is the complete
  rosbag2 BagMetadata of that file (what rosbag2 expects when the record is present).

The bag is split into a new file when the current one reaches ``max_file_size`` bytes or
spans ``max_file_duration_ns`` of log time. ``flush()`` closes the chunk in progress and
hands it to the OS, so a writer killed outright (``kill -9``) loses at most what arrived
since the last flush; :mod:`.recover` turns such a file into a valid one.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from mcap.writer import CompressionType, Writer

from tmgwr_agent.bag import qos as qos_yaml

PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
METADATA_VERSION = 9
COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
                "none": CompressionType.NONE}


@dataclass
class TopicInfo:
    """What a bag stores about one topic (a rosbag2 TopicMetadata)."""
    name: str
    type: str                       # pkg/msg/Type
    definition: str                 # ros2msg schema text
    offered_qos: list[dict[str, Any]] = field(default_factory=list)
    type_hash: str = ""             # RIHS01_...

    def channel_metadata(self) -> dict[str, str]:
        meta = {"offered_qos_profiles": qos_yaml.dump_profiles(self.offered_qos)}
        if self.type_hash:
            meta["topic_type_hash"] = self.type_hash
        return meta


@dataclass
class FileStats:
    """Counts of one ``.mcap`` file of the bag."""
    path: str                       # relative to the bag directory
    counts: dict[str, int] = field(default_factory=dict)
    start: int | None = None        # first log time (ns)
    end: int | None = None          # last log time (ns)

    @property
    def message_count(self) -> int:
        return sum(self.counts.values())

    def add(self, topic: str, log_time: int) -> None:
        self.counts[topic] = self.counts.get(topic, 0) + 1
        self.start = log_time if self.start is None else min(self.start, log_time)
        self.end = log_time if self.end is None else max(self.end, log_time)


def bag_metadata(topics: list[TopicInfo], files: list[FileStats],
                 custom_data: dict[str, str] | None = None) -> dict[str, Any]:
    """The rosbag2 BagMetadata (version 9) of ``files`` as a plain mapping."""
    starts = [f.start for f in files if f.start is not None]
    ends = [f.end for f in files if f.end is not None]
    start = min(starts) if starts else 0
    duration = (max(ends) - start) if ends else 0
    totals: dict[str, int] = {}
    for f in files:
        for name, n in f.counts.items():
            totals[name] = totals.get(name, 0) + n
    return {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": int(duration)},
        "starting_time": {"nanoseconds_since_epoch": int(start)},
        "message_count": int(sum(totals.values())),
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.type,
                    "serialization_format": MESSAGE_ENCODING,
                    "offered_qos_profiles": [qos_yaml.complete(q) for q in t.offered_qos],
                    "type_description_hash": t.type_hash,
                },
                "message_count": int(totals.get(t.name, 0)),
            }
            for t in topics
        ],
        "compression_format": "",   # MCAP chunk compression is inside the storage format
        "compression_mode": "",
        "relative_file_paths": [f.path for f in files],
        "files": [
            {
                "path": f.path,
                "starting_time": {"nanoseconds_since_epoch": int(f.start or 0)},
                "duration": {"nanoseconds": int((f.end or 0) - (f.start or 0))},
                "message_count": int(f.message_count),
            }
            for f in files
        ],
        "custom_data": dict(custom_data) if custom_data else None,
        "ros_distro": os.environ.get("ROS_DISTRO", "jazzy"),
    }


def dump_yaml(data: Any) -> str:
    return yaml.safe_dump(data, default_flow_style=False, sort_keys=False)


def write_metadata_yaml(directory: Path, metadata: dict[str, Any]) -> Path:
    """Write ``metadata.yaml`` atomically (a reader never sees half a file)."""
    path = Path(directory) / "metadata.yaml"
    tmp = path.with_suffix(".yaml.tmp")
    tmp.write_text(dump_yaml({"rosbag2_bagfile_information": metadata}))
    os.replace(tmp, path)
    return path


class McapFile:
    """One open ``.mcap`` file: schemas and channels registered on demand."""

    def __init__(self, path: Path, compression: str, chunk_size: int, library: str):
        self.path = Path(path)
        self.stream = open(self.path, "xb")
        self.writer = Writer(self.stream, chunk_size=chunk_size,
                             compression=COMPRESSIONS[compression])
        self.writer.start(profile=PROFILE, library=library)
        self.schemas: dict[str, int] = {}
        self.channels: dict[str, int] = {}

    def channel(self, topic: TopicInfo) -> int:
        cid = self.channels.get(topic.name)
        if cid is None:
            sid = self.schemas.get(topic.type)
            if sid is None:
                sid = self.writer.register_schema(
                    name=topic.type, encoding=SCHEMA_ENCODING,
                    data=topic.definition.encode())
                self.schemas[topic.type] = sid
            cid = self.writer.register_channel(
                topic=topic.name, message_encoding=MESSAGE_ENCODING, schema_id=sid,
                metadata=topic.channel_metadata())
            self.channels[topic.name] = cid
        return cid

    def size(self) -> int:
        return self.stream.tell()

    def close(self, metadata: dict[str, Any]) -> None:
        self.writer.add_metadata("rosbag2", {"serialized_metadata": dump_yaml(metadata)})
        self.writer.finish()
        self.stream.close()


class BagWriter:
    """Writes serialized messages of registered topics into a rosbag2/MCAP bag directory."""

    def __init__(self, directory: str | os.PathLike, compression: str = "zstd",
                 chunk_size: int = 1 << 20, max_file_size: int = 0,
                 max_file_duration_ns: int = 0, library: str = "tmgwr_agent recorder",
                 custom_data: dict[str, str] | None = None):
        if compression not in COMPRESSIONS:
            raise ValueError(f'compression {compression!r}: expected one of '
                             f'{", ".join(COMPRESSIONS)}')
        self.directory = Path(directory)
        # The directory may already hold other files of the run (logs, parameters), not a bag.
        if self.directory.exists() and ((self.directory / "metadata.yaml").exists()
                                        or any(self.directory.glob("*.mcap"))):
            raise FileExistsError(f"{self.directory} already holds a bag (metadata.yaml or "
                                  f".mcap files): choose another output directory")
        self.directory.mkdir(parents=True, exist_ok=True)
        self.compression = compression
        self.chunk_size = int(chunk_size)
        self.max_file_size = int(max_file_size)
        self.max_file_duration_ns = int(max_file_duration_ns)
        self.library = library
        self.custom_data = dict(custom_data or {})
        self.topics: dict[str, TopicInfo] = {}
        self.files: list[FileStats] = []
        self.written = 0
        self._file: McapFile | None = None
        self._open_next()

    # -- files
    def _open_next(self) -> None:
        name = f"{self.directory.name}_{len(self.files)}.mcap"
        self._file = McapFile(self.directory / name, self.compression, self.chunk_size,
                              self.library)
        self.files.append(FileStats(path=name))
        for topic in self.topics.values():          # every file describes every topic
            self._file.channel(topic)

    def _close_current(self) -> None:
        if self._file is None:
            return
        stats = self.files[-1]
        present = [t for t in self.topics.values() if t.name in self._file.channels]
        self._file.close(bag_metadata(present, [stats], self.custom_data))
        self._file = None

    def split(self) -> None:
        """Close the current file and continue in a new one."""
        self._close_current()
        self._open_next()
        write_metadata_yaml(self.directory, self.metadata())

    # -- topics and messages
    def add_topic(self, topic: TopicInfo) -> None:
        if topic.name in self.topics:
            raise ValueError(f"topic {topic.name} already added")
        self.topics[topic.name] = topic
        assert self._file is not None
        self._file.channel(topic)

    def write(self, topic: str, data: bytes, log_time: int, publish_time: int,
              sequence: int = 0) -> None:
        stats = self.files[-1]
        if (self.max_file_duration_ns and stats.start is not None
                and log_time - stats.start >= self.max_file_duration_ns):
            self.split()
            stats = self.files[-1]
        assert self._file is not None
        cid = self._file.channel(self.topics[topic])
        self._file.writer.add_message(cid, log_time=int(log_time), data=data,
                                      publish_time=int(publish_time),
                                      sequence=int(sequence) & 0xFFFFFFFF)
        stats.add(topic, int(log_time))
        self.written += 1
        if self.max_file_size and self._file.size() >= self.max_file_size:
            self.split()

    def flush(self) -> None:
        """Write the chunk in progress to the OS (survives a kill of this process)."""
        if self._file is not None:
            self._file.writer.flush()

    # -- end
    def metadata(self) -> dict[str, Any]:
        return bag_metadata(list(self.topics.values()), self.files, self.custom_data)

    def close(self) -> dict[str, Any]:
        """Finish the current file and write ``metadata.yaml``; returns the metadata."""
        self._close_current()
        meta = self.metadata()
        write_metadata_yaml(self.directory, meta)
        return meta

    def file_paths(self) -> list[Path]:
        return [self.directory / f.path for f in self.files]
