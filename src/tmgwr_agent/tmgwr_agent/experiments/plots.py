"""Figures of the experiments (matplotlib, Agg backend: no display needed).

* goal-change: grouped bars of % visits to the current (and previous) goal per
  transition and agent, error bars = std over trials (Tables 3-5 as one chart);
* env-change: bars of the mean steps to reach the goal after the event per agent, every
  trial as a dot (log scale), the ``oracle_steps`` lower bound as a dashed line; failed
  trials (``null``) are counted, "never" when all failed (Table 6, Fig. 5);
* sample-complexity: one panel per goal, mean steps per episode every 5th episode,
  log scale (Fig. 6 a-d);
* timing: grouped bars of CPU seconds for training, goal adaptation and recovery from
  the event, with std error bars; "never" where every trial failed (Fig. 7 a-c);
* a suite run (``--suite``, :func:`plot_suite`): one panel per maze family. env-change
  with blocks: per agent a box of the per-maze oracle ratios (median steps /
  oracle_steps; one dot per maze, log scale, the oracle as a dashed line at 1), failed
  trials and mazes whose median failed annotated; with openings: the per-maze median
  ``episodes_to_optimal`` instead (a dashed line at 10 episodes, mazes whose median
  never found the shortcut counted). goal-change: per agent a box of the per-maze mean
  % of episodes ending at the current goal.
* env-change at several event delays (``--event-delay 0,4,8``, :func:`plot_delays`): one
  panel per delay K, per agent the values a suite's ``overall`` summary boxes (or, on one
  maze, every trial's steps), on the same log scale.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def _save(fig, path: str | Path, source: str | None) -> None:
    """Write the PNG; ``source`` (what it was drawn from) goes in its ``Source`` text chunk,
    which ``./tmgwr results --check`` reads back."""
    fig.savefig(path, dpi=120, metadata={"Source": source} if source else None)
    plt.close(fig)


def _mean_std(s):
    """(mean, std, failed trials) of a STAT; NaN mean when every trial failed."""
    failed = (s or {}).get("failed", 0)
    if not s or s.get("mean") is None:
        return np.nan, 0.0, failed
    return s["mean"], s["std"], failed


def _grouped(ax, groups, series, title, ylabel, log=False):
    """Bars: ``series = {label: [(mean, std, failed) per group]}``; "never" where every
    trial failed, "k failed" above a bar where some did."""
    n = max(len(series), 1)
    width = 0.8 / n
    x = np.arange(len(groups))
    for i, (label, vals) in enumerate(series.items()):
        means = np.array([v[0] for v in vals], dtype=float)
        stds = np.array([v[1] for v in vals], dtype=float)
        pos = x - 0.4 + width * (i + 0.5)
        ax.bar(pos, np.nan_to_num(means), width, yerr=stds, capsize=2, label=label)
        for p, m, sd, v in zip(pos, means, stds, vals):
            if not np.isnan(m) and v[2]:
                ax.text(p, m + sd, f"{v[2]} failed", rotation=90, ha="center",
                        va="bottom", fontsize=7)
            if np.isnan(m):
                ax.text(p, 0.02, "never", rotation=90, ha="center", va="bottom", fontsize=7,
                        transform=ax.get_xaxis_transform())
    ax.set_xticks(x, groups)
    ax.set_title(title)
    ax.set_ylabel(ylabel)
    if log:
        ax.set_yscale("log")
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi * (10 if log else 1.15))     # room for the "k failed" labels
    ax.legend(fontsize=7)


def plot_goal_change(result: dict, path: str | Path, source: str | None = None) -> None:
    agents = result["agents"]
    first = next(iter(agents.values()))["transitions"]
    groups = [f"{t['from']}→{t['to']}" for t in first]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for ax, key, title in ((axes[0], "current_pct", "% episodes ending at the current goal"),
                           (axes[1], "previous_pct", "% episodes ending at the previous goal")):
        series = {a: [_mean_std(t[key]) for t in d["transitions"]] for a, d in agents.items()}
        _grouped(ax, groups, series, title, "% of episodes")
        ax.set_ylim(0, 118)
    fig.suptitle(f"Goal change ({result['episodes']} episodes per goal, "
                 f"{result['trials']} trials) -- Tables 3-5")
    fig.tight_layout()
    _save(fig, path, source)


def plot_env_change(result: dict, path: str | Path, source: str | None = None) -> None:
    """Mean steps per agent as bars, every trial as a dot (log scale: the spread can be
    wide), failed trials counted above the bar, the oracle bound as a dashed line."""
    agents = result["agents"]
    fig, ax = plt.subplots(figsize=(8, 4.5))
    names = list(agents)
    for i, a in enumerate(names):
        s = agents[a]["steps"]
        ok = [v for v in s["values"] if v is not None]
        if s["mean"] is None:
            ax.text(i, 0.02, "never (∞)", rotation=90, ha="center", va="bottom",
                    transform=ax.get_xaxis_transform())
            continue
        ax.bar(i, s["mean"], 0.6, color="tab:blue", alpha=0.6)
        ax.plot([i] * len(ok), ok, "k.", ms=4)
        if s.get("failed"):
            ax.text(i, max(ok), f"{s['failed']} failed", ha="center", va="bottom",
                    fontsize=7)
    ax.axhline(result["oracle_steps"], color="k", ls="--",
               label=f"oracle_steps = {result['oracle_steps']}")
    ax.set_yscale("log")
    ax.set_xticks(range(len(names)), names, rotation=20)
    ax.set_ylabel("steps to reach the goal after the event")
    ax.set_title(f"Changing environment, event {result['event']!r} "
                 f"({result['trials']} trials; bar = mean, dots = trials) -- Table 6 / Fig. 5")
    ax.legend()
    fig.tight_layout()
    _save(fig, path, source)


def plot_sample_complexity(result: dict, path: str | Path, source: str | None = None) -> None:
    agents = result["agents"]
    goals = result["goals"]
    every = result.get("every", 5)
    cols = min(2, len(goals))
    rows = (len(goals) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(5.5 * cols, 3.6 * rows), squeeze=False)
    for ax, g in zip(axes.flat, goals):
        for a, d in agents.items():
            curve = d["goals"][g]["curve"]
            ax.plot([every * (i + 1) for i in range(len(curve))], curve, marker=".",
                    label=a)
        ax.set_yscale("log")
        ax.set_title(f"goal {g}")
        ax.set_xlabel("episode")
        ax.set_ylabel("steps (mean over trials)")
        ax.legend(fontsize=7)
    for ax in list(axes.flat)[len(goals):]:
        ax.axis("off")
    fig.suptitle(f"Sample complexity ({result['trials']} trials) -- Fig. 6")
    fig.tight_layout()
    _save(fig, path, source)


def plot_timing(result: dict, path: str | Path, source: str | None = None) -> None:
    agents = result["agents"]
    keys = (("train_s", "training"), ("goal_adapt_s",
                                      f"goal {result['goals'][0]}→{result['goals'][1]}"),
            ("event_recover_s", f"event {result['event']!r}"))
    series = {a: [_mean_std(d[k]) for k, _ in keys] for a, d in agents.items()}
    fig, ax = plt.subplots(figsize=(8, 4.5))
    _grouped(ax, [label for _, label in keys], series,
             f"CPU seconds ({result['trials']} trials) -- Fig. 7", "CPU s", log=True)
    fig.tight_layout()
    _save(fig, path, source)


def plain_log_y(ax) -> None:
    """A log y axis labelled with plain numbers (minor ticks too when the axis spans less
    than a decade)."""
    ax.set_yscale("log")
    plain = matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}")
    ax.yaxis.set_major_formatter(plain)
    lo, hi = ax.get_ylim()
    if hi / lo < 10:
        ax.yaxis.set_minor_formatter(plain)


def plot_suite(result: dict, path: str | Path, source: str | None = None) -> None:
    """One panel per family (the families of the suite JSON, see :mod:`.suite_runner`)."""
    s = result["suite"]
    fams = [f for f, d in s["families"].items() if d["mazes"]]
    env = result["scenario"] == "env-change"
    n = max(len(fams), 1)
    cols = min(3, n)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(max(4.6 * cols, 7), 3.8 * rows),
                             squeeze=False)
    for ax, fam in zip(axes.flat, fams):
        d = s["families"][fam]
        opening = env and s.get("event") == "open"
        key = ("episodes_to_optimal" if opening else "oracle_ratio") if env \
            else "current_pct"
        names = list(d[key])
        data, nulls = [], []
        for a in names:
            vals = d[key][a]["values"]
            data.append([v for v in vals if v is not None])
            nulls.append(sum(v is None for v in vals))
        pos = np.arange(len(names))
        ok = [i for i, v in enumerate(data) if v]
        if ok:
            ax.boxplot([data[i] for i in ok], positions=pos[ok], widths=0.5,
                       medianprops={"color": "tab:red"}, showfliers=False)
        for i, v in enumerate(data):
            ax.plot(np.full(len(v), pos[i]), v, "k.", ms=4, alpha=0.7)
            notes = []
            if env and d["failures"][names[i]]:
                notes.append(f"{d['failures'][names[i]]} failed trials")
            if nulls[i]:
                notes.append(f"{nulls[i]} maze{'s' if nulls[i] > 1 else ''} never")
            if notes:
                ax.text(pos[i], 0.98, "\n".join(notes), ha="center", va="top", fontsize=7,
                        color="tab:red", transform=ax.get_xaxis_transform())
        if opening:
            ax.axhline(10, color="k", ls="--", lw=0.8)
            ax.set_yscale("log")
            ax.set_ylabel("episodes until the greedy path\nuses the shortcut (median)")
        elif env:
            ax.axhline(1.0, color="k", ls="--", lw=0.8)
            plain_log_y(ax)
            ax.set_ylabel("median steps / oracle_steps per maze")
        else:
            ax.set_ylabel("% episodes at the current goal per maze")
        ax.set_xticks(pos, names, rotation=20, fontsize=8)
        ax.set_xlim(-0.6, len(names) - 0.4)
        ax.set_title(f"{fam} ({d['mazes']} mazes, {d['trials']} trials)", fontsize=9)
    for ax in list(axes.flat)[len(fams):]:
        ax.axis("off")
    what = (f"env-change, {s.get('event', '')} event" if env
            else f"goal-change, {result['episodes']} episodes per goal")
    fig.suptitle(f"Suite {s['spec']} (seed {s['seed']}): {what}", fontsize=10)
    fig.tight_layout()
    _save(fig, path, source)


PLOTS = {"goal-change": plot_goal_change, "env-change": plot_env_change,
         "sample-complexity": plot_sample_complexity, "timing": plot_timing}


def plot_delays(result: dict, path: str | Path, source: str | None = None) -> None:
    """One panel per event delay K (:func:`.env_change.delay_views`): on a suite, per agent
    the per-maze values of the ``overall`` summary (oracle ratio after a block, episodes
    to optimal after an opening); on one maze, every trial's steps after the event."""
    from tmgwr_agent.experiments.env_change import delay_views
    views = delay_views(result)
    fig, axes = plt.subplots(1, len(views), figsize=(4.6 * len(views), 4.2), sharey=True,
                             squeeze=False)
    for ax, (k, v) in zip(axes.flat, views):
        if "suite" in v:
            opening = v["suite"].get("event") == "open"
            key = "episodes_to_optimal" if opening else "oracle_ratio"
            per = v["suite"]["overall"][key]
            label = ("episodes until the greedy path\nuses the shortcut (median per maze)"
                     if opening else "median steps / oracle_steps per maze")
        else:
            per = {a: d["steps"] for a, d in v["agents"].items()}
            label = "steps to reach the goal after the event (each trial)"
        names = list(per)
        for i, a in enumerate(names):
            vals = [x for x in per[a]["values"] if x is not None]
            if vals:
                ax.boxplot([vals], positions=[i], widths=0.5, showfliers=False,
                           medianprops={"color": "tab:red"})
                ax.plot([i] * len(vals), vals, "k.", ms=4, alpha=0.7)
            missing = len(per[a]["values"]) - len(vals)
            if missing:
                ax.text(i, 0.98, f"{missing} never", ha="center", va="top", fontsize=7,
                        color="tab:red", transform=ax.get_xaxis_transform())
        plain_log_y(ax)
        ax.set_xticks(range(len(names)), names, rotation=20, fontsize=8)
        ax.set_title(f"event delay K = {k}", fontsize=9)
        if ax is axes.flat[0]:
            ax.set_ylabel(label)
    first = views[0][1]
    where = (f"suite {first['suite']['spec']} (seed {first['suite']['seed']})"
             if "suite" in first else Path(str(result.get("maze"))).name)
    fig.suptitle(f"env-change, {where}, {result['trials']} trials: the event K learning "
                 f"episodes after convergence", fontsize=10)
    fig.tight_layout()
    _save(fig, path, source)


def plot(result: dict, path: str | Path, source: str | None = None) -> None:
    if "delays" in result:
        plot_delays(result, path, source)
        return
    if "suite" in result:
        plot_suite(result, path, source)
        return
    PLOTS[result["scenario"]](result, path, source)
