"""Ctrl-C of ``ros2 launch tmgwr_agent agent.launch.py`` mid-stepping, N times (issue 10,
item 5): how many stops are clean.

A terminal's Ctrl-C sends SIGINT to the whole foreground process group: the launch and
every node at once. This script does the same (``killpg(SIGINT)``) once the ring has been
stepping for a random 2-6 s, then waits for the launch to end. A stop is clean when the
launch exits 0, every node's exit is reported with code 0 ('process has finished cleanly')
and no line holds a traceback, FATAL or an exception. Run it from the repository root::

    source tools/env.sh && python test/measure_ctrl_c.py --stops 20 [--record]

(not collected by pytest: test_launch.py runs a few stops of the same check).
"""

from __future__ import annotations

import argparse
import os
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import (  # noqa: E402
    allocate_domain,
    release_domain,
    require_ros2,
    ros_env,
)

NODES = ("maze_sim", "sensory_preprocessor", "map_learner", "motivation_estimator",
         "action_selector")
BAD = re.compile(r"Traceback|FATAL|Exception|exited with code|process has died|"
                 r"terminate called|Segmentation|Aborted", re.IGNORECASE)
STEPPING = re.compile(r"goal \(\d+, \d+\) reached in \d+ steps")


def one_stop(domain: int, seed: int, wait: float, args: list[str],
             tmp: Path) -> tuple[bool, str, int | None]:
    """One launch, one Ctrl-C; (clean, why not, launch exit code)."""
    env = ros_env(domain, {"ROS_HOME": str(tmp / "ros_home")})
    cmd = [require_ros2(), "launch", "tmgwr_agent", "agent.launch.py", f"seed:={seed}", *args]
    out_path = tmp / f"launch_{seed}.log"
    with open(out_path, "w") as out:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True)
        t0 = time.monotonic()
        while time.monotonic() - t0 < 90:            # the ring steps (a first goal)
            if STEPPING.search(out_path.read_text(errors="replace")) or proc.poll() is not None:
                break
            time.sleep(0.2)
        time.sleep(wait)
        stepping = proc.poll() is None
        os.killpg(proc.pid, signal.SIGINT)           # what a terminal's Ctrl-C does
        try:
            code = proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            code = proc.wait()
    clean, why = verdict(out_path.read_text(errors="replace"), stepping, code)
    return clean, why, code


def verdict(text: str, stepping: bool, code: int | None) -> tuple[bool, str]:
    """Was a stop clean, from its launch log: (clean, why not)."""
    why = []
    if not stepping:
        why.append("the launch had ended before the Ctrl-C")
    if code != 0:
        why.append(f"launch exit code {code}")
    clean = re.findall(r"\[(\w+)-\d+\]: process has finished cleanly", text)
    missing = [n for n in NODES if n not in clean]
    if missing:
        why.append("not finished cleanly: " + ", ".join(missing))
    why += [f"line: {ln.strip()[:160]}" for ln in text.splitlines() if BAD.search(ln)][:3]
    return not why, "; ".join(why)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stops", type=int, default=20)
    ap.add_argument("--record", action="store_true", help="with record:=true")
    ap.add_argument("--out", default="/tmp/tmgwr-ctrl-c", help="logs of each launch")
    a = ap.parse_args(argv)
    tmp = Path(a.out)
    tmp.mkdir(parents=True, exist_ok=True)
    extra = [f"record:={'true' if a.record else 'false'}"]
    if a.record:
        extra.append(f"output_dir:={tmp}/bag")
    domain = allocate_domain()
    rng = random.Random(0)
    clean = 0
    try:
        for i in range(a.stops):
            if a.record:
                import shutil
                shutil.rmtree(tmp / "bag", ignore_errors=True)
            ok, why, code = one_stop(domain, i, rng.uniform(2.0, 6.0), extra, tmp)
            clean += ok
            print(f"stop {i + 1}: {'clean' if ok else 'NOT CLEAN: ' + why}", flush=True)
    finally:
        release_domain(domain)
    print(f"CTRL_C {clean} clean of {a.stops} stops mid-stepping (logs: {tmp})", flush=True)
    return 0 if clean == a.stops else 1


if __name__ == "__main__":
    raise SystemExit(main())
