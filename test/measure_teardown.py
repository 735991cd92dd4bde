"""Ctrl-C stops of ``ros2 launch tmgwr_agent agent.launch.py record:=true`` mid-stepping, with
a native stack of every node still alive some seconds after the Ctrl-C (issue 24, CI flake:
a node's DDS teardown hung inside ``destroy_node``).

Each stop: a launch (its own ROS_DOMAIN_ID), a first goal, a random 2-6 s of stepping, one
SIGINT to the launch's process group (a terminal's Ctrl-C). Any node process still alive
``--catch-after`` s later has every thread's stack, Python and native, written to
``<out>/stack_<stop>_<node>_<pid>.txt`` (``py-spy dump --native`` when ``pip install py-spy``
put it in the venv, else ``gdb -p``). A stop is clean as in
``measure_ctrl_c.py``. Options: ``--load K`` adds K busy-loop processes for the run;
``--profile FILE`` another Fast DDS profile (e.g. one without shared memory). Run from the
repository root::

    source tools/env.sh && python test/measure_teardown.py --stops 20 --load 2

(not collected by pytest: test_launch_graph.py and test_node_teardown.py hold the checks).
"""

from __future__ import annotations

import argparse
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from measure_ctrl_c import STEPPING, verdict  # noqa: E402
from ros_helpers import allocate_domain, release_domain, require_ros2, ros_env  # noqa: E402

PID = re.compile(r"\[(\w+)-\d+\]: process started with pid \[(\d+)\]")


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(") ", 1)[1][0] != "Z"
    except OSError:
        return False


def native_stack(pid: int, path: Path) -> None:
    """Every thread's stack, Python and native frames: ``py-spy dump --native`` when the
    venv has it (quick), else ``gdb -p`` (slow to load a node's libraries)."""
    spy = Path(sys.executable).with_name("py-spy")
    cmd = ([str(spy), "dump", "--native", "--pid", str(pid)] if spy.exists() else
           ["gdb", "-p", str(pid), "-batch", "-nx", "-ex", "set pagination off",
            "-ex", "thread apply all bt"])
    with open(path, "w") as out:
        subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                       timeout=120, check=False)


def ctrl_c(proc: subprocess.Popen, log: Path, wait: float, i: int, tmp: Path,
           catch_after: float) -> tuple[bool, float]:
    """Wait for stepping and ``wait`` s more, Ctrl-C, catch stacks; (stepping at the Ctrl-C,
    seconds from it to the launch's end)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < 120:
        if STEPPING.search(log.read_text(errors="replace")) or proc.poll() is not None:
            break
        time.sleep(0.2)
    time.sleep(wait)
    stepping = proc.poll() is None
    pids = {name: int(pid) for name, pid in PID.findall(log.read_text(errors="replace"))}
    os.killpg(proc.pid, signal.SIGINT)
    t_int = time.monotonic()
    caught = set()
    while proc.poll() is None and time.monotonic() - t_int < 90:
        if time.monotonic() - t_int > catch_after:
            for name, pid in pids.items():
                if pid not in caught and alive(pid):
                    caught.add(pid)
                    print(f"  stop {i}: {name} (pid {pid}) alive {catch_after:.1f} s after "
                          "the Ctrl-C: native stack", flush=True)
                    native_stack(pid, tmp / f"stack_{i}_{name}_{pid}.txt")
            # every node gone and the launch still there: the launch process hangs
            if proc.pid not in caught and time.monotonic() - t_int > 2 * catch_after and \
                    not any(alive(pid) for pid in pids.values()):
                caught.add(proc.pid)
                print(f"  stop {i}: every node ended, the launch (pid {proc.pid}) alive "
                      f"{2 * catch_after:.1f} s after the Ctrl-C: native stack", flush=True)
                native_stack(proc.pid, tmp / f"stack_{i}_launch_{proc.pid}.txt")
        time.sleep(0.05)
    took = time.monotonic() - t_int
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
    return stepping, took


def one_stop(i: int, domain: int, wait: float, env: dict, tmp: Path,
             catch_after: float) -> tuple[bool, str, float]:
    """One launch, one Ctrl-C; (clean, why not, seconds from the Ctrl-C to the launch's end)."""
    log = tmp / f"launch_{i}.log"
    shutil.rmtree(tmp / "bag", ignore_errors=True)
    cmd = [require_ros2(), "launch", "tmgwr_agent", "agent.launch.py", f"seed:={i}",
           "record:=true", f"output_dir:={tmp}/bag"]
    with open(log, "w") as out:
        proc = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True)
        try:
            stepping, took = ctrl_c(proc, log, wait, i, tmp, catch_after)
        except BaseException:
            os.killpg(proc.pid, signal.SIGKILL)
            raise
        code = proc.wait()
    clean, why = verdict(log.read_text(errors="replace"), stepping, code)
    return clean, why, took


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--stops", type=int, default=20)
    ap.add_argument("--load", type=int, default=0, help="busy-loop processes beside")
    ap.add_argument("--profile", default=None, help="FASTRTPS_DEFAULT_PROFILES_FILE")
    ap.add_argument("--catch-after", type=float, default=3.5)
    ap.add_argument("--out", default="/tmp/tmgwr-teardown")
    a = ap.parse_args(argv)
    for sig in (signal.SIGINT, signal.SIGTERM):    # either ends the loop, load and launch
        signal.signal(sig, signal.default_int_handler)
    tmp = Path(a.out)
    tmp.mkdir(parents=True, exist_ok=True)
    domain = allocate_domain()
    extra = {"ROS_HOME": str(tmp / "ros_home")}
    if a.profile:
        extra["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(Path(a.profile).resolve())
    env = ros_env(domain, extra)
    load = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(a.load)]
    rng = random.Random(0)
    clean, took = 0, []
    try:
        for i in range(a.stops):
            ok, why, t = one_stop(i, domain, rng.uniform(2.0, 6.0), env, tmp, a.catch_after)
            clean += ok
            took.append(t)
            print(f"stop {i + 1}: {'clean' if ok else 'NOT CLEAN: ' + why} "
                  f"(launch ended {t:.2f} s after the Ctrl-C)", flush=True)
    finally:
        for p in load:
            p.kill()
            p.wait()
        release_domain(domain)
    took.sort()
    print(f"TEARDOWN {clean} clean of {a.stops} stops; launch end after the Ctrl-C: median "
          f"{took[len(took) // 2]:.2f} s, max {took[-1]:.2f} s (logs: {tmp})", flush=True)
    return 0 if clean == a.stops else 1


if __name__ == "__main__":
    raise SystemExit(main())
