"""The statistics of the experiment JSON (docs/experiments.md, Experiment JSON).

``STAT = {"mean": x, "std": x, "values": [...]}``: ``values`` holds one entry per trial in
trial order, ``None`` (JSON ``null``) for a trial that failed (never reached the goal
within its cap); mean and std (population std, ``ddof=0``, as numpy) are over the other
trials, ``None`` when every trial failed, and ``"failed": k`` is added when ``k > 0``
trials failed. Failed trials are reported, never dropped.
"""

from __future__ import annotations

import math
from typing import Iterable, Sequence


def _clean(v):
    if v is None:
        return None
    f = float(v)
    if not math.isfinite(f):
        return None
    return int(f) if isinstance(v, int) and not isinstance(v, bool) else f


def stat(values: Iterable[float | int | None]) -> dict:
    vals = [_clean(v) for v in values]
    ok = [float(v) for v in vals if v is not None]
    failed = len(vals) - len(ok)
    if ok:
        mean = sum(ok) / len(ok)
        std = math.sqrt(sum((v - mean) ** 2 for v in ok) / len(ok))
    else:
        mean = std = None
    out = {"mean": mean, "std": std, "values": vals}
    if failed:
        out["failed"] = failed
    return out


def mean_curve(curves: Sequence[Sequence[float]]) -> list[float]:
    """Element-wise mean of equally long curves (one per trial)."""
    if not curves:
        return []
    n = min(len(c) for c in curves)
    return [sum(c[i] for c in curves) / len(curves) for i in range(n)]


def fmt(s: dict | None, digits: int = 1) -> str:
    """``mean ± std`` for tables, with ``(k failed)``; ``inf`` when every trial failed."""
    if not s or s.get("mean") is None:
        return "inf (all failed)" if s and s.get("values") else "-"
    text = f"{s['mean']:.{digits}f} ± {s['std']:.{digits}f}"
    if s.get("failed"):
        text += f" ({s['failed']} failed)"
    return text
