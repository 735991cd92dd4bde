"""Results kept as data: ``./tmgwr results`` (``make results``).

Every measured figure the README and the documentation show comes from a JSON file under
``results/`` (committed), and every table of them is generated from it:

* ``./tmgwr results record NAME -- COMMAND ...`` runs a ``./tmgwr`` command (an
  ``experiment`` or ``bench``) with ``--json`` pointed at a scratch file under ``runs/``
  and writes ``results/NAME.json``: the command as typed, the commit it ran at (and
  whether ``src/`` had uncommitted changes), the machine's cores and its load average at
  the start and the end, the wall time, and the command's own JSON under ``result``
  (its contract: docs, Experiments).
* ``./tmgwr results`` (``render``) rewrites every table between the marker comments
  ``<!-- results:TABLE -->`` and ``<!-- /results:TABLE -->`` in ``README.md`` and
  ``docs/**/*.md`` from those files (:data:`TABLES` says which file makes which table),
  and draws each file's figure to ``docs/figures/NAME.png`` with
  :func:`tmgwr_agent.experiments.plots.plot`.
* ``./tmgwr results --check`` rewrites nothing and exits 1 naming every table that
  differs from what its JSON gives, and every figure not drawn from its JSON as it is now
  (each PNG's ``Source`` text names the file and a digest of its result; a figure no file
  draws any more counts too). test/test_results.py runs the same check.

A table names the trial count of its runs, so a reader knows how much each cell rests on.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import shlex
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

from tmgwr_agent.experiments.stats import fmt

#: The repository root (``src/tmgwr_agent/tmgwr_agent/experiments/results.py``).
ROOT = Path(__file__).resolve().parents[4]
#: The files whose marked tables are generated.
DOC_GLOBS = ("README.md", "docs/**/*.md")
MARKER = re.compile(r"(<!-- results:([a-z0-9_-]+) -->\n)(.*?)(<!-- /results:\2 -->)", re.S)
#: Results files whose figure goes to ``docs/figures/NAME.png``.
FIGURES_DIR = "docs/figures"


class ResultsError(RuntimeError):
    """A results file or a marked table that cannot be generated (named in the message)."""


# ---------------------------------------------------------------- recording

def _git(root: Path, *args: str) -> str:
    out = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)
    return out.stdout.strip() if out.returncode == 0 else ""


def record(name: str, argv: list[str], root: Path = ROOT) -> Path:
    """Run ``./tmgwr ARGV --json SCRATCH`` and write ``results/NAME.json`` around its JSON."""
    if not re.fullmatch(r"[a-z0-9_-]+", name):
        raise ResultsError(f"results name {name!r}: use [a-z0-9_-] only")
    if not argv or argv[0] not in ("experiment", "bench"):
        raise ResultsError("record runs `experiment ...` or `bench ...` (got "
                           f"{' '.join(argv) or 'nothing'!r})")
    if "--json" in argv:
        raise ResultsError("record sets --json itself; leave it out of the command")
    scratch = root / "runs" / "results" / f"{name}.json"
    scratch.parent.mkdir(parents=True, exist_ok=True)
    scratch.unlink(missing_ok=True)
    commit = _git(root, "rev-parse", "HEAD")
    dirty = bool(_git(root, "status", "--porcelain", "--", "src"))   # what made the result
    load_start = list(os.getloadavg())
    started = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-m", "tmgwr_agent.cli", *argv, "--json",
                           str(scratch)], cwd=root)
    wall = time.monotonic() - t0
    if proc.returncode != 0 or not scratch.is_file():
        raise ResultsError(f"`./tmgwr {shlex.join(argv)}` exited {proc.returncode}; "
                           f"results/{name}.json not written")
    doc = {
        "name": name,
        "command": "./tmgwr " + shlex.join(argv),
        "commit": commit,
        "dirty": dirty,
        "started": started,
        "wall_s": round(wall, 1),
        "machine": {"cores": os.cpu_count(), "load_start": load_start,
                    "load_end": list(os.getloadavg())},
        "result": json.loads(scratch.read_text()),
    }
    out = root / "results" / f"{name}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(doc, indent=1) + "\n")
    return out


def again(names: list[str], root: Path = ROOT, skip: tuple[str, ...] = ()) -> list[Path]:
    """Record each ``results/NAME.json`` again by its own recorded command (every file when
    ``names`` is empty; ``skip``: names left as they are), in name order."""
    names = names or sorted(p.stem for p in (root / "results").glob("*.json"))
    unknown = [n for n in (*names, *skip) if not (root / "results" / f"{n}.json").is_file()]
    if unknown:
        raise ResultsError(f"no results/{unknown[0]}.json to record again")
    out = []
    for name in names:
        if name in skip:
            continue
        command = shlex.split(load(name, root)["command"])
        if command[:1] != ["./tmgwr"]:
            raise ResultsError(f"results/{name}.json: its command {shlex.join(command)!r} "
                               "is not a ./tmgwr command")
        print(f"tmgwr results: recording {name} again: {shlex.join(command)}", flush=True)
        out.append(record(name, command[1:], root))
    return out


def load(name: str, root: Path = ROOT) -> dict:
    path = root / "results" / f"{name}.json"
    if not path.is_file():
        raise ResultsError(f"results/{name}.json is missing (make it with "
                           f"`./tmgwr results record {name} -- ...`)")
    doc = json.loads(path.read_text())
    for key in ("command", "commit", "machine", "result"):
        if key not in doc:
            raise ResultsError(f"results/{name}.json has no {key!r}")
    return doc


# ---------------------------------------------------------------- tables

def _md(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def _source(*docs: dict) -> str:
    """The line under a table: the commands, their commit and the machine."""
    parts = []
    for d in docs:
        m = d["machine"]
        parts.append(f"`{d['command']}` at {d['commit'][:7]}{' (dirty)' if d['dirty'] else ''}"
                     f", {m['cores']} cores, load {m['load_start'][0]:.1f}-"
                     f"{m['load_end'][0]:.1f}")
    return "Source: " + "; ".join(parts) + "."


def _steps(s: dict) -> str:
    text = fmt(s)
    return "never" if text.startswith("inf") else text


def _goal_change_means(result: dict) -> dict[str, dict]:
    """Per agent: the mean over transitions and trials of % at the current goal, and the
    worst transition mean."""
    out = {}
    for a, d in result["agents"].items():
        means = [t["current_pct"]["mean"] for t in d["transitions"]]
        out[a] = {"mean": sum(means) / len(means), "worst": min(means)}
    return out


def table_headline(root: Path) -> str:
    """The README's table: per agent, steps after events a and b, % at the current goal."""
    a, b, gc = (load(n, root) for n in ("env_change_a", "env_change_b", "goal_change"))
    ra, rb, rg = a["result"], b["result"], gc["result"]
    pct = _goal_change_means(rg)
    agents = list(dict.fromkeys([*ra["agents"], *rg["agents"]]))
    rows = []
    for name in agents:
        cells = [f"`{name}`"]
        for r in (ra, rb):
            cells.append(_steps(r["agents"][name]["steps"]) if name in r["agents"] else "")
        cells.append(f"{pct[name]['mean']:.1f} (worst {pct[name]['worst']:.1f})"
                     if name in pct else "")
        rows.append(cells)
    header = ["agent",
              f"steps after event a (oracle {ra['oracle_steps']}, {ra['trials']} trials)",
              f"steps after event b (oracle {rb['oracle_steps']}, {rb['trials']} trials)",
              f"goal change {','.join(rg['goals'])}: % of episodes at the current goal, "
              f"mean over transitions (worst transition) ({rg['episodes']} episodes per "
              f"goal, {rg['trials']} trials)"]
    return (_md(header, rows) + "\n\nMean ± std over trials; `never`: every trial hit its "
            "cap. " + _source(a, b, gc))


def table_env_change(root: Path) -> str:
    """Table 6: per event and agent, steps of the first episode after the event and the
    episodes until the greedy path is optimal again."""
    docs = [load(n, root) for n in ("env_change_a", "env_change_b")]
    rows = []
    for d in docs:
        r = d["result"]
        for name, v in r["agents"].items():
            rows.append([f"{r['event']} ({r['oracle_steps']})", f"`{name}`", _steps(v["steps"]),
                         _steps(v["episodes_to_optimal"]), _steps(v["train_episodes"])])
    trials = sorted({d["result"]["trials"] for d in docs})
    header = ["event (oracle)", "agent", "steps after the event",
              "episodes to optimal", "training episodes"]
    return (_md(header, rows) + f"\n\nMean ± std over {'/'.join(map(str, trials))} trials; "
            "`never`: every trial hit its cap. " + _source(*docs))


def table_ablation(root: Path) -> str:
    """Our additions off (``+paper``): steps after events a and b per agent spec."""
    docs = [load(n, root) for n in ("ablation_a", "ablation_b")]
    agents = list(docs[0]["result"]["agents"])
    rows = [[f"`{a}`"] + [_steps(d["result"]["agents"][a]["steps"]) for d in docs]
            for a in agents]
    header = ["agent"] + [f"steps after event {d['result']['event']} (oracle "
                          f"{d['result']['oracle_steps']}, {d['result']['trials']} trials)"
                          for d in docs]
    return (_md(header, rows) + "\n\nMean ± std; `(k failed)`: trials that hit their cap. "
            + _source(*docs))


def table_goal_change(root: Path, name: str = "goal_change") -> str:
    """Tables 3-5: % of episodes at the previous / current goal per transition."""
    d = load(name, root)
    r = d["result"]
    agents = list(r["agents"])
    first = r["agents"][agents[0]]["transitions"]
    rows = []
    for i, t in enumerate(first):
        row = [f"{t['from']} -> {t['to']}"]
        for a in agents:
            tt = r["agents"][a]["transitions"][i]
            row.append(f"{tt['previous_pct']['mean']:.1f} / {tt['current_pct']['mean']:.1f}")
        rows.append(row)
    return (_md(["transition"] + [f"`{a}`" for a in agents], rows)
            + f"\n\n% of episodes ending at the previous / current goal, mean over "
            f"{r['trials']} trials, {r['episodes']} episodes per goal. " + _source(d))


def _families(s: dict) -> list[tuple[str, dict]]:
    return [(f, d) for f, d in list(s["families"].items()) + [("all", s["overall"])]
            if d["mazes"]]


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f} %"


def _delays(r: dict) -> tuple[list[tuple[int, dict]], bool]:
    """An env-change result per event delay, and whether a table shows a delay column
    (a file run at one delay of 0, today's protocol, does not)."""
    from tmgwr_agent.experiments.env_change import delay_views
    views = delay_views(r)
    return views, len(views) > 1 or views[0][0] != 0


def _delay_note(shown: bool) -> str:
    return ("Event delay K: the learning episodes every agent ran after convergence "
            "before the event. " if shown else "")


def table_suite(root: Path, name: str = "suite_blocks") -> str:
    """Blocks on the suite: per family and agent, the median over mazes of the per-maze
    median steps / oracle and the worst trial; the first agent's share of mazes won.
    A file run at several event delays: the rows of each delay, a column naming it."""
    d = load(name, root)
    views, shown = _delays(d["result"])
    r, s = views[0][1], views[0][1]["suite"]
    agents = list(r["agents"])
    first, others = agents[0], agents[1:]
    mapped = list(s["overall"].get("max_nodes_per_cell", {}))   # files since it was kept
    rows = []
    for k, fam, f in ((k, fam, f) for k, v in views for fam, f in _families(v["suite"])):
        row = ([str(k)] if shown else []) + [f"{fam} ({f['mazes']})"]
        for a in agents:
            ratio, worst = f["oracle_ratio"][a]["median"], f["worst_trial_ratio"][a]
            failed = f["failures"][a]
            row.append(("never" if ratio is None else f"{ratio:.2f}")
                       + ("" if worst is None else f" / {worst:.1f}")
                       + (f" ({failed} failed)" if failed else ""))
        row.append(" / ".join(_pct(f["win_rate"][first].get(b)) for b in others))
        if mapped:
            row.append(" / ".join(_f2(f["max_nodes_per_cell"].get(a)) for a in mapped))
        rows.append(row)
    header = ((["event delay K"] if shown else []) + ["family (mazes)"]
              + [f"`{a}` median / worst" for a in agents]
              + [f"`{first}` beats {' / '.join(f'`{b}`' for b in others)}"]
              + ([f"{' / '.join(f'`{a}`' for a in mapped)} map nodes / free cell (max)"]
                 if mapped else []))
    return (_md(header, rows)
            + "\n\nSteps of the first episode after the block over `oracle_steps`: the "
            "median over mazes of each maze's median trial, then the worst trial; a maze "
            "is won when the agent's median steps are strictly fewer. " + _delay_note(shown)
            + f"Suite `{s['spec']}`, suite seed {s['seed']}, {r['trials']} trials per maze. "
            + _source(d))


def table_suite_goals(root: Path, name: str) -> str:
    """Goal changes on the suite: per family and agent, the median over mazes of the
    maze's mean % of episodes at the current goal, the worst transition of any trial, and
    the share of trials with every episode at the current goal."""
    d = load(name, root)
    r, s = d["result"], d["result"]["suite"]
    agents = list(r["agents"])
    rows = []
    for fam, f in _families(s):
        rows.append([f"{fam} ({f['mazes']})"]
                    + [f"{f['current_pct'][a]['median']:.1f} / {f['worst_pct'][a]:.1f} / "
                       f"{_pct(f['perfect_trials'][a])}" for a in agents])
    return (_md(["family (mazes)"] + [f"`{a}` % current / worst / perfect" for a in agents],
                rows)
            + "\n\n% of episodes ending at the current goal: the median over mazes of each "
            "maze's mean over transitions and trials; the worst transition of any trial; "
            "the share of trials with every episode at the current goal. "
            f"Suite `{s['spec']}`, suite seed {s['seed']}, {r['trials']} trials per maze, "
            f"{r['episodes']} episodes per goal. " + _source(d))


def table_suite_openings(root: Path, name: str = "suite_openings") -> str:
    """Openings on the suite: per family and agent, the share of trials whose greedy path
    uses the shortcut within 10 episodes, and ever (within the caps). A file run at
    several event delays: the rows of each delay, a column naming it."""
    d = load(name, root)
    views, shown = _delays(d["result"])
    r, s = views[0][1], views[0][1]["suite"]
    agents = list(r["agents"])
    rows = []
    for k, v in views:
        for fam, f in _families(v["suite"]):
            rows.append(([str(k)] if shown else []) + [f"{fam} ({f['mazes']})"]
                        + [f"{_pct(f['optimal_within_10'][a])} / "
                           f"{_pct(f['optimal_found'][a])}" for a in agents])
    return (_md((["event delay K"] if shown else []) + ["family (mazes)"]
                + [f"`{a}` within 10 / ever" for a in agents], rows)
            + "\n\nShare of trials whose greedy path uses the new shortcut within 10 "
            "episodes of the opening, and within the caps. " + _delay_note(shown)
            + f"Suite `{s['spec']}`, suite seed {s['seed']}, {r['trials']} trials per maze. "
            + _source(d))


def table_settled(root: Path, name: str) -> str:
    """The cost of an episode once converged, per event delay K > 0 of a suite file: per
    family and agent, the median over mazes of each maze's median trial of
    ``settled_steps`` (the mean steps of the K learning episodes between convergence and
    the event) over the shortest path."""
    d = load(name, root)
    views = [(k, v) for k, v in _delays(d["result"])[0] if k]
    if not views:
        raise ResultsError(f"results/{name}.json was run at no event delay > 0 "
                           f"(record it with --event-delay K, K > 0)")
    agents = list(views[0][1]["agents"])
    rows = [[str(k), f"{fam} ({f['mazes']})"]
            + [_f2(f["settled_ratio"][a]["median"]) for a in agents]
            for k, v in views for fam, f in _families(v["suite"])]
    s, r = views[0][1]["suite"], views[0][1]
    return (_md(["event delay K", "family (mazes)"] + [f"`{a}`" for a in agents], rows)
            + "\n\nMean steps of the K learning episodes (exploration and any re-testing "
            "included) that every agent ran after convergence and before the event, over "
            "the shortest path: the median over mazes of each maze's median trial. "
            f"Suite `{s['spec']}`, suite seed {s['seed']}, {r['trials']} trials per maze. "
            + _source(d))


def _f2(v: float | None) -> str:
    return "never" if v is None else f"{v:.2f}"


def table_sample_complexity(root: Path) -> str:
    """Fig. 6: episodes until ten consecutive greedy rollouts take a shortest path."""
    d = load("sample_complexity", root)
    r = d["result"]
    agents = list(r["agents"])
    rows = [[f"goal {g}"] + [_steps(r["agents"][a]["goals"][g]["episodes_to_converge"])
                             for a in agents] for g in r["goals"]]
    return (_md(["goal"] + [f"`{a}`" for a in agents], rows)
            + f"\n\nEpisodes to converge, mean ± std over {r['trials']} trials. "
            + _source(d))


def table_bench(root: Path) -> str:
    """`make bench`'s summary: rates as ratios to the empty ring of 5 processes measured in
    the same run, bytes per step, CPU to convergence, the core step (with its targets)."""
    from tmgwr_agent.experiments.bench import RATIO_HEADER, ratio_rows
    d = load("bench", root)
    rows = [[c.replace("|", "/") for c in r] for r in ratio_rows(d["result"])]
    return _md(list(RATIO_HEADER), rows) + "\n\n" + _source(d)


def table_bench_scaling(root: Path) -> str:
    """`make bench`'s scaling rows: the converged core step against the map's size."""
    from tmgwr_agent.experiments.bench import SCALING_HEADER, scaling_rows
    d = load("bench", root)
    r = d["result"]
    if not r.get("scaling"):
        raise ResultsError("results/bench.json has no scaling rows (record it again with "
                           "`./tmgwr results record bench -- bench`)")
    slopes = ", ".join(f"{f} {v:.2f}" for f, v in sorted(r["scaling_slopes"].items()))
    return (_md(list(SCALING_HEADER), scaling_rows(r))
            + "\n\nMedian, p99 and mean of the converged core step over 2,000 learning steps, "
            "the median over a pure lookup of the winner's best link on the same map, the "
            "first step after a goal change, and the episode after a block. Log-log slope "
            f"of the median against nodes from about 1,400 cells: {slopes}. " + _source(d))


#: The sensors of the sensing table, and the results file of each.
SENSORS = (("identity", "sensing_identity"), ("scale=1:2", "sensing_scale-1_2"),
           ("scale=1:5", "sensing_scale-1_5"), ("rotate=30", "sensing_rotate-30"),
           ("noise=0.1", "sensing_noise-0p1"), ("noise=0.2", "sensing_noise-0p2"))


def table_sensing(root: Path) -> str:
    """How it senses: the same suite's blocks under each sensor transform, per agent: the
    median over mazes of steps / oracle and the worst trial, and the training episodes
    to convergence (mean, max, trials that never converged)."""
    docs = [(spec, load(name, root)) for spec, name in SENSORS]
    agents = list(docs[0][1]["result"]["agents"])
    rows = []
    for spec, d in docs:
        s = d["result"]["suite"]
        row = [f"`{spec}`"]
        for a in agents:
            ratio, worst = s["overall"]["oracle_ratio"][a]["median"], \
                s["overall"]["worst_trial_ratio"][a]
            train = [v for m in s["mazes"] for v in m["agents"][a]["train_episodes"]["values"]]
            done = [v for v in train if v is not None]
            never = len(train) - len(done)
            row += [("never" if ratio is None else f"{ratio:.2f}")
                    + ("" if worst is None else f" / {worst:.1f}"),
                    (f"{sum(done) / len(done):.1f} (max {max(done)})" if done else "-")
                    + (f", {never} never" if never else "")]
        rows.append(row)
    header = ["sensor"] + [h for a in agents
                           for h in (f"`{a}` blocks median / worst", f"`{a}` training episodes")]
    s0, r0 = docs[0][1]["result"]["suite"], docs[0][1]["result"]
    return (_md(header, rows)
            + "\n\nSteps of the first episode after the block over `oracle_steps` (median over "
            "mazes of each maze's median trial, then the worst trial), and the episodes each "
            "trial trained until ten greedy rollouts in a row took a shortest path. "
            f"Suite `{s0['spec']}`, suite seed {s0['seed']}, {r0['trials']} trials per maze, "
            "the same mazes and seeds under every sensor. "
            + _source(*(d for _, d in docs)))


def table_view(root: Path) -> str:
    """A local view (``--sensor view=K``) on the default maze, per agent: the trials that
    reached the goal after the block and their steps over the oracle, the trials that ever
    converged, and the mean steps of the last training episodes."""
    d = load("sensing_view-1", root)
    r = d["result"]
    rows = []
    for a, v in r["agents"].items():
        done = [s for s in v["steps"]["values"] if s is not None]
        conv = [e for e in v["train_episodes"]["values"] if e is not None]
        learn = [s for s in v["learning_steps"]["values"] if s is not None]
        n = len(v["steps"]["values"])
        rows.append([f"`{a}`", f"{len(done)} of {n}",
                     " / ".join(f"{s / r['oracle_steps']:.0f}" for s in sorted(done)) or "-",
                     f"{len(conv)} of {n}",
                     f"{sum(learn) / len(learn):.0f}" if learn else "-"])
    header = ["agent", "reached the goal after the block", "steps / oracle", "converged",
              "learning episode steps"]
    return (_md(header, rows)
            + f"\n\nDefault maze, event `{r['event']}` (oracle {r['oracle_steps']} steps), sensor "
            f"`{r['sensor']}`, {r['trials']} trials; training stops at the caps "
            f"({r['caps']['max_episodes']} episodes or {r['caps']['budget_steps']} steps). "
            + _source(d))


#: The worlds table: the world and its results file (env-change on the default maze).
WORLD_RESULTS = (("minigrid", "world_minigrid"), ("pointmaze", "world_pointmaze"))


def table_worlds(root: Path) -> str:
    """The default maze in the worlds of ``--world``, per agent: the trials that converged
    before the event, the steps of the first episode after the block over the world's
    oracle (each trial; ``-``: the goal was not reached within the caps), and the episodes
    until a greedy rollout is optimal again."""
    docs = [(w, load(name, root)) for w, name in WORLD_RESULTS]
    rows = []
    for w, d in docs:
        r = d["result"]
        for a, v in r["agents"].items():
            n = len(v["steps"]["values"])
            conv = sum(e is not None for e in v["train_episodes"]["values"])
            steps = " / ".join("-" if x is None else f"{x / r['oracle_steps']:.1f}"
                               for x in v["steps"]["values"])
            eps = " / ".join("-" if x is None else str(x)
                             for x in v["episodes_to_optimal"]["values"])
            rows.append([w, f"`{a}`", f"{conv} of {n}", steps, eps])
    header = ["world", "agent", "converged", "steps after the block / oracle (each trial)",
              "episodes to optimal"]
    oracles = ", ".join(f"{w} {d['result']['oracle_steps']}" for w, d in docs)
    return (_md(header, rows)
            + f"\n\nDefault maze, event `a`, oracle steps in each world's own primitives "
            f"({oracles}). " + _source(*(d for _, d in docs)))


#: The registered Gymnasium ids (issue 26) and their results files (sample-complexity).
GYM_RESULTS = (("MiniGrid-FourRooms-v0", "gym_fourrooms"),
               ("MiniGrid-SimpleCrossingS9N1-v0", "gym_simplecrossing"),
               ("PointMaze_UMaze-v3", "gym_umaze"), ("PointMaze_Medium-v3", "gym_medium"))


def table_gym(root: Path) -> str:
    """Registered Gymnasium envs (``--world gym:ID``), trained from scratch to the goal of
    the env's own draw: per agent, the trials that converged (ten consecutive optimal
    greedy rollouts) and the training episodes to that point (each trial; ``-``: the caps
    ran out first), and the steps of the last recorded training episode, mean over trials."""
    rows = []
    docs = []
    for env, name in GYM_RESULTS:
        if not (root / "results" / f"{name}.json").exists():
            continue
        d = load(name, root)
        docs.append(d)
        r = d["result"]
        seed = r.get("world_kwargs", {}).get("layout_seed", 0)
        for a, v in r["agents"].items():
            g = v["goals"][r["goals"][0]]
            values = g["episodes_to_converge"]["values"]
            conv = sum(x is not None for x in values)
            eps = " / ".join("-" if x is None else str(x) for x in values)
            rows.append([f"`{env}` (layout {seed}, oracle {g['shortest_steps']})", f"`{a}`",
                         f"{conv} of {len(values)}", eps, f"{g['curve'][-1]:.1f}"])
    header = ["env", "agent", "converged", "episodes to converge (each trial)",
              "steps of the last training episode"]
    return _md(header, rows) + "\n\n" + _source(*docs)


#: Marked table name -> the function that generates it from results/.
TABLES: dict[str, Callable[[Path], str]] = {
    "headline": table_headline,
    "env-change": table_env_change,
    "ablation": table_ablation,
    "goal-change": table_goal_change,
    "sample-complexity": table_sample_complexity,
    "suite": table_suite,
    "suite-openings": table_suite_openings,
    "bench": table_bench,
    "bench-scaling": table_bench_scaling,
    "sensing": table_sensing,
    "sensing-view": table_view,
    "worlds": table_worlds,
    "gym": table_gym,
    "rivals-blocks": lambda root: table_suite(root, "rivals_blocks"),
    "rivals-openings": lambda root: table_suite_openings(root, "rivals_openings"),
    "rivals-delays-blocks": lambda root: table_suite(root, "rivals_delays"),
    "rivals-delays-openings": lambda root: table_suite_openings(root,
                                                               "rivals_delays_openings"),
    "rivals-delays-settled": lambda root: table_settled(root, "rivals_delays"),
    "minigrid-suite": lambda root: table_suite(root, "world_minigrid_suite"),
    "pointmaze-suite": lambda root: table_suite(root, "world_pointmaze_suite"),
    "minigrid-goal-change": lambda root: table_goal_change(root, "world_minigrid_goal"),
    "minigrid-goal-suite": lambda root: table_suite_goals(root, "world_minigrid_goal_suite"),
}


# ---------------------------------------------------------------- rendering

def doc_files(root: Path = ROOT) -> list[Path]:
    files: list[Path] = []
    for pattern in DOC_GLOBS:
        files += sorted(root.glob(pattern))
    return files


def render_text(text: str, root: Path = ROOT, where: str = "") -> str:
    """``text`` with every marked table regenerated."""
    def sub(m: re.Match) -> str:
        name = m.group(2)
        if name not in TABLES:
            raise ResultsError(f"{where}: unknown results table {name!r} "
                               f"(known: {', '.join(TABLES)})")
        return m.group(1) + TABLES[name](root) + "\n" + m.group(4)
    return MARKER.sub(sub, text)


def stale_tables(root: Path = ROOT) -> list[str]:
    """``file: table`` for every marked table that differs from what its JSON gives."""
    stale = []
    for path in doc_files(root):
        text = path.read_text()
        rel = path.relative_to(root)
        new = render_text(text, root, str(rel))
        if new != text:
            old_tables = {m.group(2): m.group(3) for m in MARKER.finditer(text)}
            for m in MARKER.finditer(new):
                if old_tables.get(m.group(2)) != m.group(3):
                    stale.append(f"{rel}: {m.group(2)}")
    return stale


def render(root: Path = ROOT, figures: bool = True) -> list[Path]:
    """Rewrite the marked tables (and draw the figures); return the files changed."""
    changed = []
    for path in doc_files(root):
        text = path.read_text()
        new = render_text(text, root, str(path.relative_to(root)))
        if new != text:
            path.write_text(new)
            changed.append(path)
    if figures:
        from tmgwr_agent.experiments.plots import plot
        (root / FIGURES_DIR).mkdir(parents=True, exist_ok=True)
        for name, result in figure_results(root):
            png = root / FIGURES_DIR / f"{name}.png"
            plot(result, png, figure_source(name, result))
            changed.append(png)
    return changed


def figure_results(root: Path = ROOT) -> list[tuple[str, dict]]:
    """``(NAME, result)`` of every results file that has a figure (an experiment's)."""
    docs = [(f.stem, load(f.stem, root)["result"])
            for f in sorted((root / "results").glob("*.json"))]
    return [(name, result) for name, result in docs if "scenario" in result]


def figure_source(name: str, result: dict) -> str:
    """What a figure is drawn from: its results file and a digest of the ``result`` in it
    (written into the PNG, so ``--check`` can tell whether a figure shows what its file
    holds now)."""
    digest = hashlib.sha256(json.dumps(result, sort_keys=True).encode()).hexdigest()
    return f"results/{name}.json sha256:{digest}"


def stale_figures(root: Path = ROOT) -> list[str]:
    """``docs/figures/NAME.png: why`` for every figure missing, drawn from another result
    than its file holds now, or left over from a results file that is gone."""
    from PIL import Image

    stale, drawn = [], set()
    for name, result in figure_results(root):
        rel = f"{FIGURES_DIR}/{name}.png"
        drawn.add(rel)
        if not (root / rel).is_file():
            stale.append(f"{rel}: missing")
            continue
        with Image.open(root / rel) as png:
            source = png.text.get("Source")
        if source != figure_source(name, result):
            stale.append(f"{rel}: not drawn from results/{name}.json as it is")
    for png in sorted((root / FIGURES_DIR).glob("*.png")):
        rel = f"{FIGURES_DIR}/{png.name}"
        if rel not in drawn:
            stale.append(f"{rel}: no results file draws it")
    return stale


# ---------------------------------------------------------------- command line

def register(subparsers) -> None:
    p = subparsers.add_parser(
        "results", help="regenerate the results tables and figures from results/*.json",
        description="Regenerate every results table of README.md and docs/ (between "
                    "<!-- results:NAME --> markers) and the figures in docs/figures/ from "
                    "results/*.json; `record` makes such a file by running a command.")
    p.add_argument("--check", action="store_true",
                   help="change nothing; exit 1 naming every table or figure that differs "
                        "from its JSON")
    p.add_argument("--no-figures", action="store_true", help="tables only")
    p.set_defaults(func=cmd_results)
    sub = p.add_subparsers(dest="results_command", metavar="SUBCOMMAND")
    r = sub.add_parser("record", help="run a ./tmgwr command and keep its JSON as "
                                      "results/NAME.json with its provenance",
                       description="./tmgwr results record NAME -- experiment env-change ...")
    r.add_argument("name", metavar="NAME", help="results/NAME.json ([a-z0-9_-])")
    r.add_argument("argv", nargs=argparse.REMAINDER, metavar="-- COMMAND ...",
                   help="the ./tmgwr command to run, without --json")
    r.set_defaults(func=cmd_record)
    a = sub.add_parser("again", help="record results/NAME.json again by its own command",
                       description="Re-run the command each results file records (all of "
                                   "them without NAME) and keep the new JSON; then run "
                                   "./tmgwr results.")
    a.add_argument("names", nargs="*", metavar="NAME", help="results/NAME.json (default: all)")
    a.add_argument("--skip", default="", metavar="NAME,...", help="files left as they are")
    a.set_defaults(func=cmd_again)


def cmd_results(args: argparse.Namespace) -> int:
    try:
        if args.check:
            stale = [f"table {t}" for t in stale_tables()]
            stale += [f"figure {f}" for f in stale_figures()]
            for s in stale:
                print(f"tmgwr results: stale {s}", file=sys.stderr)
            return 1 if stale else 0
        for path in render(figures=not args.no_figures):
            print(f"wrote {path.relative_to(ROOT)}")
    except ResultsError as exc:
        print(f"tmgwr: error: {exc}", file=sys.stderr)
        return 2
    return 0


def cmd_record(args: argparse.Namespace) -> int:
    argv = args.argv[1:] if args.argv[:1] == ["--"] else args.argv
    try:
        out = record(args.name, argv)
    except ResultsError as exc:
        print(f"tmgwr: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {out.relative_to(ROOT)}")
    return 0


def cmd_again(args: argparse.Namespace) -> int:
    skip = tuple(n for n in args.skip.split(",") if n)
    try:
        for out in again(args.names, skip=skip):
            print(f"wrote {out.relative_to(ROOT)}")
    except ResultsError as exc:
        print(f"tmgwr: error: {exc}", file=sys.stderr)
        return 2
    return 0
