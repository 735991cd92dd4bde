"""``experiment env-change | goal-change --suite SPEC``: a scenario over generated mazes.

The mazes come from :func:`maze_sim.suite.suite` (``SPEC`` = ``FAMILY[:N]``, ``all[:N]``
or a comma list such as ``braided:3,rooms:3``; ``--suite-seed`` and ``--suite-first``
pick the seed and the first index of each family, so a disjoint ``--suite-first`` is a
held-out split). Every maze is written as ``NAME.txt`` into a maze folder (``OUT_mazes/``
beside ``--json OUT.json``; a temporary folder when the JSON goes to stdout) and run by
the scenario's own trial function, with the trial seeds of ``--seed`` (the same ones for
every maze). So one maze's entry of the suite JSON is exactly what
``experiment SCENARIO --maze OUT_mazes/NAME.txt --seed S --trials N --event E`` (or
``--goals ...``) gives for the same agents.

* env-change: each maze's block event (``--event block``, the default; ``a`` is accepted)
  or its opening event (``--event open`` or ``b``: a new shortcut). ``steps`` counts the
  steps of the first episode after the event, ``oracle_steps`` is
  :func:`.env_change.oracle_steps` (for an opening the agent cannot know of, the old
  shortest path). It bounds an agent that keeps to its old optimal route until it bumps;
  one that leaves the route before the block (an exploratory step, or a wall sensor
  seeing the new wall) can beat it, down to ``shortest_after``: a ratio below 1 is
  possible. ``episodes_to_optimal`` counts the episodes after the event until a
  greedy rollout takes a shortest path of the *new* maze: for an opening, whose new
  shortest path is strictly shorter than every old path, that is the first time the
  greedy path uses the shortcut.
* goal-change: each maze's named goals in the order ``1, 2, 3, 4, 1``
  (``SuiteMaze.goal_sequence``; ``--goals`` overrides it), ``--episodes`` per goal.

A maze without the event (``shortcut`` mazes have no block, ``blocking`` mazes no
opening) or without the goals is skipped and listed in ``suite.skipped``.

Parameter overrides (``--params``) apply to every maze and are recorded as ``params``
before ``agents``, as in a single-maze run (:func:`.scenarios.params_record`).

JSON: the scenario's header (``sensor`` included: ``--sensor`` applies to every maze) and
``agents`` (each statistic over every trial of every maze,
maze by maze; env-change adds ``oracle_ratio``: steps / oracle_steps per trial), then::

    "suite": {"spec", "seed", "first", "event" (env-change: "block" | "open"),
      "mazes": [{"name", "family", "index", "file", "free_cells",
                 env-change: "event", "oracle_steps", "shortest_before", "shortest_after",
                 goal-change: "goals",
                 "caps", "agents": {NAME: the scenario's per-agent entry on this maze}}],
      "skipped": [{"name", "family", "reason"}],
      "families": {FAMILY: SUMMARY}, "overall": SUMMARY}

A maze's *score* of an agent is the median over its trials, a failed trial (``null``)
counting as infinitely long (so a maze where most trials fail scores ``null``); the
``median`` beside a family's STAT treats its ``null`` values the same way. An
env-change ``SUMMARY`` (over the mazes of the family, or over all of them)::

    {"mazes": n, "skipped": k, "trials": trials per agent,
     "oracle_ratio": {NAME: STAT + "median", one value per maze: score / oracle_steps},
     "steps": {NAME: STAT + "median" of the scores},
     "episodes_to_optimal": {NAME: STAT + "median" of the per-maze median},
     "win_rate": {NAME: {OTHER: fraction of mazes where NAME's score < OTHER's}},
     "failures": {NAME: trials with steps null},
     "train_failures": {NAME: trials that did not converge before the event (they still
                        go on to it: env_change's step 1)},
     "worst_trial_ratio": {NAME: largest steps / oracle_steps of a trial that reached
                           the goal (null if none)},
     "optimal_within_10": {NAME: fraction of trials with episodes_to_optimal <= 10},
     "optimal_found": {NAME: fraction of trials with episodes_to_optimal not null},
     "episodes_win_rate": {NAME: {OTHER: as win_rate, on the per-maze median
                                  episodes_to_optimal}},
     "max_nodes_per_cell": {NAME: largest nodes / free_cells of a trial, for the agents
                            with a learnt map (their ``nodes`` when the event fired)}}

With ``--event-delay K`` (K > 0) each maze's agents also hold ``settled_steps`` (the mean
steps of the K learning episodes between convergence and the event, per trial) and the
SUMMARY ``settled_ratio`` ({NAME: STAT + "median" over mazes of each maze's median trial
over ``shortest_before``}); with several delays the JSON holds one ``agents`` and
``suite`` per delay under ``delays`` (:func:`.env_change.with_delays`).

For an opening the first episode's steps hardly differ from the old path (the oracle):
the measures that matter are ``optimal_within_10``, ``optimal_found`` and
``episodes_win_rate``.

A goal-change ``SUMMARY``: ``current_pct`` (STAT + median over mazes of the maze's mean %
of episodes ending at the current goal, over transitions and trials), ``worst_pct``
(the smallest % of any transition of any trial), ``perfect_trials`` (fraction of the
trials with every episode of every transition at the current goal), ``win_rate`` (mean
% higher), plus ``mazes``, ``skipped``, ``trials``.
"""

from __future__ import annotations

import math
import statistics
import tempfile
from dataclasses import asdict
from functools import partial
from pathlib import Path
from typing import Any, Mapping, Sequence

from maze_sim.suite import SuiteError, SuiteMaze, suite
from maze_sim.worlds import WorldSpec
from tmgwr_agent.experiments import env_change, goal_change
from tmgwr_agent.experiments.parallel import run_items, trial_seeds
from tmgwr_agent.experiments.runner import (
    Caps,
    declared_probe_tolerance,
    scenario_trial,
    with_overrides,
)
from tmgwr_agent.experiments.scenarios import (
    DEFAULTS,
    UsageError,
    check_delays,
    check_overrides,
    check_sensor_spec,
    check_world_spec,
    params_record,
    parse_sensor_spec,
)
from tmgwr_agent.experiments.stats import stat

SUITE_SCENARIOS = ("env-change", "goal-change")
#: --event with --suite: the event kind, and the SuiteMaze attribute that names it.
EVENT_KINDS = {"block": "block", "a": "block", "open": "open", "b": "open"}
GOAL = "G"
WITHIN = 10        # optimal_within_10: episodes after the event


def maze_dir_for(json_path: str | Path) -> Path:
    """``results/x.json`` -> ``results/x_mazes``."""
    p = Path(json_path)
    return p.with_name(p.stem + "_mazes")


def _median_score(values: Sequence) -> float | None:
    """Median with failed trials (None) as +inf; None when the median is infinite."""
    m = statistics.median([math.inf if v is None else float(v) for v in values])
    return None if math.isinf(m) else m


def _stat_median(values: Sequence) -> dict:
    """STAT plus ``median`` (a null value counting as infinite, as in a maze's score)."""
    s = stat(values)
    s["median"] = _median_score(s["values"]) if s["values"] else None
    return s


def _fraction(values: Sequence, pred) -> float | None:
    return sum(bool(pred(v)) for v in values) / len(values) if values else None


def _wins(scores: dict[str, list], higher_better: bool = False) -> dict:
    """Fraction of mazes where one agent's score beats another's (None = worst; a tie,
    or both None, is no win)."""
    bad = -math.inf if higher_better else math.inf

    def key(v):
        return bad if v is None else v

    out = {}
    for a, sa in scores.items():
        out[a] = {}
        for b, sb in scores.items():
            if a == b or not sa:
                continue
            won = sum((key(x) > key(y)) if higher_better else (key(x) < key(y))
                      for x, y in zip(sa, sb))
            out[a][b] = won / len(sa)
    return out


# ------------------------------------------------------------------ env-change summaries
def _env_summary(mazes: list[dict], agents: list[str], trials: int, skipped: int,
                 delay: int = 0) -> dict:
    out: dict = {"mazes": len(mazes), "skipped": skipped, "trials": trials}
    scores = {a: [_median_score(m["agents"][a]["steps"]["values"]) for m in mazes]
              for a in agents}
    out["oracle_ratio"] = {a: _stat_median([None if s is None else s / m["oracle_steps"]
                                            for s, m in zip(scores[a], mazes)])
                           for a in agents}
    out["steps"] = {a: _stat_median(scores[a]) for a in agents}
    out["episodes_to_optimal"] = {
        a: _stat_median([_median_score(m["agents"][a]["episodes_to_optimal"]["values"])
                         for m in mazes]) for a in agents}
    out["win_rate"] = _wins(scores)
    for key, field in (("failures", "steps"), ("train_failures", "train_episodes")):
        out[key] = {a: sum(v is None for m in mazes for v in m["agents"][a][field]["values"])
                    for a in agents}
    worst = {}
    for a in agents:
        ratios = [v / m["oracle_steps"] for m in mazes
                  for v in m["agents"][a]["steps"]["values"] if v is not None]
        worst[a] = max(ratios) if ratios else None
    out["worst_trial_ratio"] = worst
    for key, pred in ((f"optimal_within_{WITHIN}", lambda v: v is not None and v <= WITHIN),
                      ("optimal_found", lambda v: v is not None)):
        out[key] = {a: _fraction([v for m in mazes
                                  for v in m["agents"][a]["episodes_to_optimal"]["values"]],
                                 pred) for a in agents}
    out["episodes_win_rate"] = _wins({a: out["episodes_to_optimal"][a]["values"]
                                      for a in agents})
    out["max_nodes_per_cell"] = {
        a: max((v / m["free_cells"] for m in mazes
                for v in m["agents"][a]["nodes"]["values"]), default=None)
        for a in agents if mazes and all("nodes" in m["agents"][a] for m in mazes)}
    if delay:
        out["settled_ratio"] = {
            a: _stat_median([statistics.median(m["agents"][a]["settled_steps"]["values"])
                             / m["shortest_before"] for m in mazes]) for a in agents}
    return out


def _env_maze(sm: SuiteMaze, event: str, res: dict[str, list[dict]],
              world: WorldSpec | None = None, delay: int = 0) -> dict:
    maze = sm.maze()
    return {"event": event, **env_change.event_oracle(world, maze, event, GOAL),
            "caps": asdict(Caps.for_maze(maze)),
            "agents": {a: {k: stat(r[k] for r in rs)
                           for k in env_change.agent_keys(rs, delay)}
                       for a, rs in res.items()}}


def _env_agents(mazes: list[dict], agents: list[str], delay: int = 0) -> dict:
    out = {}
    for a in agents:
        d = {k: stat(v for m in mazes for v in m["agents"][a][k]["values"])
             for k in env_change.agent_keys([m["agents"][a] for m in mazes], delay)}
        d["oracle_ratio"] = stat(None if v is None else v / m["oracle_steps"]
                                 for m in mazes for v in m["agents"][a]["steps"]["values"])
        out[a] = d
    return out


# ----------------------------------------------------------------- goal-change summaries
def _goal_rows(per_trial: list[list[dict]]) -> list[dict]:
    return [{"from": tr["from"], "to": tr["to"],
             "previous_pct": stat(p[k]["previous_pct"] for p in per_trial),
             "current_pct": stat(p[k]["current_pct"] for p in per_trial),
             "learning_steps": stat(p[k]["learning_steps"] for p in per_trial)}
            for k, tr in enumerate(per_trial[0])]


def _goal_summary(mazes: list[dict], raw: dict[str, dict[str, list]], agents: list[str],
                  trials: int, skipped: int) -> dict:
    out: dict = {"mazes": len(mazes), "skipped": skipped, "trials": trials}
    scores = {a: [statistics.fmean(v for t in m["agents"][a]["transitions"]
                                   for v in t["current_pct"]["values"]) for m in mazes]
              for a in agents}
    out["current_pct"] = {a: _stat_median(scores[a]) for a in agents}
    out["worst_pct"] = {a: min((tr["current_pct"] for m in mazes
                                for trial in raw[m["name"]][a] for tr in trial),
                               default=None) for a in agents}
    out["perfect_trials"] = {}
    for a in agents:
        runs = [trial for m in mazes for trial in raw[m["name"]][a]]
        out["perfect_trials"][a] = (sum(all(tr["current_pct"] == 100.0 for tr in trial)
                                        for trial in runs) / len(runs) if runs else None)
    out["win_rate"] = _wins(scores, higher_better=True)
    return out


# ------------------------------------------------------------------------------ the run
def select(mazes: list[SuiteMaze], scenario: str, kind: str | None,
           goals: Sequence[str] | None) -> tuple[list[tuple[SuiteMaze, object]], list[dict]]:
    """``([(maze, event or goal tuple)], skipped)``: what each maze runs, and why not."""
    run, skipped = [], []
    for sm in mazes:
        if scenario == "env-change":
            ev = sm.block_event if kind == "block" else sm.open_event
            if ev is None:
                skipped.append({"name": sm.name, "family": sm.family,
                                "reason": f"no {kind} event"})
            else:
                run.append((sm, ev))
        else:
            seq = tuple(goals) if goals else sm.goal_sequence
            missing = sorted(set(seq) - set(sm.goals))
            if len(seq) < 2 or missing:
                skipped.append({"name": sm.name, "family": sm.family,
                                "reason": f"no goal {', '.join(missing)}" if missing
                                else "fewer than two goals"})
            else:
                run.append((sm, seq))
    return run, skipped


def run_suite(scenario: str, spec: str, agents: Sequence[str] | None = None,
              trials: int = 10, seed: int = 0, suite_seed: int = 0, first: int = 0,
              event: str = "block", goals: Sequence[str] | None = None,
              episodes: int | None = None, jobs: int | None = None, progress: bool = True,
              maze_dir: str | Path | None = None,
              overrides: Mapping[str, Mapping[str, Any]] | None = None,
              params_files: Sequence[str] = (), sensor: str | None = None,
              world: str | None = None, world_kwargs: str | None = None,
              delays: str | Sequence[int] | None = None) -> dict:
    """Run ``scenario`` on every maze of ``spec``; returns the suite JSON (see above).
    ``maze_dir``: where the maze files go (None: a temporary folder, removed after);
    ``overrides``, ``params_files``, ``sensor``, ``world``, ``world_kwargs``, ``delays``:
    as for :func:`.scenarios.run_scenario` (a ``gym:ID`` world has no suite; several
    delays: one suite body per delay, :func:`.env_change.with_delays`)."""
    if scenario not in SUITE_SCENARIOS:
        raise UsageError(f"--suite runs {' and '.join(SUITE_SCENARIOS)}, not {scenario}")
    delays = check_delays(delays, scenario)
    if trials < 1:
        raise UsageError(f"--trials must be >= 1, got {trials}")
    if suite_seed < 0 or first < 0:
        raise UsageError("--suite-seed and --suite-first must be >= 0")
    kind = None
    if scenario == "env-change":
        if event not in EVENT_KINDS:
            raise UsageError(f"with --suite, --event is block or open (or a / b), "
                             f"got {event!r}")
        kind = EVENT_KINDS[event]
    wspec, agents = check_world_spec(world, world_kwargs, agents,
                                     DEFAULTS[scenario]["agents"], scenario,
                                     parse_sensor_spec(sensor))
    sensor = check_sensor_spec(sensor, agents).text
    if not wspec.from_maze:
        raise UsageError(f"--world {wspec.text}: a registered env is one layout, not a "
                         f"suite of mazes")
    if scenario == "goal-change":
        episodes = episodes if episodes is not None else goal_change.DEFAULT_EPISODES
        if episodes < 1:
            raise UsageError(f"--episodes must be >= 1, got {episodes}")
    try:
        mazes = suite(spec, suite_seed, first)
    except SuiteError as exc:
        raise UsageError(str(exc)) from exc
    todo, skipped = select(mazes, scenario, kind, goals)
    params = None
    if overrides is not None:
        probe = (todo[0][0] if todo else mazes[0]).maze()     # agents built once on it
        overrides = check_overrides(agents, overrides, probe)
        params = (overrides, tuple(params_files))
    if maze_dir is None:
        with tempfile.TemporaryDirectory(prefix="tmgwr_suite_") as tmp:
            return _run(scenario, spec, agents, trials, seed, suite_seed, first, kind,
                        episodes, jobs, progress, Path(tmp), mazes, todo, skipped, params,
                        sensor, wspec, delays)
    return _run(scenario, spec, agents, trials, seed, suite_seed, first, kind, episodes,
                jobs, progress, Path(maze_dir), mazes, todo, skipped, params, sensor, wspec,
                delays)


def _run(scenario, spec, agents, trials, seed, suite_seed, first, kind, episodes, jobs,
         progress, maze_dir: Path, mazes, todo, skipped, params, sensor: str,
         wspec: WorldSpec, delays: tuple[int, ...] = (0,)) -> dict:
    for sm in mazes:                      # every maze, skipped ones too: all inspectable
        sm.write(maze_dir)
    seeds = trial_seeds(seed, trials)
    items, owner = [], []
    several = len(delays) > 1 or delays[0] != 0
    for k in delays:
        for m, (sm, arg) in enumerate(todo):
            path = str(maze_dir / f"{sm.name}.txt")
            extra = (path, arg, GOAL) if scenario == "env-change" else (path, arg, episodes)
            for a in agents:
                for t in range(trials):
                    items.append((a, t, seeds[t]) + extra + ((k,) if several else ()))
                    owner.append((k, m, a))
    fn = env_change.trial if scenario == "env-change" else goal_change.trial
    fn = scenario_trial(fn, sensor, wspec)
    if several:                           # the delay rides as each item's last argument
        fn = partial(env_change.trial_at_delay, fn)
    fn = with_overrides(fn, params[0] if params else None)
    # Biggest mazes first (the pool's tail is shorter); results go back in item order.
    order = sorted(range(len(items)), key=lambda i: -todo[owner[i][1]][0].free_cells)
    done = run_items(fn, [items[i] for i in order], jobs,
                     f"{scenario} suite {spec}", progress)
    flat: list = [None] * len(items)
    for i, r in zip(order, done):
        flat[i] = r
    views = []
    for k in delays:
        res: list[dict[str, list]] = [{a: [] for a in agents} for _ in todo]
        for (kk, m, a), r in zip(owner, flat):
            if kk == k:
                res[m][a].append(r)
        views.append((k, _body(scenario, spec, agents, trials, seed, suite_seed, first,
                               kind, episodes, mazes, todo, skipped, params, sensor, wspec,
                               res, k)))
    return env_change.with_delays(views)


def _body(scenario, spec, agents, trials, seed, suite_seed, first, kind, episodes, mazes,
          todo, skipped, params, sensor: str, wspec: WorldSpec, res: list[dict[str, list]],
          delay: int) -> dict:
    """The suite JSON of one delay's results ``res`` (per maze of ``todo``, per agent)."""
    entries, raw = [], {}
    for (sm, arg), r in zip(todo, res):
        entry = {"name": sm.name, "family": sm.family, "index": sm.index,
                 "file": f"{sm.name}.txt", "free_cells": sm.free_cells}
        if scenario == "env-change":
            entry.update(_env_maze(sm, arg, r, wspec, delay))
        else:
            entry.update({"goals": list(arg), "caps": asdict(Caps.for_maze(sm.maze())),
                          "agents": {a: {"transitions": _goal_rows(rs)}
                                     for a, rs in r.items()}})
            raw[sm.name] = r
        entries.append(entry)

    families = []
    for sm in mazes:
        if sm.family not in families:
            families.append(sm.family)

    def summary(ms: list[dict], n_skipped: int) -> dict:
        if scenario == "env-change":
            return _env_summary(ms, agents, trials, n_skipped, delay)
        return _goal_summary(ms, raw, agents, trials, n_skipped)

    fam_summary = {f: summary([e for e in entries if e["family"] == f],
                              sum(s["family"] == f for s in skipped)) for f in families}
    out: dict = {"scenario": scenario, "maze": None, "trials": trials, "seed": seed,
                 "sensor": sensor, "world": wspec.text}
    if wspec.kwargs:
        out["world_kwargs"] = dict(wspec.kwargs)
    if declared_probe_tolerance(wspec):
        out["probe_tolerance"] = declared_probe_tolerance(wspec)
    if scenario == "env-change":
        out.update({"event": kind, "goal": GOAL})
    else:
        seqs = {tuple(e["goals"]) for e in entries}
        out["episodes"] = episodes
        out["goals"] = list(next(iter(seqs))) if len(seqs) == 1 else None
    if params:
        out["params"] = params_record(*params)
    if scenario == "env-change":
        out["agents"] = _env_agents(entries, agents, delay)
    else:
        out["agents"] = ({a: {"transitions": _goal_rows(
            [trial for e in entries for trial in raw[e["name"]][a]])} for a in agents}
            if len(seqs) == 1 else {})
    out["suite"] = {"spec": spec, "seed": suite_seed, "first": first}
    if kind:
        out["suite"]["event"] = kind
    out["suite"].update({"mazes": entries, "skipped": skipped, "families": fam_summary,
                         "overall": summary(entries, len(skipped))})
    return out


# ------------------------------------------------------------------------------ report
def _f(v, digits: int = 2) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def table(result: dict) -> str:
    """Per family and agent: median oracle ratio (env-change) or mean % at the current
    goal (goal-change), failures, and win rates against every other agent (on
    ``episodes_to_optimal`` for openings); after an event delay K > 0 also the median
    ``settled_ratio``; several delays: one table per delay."""
    views = env_change.delay_views(result) if result["scenario"] == "env-change" \
        else [(0, result)]
    if len(views) == 1 and not views[0][0]:
        return _table(result)
    return "\n\n".join(f"event delay {k}:\n{_table(v, k)}" for k, v in views)


def _table(result: dict, delay: int = 0) -> str:
    s = result["suite"]
    agents = list(result["agents"]) or (list(s["mazes"][0]["agents"]) if s["mazes"] else [])
    lines = []
    env = result["scenario"] == "env-change"
    opening = env and s.get("event") == "open"       # steps hardly differ: rank episodes
    wins_key = "episodes_win_rate" if opening else "win_rate"
    header = (["family", "mazes", "agent", "ratio med", "ratio mean", "worst", "failed",
               "ep-opt med", f"opt<={WITHIN}", "found"] + (["settled"] if delay else [])
              + ["wins vs (episodes)" if opening else "wins vs (steps)"] if env else
              ["family", "mazes", "agent", "% cur med", "worst %", "perfect", "wins vs"])
    rows = []
    for fam, d in list(s["families"].items()) + [("overall", s["overall"])]:
        if not d["mazes"]:
            rows.append([fam, f"0 ({d['skipped']} skipped)"] + [""] * (len(header) - 2))
            continue
        for a in agents:
            wins = ", ".join(f"{b} {w:.0%}" for b, w in d[wins_key].get(a, {}).items())
            if env:
                r = d["oracle_ratio"][a]
                rows.append([fam, str(d["mazes"]), a, _f(r["median"]), _f(r["mean"]),
                             _f(d["worst_trial_ratio"][a], 1), str(d["failures"][a]),
                             _f(d["episodes_to_optimal"][a]["median"], 1),
                             _f(d[f"optimal_within_{WITHIN}"][a]),
                             _f(d["optimal_found"][a])]
                            + ([_f(d["settled_ratio"][a]["median"])] if delay else [])
                            + [wins])
            else:
                c = d["current_pct"][a]
                rows.append([fam, str(d["mazes"]), a, _f(c["median"], 1),
                             _f(d["worst_pct"][a], 1), _f(d["perfect_trials"][a]), wins])
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    lines.append("  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip())
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    if s["skipped"]:
        lines.append("skipped: " + ", ".join(f"{k['name']} ({k['reason']})"
                                             for k in s["skipped"]))
    return "\n".join(lines)
