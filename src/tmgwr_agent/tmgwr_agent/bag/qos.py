"""QoS profiles as rosbag2 stores them, and the QoS a recorder or a replayer should use.

rosbag2 (metadata version 9, and the MCAP channel metadata ``offered_qos_profiles``) stores
the publishers' offered QoS as a YAML list of mappings with lowercase policy names and
durations as ``{sec, nsec}``::

    - history: keep_last
      depth: 1
      reliability: reliable
      durability: transient_local
      deadline: {sec: 9223372036, nsec: 854775807}
      ...

The recorder subscribes with a QoS compatible with every publisher of a topic (the rule of
rosbag2's ``Recorder::subscription_qos_for_topic``): reliable only if all publishers are
reliable, transient local only if all publishers are transient local (so latched messages
published before the recorder joined are delivered to it), and a history deep enough that a
briefly busy recorder does not drop samples.
"""

from __future__ import annotations

from typing import Any, Iterable

import yaml

# rosbag2 writes an infinite duration (RMW_DURATION_INFINITE) as this pair.
INFINITE = {"sec": 9223372036, "nsec": 854775807}
_INFINITE_NS = 9223372036854775807

_HISTORY = {0: "system_default", 1: "keep_last", 2: "keep_all", 3: "unknown"}
_RELIABILITY = {0: "system_default", 1: "reliable", 2: "best_effort", 3: "unknown",
                4: "best_available"}
_DURABILITY = {0: "system_default", 1: "transient_local", 2: "volatile", 3: "unknown",
               4: "best_available"}
_LIVELINESS = {0: "system_default", 1: "automatic", 3: "manual_by_topic", 4: "unknown",
               5: "best_available"}


def _duration(ns: int) -> dict[str, int]:
    # DDS implementations report "infinite" in several ways (INT64_MAX ns, or the DDS
    # {0x7fffffff s, 0xffffffff ns} pair): store all of them as rosbag2's infinite value.
    if ns >= 0x7FFFFFFF * 10**9 or ns < 0:
        return dict(INFINITE)
    return {"sec": ns // 10**9, "nsec": ns % 10**9}


def _ns(d: dict[str, int] | None) -> int:
    if not d:
        return 0
    sec, nsec = int(d.get("sec", 0)), int(d.get("nsec", 0))
    if (sec, nsec) == (INFINITE["sec"], INFINITE["nsec"]) or sec >= 0x7FFFFFFF:
        return _INFINITE_NS
    return sec * 10**9 + nsec


def profile_to_dict(qos) -> dict[str, Any]:
    """An ``rclpy.qos.QoSProfile`` as a rosbag2 v9 mapping."""
    return {
        "history": _HISTORY.get(int(qos.history), "unknown"),
        "depth": int(qos.depth),
        "reliability": _RELIABILITY.get(int(qos.reliability), "unknown"),
        "durability": _DURABILITY.get(int(qos.durability), "unknown"),
        "deadline": _duration(qos.deadline.nanoseconds),
        "lifespan": _duration(qos.lifespan.nanoseconds),
        "liveliness": _LIVELINESS.get(int(qos.liveliness), "unknown"),
        "liveliness_lease_duration": _duration(qos.liveliness_lease_duration.nanoseconds),
        "avoid_ros_namespace_conventions": bool(qos.avoid_ros_namespace_conventions),
    }


DEFAULT_PROFILE = {
    "history": "unknown", "depth": 0, "reliability": "reliable", "durability": "volatile",
    "deadline": INFINITE, "lifespan": INFINITE, "liveliness": "automatic",
    "liveliness_lease_duration": INFINITE, "avoid_ros_namespace_conventions": False,
}


def complete(profile: dict[str, Any]) -> dict[str, Any]:
    """A profile with every key rosbag2 (and rosbags) expect; missing keys get defaults."""
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in DEFAULT_PROFILE.items()}
    out.update(profile)
    return out


def dump_profiles(profiles: Iterable[dict[str, Any]]) -> str:
    """The YAML text of ``offered_qos_profiles`` (MCAP channel metadata)."""
    return yaml.safe_dump([complete(p) for p in profiles], default_flow_style=False,
                          sort_keys=False)


def load_profiles(text: str) -> list[dict[str, Any]]:
    """Parse ``offered_qos_profiles`` YAML (empty text -> no profiles)."""
    if not text or not text.strip():
        return []
    data = yaml.safe_load(text)
    if not isinstance(data, list):
        raise ValueError(f"offered_qos_profiles is not a YAML list: {text[:80]!r}")
    return data


def dict_to_profile(d: dict[str, Any]):
    """A rosbag2 v9 mapping back to an ``rclpy.qos.QoSProfile`` (for replay)."""
    from rclpy.duration import Duration
    from rclpy.qos import (
        DurabilityPolicy,
        HistoryPolicy,
        LivelinessPolicy,
        QoSProfile,
        ReliabilityPolicy,
    )

    def enum(cls, name, default):
        name = str(name or "").upper()
        return getattr(cls, name) if name in cls.__members__ else default

    kwargs = dict(
        history=enum(HistoryPolicy, d.get("history"), HistoryPolicy.KEEP_LAST),
        depth=max(1, int(d.get("depth", 10) or 10)),
        reliability=enum(ReliabilityPolicy, d.get("reliability"), ReliabilityPolicy.RELIABLE),
        durability=enum(DurabilityPolicy, d.get("durability"), DurabilityPolicy.VOLATILE),
        liveliness=enum(LivelinessPolicy, d.get("liveliness"), LivelinessPolicy.AUTOMATIC),
    )
    for key in ("deadline", "lifespan", "liveliness_lease_duration"):
        ns = _ns(d.get(key))
        if 0 < ns < _INFINITE_NS:
            kwargs[key] = Duration(nanoseconds=ns)
    return QoSProfile(**kwargs)


def subscription_qos(offered: list[dict[str, Any]], depth: int):
    """The QoS to subscribe with so that every offering publisher is matched (rosbag2 rule).

    ``depth`` is the minimum history depth of the subscription; a transient local topic gets
    at least the deepest publisher history so that every latched sample is delivered.
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    reliable = bool(offered) and all(p.get("reliability") == "reliable" for p in offered)
    latched = bool(offered) and all(p.get("durability") == "transient_local" for p in offered)
    deepest = max((int(p.get("depth") or 0) for p in offered), default=0)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max(int(depth), deepest, 1),
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
    )
