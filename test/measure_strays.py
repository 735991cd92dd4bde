"""Rate after / rate before each stray on the per-step topics (issue 24, point 1 target:
>= 0.8). Not a test (pytest does not collect it): a measurement, run by hand::

    source tools/env.sh && python test/measure_strays.py [--window 10] [--json OUT]

Starts the five nodes and the simulator as ``ros2 run`` does (a free ROS_DOMAIN_ID of its
own), a step monitor on ``/observation``, then for each stray of ``strays.strays``: the
ring's rate over ``--window`` s, the stray (real ``ros2 topic pub``), the rate over the next
``--window`` s. Prints one line per stray and the ratios; needs the ``ros2`` command.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ros_helpers import allocate_domain, release_domain, spawn_python  # noqa: E402
from strays import STEP_MONITOR, newest_step, publish, strays  # noqa: E402
from test_lockstep_graph import run_of  # noqa: E402
from test_nodes import start_graph, stop_graph  # noqa: E402


def rate(monitor, run: int, window: float) -> float:
    """Steps per second of run ``run`` over the next ``window`` seconds."""
    s0, t0 = newest_step(monitor, run), time.monotonic()
    time.sleep(window)
    return (newest_step(monitor, run, s0) - s0) / (time.monotonic() - t0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--window", type=float, default=10.0, help="seconds per rate")
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args()
    domain = allocate_domain()
    with tempfile.TemporaryDirectory() as tmp:
        procs = start_graph(domain, Path(tmp))
        monitor = procs["monitor"] = spawn_python(STEP_MONITOR, domain=domain,
                                                  name="monitor")
        rows = []
        try:
            run = run_of(procs["maze_sim"])
            monitor.wait_for_line("MONITOR READY", timeout=60)
            while (newest_step(monitor, run) or 0) < 500:      # past the start
                time.sleep(0.5)
            for stray in strays(run):
                before = rate(monitor, run, args.window)
                publish(domain, stray)
                after = rate(monitor, run, args.window)
                rows.append({"stray": str(stray), "before": before, "after": after,
                             "ratio": after / before if before else None})
                print(f"{str(stray):75s} before {before:6.1f}/s after {after:6.1f}/s "
                      f"ratio {after / before:.2f}", flush=True)
        finally:
            stop_graph(procs)
            release_domain(domain)
    ratios = [r["ratio"] for r in rows]
    print(f"ratio after/before: min {min(ratios):.2f}, median "
          f"{sorted(ratios)[len(ratios) // 2]:.2f} over {len(ratios)} strays")
    if args.json:
        Path(args.json).write_text(json.dumps({"window_s": args.window, "strays": rows},
                                              indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
