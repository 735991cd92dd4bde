"""Gaps in the per-step topics of a recording, counted as the messages arrive
(docs/recording.md).

Every per-step message of the graph (Observation, Features, SensorimotorState,
MotivationField, Action) starts with ``std_msgs/Header header``, ``uint64 run_id``,
``uint64 step_id``; :func:`header_step` reads the two ids straight from the CDR bytes the
recorder writes (no deserialization). The simulator numbers the steps of a run 0, 1, 2,
...; a node publishes each step once (and again on a resend), so on each topic the step
ids of a run must follow each other. :class:`StepGaps` keeps, per topic and run, the first
and last step recorded, the count, the resends and every missing range: a step id that
jumps ahead is a gap of exactly the steps between, stated at once (``add`` returns it) and
at the end (:meth:`StepGaps.summary`, :meth:`StepGaps.as_dict` for the bag's metadata).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

MAX_RANGES = 100          # missing ranges kept per topic and run (the count stays exact)


def header_step(cdr: bytes) -> tuple[int, int]:
    """(run_id, step_id) of a serialized message that starts with a Header, then
    ``uint64 run_id``, ``uint64 step_id`` (XCDR1, either byte order)."""
    fmt = "<" if cdr[1] & 1 else ">"       # encapsulation 0x0001 / 0x0003: little endian
    body = memoryview(cdr)[4:]
    (length,) = struct.unpack_from(fmt + "I", body, 8)      # after stamp sec, nanosec
    offset = (12 + length + 7) & ~7                           # frame_id, then align 8
    run_id, step_id = struct.unpack_from(fmt + "QQ", body, offset)
    return run_id, step_id


@dataclass
class RunSteps:
    """What one topic recorded of one run."""

    first: int
    last: int
    received: int = 1
    resent: int = 0                      # a step again (the simulator's resends)
    missing: int = 0                     # steps never recorded between first and last
    ranges: list[tuple[int, int]] = field(default_factory=list)   # missing, inclusive

    def as_dict(self) -> dict:
        return {"first": self.first, "last": self.last, "received": self.received,
                "resent": self.resent, "missing": self.missing,
                "ranges": [list(r) for r in self.ranges],
                "ranges_cut": self.missing > sum(b - a + 1 for a, b in self.ranges)}


class StepGaps:
    """Per topic and run: the steps recorded and the gaps between them."""

    def __init__(self):
        self.topics: dict[str, dict[int, RunSteps]] = {}
        self.unreadable: dict[str, int] = {}
        self.newest_run: dict[str, int | None] = {}   # run of each topic's newest message

    def add(self, topic: str, cdr: bytes) -> tuple[int, int, int] | None:
        """Count one message; returns ``(run_id, first, last)`` of the steps it shows
        missing, or None."""
        try:
            run_id, step_id = header_step(cdr)
        except (struct.error, IndexError):
            self.unreadable[topic] = self.unreadable.get(topic, 0) + 1
            self.newest_run[topic] = None
            return None
        self.newest_run[topic] = run_id
        runs = self.topics.setdefault(topic, {})
        r = runs.get(run_id)
        if r is None:
            runs[run_id] = RunSteps(first=step_id, last=step_id)
            return None
        r.received += 1
        if step_id <= r.last:
            r.resent += 1
            return None
        gap = None
        if step_id > r.last + 1:
            gap = (run_id, r.last + 1, step_id - 1)
            r.missing += step_id - 1 - r.last
            if len(r.ranges) < MAX_RANGES:
                r.ranges.append((r.last + 1, step_id - 1))
        r.last = step_id
        return gap

    @property
    def missing(self) -> int:
        return sum(r.missing for runs in self.topics.values() for r in runs.values())

    def as_dict(self) -> dict:
        """JSON-ready: {topic: {run_id: RunSteps.as_dict()}} (run ids as strings)."""
        return {t: {str(run): r.as_dict() for run, r in sorted(runs.items())}
                for t, runs in sorted(self.topics.items())}

    def topic_lines(self, topic: str) -> list[str]:
        """One line per run of ``topic``: its steps and what is missing."""
        out = []
        for run, r in sorted(self.topics.get(topic, {}).items()):
            text = f"run {run}: steps {r.first}-{r.last}, "
            if r.missing:
                shown = ", ".join(f"{a}-{b}" if a != b else f"{a}" for a, b in r.ranges[:5])
                more = ", ..." if len(r.ranges) > 5 else ""
                text += (f"{r.missing} MISSING in {len(r.ranges)} gap"
                         f"{'s' if len(r.ranges) != 1 else ''} ({shown}{more})")
            else:
                text += "no gap"
            out.append(text + (f", {r.resent} resent" if r.resent else ""))
        if self.unreadable.get(topic):
            out.append(f"{self.unreadable[topic]} messages without a readable step id")
        return out

    def summary(self) -> str:
        """One line over every topic counted."""
        if not self.topics:
            return "step gaps: no per-step message recorded"
        missing = self.missing
        n = len(self.topics)
        if not missing:
            return f"step gaps: none on {n} per-step topics"
        worst = {t: sum(r.missing for r in runs.values()) for t, runs in self.topics.items()}
        return (f"step gaps: {missing} steps MISSING on {n} per-step topics ("
                + ", ".join(f"{t} {m}" for t, m in sorted(worst.items()) if m) + ")")
