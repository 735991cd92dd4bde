"""``./tmgwr demo`` (``make demo``): every scenario, briefly, on the default maze.

Few trials (``--trials``, default 3) and short phases so the whole run takes a couple of
minutes on two cores: goal-change ``1,2,3,4,1`` with 100 episodes per goal; env-change
for events ``a`` and ``b`` with both TMGWR link rules; sample-complexity on goals
``1,2,3,4`` with 50-episode curves; timing (train on G, goal 4 -> 3, event a). Each
scenario writes ``<name>.json`` and ``<name>.png`` under ``results/<UTC time>/`` (or
``--out``) and prints its table. The full-size runs are ``./tmgwr experiment ...``
(docs/experiments.md). Then :mod:`tmgwr_agent.graph.demo` plays the ROS 2 graph scenario (not with
``--no-graph``).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

#: (file name, scenario, keyword arguments of run_scenario)
RUNS = (
    ("goal-change", "goal-change", {"goals": ("1", "2", "3", "4", "1"), "episodes": 100}),
    ("env-change-a", "env-change", {"event": "a"}),
    ("env-change-b", "env-change", {"event": "b"}),
    ("sample-complexity", "sample-complexity", {"episodes": 50}),
    ("timing", "timing", {"event": "a"}),
)


def run(args) -> int:
    from tmgwr_agent.experiments.output import write_json
    from tmgwr_agent.experiments.plots import plot
    from tmgwr_agent.experiments.report import table
    from tmgwr_agent.experiments.scenarios import DEFAULT_MAZE, UsageError, run_scenario
    if args.trials < 1:
        print("tmgwr: error: --trials must be >= 1", file=sys.stderr)
        return 2
    out = Path(args.out) if args.out else \
        Path("results") / time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    out.mkdir(parents=True, exist_ok=True)
    t_all = time.time()
    for name, scenario, kw in RUNS:
        t0 = time.time()
        try:
            result = run_scenario(scenario, DEFAULT_MAZE, None, args.trials, args.seed,
                                  jobs=args.jobs, **kw)
        except UsageError as exc:
            print(f"tmgwr: error: {exc}", file=sys.stderr)
            return 2
        write_json(result, out / f"{name}.json")
        plot(result, out / f"{name}.png")
        print(f"\n== {name} ({args.trials} trials, {time.time() - t0:.0f} s): "
              f"{out / (name + '.json')}, {out / (name + '.png')}")
        print(table(result))
    print(f"\nscenarios done in {time.time() - t_all:.0f} s; results in {out}/")
    if getattr(args, "no_graph", False):
        return 0
    print("\n== ROS 2 graph demo")
    args.out = str(out)
    from tmgwr_agent.graph.demo import run as graph_demo
    return int(graph_demo(args) or 0)
