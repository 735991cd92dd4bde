"""``./tmgwr tune AGENT``: fair hyperparameter tuning with Optuna (docs/tuning.md).

The paper tuned every agent by Bayesian optimisation (hyperopt's TPE, section 5.3); this
is the same with Optuna's :class:`~optuna.samplers.TPESampler`, the same budget and the
same objective for every agent (``tmgwr``, ``q_learning``, ``model_based``,
``dyna_q_plus``, ``rmax``, ``freespace``; TMGWR options as in ``experiment``, e.g.
``tmgwr:credit``).

Objective (minimised), on a *training split* of the generated suite
(:func:`maze_sim.suite.suite`, ``--suite SPEC --suite-seed K --suite-first I``; default
:data:`TRAIN_SUITE`, the families with a block event and small mazes): for every maze and
each of ``--seeds`` trial seeds (``SeedSequence(--seed).spawn``, the same for every
Optuna trial: common random numbers), one *block run* is steps 1-3 of the env-change
protocol (:func:`.env_change.trial` itself, ``to_optimal=False``): train to convergence
on G, fire the maze's block event, count the steps of the first episode until G. A run's
ratio is steps / ``oracle_steps``; a run *fails* when training did not converge within the
caps or the episode hit its step cap (:class:`.runner.Caps`); a failed episode's ratio is
the cap's (``episode_steps / oracle_steps``). The *openings* of ``--open-suite`` (default
:data:`TRAIN_OPEN_SUITE`, the same indices of the families with an opening) add one
*opening run* per maze and seed: the same trial with the maze's opening, step 4 capped at
:data:`OPEN_WITHIN` episodes (``env_change.trial(..., within=10)``); it is *missed* when the
greedy path does not use the shortcut by then. Then::

    objective = geometric mean over block mazes (median over seeds of the ratio)
                + PENALTY * (failed runs / runs)
                + open_weight * (missed opening runs / opening runs)

The median over seeds is robust to one odd run. Over mazes the geometric mean, not the
median: every maze counts (a median of 16 mazes ignores what happens on the hardest
half, where the agents differ most), yet a maze at a hundred times the oracle weighs
log(100), not 100. The penalty (:data:`PENALTY` = 10 oracle ratios spread over the runs)
makes a setting that fails anywhere worse than one that does not. A trial runs the tasks block and
opening alternately and is stopped early by Optuna's median rule (:func:`pruner`) when
its objective so far is worse than the earlier trials' median: the same for every agent,
it spends the budget's time on settings that can win. ``--open-weight`` (default 1: every
tenth of the openings missed weighs as much as a tenth of the oracle on every block; 0:
blocks only, the objective before openings were scored) prices the two events against
each other: finding a shortcut costs re-tests, and a re-test costs steps in every
episode, the block's too. The summary also reports the median over mazes and the
fraction of openings found.

Search space, one place per fact: *which* parameters an agent tunes and the interval
searched are :data:`SEARCH` (a parameter's default, type and valid range stay its
``param()`` declaration in the agent's Config class, read at run time, so a parameter
added to a Config is seen by ``tune --list`` and can be searched with ``--space`` without
editing this module). A name given to ``--space`` without bounds takes its
:data:`SEARCH` interval, else its declared range (an interval bound left ``None`` is the
declared bound); ``--fix`` holds parameters of the space at their defaults (the
goal-change scenario needs ``eps_min`` 0, docs/tuning.md); every interval is
checked against the declared range. The shared exploration parameters
(``eps_min``, ``eps_decay``, ``p_turn``) are searched for every agent over the same
intervals. The study's first trial is the agent's defaults (the paper's settings), so
the report shows what tuning gained on the training split.

Budget and workers: ``--trials N`` is the size of the study. ``--workers W`` starts W
processes on one study (worker i runs its share of N, so a fresh study holds exactly N
trials with every worker's share in it); more machines join the same study with the same
``--storage`` and ``--study`` (an RDB URL, or a journal file on a shared file system).
Every worker stops once the study holds N finished trials; the result is the best of the
first N trials by number, whatever extra trials a race between machines added, so every
agent gets exactly the same budget. The sampler is seeded per worker
(``SeedSequence([--seed, worker])``): a one-worker study is reproducible; with several
workers the interleaving is not.

Storage: ``--storage PATH`` is an Optuna journal file (:class:`~optuna.storages.JournalStorage`
over :class:`~optuna.storages.journal.JournalFileBackend` with a
:class:`~optuna.storages.journal.JournalFileOpenLock`, safe for processes on one machine
and on NFS); a URL (``sqlite:///x.db``, ``postgresql://...``) is passed to Optuna as an
RDB storage. A study remembers its objective (agent, split, seeds, space); re-opening it
with other options is refused.

Outputs: the best parameters as a parameter file in the ROS 2 layout (TMGWR: the ``/**``
section every node of the graph reads; a baseline: a section named after it, so its
``beta`` never reaches the motivation estimator's), read back by :func:`load_tuned` and
by ``experiment --params`` (:func:`experiment_params`); and a JSON summary.
``--evaluate`` runs the same protocol on a *held-out* split (default: the training
families at the indices after the training ones) with ``--eval-trials`` seeds, for the
tuned parameters and the defaults alongside.
"""

from __future__ import annotations

import difflib
import json
import math
import os
import socket
import statistics
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml

from maze_sim.maze import Maze
from maze_sim.suite import SuiteError, suite
from maze_sim.suite import parse_spec as suite_counts
from maze_sim.worlds import WORLDS, WorldError, WorldSpec, parse_world
from tmgwr_agent.experiments import env_change
from tmgwr_agent.experiments.agent_factory import AGENT_NAMES, baseline_class, make_agent
from tmgwr_agent.experiments.agent_factory import parse_spec as parse_agent
from tmgwr_agent.experiments.parallel import run_items, trial_seeds, warm_up
from tmgwr_agent.experiments.results import ROOT
from tmgwr_agent.experiments.runner import Caps
from tmgwr_agent.experiments.scenarios import UsageError
from tmgwr_agent.experiments.sensing import check_world
from tmgwr_common.params import (
    Param,
    ParamError,
    make_config,
    read_params_file,
    specs,
    unknown_name_message,
)

GOAL = "G"
#: Training split: the families with a block event, small mazes (``large`` costs minutes).
TRAIN_SUITE = "braided:4,rooms:4,open:4,blocking:4"
#: ... and the families with an opening (``--open-suite``).
TRAIN_OPEN_SUITE = "shortcut:4,braided:4,rooms:4,open:4"
#: An opening run counts as found when the greedy path uses the shortcut within this many
#: episodes after it opened (issue 9's measure).
OPEN_WITHIN = 10
#: The median pruner (:func:`pruner`): complete trials before any is pruned, the first
#: task index it may prune at, and how often a trial reports.
PRUNE_STARTUP, PRUNE_WARMUP, PRUNE_EVERY = 10, 7, 4
#: Weight of the fraction of failed runs in the objective (in oracle-ratio units).
PENALTY = 10.0
#: Where results go by default (``results/`` is not committed; another world's in
#: ``results/tune/WORLD/``).
RESULTS = Path("results") / "tune"
#: The committed tuned files (:func:`tuned_file`), and the ``--params AGENT=tuned`` word.
TUNED = ROOT / "config" / "tuned"
TUNED_WORD = "tuned"


@dataclass(frozen=True)
class Interval:
    """A search interval; ``None`` bounds are the parameter's declared ones."""

    low: float | None = None
    high: float | None = None
    log: bool = False


#: The exploration every agent shares (same names and ranges in every Config).
_EXPLORATION = {
    "eps_min": Interval(0.0, 0.3),
    "eps_decay": Interval(0.02, 0.5, log=True),
    "p_turn": Interval(0.05, 0.6),
}
#: Rewards of Eq. 8 (Q-learning, Dyna-Q+) and Eq. 9 (model-based): the declared range
#: (+-1e6) says what is valid, not what is worth searching.
_REWARDS = {
    "r_goal": Interval(1.0, 200.0),
    "r_wall": Interval(-300.0, 0.0),
    "r_empty": Interval(-100.0, 0.0),
}

#: What ``tune`` searches per agent (docs/tuning.md): name -> interval. Everything else
#: keeps its default (``tune AGENT --list`` shows both sides).
SEARCH: dict[str, dict[str, Interval]] = {
    "tmgwr": {
        "alpha": Interval(0.05, None),               # Eq. 1 rate (Table 2: 0.52)
        "gamma": Interval(0.8, 0.999),               # Eq. 5 (Table 2: 0.97)
        "beta": Interval(0.1, None),                 # Eq. 4 (Table 2: 0.80)
        # GWR insertion threshold: above exp(-feature_scale) = exp(-0.1) = 0.905, the
        # activity of a neighbouring cell, so that every cell gets its own node (below it
        # cells merge, training fails to its caps and a trial costs minutes)
        "a_T": Interval(0.91, 0.99),
        "max_age": Interval(20, 1000, log=True),     # link ageing
        "E_min": Interval(1e-3, 0.3, log=True),      # link deletion
        "sigma_a": Interval(0.2, 0.6),               # Eq. 2 width
        "stale_horizon": Interval(1.0, 20.0, log=True),   # Eq. 5': episodes a wall is trusted
        "stale_prior": Interval(0.1, None),          # Eq. 5': rho of a stale wall
        "stale_budget": Interval(0.0, 0.3),          # Eq. 5': re-tests per route step
        **_EXPLORATION,
    },
    "q_learning": {
        "gamma": Interval(0.5, 0.999),
        "beta": Interval(0.05, None),
        **_REWARDS,
        **_EXPLORATION,
    },
    "dyna_q_plus": {
        "gamma": Interval(0.5, 0.999),
        "beta": Interval(0.05, None),
        **_REWARDS,
        "n_planning": Interval(1, 100, log=True),
        "kappa": Interval(1e-4, 10.0, log=True),
        **_EXPLORATION,
    },
    "model_based": {
        "gamma": Interval(0.5, 0.999),
        "beta": Interval(0.05, None),
        "r_goal": _REWARDS["r_goal"],
        "r_empty": _REWARDS["r_empty"],
        **_EXPLORATION,
    },
    # R-max and the free-space planner explore by optimism: epsilon starts at 0, and its
    # start is searched instead of its floor (a floor above the start is refused)
    "rmax": {
        "gamma": Interval(0.8, 0.99),
        **_REWARDS,
        "m_known": Interval(1, 5),
        "forget_after": Interval(0, 30),
        "eps_start": Interval(0.0, 0.3),
        "p_turn": _EXPLORATION["p_turn"],
    },
    "freespace": {
        "forget_after": Interval(0, 30),
        "eps_start": Interval(0.0, 0.3),
        "p_turn": _EXPLORATION["p_turn"],
    },
}


def agent_specs(agent: str) -> tuple[Param, ...]:
    """The parameter declarations of an agent (read from its Config classes now)."""
    name, _ = parse_agent(agent)
    if name == "tmgwr":
        from tmgwr_agent.core.agent import SPECS
        return SPECS
    return specs(_config_class(name))


@dataclass(frozen=True)
class Dim:
    """One searched parameter: resolved interval, type and default."""

    name: str
    low: float
    high: float
    log: bool
    integer: bool
    default: Any

    def suggest(self, trial) -> Any:
        if self.integer:
            return trial.suggest_int(self.name, int(self.low), int(self.high), log=self.log)
        return trial.suggest_float(self.name, self.low, self.high, log=self.log)

    def contains(self, value: Any) -> bool:
        return self.low <= value <= self.high


def parse_space(text: str) -> dict[str, Interval]:
    """``--space "alpha,gamma=0.9:0.999,kappa=1e-3:1:log"`` -> {name: Interval}."""
    out: dict[str, Interval] = {}
    for part in (p.strip() for p in text.split(",") if p.strip()):
        name, _, rng = part.partition("=")
        if not rng:
            out[name] = Interval()
            continue
        bits = rng.split(":")
        try:
            if len(bits) not in (2, 3) or (len(bits) == 3 and bits[2] != "log"):
                raise ValueError
            out[name] = Interval(float(bits[0]), float(bits[1]), len(bits) == 3)
        except ValueError:
            raise UsageError(f"--space: {part!r} is not NAME, NAME=LOW:HIGH or "
                             "NAME=LOW:HIGH:log") from None
    if not out:
        raise UsageError("--space names no parameter")
    return out


def search_space(agent: str, space: Mapping[str, Interval] | None = None,
                 fix: Sequence[str] = ()) -> list[Dim]:
    """The resolved search space of ``agent`` (``space``: instead of :data:`SEARCH`; a
    name given without bounds there takes its :data:`SEARCH` interval when it has one,
    else its declared range), without the parameters ``fix`` (kept at their defaults)."""
    declared = {p.name: p for p in agent_specs(agent)}
    name, _ = parse_agent(agent)
    wanted = SEARCH[name] if space is None else \
        {k: SEARCH[name].get(k, iv) if iv == Interval() else iv for k, iv in space.items()}
    for pname in fix:
        if pname not in declared:
            raise UsageError(f"tune {agent}: --fix: " + unknown_name_message(pname, declared))
        if pname not in wanted:
            raise UsageError(f"tune {agent}: --fix {pname!r}: it is not searched "
                             f"(searched: {', '.join(wanted)})")
    wanted = {k: iv for k, iv in wanted.items() if k not in fix}
    if not wanted:
        raise UsageError(f"tune {agent}: --fix leaves no parameter to search")
    dims = []
    for pname, iv in wanted.items():
        p = declared.get(pname)
        if p is None:
            raise UsageError(f"tune {agent}: " + unknown_name_message(pname, declared))
        if p.choices is not None or isinstance(p.default, (bool, str, tuple)):
            raise UsageError(f"tune {agent}: parameter {pname!r} is not numeric "
                             "(only numbers are searched)")
        low = p.low if iv.low is None else iv.low
        high = p.high if iv.high is None else iv.high
        if low is None or high is None or not low < high:
            raise UsageError(f"tune {agent}: give {pname!r} a finite interval "
                             f"(declared {p.range_text()}): --space {pname}=LOW:HIGH")
        for bound in (low, high):
            try:
                p.check(int(bound) if p.integer else float(bound))
            except ParamError as exc:
                raise UsageError(f"tune {agent}: search interval [{low:g}, {high:g}] of "
                                 f"{pname!r} leaves its declared range: {exc}; give "
                                 f"--space {pname}=LOW:HIGH inside it") from None
        if iv.log and low <= 0:
            raise UsageError(f"tune {agent}: a log interval of {pname!r} needs LOW > 0")
        dims.append(Dim(pname, low, high, iv.log, p.integer, p.default))
    return dims


def describe_space(agent: str, space: Mapping[str, Interval] | None = None,
                   fix: Sequence[str] = ()) -> str:
    """``tune AGENT --list``: every parameter, searched (with its interval) or fixed."""
    dims = {d.name: d for d in search_space(agent, space, fix)}
    lines = [f"parameters of {agent} ('*' = searched by tune; --space changes the set)"]
    for p in agent_specs(agent):
        d = dims.get(p.name)
        declared = ("true/false" if isinstance(p.default, bool) else
                    "/".join(p.choices) if p.choices else p.range_text())
        what = (f"* [{d.low:g}, {d.high:g}]{' log' if d.log else ''}" if d else
                f"  fixed, declared {declared}")
        lines.append(f"  {p.name:<22} default {p.default!r:<10} {what}")
    return "\n".join(lines)


# ------------------------------------------------------------------------- the runs
@dataclass(frozen=True)
class Task:
    """One maze of a split and its event: a block (``oracle``: its oracle steps) or an
    opening (``kind`` "open"; ``oracle``: the new shortest path)."""

    name: str
    family: str
    text: str
    event: str
    oracle: int
    cap_ratio: float           # a failed episode's ratio: episode_steps / oracle
    kind: str = "block"
    world: WorldSpec | None = None   # --world (None: the grid), oracles in its steps

    @classmethod
    def of(cls, sm, kind: str = "block", world: WorldSpec | None = None) -> "Task":
        maze = sm.maze()
        if kind == "open":
            d = env_change.event_oracle(world, maze, sm.open_event, GOAL)["shortest_after"]
            return cls(sm.name, sm.family, sm.text, sm.open_event, d,
                       Caps.for_maze(maze).episode_steps / d, kind, world)
        oracle = env_change.event_oracle(world, maze, sm.block_event, GOAL)["oracle_steps"]
        return cls(sm.name, sm.family, sm.text, sm.block_event, oracle,
                   Caps.for_maze(maze).episode_steps / oracle, "block", world)


def tasks(spec: str, suite_seed: int, first: int, kind: str = "block",
          world: WorldSpec | None = None) -> tuple[list[Task], list[str]]:
    """The mazes of a split with a block event (``kind`` "open": an opening), and the
    names of those without one; ``world``: the ``--world`` they run in."""
    try:
        mazes = suite(spec, suite_seed, first)
    except SuiteError as exc:
        raise UsageError(str(exc)) from exc
    event = (lambda sm: sm.open_event) if kind == "open" else (lambda sm: sm.block_event)
    todo = [Task.of(sm, kind, world) for sm in mazes if event(sm)]
    skipped = [sm.name for sm in mazes if not event(sm)]
    if not todo:
        raise UsageError(f"suite {spec!r} has no maze with an opening (blocking mazes "
                         "have none)" if kind == "open" else
                         f"suite {spec!r} has no maze with a block event "
                         "(shortcut mazes have none)")
    return todo, skipped


def block_run(agent: str, overrides: Mapping[str, Any], task: Task,
              seed: np.random.SeedSequence) -> dict:
    """Steps 1-3 of the env-change protocol, :func:`.env_change.trial` itself with the
    overrides: train on G to convergence, fire the block, the first episode's steps."""
    maze = Maze.from_text(task.text, source=task.name)
    r = env_change.trial(agent, 0, seed, maze, task.event, GOAL, overrides,
                         to_optimal=False, world_spec=task.world)
    return {"steps": r["steps"], "train_episodes": r["train_episodes"]}


def open_run(agent: str, overrides: Mapping[str, Any], task: Task,
             seed: np.random.SeedSequence) -> dict:
    """The env-change protocol with the maze's opening, step 4 capped at
    :data:`OPEN_WITHIN` episodes: the episodes until the greedy path uses the shortcut
    (``None``: not within the cap)."""
    maze = Maze.from_text(task.text, source=task.name)
    r = env_change.trial(agent, 0, seed, maze, task.event, GOAL, overrides,
                         within=OPEN_WITHIN, world_spec=task.world)
    return {"episodes": r["episodes_to_optimal"], "train_episodes": r["train_episodes"]}


def run_task(agent: str, overrides: Mapping[str, Any], task: Task,
             seed: np.random.SeedSequence) -> dict:
    """:func:`block_run` or :func:`open_run`, by the task's kind."""
    return (open_run if task.kind == "open" else block_run)(agent, overrides, task, seed)


def score(task_list: Sequence[Task], runs: Sequence[Sequence[dict]],
          open_weight: float = 0.0) -> dict:
    """The objective of runs[m][s] (maze m, seed s; block and opening tasks in any order),
    with what it is made of."""
    per_maze, failed, total, worst = [], 0, 0, 0.0
    found, opened, open_per_maze = 0, 0, {}
    blocks = [(t, rs) for t, rs in zip(task_list, runs) if t.kind == "block"]
    for task, rs in zip(task_list, runs):
        if task.kind != "open":
            continue
        hits = [r["episodes"] is not None for r in rs]
        found += sum(hits)
        opened += len(hits)
        failed += sum(r["train_episodes"] is None for r in rs)
        total += len(rs)
        open_per_maze[task.name] = sum(hits) / len(hits)
    for task, rs in blocks:
        ratios = []
        for r in rs:
            ok = r["steps"] is not None
            ratio = r["steps"] / task.oracle if ok else task.cap_ratio
            ratios.append(ratio)
            failed += (not ok) or r["train_episodes"] is None
            total += 1
            worst = max(worst, ratio)
        per_maze.append(statistics.median(ratios))
    geo = math.exp(statistics.fmean(math.log(m) for m in per_maze))
    missed = (opened - found) / opened if opened else 0.0
    return {"objective": geo + PENALTY * failed / total + open_weight * missed,
            "geo_mean_ratio": geo, "median_ratio": statistics.median(per_maze),
            "failed_runs": failed, "runs": total, "worst_ratio": worst,
            "per_maze": {t.name: m for (t, _), m in zip(blocks, per_maze)},
            "open_found": found / opened if opened else None, "open_runs": opened,
            "open_per_maze": open_per_maze}


def evaluate(agent: str, overrides: Mapping[str, Any], task_list: Sequence[Task],
             seeds: Sequence[np.random.SeedSequence], jobs: int = 1,
             progress: bool = False, desc: str = "runs", open_weight: float = 0.0) -> dict:
    """:func:`score` of ``agent`` with ``overrides`` on every task and seed (``jobs`` > 1:
    the experiments' process pool, :func:`.parallel.run_items`)."""
    items = [(agent, dict(overrides), t, s) for t in task_list for s in seeds]
    flat = (run_items(run_task, items, jobs, desc, progress) if jobs > 1 else
            [run_task(*item) for item in items])
    n = len(seeds)
    return score(task_list, [flat[i * n:(i + 1) * n] for i in range(len(task_list))],
                 open_weight)


# ------------------------------------------------------------------------- storage
def open_storage(where: str):
    """An Optuna storage: an RDB URL as given, else a journal file with a file lock."""
    import optuna
    from optuna.storages.journal import JournalFileBackend, JournalFileOpenLock
    if "://" in where:
        try:
            return optuna.storages.RDBStorage(where)
        except Exception as exc:  # noqa: BLE001 -- sqlalchemy/optuna errors of many kinds
            raise UsageError(f"--storage {where}: cannot open the RDB storage: "
                             f"{type(exc).__name__}: {exc}") from None
    path = Path(where)
    try:
        if path.is_dir():
            raise IsADirectoryError(f"{path} is a directory")
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "ab"):
            pass
        return optuna.storages.JournalStorage(
            JournalFileBackend(str(path), lock_obj=JournalFileOpenLock(str(path))))
    except Exception as exc:  # noqa: BLE001 -- OSError, or a file that is no journal
        raise UsageError(f"--storage {where}: cannot use it as an Optuna journal file: "
                         f"{type(exc).__name__}: {exc}") from None


# ------------------------------------------------------------------------- the study
@dataclass(frozen=True)
class Setup:
    """Everything that defines a study's objective (stored with the study)."""

    agent: str
    suite: str
    suite_seed: int
    suite_first: int
    seeds: int
    seed: int
    penalty: float
    space: tuple[tuple, ...]      # (name, low, high, log, integer) per searched parameter
    open_suite: str = ""          # the openings' split ("": none)
    open_weight: float = 0.0
    world: str = "grid"           # --world (and --world-kwargs JSON, "" none)
    world_kwargs: str = ""

    @property
    def world_spec(self) -> WorldSpec:
        return parse_world(self.world, self.world_kwargs)

    def task_list(self) -> list[Task]:
        """The block tasks, then the opening tasks, of the training split."""
        w = self.world_spec
        todo, _ = tasks(self.suite, self.suite_seed, self.suite_first, world=w)
        if self.open_suite:
            todo += tasks(self.open_suite, self.suite_seed, self.suite_first, "open", w)[0]
        return todo

    def dims(self) -> list[Dim]:
        declared = {p.name: p for p in agent_specs(self.agent)}
        return [Dim(n, lo, hi, lg, it, declared[n].default)
                for n, lo, hi, lg, it in self.space]


def interleaved(task_list: Sequence[Task]) -> list[Task]:
    """The tasks in the order a trial runs them: block and opening tasks alternating (as
    long as both last), so that the objective of the first k tasks, which the pruner
    compares, is made of both."""
    blocks = [t for t in task_list if t.kind == "block"]
    opens = [t for t in task_list if t.kind != "block"]
    out = []
    for k in range(max(len(blocks), len(opens))):
        out += blocks[k:k + 1] + opens[k:k + 1]
    return out


def _objective(setup: Setup, task_list: list[Task], worker: str):
    import optuna
    seeds = trial_seeds(setup.seed, setup.seeds)
    dims = setup.dims()
    order = interleaved(task_list)

    def objective(trial) -> float:
        trial.set_user_attr("worker", worker)
        params = {d.name: d.suggest(trial) for d in dims}
        # an invalid combination (ParamError) fails the trial before any run
        make_agent(setup.agent, Maze.from_text(task_list[0].text), np.random.default_rng(0),
                   params)
        runs = []
        for k, task in enumerate(order):
            runs.append([run_task(setup.agent, params, task, sd) for sd in seeds])
            if k % PRUNE_EVERY == PRUNE_EVERY - 1 and k < len(order) - 1:
                trial.report(score(order[:k + 1], runs, setup.open_weight)["objective"], k)
                if trial.should_prune():
                    raise optuna.TrialPruned()
        s = score(order, runs, setup.open_weight)
        for key in ("geo_mean_ratio", "median_ratio", "failed_runs", "worst_ratio",
                    "open_found"):
            trial.set_user_attr(key, s[key])
        return s["objective"]

    return objective


def pruner():
    """Optuna's median rule, the same for every agent: after :data:`PRUNE_STARTUP`
    trials ran to the end, a trial whose objective over its first k tasks (every
    :data:`PRUNE_EVERY`, from the :data:`PRUNE_WARMUP`-th on) is worse than the median of
    the earlier trials at k stops there (PRUNED: it counts in the budget, and is never
    the best). A setting that fails its first mazes costs their caps, not the split's."""
    import optuna
    return optuna.pruners.MedianPruner(n_startup_trials=PRUNE_STARTUP,
                                       n_warmup_steps=PRUNE_WARMUP)


def _worker(storage: str, study_name: str, setup: Setup, n_trials: int, budget: int,
            index: int, quiet: bool) -> int:
    """One worker process: ``n_trials`` trials at most, until the study holds ``budget``."""
    import optuna
    from optuna.study import MaxTrialsCallback
    from optuna.trial import TrialState
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    if parse_agent(setup.agent)[0] == "tmgwr":
        warm_up()
    task_list = setup.task_list()
    seed = int(np.random.SeedSequence([setup.seed, index]).generate_state(1)[0])
    study = optuna.load_study(study_name=study_name, storage=open_storage(storage),
                              sampler=optuna.samplers.TPESampler(seed=seed),
                              pruner=pruner())
    worker = f"{socket.gethostname()}:{os.getpid()}:{index}"
    done = (TrialState.COMPLETE, TrialState.FAIL, TrialState.PRUNED)

    def say(study, trial) -> None:
        if not quiet:
            value = (trial.state.name.lower() if trial.value is None else
                     f"{trial.value:.3f}")
            print(f"tune {study_name}: trial {trial.number} ({worker}): {value}",
                  file=sys.stderr, flush=True)

    if len(study.get_trials(deepcopy=False, states=done)) >= budget:
        return 0
    before = len(study.get_trials(deepcopy=False))
    study.optimize(_objective(setup, task_list, worker), n_trials=n_trials,
                   callbacks=[MaxTrialsCallback(budget, states=done), say],
                   catch=(ParamError,))
    return len(study.get_trials(deepcopy=False)) - before


def _create(storage: str, study_name: str, setup: Setup):
    """Create or re-open the study; refuse one made for another objective."""
    import optuna
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(study_name=study_name, storage=open_storage(storage),
                                direction="minimize", load_if_exists=True)
    mine = json.loads(json.dumps(asdict(setup)))
    if mine["world"] == "grid" and not mine["world_kwargs"]:
        del mine["world"], mine["world_kwargs"]   # as studies made before --world store it
    mine["space"] = sorted(mine["space"])       # the same space named in any order
    theirs = study.user_attrs.get("setup")
    if theirs is not None and "space" in theirs:
        theirs = {**theirs, "space": sorted(theirs["space"])}
    if theirs is None:
        study.set_user_attr("setup", mine)
        defaults = {d.name: d.default for d in setup.dims() if d.contains(d.default)}
        study.enqueue_trial(defaults, user_attrs={"defaults": True})
    elif theirs != mine:
        grid = {"world": "grid", "world_kwargs": ""}    # what a study without them means
        theirs, mine = {**grid, **theirs}, {**grid, **mine}
        diff = ", ".join(f"{k} {theirs.get(k)!r} (now {mine[k]!r})" for k in mine
                         if theirs.get(k) != mine[k])
        raise UsageError(f"study {study_name!r} in {storage} was made with other options: "
                         f"{diff}; give another --study or the same options")
    return study


def run_workers(storage: str, study_name: str, setup: Setup, budget: int, workers: int,
                quiet: bool = False) -> None:
    """``workers`` processes on one study, worker i running its share of ``budget``."""
    shares = [budget // workers + (i < budget % workers) for i in range(workers)]
    if workers == 1:
        _worker(storage, study_name, setup, shares[0], budget, 0, quiet)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        futures = [pool.submit(_worker, storage, study_name, setup, n, budget, i, quiet)
                   for i, n in enumerate(shares)]
        for f in futures:
            f.result()


def best_of(study, budget: int) -> tuple[Any, list]:
    """(best complete trial among the first ``budget`` by number, those trials)."""
    from optuna.trial import TrialState
    counted = sorted(study.get_trials(deepcopy=False), key=lambda t: t.number)[:budget]
    complete = [t for t in counted if t.state == TrialState.COMPLETE]
    if not complete:
        return None, counted
    return min(complete, key=lambda t: (t.value, t.number)), counted


# ------------------------------------------------------------------------- outputs
def params_section(agent: str) -> str:
    """The parameter-file section of an agent's values (see the module docstring)."""
    name, _ = parse_agent(agent)
    return "/**" if name == "tmgwr" else name


def write_params(path: str | Path, agent: str, params: Mapping[str, Any],
                 header: str) -> Path:
    """The tuned values as a ROS 2 parameter file (values as plain Python numbers)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    clean = {k: (int(v) if isinstance(v, (int, np.integer)) else float(v))
             for k, v in sorted(params.items())}
    body = yaml.safe_dump({params_section(agent): {"ros__parameters": clean}},
                          sort_keys=False, default_flow_style=False)
    comment = "".join(f"# {line}\n" for line in header.splitlines())
    path.write_text(comment + body)
    return path


def tuned_sections(path: str | Path) -> dict[str, dict[str, Any]]:
    """Every section of a parameter file of agents, by agent name (``tmgwr`` for ``/**``),
    each value checked by its agent's Config. A section no agent reads, an unknown name
    or a value out of range is refused, naming it and the file."""
    known = {params_section(a): a for a in AGENT_NAMES}
    out: dict[str, dict[str, Any]] = {}
    for section, values in read_params_file(path).items():
        key = section if section == "/**" else section.lstrip("/")
        if key not in known:
            close = [c for c in known if c != "/**"]
            hint = next(iter(difflib.get_close_matches(key, close, n=1)), None)
            raise ParamError(
                f"{path}: section '{section}' is read by no agent"
                f"{f' (did you mean {hint!r}?)' if hint else ''}; sections: '/**' (tmgwr), "
                + ", ".join(f"'{c}'" for c in close))
        agent = known[key]
        declared = {p.name: p for p in agent_specs(agent)}
        where = f"{path} [{section}]"
        checked = {}
        for name, v in values.items():
            if name not in declared:
                raise ParamError(unknown_name_message(name, declared, where))
            checked[name] = declared[name].check(v, where)
        if agent != "tmgwr":    # the baselines' own cross-field checks (eps_min <= eps_start)
            make_config(_config_class(agent), checked, where)
        out[agent] = {**out.get(agent, {}), **checked}
    return out


def load_tuned(path: str | Path, agent: str) -> dict[str, Any]:
    """The overrides a parameter file holds for ``agent`` (its section; see
    :func:`tuned_sections`, which checks the whole file)."""
    return tuned_sections(path).get(parse_agent(agent)[0], {})


def experiment_params(agents: Sequence[str],
                      params: Sequence[str]) -> dict[str, dict[str, Any]]:
    """``experiment --params``: the overrides of every agent spec of ``agents`` read from
    the parameter files ``params``, in order (a later file's value wins).

    ``FILE``: each agent takes its own section (TMGWR specs ``/**``, a baseline the section
    named after it; sections of agents not run are checked, then ignored), and a file
    with nothing for any of the agents is refused. ``AGENT=FILE``: only the specs
    ``AGENT`` names take the file's section for them (``AGENT`` a spec of ``agents``, or an
    agent name for all its specs, e.g. ``tmgwr:credit=a.yaml`` and ``tmgwr:literal=b.yaml``
    give two TMGWR runs their own ``/**`` values). A spec's own options
    (``tmgwr:credit``) win over a file."""
    out: dict[str, dict[str, Any]] = {a: {} for a in agents}
    for arg in params:
        name, eq, path = arg.partition("=")
        restricted = bool(eq) and not Path(arg).exists()
        if restricted:
            try:
                base, _ = parse_agent(name)
            except ValueError as exc:
                raise UsageError(f"--params {arg}: {exc}") from None
            targets = [a for a in agents
                       if a == name or (name == base and parse_agent(a)[0] == base)]
            if not targets:
                raise UsageError(f"--params {arg}: agent {name!r} is not among the agents "
                                 f"run ({', '.join(agents)})")
        else:
            targets, path = list(agents), arg
        try:
            sections = tuned_sections(path)
        except ParamError as exc:
            raise UsageError(str(exc)) from None
        have = ", ".join(f"'{params_section(s)}'" for s in sections) or "none"
        used = False
        for spec in targets:
            values = sections.get(parse_agent(spec)[0])
            if values is None and restricted:
                raise UsageError(f"--params {arg}: {path} has no section "
                                 f"'{params_section(spec)}' for {spec} (its sections: "
                                 f"{have})")
            if values is not None:
                out[spec].update(values)
                used = True
        if not used:
            raise UsageError(f"--params {arg}: {path} has values for none of the agents "
                             f"{', '.join(agents)} (its sections: {have})")
    return out


def tuned_file(agent: str, world: str = "grid") -> Path:
    """The committed tuned file of ``agent`` (a spec; its agent name picks the file) for
    ``world`` (a ``--world`` name): ``config/tuned/AGENT.yaml`` in the grid,
    ``config/tuned/WORLD/AGENT.yaml`` in another world. A world's values are tuned in
    that world, so there is no fallback to the grid's file: a missing file is refused,
    naming it and the command that makes it."""
    name, _ = parse_agent(agent)
    world = world.partition(":")[0] or "grid"
    path = TUNED / f"{name}.yaml" if world == "grid" else TUNED / world / f"{name}.yaml"
    if world == "gym":
        raise UsageError(f"no tuned file for {agent} in a registered env: tune runs on the "
                         f"mazes of a maze world ({', '.join(WORLDS)})")
    if not path.is_file():
        how = "" if world == "grid" else f" --world {world}"
        raise UsageError(f"no tuned file for {agent} in --world {world}: {_shown(path)} "
                         f"does not exist (./tmgwr tune {name}{how} makes it, "
                         "docs/tuning.md)")
    return path


def resolve_tuned(params: Sequence[str], world: str | None) -> list[str]:
    """``experiment --params AGENT=tuned``: ``AGENT=`` the committed tuned file of that
    agent for the ``--world`` (:func:`tuned_file`); other arguments as given. The JSON
    then records the file used."""
    out = []
    for arg in params:
        name, eq, value = arg.partition("=")
        if arg == TUNED_WORD:
            raise UsageError("--params tuned: name the agent, --params AGENT=tuned (e.g. "
                             "q_learning=tuned): the tuned file is per agent and world")
        if eq and value == TUNED_WORD and not Path(arg).exists():
            try:
                arg = f"{name}={_shown(tuned_file(name, world or 'grid'))}"
            except ValueError as exc:
                raise UsageError(f"--params {arg}: {exc}") from None
        out.append(arg)
    return out


def _shown(path: Path) -> str:
    """``path`` relative to the working directory when it is below it."""
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def _config_class(name: str):
    return baseline_class(name).Config


def _trial_row(t) -> dict:
    return {"number": t.number, "state": t.state.name, "value": t.value,
            "params": t.params, "worker": t.user_attrs.get("worker"),
            "defaults": bool(t.user_attrs.get("defaults")),
            **{k: t.user_attrs.get(k) for k in ("geo_mean_ratio", "median_ratio",
                                                "failed_runs", "worst_ratio",
                                                "open_found")}}


def _table(held: dict) -> str:
    t, d = held["tuned"], held["defaults"]
    lines = [f"held-out {held['suite']} (first {held['first']}, {held['trials']} seeds, "
             f"{len(held['mazes'])} mazes): steps / oracle of the first episode after "
             "the block",
             f"  {'maze':<14} {'oracle':>6} {'tuned':>8} {'defaults':>8}"]
    for m in held["mazes"]:
        lines.append(f"  {m:<14} {held['oracle'][m]:>6} {t['per_maze'][m]:>8.2f} "
                     f"{d['per_maze'][m]:>8.2f}")
    for label, s in (("tuned", t), ("defaults", d)):
        found = ("" if s["open_found"] is None else
                 f", openings found within {OPEN_WITHIN} episodes {s['open_found']:.0%}")
        lines.append(f"  {label}: geometric mean ratio {s['geo_mean_ratio']:.2f}, median "
                     f"{s['median_ratio']:.2f}, objective "
                     f"{s['objective']:.2f}, failed runs {s['failed_runs']}/{s['runs']}, "
                     f"worst {s['worst_ratio']:.1f}{found}")
    lines.append(f"  tuned better on {held['tuned_wins']:.0%} of the mazes, worse on "
                 f"{held['tuned_losses']:.0%}")
    return "\n".join(lines)


def held_out(agent: str, params: Mapping[str, Any], spec: str, suite_seed: int,
             first: int, trials: int, seed: int, jobs: int, progress: bool,
             open_spec: str = "", open_weight: float = 0.0,
             world: WorldSpec | None = None) -> dict:
    """The tuned parameters and the defaults on a held-out split (same runs as tuning;
    ``open_spec``: its openings; ``world``: the ``--world``)."""
    task_list, skipped = tasks(spec, suite_seed, first, world=world)
    names = [t.name for t in task_list]
    if open_spec:
        task_list += tasks(open_spec, suite_seed, first, "open", world)[0]
    seeds = trial_seeds(seed, trials)
    res = {label: evaluate(agent, p, task_list, seeds, jobs, progress, f"held-out {label}",
                           open_weight)
           for label, p in (("tuned", params), ("defaults", {}))}
    t, d = res["tuned"]["per_maze"], res["defaults"]["per_maze"]
    return {"suite": spec, "open_suite": open_spec, "suite_seed": suite_seed,
            "first": first, "trials": trials,
            "seed": seed, "mazes": names, "skipped": skipped,
            "oracle": {x.name: x.oracle for x in task_list if x.kind == "block"}, **res,
            "tuned_wins": sum(t[m] < d[m] for m in names) / len(names),
            "tuned_losses": sum(t[m] > d[m] for m in names) / len(names)}


def _default_eval_first(spec: str, first: int) -> int:
    return first + max(n for _, n in suite_counts(spec))


def run(args) -> int:
    """``./tmgwr tune`` (arguments: :mod:`.cli`)."""
    try:
        parse_agent(args.agent)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    space = parse_space(args.space) if args.space else None
    fix = [f.strip() for f in (args.fix or "").split(",") if f.strip()]
    dims = search_space(args.agent, space, fix)
    if args.list:
        print(describe_space(args.agent, space, fix))
        return 0
    if args.trials < 1 or args.workers < 1 or args.seeds < 1 or args.eval_trials < 1:
        raise UsageError("--trials, --workers, --seeds and --eval-trials must be >= 1")
    if args.suite_seed < 0 or args.suite_first < 0:
        raise UsageError("--suite-seed and --suite-first must be >= 0")
    try:
        wspec = parse_world(args.world, args.world_kwargs)
    except WorldError as exc:
        raise UsageError(f"--world: {exc}") from None
    if not wspec.from_maze:
        raise UsageError(f"--world {wspec.text}: tuning runs the env-change protocol on a "
                         f"maze suite; a registered env has neither")
    why = check_world([args.agent], wspec)
    if why:
        raise UsageError(f"--world: {why}")
    stem = args.study or args.agent.replace(":", "-").replace("+", "-")
    study_name = stem if args.study or wspec.name == "grid" else f"{stem}-{wspec.name}"
    out_dir = RESULTS if wspec.name == "grid" else RESULTS / wspec.name
    storage = args.storage or str(RESULTS / "optuna.journal")
    if args.open_weight < 0:
        raise UsageError("--open-weight must be >= 0")
    open_suite = args.open_suite if args.open_weight > 0 else ""
    setup = Setup(args.agent, args.suite, args.suite_seed, args.suite_first, args.seeds,
                  args.seed, PENALTY,
                  tuple((d.name, d.low, d.high, d.log, d.integer) for d in dims),
                  open_suite, args.open_weight if open_suite else 0.0, wspec.name,
                  args.world_kwargs or "")
    _, skipped = tasks(args.suite, args.suite_seed, args.suite_first, world=wspec)
    task_list = setup.task_list()
    study = _create(storage, study_name, setup)
    if not args.quiet:
        print(f"tune {args.agent}: study {study_name!r} in {storage}, {args.trials} trials, "
              f"{args.workers} worker(s), {len(task_list)} runs of mazes x {args.seeds} "
              "seeds",
              file=sys.stderr)
    run_workers(storage, study_name, setup, args.trials, args.workers, args.quiet)

    import optuna
    study = optuna.load_study(study_name=study_name, storage=open_storage(storage))
    best, counted = best_of(study, args.trials)
    if best is None:
        raise UsageError(f"study {study_name!r}: no trial of the first {args.trials} "
                         "completed (see the failed trials in the journal)")
    default_trial = next((t for t in counted if t.user_attrs.get("defaults")), None)
    params = dict(best.params)
    out_params = Path(args.params_out or out_dir / f"{stem}.yaml")
    d_value = None if default_trial is None else default_trial.value
    header = (f"tuned by ./tmgwr tune {args.agent} (docs/tuning.md): study {study_name}, "
              f"best of {len(counted)} trials\n"
              f"objective {best.value:.4f} (defaults "
              f"{'-' if d_value is None else format(d_value, '.4f')}) "
              f"on {'' if wspec.name == 'grid' else f'--world {wspec.text} '}"
              f"--suite {args.suite} --open-suite {open_suite or '-'} --open-weight "
              f"{setup.open_weight:g} --suite-seed {args.suite_seed} "
              f"--suite-first {args.suite_first}, {args.seeds} seeds\n"
              f"searched: {', '.join(sorted(d.name for d in dims))}; the rest at their "
              "defaults")
    write_params(out_params, args.agent, params, header)
    load_tuned(out_params, args.agent)          # what we wrote reads back
    workers = {}
    for t in counted:
        w = t.user_attrs.get("worker")
        workers[w] = workers.get(w, 0) + 1
    summary = {
        "agent": args.agent, "study": study_name, "storage": storage,
        "objective": {"definition": "geometric mean over mazes of the median over seeds of "
                                    "steps / oracle_steps of the first episode after the "
                                    f"block, + {PENALTY:g} x failed runs / runs, + "
                                    f"{setup.open_weight:g} x openings missed (greedy path "
                                    f"not on the shortcut within {OPEN_WITHIN} episodes) "
                                    "/ opening runs",
                      "suite": args.suite, "open_suite": open_suite,
                      "open_weight": setup.open_weight, "suite_seed": args.suite_seed,
                      "suite_first": args.suite_first, "mazes": [t.name for t in task_list],
                      "skipped": skipped, "seeds": args.seeds, "seed": args.seed,
                      "world": wspec.text},
        "space": [{"name": d.name, "low": d.low, "high": d.high, "log": d.log,
                   "integer": d.integer, "default": d.default} for d in dims],
        "budget": args.trials,
        "trials": {"counted": len(counted),
                   "complete": sum(t.state.name == "COMPLETE" for t in counted),
                   "failed": sum(t.state.name == "FAIL" for t in counted),
                   "pruned": sum(t.state.name == "PRUNED" for t in counted),
                   "beyond_budget": max(0, len(study.trials) - args.trials),
                   "by_worker": workers},
        "best": _trial_row(best),
        "defaults": None if default_trial is None else _trial_row(default_trial),
        "params_file": str(out_params),
        "history": [_trial_row(t) for t in counted],
    }
    if args.evaluate:
        first = (args.eval_first if args.eval_first is not None
                 else _default_eval_first(args.suite, args.suite_first))
        spec = args.eval_suite or args.suite
        open_spec = (args.eval_open_suite or open_suite) if open_suite else ""
        summary["held_out"] = held_out(args.agent, params, spec, args.suite_seed, first,
                                       args.eval_trials, args.seed, args.workers,
                                       not args.quiet, open_spec, setup.open_weight,
                                       wspec)
    out_json = Path(args.json or out_dir / f"{stem}.json")
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(summary, indent=1, default=_json_default) + "\n")
    d = summary["defaults"]
    print(f"best of {len(counted)} trials: objective {best.value:.3f} (trial {best.number}; "
          f"defaults {'-' if not d or d['value'] is None else format(d['value'], '.3f')})")
    for k, v in sorted(params.items()):
        print(f"  {k} = {v:.6g}" if isinstance(v, float) else f"  {k} = {v}")
    if args.evaluate:
        print(_table(summary["held_out"]))
    print(f"parameters: {out_params}\nsummary: {out_json}")
    return 0


def _json_default(v):
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating,)):
        f = float(v)
        return f if math.isfinite(f) else None
    raise TypeError(f"not JSON: {v!r}")
