"""``./tmgwr recover BAG [-o OUT]``: salvage a recording whose writer died.

A recorder killed before it finished its file (``kill -9``, power loss, a crash) leaves an
MCAP file without summary, footer and end magic, maybe with half a chunk at the end: the
indexed readers (``mcap.reader.make_reader``, rosbags ``AnyReader``, Foxglove) refuse it.
Its data section is still a valid *stream* of records up to the last complete one, so we
read it with ``mcap.stream_reader.StreamReader`` (which decompresses the chunks) until the
stream ends or breaks, and write every schema, channel, message and metadata record found
into a new, finished, indexed file: ros2 profile, Statistics, and a fresh complete
``rosbag2`` metadata record computed from what was saved.

``BAG`` is an ``.mcap`` file (output: ``<name>.recovered.mcap`` beside it) or a bag
directory (output: ``<dir>.recovered/`` with every file rewritten and a new
``metadata.yaml``). Valid files are rewritten the same way, so the result is uniform.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, DataEnd, Header, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from tmgwr_agent.bag import qos as bag_qos
from tmgwr_agent.bag.writer import (
    COMPRESSIONS,
    FileStats,
    McapFile,
    TopicInfo,
    bag_metadata,
    write_metadata_yaml,
)

MAGIC = b"\x89MCAP0\r\n"     # MCAP version 0 magic, at the start and the end of every file


class UnfinishedBag(ValueError):
    """A recording whose writer never finished it: readers need ``./tmgwr recover`` first."""


def require_finished(bag: str | Path, files: list[Path]) -> None:
    """Raise :class:`UnfinishedBag` (one line: which file, why, what to run) unless every
    ``.mcap`` file of ``bag`` is a finished MCAP file (it ends with the MCAP magic, written
    after the summary; a writer killed with ``kill -9`` never writes it)."""
    for path in files:
        with open(path, "rb") as f:
            head = f.read(len(MAGIC))
            size = f.seek(0, 2)
            f.seek(max(size - len(MAGIC), 0))
            tail = f.read(len(MAGIC))
        if head != MAGIC:
            raise ValueError(f"{path} is not an MCAP file")
        if tail != MAGIC or size < 2 * len(MAGIC):
            which = "" if Path(path) == Path(bag) else f" ({Path(path).name})"
            raise UnfinishedBag(
                f"{bag}{which} is an unfinished recording (its recorder was stopped before "
                f"writing the summary, e.g. by kill -9): run ./tmgwr recover {bag} first, "
                f"then use {default_output(Path(bag))}")


@dataclass
class FileRecovery:
    source: Path
    output: Path
    messages: int = 0
    counts: dict[str, int] = field(default_factory=dict)
    complete: bool = False          # the source's data section ended cleanly (DataEnd)
    stopped_at: int = 0             # bytes of the source that were read
    size: int = 0                   # size of the source
    error: str = ""                 # why reading stopped early, if it did

    def describe(self) -> str:
        state = ("intact" if self.complete else
                 f"truncated: read {self.stopped_at} of {self.size} bytes ({self.error})")
        return f"{self.source} -> {self.output}: {self.messages} messages saved ({state})"


def recover_file(source: Path, output: Path, compression: str = "zstd",
                 chunk_size: int = 1 << 20) -> tuple[FileRecovery, list[TopicInfo], FileStats]:
    """Stream-read ``source`` and write everything readable into the new file ``output``."""
    source, output = Path(source), Path(output)
    with open(source, "rb") as f:
        head = f.read(8)
    if head and not MAGIC.startswith(head[:len(MAGIC)]):
        raise ValueError(f"{source} is not an MCAP file (it starts with {head!r})")
    result = FileRecovery(source=source, output=output, size=source.stat().st_size)
    out = McapFile(output, compression, chunk_size, library="tmgwr_agent recover (mcap-python)")
    schemas: dict[int, Schema] = {}
    topics: dict[int, TopicInfo] = {}
    stats = FileStats(path=output.name)
    extra_metadata: list[Metadata] = []
    with open(source, "rb") as stream:
        try:
            for record in StreamReader(stream, skip_magic=False, emit_chunks=False).records:
                if isinstance(record, Header):
                    if record.profile and record.profile != "ros2":
                        raise ValueError(f"{source}: profile {record.profile!r} is not ros2")
                elif isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel) and record.id not in topics:
                    schema = schemas.get(record.schema_id)
                    if schema is None:
                        raise ValueError(f"{source}: channel {record.topic} refers to the "
                                         f"unknown schema id {record.schema_id}")
                    topics[record.id] = TopicInfo(
                        name=record.topic, type=schema.name,
                        definition=schema.data.decode(),
                        offered_qos=bag_qos.load_profiles(
                            record.metadata.get("offered_qos_profiles", "")),
                        type_hash=record.metadata.get("topic_type_hash", ""))
                elif isinstance(record, Message):
                    topic = topics.get(record.channel_id)
                    if topic is None:
                        continue            # a message before its channel: not decodable
                    out.writer.add_message(out.channel(topic), log_time=record.log_time,
                                           data=record.data, publish_time=record.publish_time,
                                           sequence=record.sequence)
                    stats.add(topic.name, record.log_time)
                    result.messages += 1
                elif isinstance(record, Metadata) and record.name != "rosbag2":
                    extra_metadata.append(record)
                elif isinstance(record, Attachment):
                    out.writer.add_attachment(record.create_time, record.log_time, record.name,
                                              record.media_type, record.data)
                elif isinstance(record, DataEnd):
                    result.complete = True
                    break               # the summary section follows: nothing new in it
                result.stopped_at = stream.tell()
        except (McapError, EOFError, struct.error, ValueError, UnicodeDecodeError) as exc:
            if isinstance(exc, ValueError) and "profile" in str(exc):
                raise
            result.error = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    for m in extra_metadata:
        out.writer.add_metadata(m.name, m.metadata)
    infos = list(topics.values())
    for t in infos:                          # channels without messages are kept as well
        out.channel(t)
    out.close(bag_metadata(infos, [stats], {"recovered_from": str(source)}))
    result.counts = dict(stats.counts)
    return result, infos, stats


def default_output(bag: Path) -> Path:
    bag = Path(bag)
    if bag.is_dir():
        return bag.with_name(bag.name + ".recovered")
    return bag.with_name(bag.stem + ".recovered.mcap")


def recover(bag: str | Path, output: str | Path | None = None,
            compression: str = "zstd") -> list[FileRecovery]:
    """Recover a ``.mcap`` file or every ``.mcap`` file of a bag directory."""
    bag = Path(bag)
    if not bag.exists():
        raise FileNotFoundError(f"{bag} does not exist")
    if compression not in COMPRESSIONS:
        raise ValueError(f'compression {compression!r}: expected one of {", ".join(COMPRESSIONS)}')
    out = Path(output) if output else default_output(bag)
    if out.exists() and (out.is_file() or any(out.iterdir())):
        raise FileExistsError(f"{out} already exists: give another output with -o")
    if bag.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        return [recover_file(bag, out, compression)[0]]
    sources = sorted(bag.glob("*.mcap"), key=_file_index)
    if not sources:
        raise FileNotFoundError(f"{bag} holds no .mcap file")
    out.mkdir(parents=True, exist_ok=True)
    results, all_topics, all_stats = [], {}, []
    for src in sources:
        res, infos, stats = recover_file(src, out / src.name, compression)
        results.append(res)
        all_stats.append(stats)
        for t in infos:
            all_topics.setdefault(t.name, t)
    write_metadata_yaml(out, bag_metadata(list(all_topics.values()), all_stats,
                                          {"recovered_from": str(bag)}))
    return results


def _file_index(path: Path) -> tuple[int, str]:
    """``name_12.mcap`` sorts after ``name_2.mcap``."""
    tail = path.stem.rsplit("_", 1)[-1]
    return (int(tail) if tail.isdigit() else -1, path.name)
