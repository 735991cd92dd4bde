"""Rate after / rate before each stray on the per-step topics (issue 24, point 1 target:
>= 0.8). Not a test (pytest does not collect it): a measurement, run by hand::

    source tools/env.sh && python test/measure_strays.py [--window 10] [--json OUT] [--match T]
        [--repeat N]

Starts the five nodes and the simulator as ``ros2 run`` does (a free ROS_DOMAIN_ID of its
own), a step monitor on ``/observation``, then for each stray of ``strays.strays``: the
ring's rate over ``--window`` s, the stray (real ``ros2 topic pub``), the rate over the next
``--window`` s; before each, a control pair of windows with no stray between them (how
much the rate moves by itself: the agent's phase, the machine's load); and in each window
the longest stall (the newest step unchanged), which a resend-paced ring shows as ~1 s.
Prints one line per stray and the ratios; needs the ``ros2`` command. ``--repeat N``
measures each stray N times in a row: on a loaded machine the control ratio of a single
pair of windows spreads widely, so a ratio is judged against the controls' spread. Beside
the rate, the steps per CPU second of the graph's six processes: a machine's load takes CPU
from the graph but not the work a step costs, so a stray that adds work shows there whatever
the load; a stray that makes the ring wait shows as a stall.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from ros_helpers import allocate_domain, release_domain, spawn_python  # noqa: E402
from strays import STEP_MONITOR, newest_step, publish, strays  # noqa: E402
from test_lockstep_graph import run_of  # noqa: E402
from test_nodes import start_graph, stop_graph  # noqa: E402


def cpu_seconds(procs) -> float:
    """User + system CPU seconds the processes ``procs`` have used (Linux /proc)."""
    total = 0
    for p in procs:
        fields = Path(f"/proc/{p.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        total += int(fields[11]) + int(fields[12])        # utime, stime (stat fields 14, 15)
    return total / os.sysconf("SC_CLK_TCK")


def rate(monitor, run: int, window: float, graph) -> tuple[float, float, float]:
    """(steps per second, longest stall in seconds: the longest time the newest step did
    not move, steps per CPU second of the processes ``graph``) of run ``run`` over the next
    ``window`` seconds."""
    s0 = newest_step(monitor, run)
    t0 = last_move = time.monotonic()
    c0 = cpu_seconds(graph)
    step, stall = s0, 0.0
    while time.monotonic() - t0 < window:
        time.sleep(0.05)
        now, s = time.monotonic(), newest_step(monitor, run, s0)
        if s != step:
            step, last_move = s, now
        stall = max(stall, now - last_move)
    cpu = max(cpu_seconds(graph) - c0, 1e-9)
    return (step - s0) / (time.monotonic() - t0), stall, (step - s0) / cpu


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--window", type=float, default=10.0, help="seconds per rate")
    ap.add_argument("--json", help="write the figures here")
    ap.add_argument("--match", nargs="+", default=[""], help="only the strays whose "
                    "description holds one of these texts (e.g. /motivation)")
    ap.add_argument("--repeat", type=int, default=1, help="measurements of each stray")
    args = ap.parse_args()
    domain = allocate_domain()
    with tempfile.TemporaryDirectory() as tmp:
        procs = start_graph(domain, Path(tmp))
        graph = list(procs.values())
        monitor = procs["monitor"] = spawn_python(STEP_MONITOR, domain=domain,
                                                  name="monitor")
        rows, pause = [], 2.0
        try:
            run = run_of(procs["maze_sim"])
            monitor.wait_for_line("MONITOR READY", timeout=60)
            while (newest_step(monitor, run) or 0) < 500:      # past the start
                time.sleep(0.5)
            chosen = [s for s in strays(run) if any(m in str(s) for m in args.match)]
            for stray in [s for s in chosen for _ in range(args.repeat)]:
                # a control pair first (no stray between two windows, a pause as long as
                # the last publication took): how much the rate moves by itself
                first, _, per_cpu_first = rate(monitor, run, args.window, graph)
                time.sleep(pause)
                before, stall_before, per_cpu_before = rate(monitor, run, args.window, graph)
                t0 = time.monotonic()
                publish(domain, stray)
                pause = time.monotonic() - t0
                after, stall_after, per_cpu_after = rate(monitor, run, args.window, graph)
                rows.append({"stray": str(stray), "before": before, "after": after,
                             "ratio": after / before, "control_ratio": before / first,
                             "cpu_ratio": per_cpu_after / per_cpu_before,
                             "cpu_control_ratio": per_cpu_before / per_cpu_first,
                             "stall_before_s": stall_before, "stall_after_s": stall_after})
                print(f"{str(stray):75s} before {before:6.1f}/s after {after:6.1f}/s "
                      f"ratio {after / before:.2f} (control {before / first:.2f}), per CPU s "
                      f"{per_cpu_after / per_cpu_before:.2f} (control "
                      f"{per_cpu_before / per_cpu_first:.2f}); longest "
                      f"stall before {stall_before:.1f} s, after {stall_after:.1f} s",
                      flush=True)
        finally:
            stop_graph(procs)
            release_domain(domain)
    for key in ("ratio", "control_ratio", "cpu_ratio", "cpu_control_ratio", "stall_before_s",
                "stall_after_s"):
        v = sorted(r[key] for r in rows)
        print(f"{key}: min {v[0]:.2f}, median {v[len(v) // 2]:.2f}, max {v[-1]:.2f} over "
              f"{len(v)} strays")
    if args.json:
        Path(args.json).write_text(json.dumps({"window_s": args.window, "strays": rows},
                                              indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
