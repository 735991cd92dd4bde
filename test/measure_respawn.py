"""Measure respawn (issue 24, item 4): SIGKILLs spread over every process of a running
graph, under ``./tmgwr up`` or ``ros2 launch``; prints one JSON line.

    python test/measure_respawn.py up --kills 20
    python test/measure_respawn.py launch --kills 20     # needs the real ros2 (ros2-tools)

The graph (seed 1, recording on) runs in a domain of its own; an observer in this process
follows ``/observation`` (tmgwr_agent.episodes.EpisodeMonitor). The processes are killed in
turn (recorder, maze_sim, sensory_preprocessor, map_learner, motivation_estimator,
action_selector, again ...), each once the previous victim's restart has rejoined and
``--gap`` seconds passed. For each kill: the time from the restarted node's ready line (as
read from the graph's output here) to two new steps seen by the observer (a lap through the
node). Then the steps per episode of the last ``--episodes`` episodes before the first kill
and of the first ``--episodes`` after the last one: learning kept means they match.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ros_helpers import (  # noqa: E402
    ROOT,
    allocate_domain,
    release_domain,
    require_ros2,
    ros_env,
)

VICTIMS = ("recorder", "maze_sim", "sensory_preprocessor", "map_learner",
           "motivation_estimator", "action_selector")


class Graph:
    """A graph process whose output lines are kept with their arrival times."""

    def __init__(self, cmd: list[str], env: dict[str, str]):
        self.proc = subprocess.Popen(cmd, env=env, cwd=str(ROOT), stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, errors="replace",
                                     bufsize=1, start_new_session=True)
        self.lines: list[tuple[float, str]] = []
        self.lock = threading.Lock()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            with self.lock:
                self.lines.append((time.monotonic(), line.rstrip("\n")))

    def find(self, pattern: str, start: int = 0) -> list[tuple[int, float, str]]:
        regex = re.compile(pattern)
        with self.lock:
            tail = self.lines[start:]
        return [(start + i, t, ln) for i, (t, ln) in enumerate(tail) if regex.search(ln)]

    def wait(self, pattern: str, start: int = 0, timeout: float = 120.0, spin=None):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            n = len(self.lines)
            hits = self.find(pattern, start)
            if hits:
                return hits[0]
            start = n
            if self.proc.poll() is not None:
                break
            spin(0.02) if spin else time.sleep(0.02)
        tail = "\n".join(ln for _, ln in self.lines[-40:])
        raise RuntimeError(f"no /{pattern}/ within {timeout} s (exit {self.proc.poll()}):\n"
                           f"{tail}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
            try:
                self.proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mode", choices=("up", "launch"))
    ap.add_argument("--kills", type=int, default=20)
    ap.add_argument("--gap", type=float, default=2.0, help="seconds of stepping between kills")
    ap.add_argument("--episodes", type=int, default=5)
    ap.add_argument("--warmup-episodes", type=int, default=12)
    ap.add_argument("--victims", default=",".join(VICTIMS),
                    help="the processes killed in turn (comma-separated)")
    args = ap.parse_args()
    victims = args.victims.split(",")
    if set(victims) - set(VICTIMS):
        ap.error(f"--victims: unknown {sorted(set(victims) - set(VICTIMS))}; one of {VICTIMS}")

    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from tmgwr_agent.episodes import EpisodeMonitor
    from tmgwr_agent.graph.clients import subscribe_monitor

    domain = allocate_domain()
    tmp = Path(tempfile.mkdtemp(prefix="respawn_"))
    env = ros_env(domain, {"ROS_HOME": str(tmp / "ros_home")})
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    rclpy.init()
    node = rclpy.create_node("respawn_observer")
    monitor = EpisodeMonitor()
    subscribe_monitor(node, monitor)
    ex = SingleThreadedExecutor()
    ex.add_node(node)

    def spin(t: float) -> None:
        ex.spin_once(timeout_sec=t)

    limit = ["--respawn-limit", str(args.kills + 1), "--respawn-window", "3600"]
    if args.mode == "up":
        cmd = [sys.executable, "-u", "-m", "tmgwr_agent.cli", "up", "--seed", "1",
               "--record-dir", str(tmp / "run"), *limit]
        started = r"^graph up in ROS_DOMAIN_ID="
    else:
        cmd = [require_ros2(), "launch", "tmgwr_agent", "agent.launch.py", "seed:=1",
               "record:=true", f"respawn_limit:={args.kills + 1}", "respawn_window:=3600"]
        started = r"\[action_selector-\d+\].*\bready\b"
    g = Graph(cmd, env)
    result: dict = {"mode": args.mode, "kills": [], "domain": domain}
    try:
        g.wait(started, timeout=180, spin=spin)
        while len(monitor.episodes) < args.warmup_episodes:
            spin(0.1)
            if g.proc.poll() is not None:
                raise RuntimeError("the graph ended during warm-up")
        before = [e.steps for e in monitor.episodes[-args.episodes:]]
        n_before = len(monitor.episodes)
        for k in range(args.kills):
            name = victims[k % len(victims)]
            pid = current_pid(g, args.mode, name)
            mark = len(g.lines)
            os.kill(pid, signal.SIGKILL)
            t_kill = time.monotonic()
            ready = (r"recording .* to " if name == "recorder" else r"\bready\b")
            prefix = rf"^\[{name}(-\d+)?\] "
            _, t_ready, _ = g.wait(prefix + ".*" + ready, start=mark, timeout=120, spin=spin)
            seen = monitor.seen
            while monitor.seen < seen + 2:
                spin(0.01)
                if time.monotonic() - t_ready > 120:
                    raise RuntimeError(f"the ring did not turn after {name}'s restart")
            t_turn = time.monotonic()
            result["kills"].append({"node": name, "down_s": round(t_ready - t_kill, 2),
                                    "ring_after_ready_s": round(t_turn - t_ready, 3)})
            print(json.dumps(result["kills"][-1]), file=sys.stderr, flush=True)
            t_end = time.monotonic() + args.gap
            while time.monotonic() < t_end:
                spin(0.05)
        n_after = len(monitor.episodes)
        while len(monitor.episodes) < n_after + args.episodes:
            spin(0.1)
            if g.proc.poll() is not None:
                raise RuntimeError("the graph ended after the kills")
        after = [e.steps for e in monitor.episodes[n_after:n_after + args.episodes]]
        turns = [k["ring_after_ready_s"] for k in result["kills"]]
        result.update({
            "alive": g.proc.poll() is None,
            "ring_after_ready_s": {"median": statistics.median(turns), "max": max(turns)},
            "within_2_s": sum(t <= 2.0 for t in turns),
            "steps_per_episode_before": before, "steps_per_episode_after": after,
            "episodes_during_kills": n_after - n_before,
            "runs_seen": monitor.runs})
    finally:
        g.stop()
        ex.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
        release_domain(domain)
    print(json.dumps(result))
    return 0


def current_pid(g: Graph, mode: str, name: str) -> int:
    """The pid of the running process ``name`` (the newest start)."""
    if mode == "up":
        hits = g.find(rf"node '{name}' restarted \(pid (\d+)")
        if hits:
            return int(re.search(r"pid (\d+)", hits[-1][2])[1])
        line = g.find(r"^graph up in ROS_DOMAIN_ID=")[0][2]
        return int(re.search(rf"\b{name} \(pid (\d+)\)", line)[1])
    hits = g.find(rf"\[{name}-\d+\]: process started with pid \[(\d+)\]")
    return int(re.search(r"pid \[(\d+)\]", hits[-1][2])[1])


if __name__ == "__main__":
    raise SystemExit(main())
