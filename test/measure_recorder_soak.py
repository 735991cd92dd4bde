"""Soak the recorder beside a busy-loop load (issue 24, item 5); prints one JSON line.

    python test/measure_recorder_soak.py --steps 30000 --load 4

Starts ``--load`` busy-loop processes (one spinning Python each), then ``./tmgwr up --seed
1 --max-steps N`` with the recorder in a domain of its own, and reads the recorder's own
account of the per-step topics from the bag's metadata (``custom_data.step_gaps``: steps
missing per topic, tmgwr_agent.bag.gaps) and the graph's rate from up's last progress line.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import ROOT, allocate_domain, release_domain, ros_env  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=30000)
    ap.add_argument("--load", type=int, default=4, help="busy-loop processes beside it")
    ap.add_argument("--timeout", type=float, default=900.0)
    args = ap.parse_args()
    domain = allocate_domain()
    bag = Path(tempfile.mkdtemp(prefix="soak_")) / "run"
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"],
                             start_new_session=True) for _ in range(args.load)]
    t0 = time.monotonic()
    try:
        up = subprocess.run(
            [sys.executable, "-u", "-m", "tmgwr_agent.cli", "up", "--seed", "1", "--quiet",
             "--record-dir", str(bag), "--max-steps", str(args.steps)],
            env=ros_env(domain), cwd=str(ROOT), capture_output=True, text=True,
            timeout=args.timeout)
    finally:
        load = os.getloadavg()[0]
        for p in busy:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
        release_domain(domain)
    seconds = time.monotonic() - t0
    out = up.stdout + up.stderr
    if not (bag / "metadata.yaml").is_file():
        print(out[-5000:], file=sys.stderr)
        raise SystemExit(f"no finished bag in {bag} (up exit {up.returncode})")
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    gaps = json.loads(meta["custom_data"]["step_gaps"])
    missing = {t: sum(r["missing"] for r in runs.values()) for t, runs in gaps.items()}
    recorded = {t: sum(r["last"] - r["first"] + 1 - r["missing"] for r in runs.values())
                for t, runs in gaps.items()}
    rates = re.findall(r"(\d+) steps/s", out)
    print(json.dumps({"steps": args.steps, "busy_loops": args.load,
                      "load_avg_1min_at_end": round(load, 2), "up_exit": up.returncode,
                      "seconds": round(seconds, 1),
                      "graph_steps_per_s_last": int(rates[-1]) if rates else None,
                      "lost_steps_total": sum(missing.values()), "lost_steps": missing,
                      "recorded_steps": recorded, "bag": str(bag)}))
    return 0 if up.returncode == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
