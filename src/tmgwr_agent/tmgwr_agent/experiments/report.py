"""Short text tables of experiment results (printed by ``experiment``, ``demo``, ``bench``)."""

from __future__ import annotations

from tmgwr_agent.experiments.env_change import delay_views
from tmgwr_agent.experiments.stats import fmt


def _table(header: list[str], rows: list[list[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h)
              for i, h in enumerate(header)]
    line = "  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip()
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    return "\n".join(out)


def table(result: dict) -> str:
    sc, agents = result["scenario"], result.get("agents")
    if sc == "goal-change":
        rows = [[a, f"{t['from']}->{t['to']}", fmt(t["previous_pct"]), fmt(t["current_pct"])]
                for a, d in agents.items() for t in d["transitions"]]
        return _table(["agent", "goals", "% previous", "% current"], rows)
    if sc == "env-change":
        return "\n\n".join(_env_change(v, k) for k, v in delay_views(result))
    if sc == "sample-complexity":
        goals = result["goals"]
        rows = [[a] + [fmt(d["goals"][g]["episodes_to_converge"]) for g in goals]
                for a, d in agents.items()]
        return ("episodes to converge (ten consecutive optimal greedy paths)\n"
                + _table(["agent"] + [f"goal {g}" for g in goals], rows))
    if sc == "timing":
        rows = [[a, fmt(d["train_s"], 3), fmt(d["goal_adapt_s"], 3),
                 fmt(d["event_recover_s"], 3)] for a, d in agents.items()]
        return ("CPU seconds\n" + _table(
            ["agent", "train", f"goal {'->'.join(result['goals'])}",
             f"event {result['event']}"], rows))
    raise ValueError(f"unknown scenario {sc!r}")


def _env_change(result: dict, delay: int) -> str:
    """One delay's env-change table (``settled_steps`` after a delay K > 0)."""
    rows = [[a, fmt(d["steps"]), fmt(d["episodes_to_optimal"])]
            + ([fmt(d["settled_steps"])] if delay else []) for a, d in result["agents"].items()]
    return ((f"event delay {delay}: " if delay else "")
            + f"event {result['event']}: oracle_steps {result['oracle_steps']} "
            f"(shortest path {result['shortest_before']} -> {result['shortest_after']})\n"
            + _table(["agent", "steps", "episodes_to_optimal"]
                     + (["settled_steps"] if delay else []), rows))


def bench_table(result: dict) -> str:
    """Every leaf of the (nested) bench dict as ``a.b.c  value``; a STAT is one leaf; long
    values are cut at 90 characters (the JSON has them whole)."""
    rows: list[list[str]] = []

    def walk(prefix: str, val) -> None:
        if isinstance(val, dict) and "mean" not in val:
            for k, v in val.items():
                walk(f"{prefix}.{k}" if prefix else str(k), v)
        else:
            text = _short(val)
            rows.append([prefix, text if len(text) <= 90 else text[:87] + "..."])

    walk("", result)
    return _table(["measure", "value"], rows)


def _short(v) -> str:
    if isinstance(v, dict) and "mean" in v:
        return fmt(v, 4)
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return ", ".join(_short(x) for x in v)
    if isinstance(v, dict):
        return "; ".join(f"{k}={_short(x)}" for k, x in v.items())
    return str(v)
