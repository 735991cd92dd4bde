"""``./tmgwr report BAG [-o DIR]``: what a recorded run did, from the recording alone.

The bag is read with rosbags' ``AnyReader`` (types come from the schemas embedded in the
file, no ROS installation needed) and summarised as the experiments CLI and the demo
summarise a run:

* **episodes** from ``/observation``, with the demo's own episode rules
  (:class:`tmgwr_agent.episodes.EpisodeMonitor`: resent observations ignored, steps
  count actions, an episode ends with a ``terminal`` observation: ``goal``,
  ``previous_goal`` or ``cut``), so the report states the figures the run itself stated;
* **goal changes** (``/maze_events`` lines ``step N: goal -> row R, col C``, the step whose
  observation first carries the new goal; else ``/goal`` messages): for each change, the
  episodes until the next change and the % of them that ended at the previous and at the
  current goal (the goal-change scenario's ``previous_pct`` / ``current_pct``), the % whose
  path stood on the previous goal's cell at all (``previous_visit_pct``: in the graph the
  previous goal does not end an episode), and the steps from the change until the goal is
  first reached;
* **events** (``/maze_events`` lines about events and cells): the steps from the event to
  the first time the goal is reached (the env-change scenario's ``steps``);
* for the initial learning and after every change: the shortest path in the maze then in
  force (``/maze_grid``, start cell of the first episode), the episodes until one takes it
  (``episodes_to_optimal``, counted on the run's own episodes: the graph runs no greedy
  probes) and until 3 in a row take at most 1.5 x it (the demo's "reliable");
* **map** growth: the map rebuilt step by step from the recording (:class:`MapRebuild`:
  the per-step changes of ``/sensorimotor_state`` applied to a
  :class:`~tmgwr_agent.map_replica.Replica`, which starts, and after a gap starts again,
  from the whole maps of ``/sensorimotor_snapshot``): nodes, links, mean link reliability
  E (Eq. 1-2) whenever the map's version changes (and every :data:`MAP_SAMPLE` steps); a
  recording without them uses the latched ``/map`` snapshots;
* the **final map** (the rebuilt one, else the last ``/map``) drawn over the maze
  (``/maze_grid``): every node at the cell where it most often won (``/sensorimotor_state``
  winner joined with the ``/observation`` cell of the same step), coloured by its
  motivation potential (last ``/potentials``, Eq. 4-5; older recordings: ``/motivation``),
  links coloured by E.

Writes ``report.json`` and PNG figures into DIR (default: ``BAG/report`` for a bag
directory, ``<file>_report/`` for a single file).
"""

from __future__ import annotations

import json
import re
from collections import Counter, defaultdict
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from tmgwr_agent.map_replica import APPLIED, FULL, GAP, MapChange, Replica
from tmgwr_common.topics import GraphNames

T = GraphNames()         # names at the root namespace (texts, defaults)

GOAL_EVENT = re.compile(r"step (\d+): goal -> row (-?\d+), col (-?\d+)")
STEP_EVENT = re.compile(r"step (\d+): (.*)")


MAP_SAMPLE = 50          # steps between two map-growth samples of an unchanged version


class MapRebuild:
    """The learner's map rebuilt from a recording: snapshots and per-step changes, in
    log-time order, applied to a replica; counts the changes applied, the gaps (a change
    that did not follow: the replica waits for the next whole map) and the resyncs."""

    def __init__(self):
        self.replica = Replica()
        self.applied = self.gaps = self.resyncs = 0
        self.waiting = False
        self.samples: list[dict] = []
        self._sampled = (-1, -MAP_SAMPLE)        # (version, step) of the last sample
        self._legacy = 0
        self._last = (0, -1)                     # (log time, step) of the newest state

    def on_message(self, msg, t: int, snapshot: bool) -> None:
        c = self.change_of(msg)
        status = self.replica.apply(c)
        if status == GAP:
            self.gaps += not self.waiting
            self.waiting = True
            return
        if status == APPLIED:
            self.applied += 1
            if self.waiting and c.full:
                self.resyncs += 1
            self.waiting = False
        if not snapshot:
            self._last = (t, int(msg.step_id))
            self.sample(t, int(msg.step_id))

    def finish(self) -> None:
        """A last sample at the newest state (its reliabilities may have moved since)."""
        if self.samples and self.samples[-1]["step_id"] != self._last[1]:
            self._sampled = (-1, -MAP_SAMPLE)
            self.sample(*self._last)

    def change_of(self, msg) -> MapChange:
        if hasattr(msg, "map_change"):
            return MapChange.of_fields(msg.map_change, msg.map_version, msg.run_id, msg.step_id)
        if hasattr(msg, "map"):                   # SensorimotorSnapshot
            return MapChange.of_fields(msg.map, msg.map_version, msg.run_id, msg.step_id)
        # a recording made before the per-step changes: every state holds the whole map
        self._legacy += 1
        n = int(msg.n_slots)
        fields = SimpleNamespace(map_id=1, base_sequence=FULL, sequence=self._legacy,
                                 n_slots=n, degree=msg.degree, dim=msg.dim,
                                 slots=np.arange(n, dtype=np.int32), alive=msg.alive,
                                 terminal_nodes=msg.terminal_nodes, weights=msg.weights,
                                 link_targets=msg.link_targets,
                                 link_reliability=msg.link_reliability)
        return MapChange.of_fields(fields, msg.map_version, msg.run_id, msg.step_id)

    def sample(self, t: int, step: int) -> None:
        r = self.replica
        if (r.version, step) != self._sampled and (r.version != self._sampled[0]
                                                   or step - self._sampled[1] >= MAP_SAMPLE):
            self._sampled = (r.version, step)
            nodes, links, E = self.stats()
            self.samples.append({"t": t, "step_id": step, "nodes": nodes, "links": links,
                                 "mean_reliability": E})

    def stats(self) -> tuple[int, int, float]:
        r = self.replica
        linked = r.out >= 0
        E = r.E[linked]
        return int(r.alive.sum()), int(linked.sum()), float(E.mean()) if len(E) else 0.0

    def final_map(self):
        """The rebuilt map in the form of a ``/map`` message (node ids, links)."""
        r = self.replica
        src, slot = np.nonzero(r.out >= 0)
        return SimpleNamespace(
            step_id=r.step_id, nodes=[SimpleNamespace(id=int(i)) for i in np.flatnonzero(r.alive)],
            links=[SimpleNamespace(source=int(s), target=int(r.out[s, k]),
                                   reliability=float(r.E[s, k])) for s, k in zip(src, slot)])

    def summary(self) -> dict:
        nodes, links, E = self.stats()
        return {"changes_applied": self.applied, "gaps": self.gaps, "resyncs": self.resyncs,
                "map_id": self.replica.map_id, "state": self.replica.sequence,
                "step_id": self.replica.step_id, "nodes": nodes, "links": links,
                "mean_reliability": round(E, 4)}


def default_output(bag: Path) -> Path:
    bag = Path(bag)
    return bag / "report" if bag.is_dir() else bag.with_name(bag.stem + "_report")


def _bag_paths(bag: Path) -> list[Path]:
    if bag.is_dir():
        if (bag / "metadata.yaml").is_file():
            return [bag]                       # rosbag2 directory: AnyReader reads it whole
        files = sorted(bag.glob("*.mcap"))
        if not files:
            raise FileNotFoundError(f"{bag} holds neither metadata.yaml nor .mcap files")
        return files
    if not bag.is_file():
        raise FileNotFoundError(f"{bag} does not exist")
    return [bag]


# ----------------------------------------------------------------------------- reading
def read_bag(bag: str | Path) -> dict[str, Any]:
    """Everything the report needs, in plain Python/numpy form."""
    from rosbags.highlevel import AnyReader

    from tmgwr_agent.bag.recover import require_finished
    from tmgwr_agent.bag.replay import bag_files
    from tmgwr_agent.episodes import EpisodeMonitor

    bag = Path(bag)
    data: dict[str, Any] = {"topics": {}, "goals": [], "events": [], "map": [],
                            "winners": {}, "cells": {}, "grid": None, "motivation": None,
                            "grids": [], "start_cell": None}
    monitor = EpisodeMonitor()
    rebuild = MapRebuild()
    obs_times: dict[int, int] = {}
    last_raw: dict[str, tuple[Any, bytes]] = {}
    require_finished(bag, bag_files(bag))   # a killed recorder's bag: recover it first
    with AnyReader(_bag_paths(bag)) as reader:
        T = data["names"] = GraphNames.of_bag({c.topic for c in reader.connections})
        for c in reader.connections:
            entry = data["topics"].setdefault(c.topic, {"type": c.msgtype, "count": 0})
            entry["count"] += c.msgcount
        data["start_ns"], data["end_ns"] = reader.start_time, reader.end_time
        wanted = {T.OBSERVATION, T.SENSORIMOTOR_STATE, T.MAP_SNAPSHOT, T.MAP, T.GOAL,
                  T.EVENTS, T.GRID}
        conns = [c for c in reader.connections if c.topic in wanted]
        for conn, t, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == T.OBSERVATION:
                monitor.on_observation(msg)
                sid = int(msg.step_id)
                if msg.episode_start and data.get("start_cell") is None:
                    data["start_cell"] = (int(msg.row), int(msg.col))
                obs_times.setdefault(sid, t)
                data["cells"][sid] = (int(msg.row), int(msg.col))
            elif conn.topic == T.SENSORIMOTOR_STATE:
                data["winners"][int(msg.step_id)] = int(msg.winner)
                rebuild.on_message(msg, t, snapshot=False)
            elif conn.topic == T.MAP_SNAPSHOT:
                rebuild.on_message(msg, t, snapshot=True)
            elif conn.topic == T.MAP:
                E = np.array([float(lk.reliability) for lk in msg.links])
                data["map"].append({"t": t, "step_id": int(msg.step_id),
                                    "nodes": len(msg.nodes), "links": len(msg.links),
                                    "mean_reliability": float(E.mean()) if len(E) else 0.0})
                last_raw[T.MAP] = (conn, raw)
            elif conn.topic == T.GOAL:
                data["goals"].append({"t": t, "cell": (int(round(msg.point.y)),
                                                       int(round(msg.point.x)))})
            elif conn.topic == T.EVENTS:
                data["events"].append({"t": t, "text": str(msg.data)})
            elif conn.topic == T.GRID:
                walls = np.asarray(msg.data, dtype=np.int16).reshape(
                    int(msg.info.height), int(msg.info.width)) >= 50
                data["grids"].append((t, walls))
                last_raw[T.GRID] = (conn, raw)
        # every node's potential: the newest /potentials (older recordings: /motivation,
        # which carried them every step); only the newest is needed
        mot = T.POTENTIALS if any(c.topic == T.POTENTIALS for c in reader.connections) \
            else T.MOTIVATION
        cs = [c for c in reader.connections if c.topic == mot]
        for conn, _t, raw in reader.messages(connections=cs):
            last_raw[mot] = (conn, raw)
        for topic, key in ((mot, "motivation"), (T.GRID, "grid"), (T.MAP, "final_map")):
            if topic in last_raw:
                conn, raw = last_raw[topic]
                data[key] = reader.deserialize(raw, conn.msgtype)
        if data["motivation"] is not None and not hasattr(data["motivation"], "potentials"):
            data["motivation"] = None
    if rebuild.replica.synced:                  # the exact map, step by step
        rebuild.finish()
        data["map"] = rebuild.samples
        data["final_map"] = rebuild.final_map()
    data["map_rebuild"] = rebuild.summary() if rebuild.replica.synced else None
    data["monitor"] = monitor
    data["obs_times"] = obs_times
    return data


# ----------------------------------------------------------------------------- metrics
def goal_changes(data: dict) -> list[dict]:
    """Goal changes with the step whose observation first carries the new goal."""
    out = []
    for e in data["events"]:
        m = GOAL_EVENT.search(e["text"])
        if m:
            out.append({"step": int(m.group(1)), "cell": [int(m.group(2)), int(m.group(3))],
                        "t": e["t"], "source": T.EVENTS})
    if out or len(data["goals"]) < 2:
        return out
    # no event lines recorded: the latched /goal messages after the first one, each placed
    # at the first observation received after it
    times = sorted((t, s) for s, t in data["obs_times"].items())
    for g in data["goals"][1:]:
        step = next((s for t, s in times if t >= g["t"]), None)
        if step is not None:
            out.append({"step": step, "cell": list(g["cell"]), "t": g["t"],
                        "source": T.GOAL})
    return out


def maze_events(data: dict) -> list[dict]:
    """Layout events (event fired, cell blocked/opened) with their step."""
    out = []
    for e in data["events"]:
        if GOAL_EVENT.search(e["text"]):
            continue
        m = STEP_EVENT.search(e["text"])
        if m:
            out.append({"step": int(m.group(1)), "what": m.group(2), "t": e["t"]})
    return out


def after(episodes, after_step: int, until_step: int | None = None) -> dict:
    """Episodes that ended after ``after_step`` (and not after ``until_step``): the
    goal-change percentages and the steps until the goal is first reached."""
    eps = [e for e in episodes if e.end_step > after_step
           and (until_step is None or e.end_step <= until_step)]
    n = len(eps)
    first = next((e for e in eps if e.outcome == "goal"), None)
    return {
        "after_step": after_step,
        "episodes": n,
        "steps_per_episode": [e.steps for e in eps],
        "previous_pct": 100.0 * sum(e.outcome == "previous_goal" for e in eps) / n if n else None,
        "current_pct": 100.0 * sum(e.outcome == "goal" for e in eps) / n if n else None,
        "goal_reached_episodes": sum(e.outcome == "goal" for e in eps),
        "first_goal_steps_after": (first.end_step - after_step) if first else None,
    }


STREAK, SLACK = 3, 1.5        # the demo's "reliable": 3 episodes in a row <= 1.5 x optimal


def optimal_steps(data: dict, goal, at_ns: int) -> int | None:
    """Shortest path from the start cell to ``goal`` in the maze in force at ``at_ns``
    (the newest ``/maze_grid`` recorded by then)."""
    from maze_sim.maze import bfs_distances
    grids = [w for t, w in data["grids"] if t <= at_ns] or [w for _t, w in data["grids"][:1]]
    if not grids or goal is None or data.get("start_cell") is None:
        return None
    d = int(bfs_distances(grids[-1], tuple(data["start_cell"]))[tuple(goal)])
    return d if d >= 0 else None


def convergence(eps: list, optimal: int | None) -> dict:
    """Episodes (1 = the first one counted) until one takes the shortest path, and until
    ``STREAK`` in a row reach the goal within ``SLACK`` x the shortest path."""
    first_opt = reliable = None
    if optimal:
        for k, e in enumerate(eps, 1):
            if first_opt is None and e.outcome == "goal" and e.steps == optimal:
                first_opt = k
            last = eps[max(0, k - STREAK):k]
            if reliable is None and len(last) == STREAK and all(
                    x.outcome == "goal" and x.steps <= SLACK * optimal for x in last):
                reliable = k
    return {"optimal_steps": optimal, "episodes_to_optimal": first_opt,
            "episodes_to_reliable": reliable}


def summarise(data: dict, bag: Path) -> dict:
    mon = data["monitor"]
    eps = mon.episodes
    changes = goal_changes(data)
    events = maze_events(data)
    boundaries = sorted([c["step"] - 1 for c in changes] + [e["step"] for e in events])
    initial_goal = data["goals"][0]["cell"] if data["goals"] else None

    def next_boundary(step):
        return next((b for b in boundaries if b > step), None)

    times = data["obs_times"]
    end_ns = data.get("end_ns") or 0

    def goal_at(step):
        cell = list(initial_goal) if initial_goal else None
        for c in changes:
            if c["step"] <= step:
                cell = c["cell"]
        return cell

    # first step of every episode: the step after the previous episode's end
    starts = {id(e): (eps[k - 1].end_step + 1 if k else mon.first_step_id)
              for k, e in enumerate(eps)}

    def phase(after_step, previous_cell=None):
        until = next_boundary(after_step)
        res = after(eps, after_step, until)
        in_phase = [e for e in eps if e.end_step > after_step
                    and (until is None or e.end_step <= until)]
        at = times.get(after_step + 1, end_ns)
        res.update(convergence(in_phase, optimal_steps(data, goal_at(after_step + 1), at)))
        if previous_cell is not None:
            # the previous goal need not end an episode (the graph's /set_goal drops it):
            # count the episodes whose path stood on its cell at all
            cell = tuple(previous_cell)
            passed = sum(any(data["cells"].get(s) == cell
                             for s in range(starts[id(e)], e.end_step + 1)) for e in in_phase)
            res["previous_visit_pct"] = 100.0 * passed / len(in_phase) if in_phase else None
        return res

    transitions = []
    previous = list(initial_goal) if initial_goal else None
    for c in changes:
        # the new goal is sensed from step c['step']: step c['step'] - 1 is the last one
        # under the old goal (the demo's "at_step" of the /set_goal call)
        transitions.append({"step": c["step"], "from": previous, "to": c["cell"],
                            **phase(c["step"] - 1, previous)})
        previous = c["cell"]
    event_rows = [{"step": e["step"], "what": e["what"], **phase(e["step"])} for e in events]
    first_phase = phase(mon.first_step_id - 1) if eps else None
    seconds = (data["end_ns"] - data["start_ns"]) / 1e9 if data.get("end_ns") else 0.0
    steps_total = mon.last_step_id - mon.first_step_id + 1 if mon.first_step_id >= 0 else 0
    final = data["map"][-1] if data["map"] else None
    return {
        "bag": str(bag),
        "seconds": round(seconds, 3),
        "topics": data["topics"],
        "steps": {"first": mon.first_step_id, "last": mon.last_step_id,
                  "count": steps_total, "seen": mon.seen, "missed": mon.missed,
                  "steps_per_s": round(_rate(data), 1)},
        "episodes": {
            "count": len(eps),
            "steps_per_episode": [e.steps for e in eps],
            "end_steps": [e.end_step for e in eps],
            "outcomes": dict(Counter(e.outcome for e in eps)),
        },
        "initial_goal": initial_goal,
        "start_cell": list(data["start_cell"]) if data.get("start_cell") else None,
        "learning": ({k: first_phase[k] for k in ("episodes", "optimal_steps",
                                                   "episodes_to_optimal",
                                                   "episodes_to_reliable")}
                     if first_phase else None),
        "goal_changes": transitions,
        "events": event_rows,
        "map": ({"snapshots": len(data["map"]), "nodes": final["nodes"],
                 "links": final["links"], "mean_reliability": round(final["mean_reliability"], 4),
                 "step_id": final["step_id"],
                 "source": T.SENSORIMOTOR_STATE if data.get("map_rebuild") else T.MAP,
                 "rebuilt": data.get("map_rebuild")} if final else None),
    }


def _rate(data: dict) -> float:
    times = data["obs_times"]
    if len(times) < 2:
        return 0.0
    s0, s1 = min(times), max(times)
    dt = (times[s1] - times[s0]) / 1e9
    return (s1 - s0) / dt if dt > 0 else 0.0


# ----------------------------------------------------------------------------- figures
def _figures(data: dict, summary: dict, out: Path) -> list[str]:
    """Draw every figure into ``out``; returns the files written."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t_of = _seconds_since_start(data)
    files = [
        _steps_per_episode(data["monitor"].episodes, summary, t_of,
                           out / "steps_per_episode.png"),
        _goal_change_visits(summary, out / "goal_change_visits.png"),
        _steps_to_goal(summary, out / "steps_to_goal.png"),
        _map_over_time(data, summary, t_of, out / "map_over_time.png"),
        _final_map(data, out / "final_map.png"),
    ]
    plt.close("all")
    return files


def _seconds_since_start(data: dict):
    """``t_of(step)``: seconds from the start of the recording to the step's observation
    (the figures over time share this axis)."""
    t0 = data.get("start_ns") or 0
    times = data["obs_times"]

    def t_of(step):
        return (times.get(step, t0) - t0) / 1e9

    return t_of


def _mark_changes(ax, summary: dict, t_of) -> None:
    """Vertical lines at every goal change (purple) and maze event (red), labelled."""
    for c in summary["goal_changes"]:
        x = t_of(c["step"])
        ax.axvline(x, color="tab:purple", ls="--", lw=1)
        ax.annotate(f'goal -> {tuple(c["to"])}', (x, 1), xycoords=("data", "axes fraction"),
                    rotation=90, va="top", ha="right", fontsize=7, color="tab:purple")
    for e in summary["events"]:
        x = t_of(e["step"])
        ax.axvline(x, color="tab:red", ls=":", lw=1)
        ax.annotate(e["what"], (x, 1), xycoords=("data", "axes fraction"), rotation=90,
                    va="top", ha="right", fontsize=7, color="tab:red")


def _steps_per_episode(eps: list, summary: dict, t_of, path: Path) -> str:
    """Steps per episode over time, coloured by how the episode ended."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    colours = {"goal": "tab:green", "previous_goal": "tab:orange", "cut": "tab:gray"}
    for outcome, colour in colours.items():
        sel = [e for e in eps if e.outcome == outcome]
        ax.scatter([t_of(e.end_step) for e in sel], [e.steps for e in sel], s=12, c=colour,
                   label=outcome.replace("_", " "))
    ax.plot([t_of(e.end_step) for e in eps], [e.steps for e in eps], lw=0.5, c="k", alpha=0.4)
    _mark_changes(ax, summary, t_of)
    ax.set_xlabel("time since the recording started (s)")
    ax.set_ylabel("steps in the episode")
    ax.set_title("Steps per episode")
    ax.legend(fontsize=8)
    return _save(fig, path)


def _goal_change_visits(summary: dict, path: Path) -> str:
    """After each goal change: % of the episodes that ended at the previous goal, passed
    its cell, and ended at the current goal (the goal-change scenario's figures)."""
    import matplotlib.pyplot as plt

    tr = summary["goal_changes"]
    fig, ax = plt.subplots(figsize=(max(4, 1.6 * len(tr) + 2), 3.5))
    if tr:
        x = np.arange(len(tr))
        ax.bar(x - 0.27, [t["previous_pct"] or 0 for t in tr], 0.27,
               label="ended at the previous goal", color="tab:orange")
        ax.bar(x, [t.get("previous_visit_pct") or 0 for t in tr], 0.27,
               label="passed the previous goal's cell", color="navajowhite")
        ax.bar(x + 0.27, [t["current_pct"] or 0 for t in tr], 0.27,
               label="ended at the current goal", color="tab:green")
        ax.legend(fontsize=7, loc="upper center", ncol=1)
        ax.set_xticks(x, [f'{tuple(t["from"]) if t["from"] else "?"}->{tuple(t["to"])}\n'
                          f'step {t["step"]}, {t["episodes"]} ep.' for t in tr], fontsize=7)
    else:
        ax.text(0.5, 0.5, "no goal change recorded", ha="center", va="center",
                transform=ax.transAxes)
    ax.set_ylim(0, 140)                     # room for the legend above the bars
    ax.set_yticks(range(0, 101, 20))
    ax.set_ylabel("% of the episodes after the change")
    ax.set_title("Visits after each goal change")
    return _save(fig, path)


def _steps_to_goal(summary: dict, path: Path) -> str:
    """Steps from each goal change and event until the goal is first reached, against the
    shortest path then in force."""
    import matplotlib.pyplot as plt

    tr, events = summary["goal_changes"], summary["events"]
    rows = [(f'goal -> {tuple(t["to"])}\n(step {t["step"]})', t["first_goal_steps_after"])
            for t in tr] + [(f'{e["what"]}\n(step {e["step"]})', e["first_goal_steps_after"])
                            for e in events]
    fig, ax = plt.subplots(figsize=(max(4, 1.6 * len(rows) + 2), 3.5))
    if rows:
        vals = [v if v is not None else 0 for _l, v in rows]
        bars = ax.bar(range(len(rows)), vals, color=["tab:purple"] * len(tr) +
                      ["tab:red"] * len(events))
        for b, (_l, v) in zip(bars, rows):
            ax.annotate("not reached" if v is None else str(v), (b.get_x() + b.get_width() / 2,
                        b.get_height()), ha="center", va="bottom", fontsize=8)
        ax.set_xticks(range(len(rows)), [label for label, _v in rows], fontsize=7)
        optimal = [t["optimal_steps"] for t in tr] + [e["optimal_steps"] for e in events]
        xs = [k for k, o in enumerate(optimal) if o]
        if xs:
            ax.scatter(xs, [optimal[k] for k in xs], marker="_", s=900, c="k", zorder=3,
                       label="shortest path")
            ax.legend(fontsize=8, loc="upper left", markerscale=0.4)
    else:
        ax.text(0.5, 0.5, "no goal change or event recorded", ha="center", va="center",
                transform=ax.transAxes)
    ax.set_ylabel("steps until the goal is first reached")
    ax.set_title("Steps to the goal after each change")
    return _save(fig, path)


def _map_over_time(data: dict, summary: dict, t_of, path: Path) -> str:
    """The map's nodes and links, and its mean link reliability E, over time."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    if data["map"]:
        t0 = data.get("start_ns") or 0
        tm = [(m["t"] - t0) / 1e9 for m in data["map"]]
        ax.plot(tm, [m["nodes"] for m in data["map"]], label="nodes", c="tab:blue")
        ax.plot(tm, [m["links"] for m in data["map"]], label="links", c="tab:cyan")
        ax.set_ylabel("count")
        ax2 = ax.twinx()
        ax2.plot(tm, [m["mean_reliability"] for m in data["map"]], c="tab:green",
                 label="mean link reliability E")
        ax2.set_ylabel("mean reliability E (Eq. 1-2)")
        ax2.set_ylim(0, 1.05)
        h1, l1 = ax.get_legend_handles_labels()
        h2, l2 = ax2.get_legend_handles_labels()
        ax.legend(h1 + h2, l1 + l2, fontsize=8, loc="lower right")
        _mark_changes(ax, summary, t_of)
    else:
        ax.text(0.5, 0.5, f"no {T.SENSORIMOTOR_STATE} or {T.MAP} messages recorded",
                ha="center", va="center",
                transform=ax.transAxes)
    ax.set_xlabel("time since the recording started (s)")
    ax.set_title("Sensorimotor map size and reliability")
    return _save(fig, path)


def node_cells(data: dict) -> dict[int, tuple[int, int]]:
    """Each node's cell: where it most often won (winner of step s, cell of step s)."""
    votes: dict[int, Counter] = defaultdict(Counter)
    for sid, w in data["winners"].items():
        cell = data["cells"].get(sid)
        if w >= 0 and cell is not None:
            votes[w][cell] += 1
    return {n: c.most_common(1)[0][0] for n, c in votes.items()}


def _final_map(data: dict, path: Path) -> str:
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    fig, ax = plt.subplots(figsize=(7, 6))
    grid = data.get("grid")
    if grid is not None:
        walls = (np.asarray(grid.data, dtype=np.int16).reshape(grid.info.height,
                                                                grid.info.width) >= 50)
        ax.imshow(walls, cmap="Greys", vmin=0, vmax=1.5, origin="upper")
    cells = node_cells(data)
    final = data.get("final_map")
    alive = {int(n.id) for n in final.nodes} if final is not None else set(cells)
    pos = {n: np.array([c[1], c[0]], float) for n, c in cells.items() if n in alive}
    # several nodes in one cell: spread them on a small circle so all are visible
    by_cell: dict[tuple, list[int]] = defaultdict(list)
    for n, c in cells.items():
        if n in pos:
            by_cell[c].append(n)
    for members in by_cell.values():
        if len(members) > 1:
            for k, n in enumerate(sorted(members)):
                a = 2 * np.pi * k / len(members)
                pos[n] = pos[n] + 0.22 * np.array([np.cos(a), np.sin(a)])
    if final is not None and pos:
        segs, rel = [], []
        for lk in final.links:
            s, t = int(lk.source), int(lk.target)
            if s in pos and t in pos:
                segs.append([pos[s], pos[t]])
                rel.append(float(lk.reliability))
        if segs:
            lc = LineCollection(segs, cmap="RdYlGn", linewidths=1.2, alpha=0.8)
            lc.set_array(np.array(rel))
            lc.set_clim(0, 1)
            ax.add_collection(lc)
            fig.colorbar(lc, ax=ax, fraction=0.04, pad=0.08, orientation="horizontal",
                         label="link reliability E (Eq. 1-2)")
    potentials = {}
    mot = data.get("motivation")
    if mot is not None:
        potentials = {int(i): float(v) for i, v in zip(mot.node_ids, mot.potentials)}
    if pos:
        ids = sorted(pos)
        xy = np.array([pos[i] for i in ids])
        v = np.array([potentials.get(i, np.nan) for i in ids])
        sc = ax.scatter(xy[:, 0], xy[:, 1], c=np.nan_to_num(v, nan=0.0), cmap="plasma", s=45,
                        edgecolors="k", linewidths=0.4, zorder=3)
        fig.colorbar(sc, ax=ax, fraction=0.04, pad=0.02, label="motivation potential (Eq. 4-5)")
    if data["goals"]:
        r, c = data["goals"][-1]["cell"]
        ax.scatter([c], [r], marker="*", s=300, c="gold", edgecolors="k", zorder=4,
                   label="goal")
        ax.legend(loc="upper right", fontsize=8)
    ax.set_title(f"Final map: {len(pos)} nodes at the cells where they won"
                 + (f", {len(final.links)} links" if final is not None else ""))
    ax.set_xlabel("column")
    ax.set_ylabel("row")
    return _save(fig, path)


def _save(fig, path: Path) -> str:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return str(path)


# ----------------------------------------------------------------------------- entry
def name_goals(summary: dict, maze_path: str | Path) -> None:
    """Add the maze's goal names (``G``, ``1``-``9``) beside the goal cells, as the
    experiments CLI names its transitions."""
    from maze_sim.maze import Maze, maze_file
    names = {tuple(c): n for n, c in Maze.from_file(maze_file(maze_path)).goals.items()}

    def name(cell):
        return names.get(tuple(cell)) if cell is not None else None

    summary["maze"] = str(maze_path)
    summary["initial_goal_name"] = name(summary["initial_goal"])
    for t in summary["goal_changes"]:
        t["from_name"], t["to_name"] = name(t["from"]), name(t["to"])


def report(bag: str | Path, output: str | Path | None = None, figures: bool = True,
           maze: str | Path | None = None) -> dict:
    """Read ``bag``, write ``report.json`` and the figures; returns the summary.
    ``maze`` (the run's maze file, optional) names the goal cells."""
    bag = Path(bag)
    data = read_bag(bag)
    if data["names"].OBSERVATION not in data["topics"]:
        raise ValueError(f'{bag} has no {T.OBSERVATION} topic: not a recording of the graph '
                         f'(topics: {", ".join(sorted(data["topics"])) or "none"})')
    summary = summarise(data, bag)
    if maze:
        name_goals(summary, maze)
    out = Path(output) if output else default_output(bag)
    out.mkdir(parents=True, exist_ok=True)
    summary["output"] = {"dir": str(out), "json": str(out / "report.json"),
                         "figures": _figures(data, summary, out) if figures else []}
    (out / "report.json").write_text(json.dumps(summary, indent=2, default=_jsonable))
    return summary


def _jsonable(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, tuple):
        return list(o)
    raise TypeError(f"not JSON serialisable: {type(o)}")
