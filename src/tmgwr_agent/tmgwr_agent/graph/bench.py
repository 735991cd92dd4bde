"""How fast the lockstep graph runs, against the ceiling of its design.

Measured in one run, on the same machine and middleware settings:

(a) **ring ceiling**: an empty ring of 5 rclpy processes (and of 2) relaying a step id
    (:mod:`.ring`) with the graph's per-step QoS, the Fast DDS profile and discovery range
    of tools/env.sh, and the same executor loop as the nodes; in laps/s. One lap = one
    message through every process, exactly what one lockstep step of the graph costs in
    messaging alone.
(b) **graph rate**: the five nodes started as for ``./tmgwr up`` (no recorder), steps/s
    over ``graph_steps`` steps after ``warmup`` steps, timed from the Observation topic by
    an in-process observer; plus each node's own per-step callback time (the nodes print
    it at shutdown), which splits a step into computation and messaging.
(c) **in-process rate**: the same core loop (simulator, preprocessor, map, motivation,
    action selection) in one process with the same seed and step window.

(d) **composed**: the same five nodes in one process on one executor
    (:mod:`tmgwr_agent.nodes.composed`, ``./tmgwr up --composed``); the goal is >= 1.5x
    the ring of 5.
(e) **two hosts**: maze_sim in one network namespace and the four agent nodes in
    another, joined by a veth pair (:class:`TwoHosts`, root only; skipped with the
    reason otherwise); steps/s from the simulator's steady rate and bytes over the link.
(f) **large mazes**: the graph for ``large_seconds`` seconds on the generated 51 x 51
    maze of ``step_large`` (about 1300 free cells) and on a 200 x 200 open maze, where the
    map keeps growing: steps/s over the window and over its last quarter.
(g) **PointMaze**: the graph of (b) with maze_sim hosting MuJoCo's PointMaze (``world``
    pointmaze) on the same maze; the physics (maze_sim's ``world.step``) timed apart.

Bytes per step: after the timed window of (b) and (f) the observer subscribes (raw, the
recorder's QoS rule) to every topic the graph publishes and counts the CDR bytes of each
over ``bytes_steps`` steps: what a recorder writes before compression.

Every ratio is against the ring of 5 measured in the same run (``ratios``);
``graph_over_ring`` = (b) / (a, 5 processes): the target is >= 0.6. A part that fails is
recorded under ``errors`` (and makes ``./tmgwr bench`` exit 1), the others still run.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tmgwr_agent.graph.output import say

CALLBACKS = re.compile(r"(\d+) step callbacks, mean (\d+) us, total ([\d.]+) s")
WORLD_STEPS = re.compile(r"maze_sim world (\S+): (\d+) world steps, mean (\d+) us, "
                         r"cpu mean (\d+) us")


def _opt(args, name, default):
    value = getattr(args, name, None) if args is not None else None
    return default if value is None else value


# ------------------------------------------------------------------------------ (a) ring
def ring(size: int, laps: int, warmup: int = 100, timeout: float = 120.0) -> dict:
    """Laps/s of an empty ring of ``size`` processes (member 0 times it)."""
    from tmgwr_agent.graph.supervisor import GraphError, GraphSupervisor, NodeSpec

    py = sys.executable
    specs = [NodeSpec("", f"ring_{i}", name=f"ring{size}_{i}", argv=[
        py, "-u", "-m", "tmgwr_agent.graph.ring", "--index", str(i), "--size", str(size),
        "--laps", str(laps), "--warmup", str(warmup), "--timeout", str(timeout)])
        for i in range(size)]
    sup = GraphSupervisor(specs, echo=False)
    try:
        # no wait for 'ready' lines: member 0 waits for the whole ring itself (probes)
        sup.start(wait_ready=False)
        leader = sup.process(f"ring{size}_0")
        try:
            leader.proc.wait(timeout=timeout + 10)
        except Exception:  # noqa: BLE001 -- report below with its output
            pass
        leader._reader.join(timeout=2.0)
        for line in reversed(leader.tail):
            if line.startswith("RING "):
                return json.loads(line[5:])
        raise GraphError(leader.describe(f"ring of {size}: no RING result"))
    finally:
        sup.stop(sigint_timeout=3.0)


# ------------------------------------------------------------------------------ (b) graph
def graph_rate(steps: int | None = 2000, warmup: int = 200, seed: int = 0,
               maze: str | None = None, timeout: float = 300.0, composed: bool = False,
               seconds: float | None = None, bytes_steps: int = 0,
               world: str | None = None) -> dict:
    """Steps/s of the lockstep graph after ``warmup`` steps, over ``steps`` steps or, with
    ``seconds``, over that many seconds (then also over the window's last quarter, which
    shows a rate that falls as the map grows); ``composed``: the one-process graph. With
    ``bytes_steps``, then the bytes per step of every topic (:func:`bytes_per_step`).
    ``world``: the world maze_sim hosts (default grid); its own step time (the physics of
    PointMaze) is reported apart (``world_step``), from maze_sim's shutdown line.

    Timed by the observations' header stamps (maze_sim's clock when it publishes), not by
    when this process gets them: an observer slower than the graph (one rclpy executor in
    Python, about 400 messages/s under load) would otherwise measure itself."""
    from tmgwr_agent.graph.clients import monitor_qos
    from tmgwr_agent.graph.run import GraphRun, describe_exit
    from tmgwr_agent.graph.supervisor import GraphError, composed_specs
    from tmgwr_common import topics
    from tmgwr_interfaces.msg import Observation

    run = GraphRun(maze=maze, seed=seed, world=world, record=False, echo=False)
    if composed:
        run.specs = run.supervisor.specs = composed_specs(run.specs)
    run.start(ready_timeout=120.0)
    mon = run.monitor
    stamps: list[tuple[float, int]] = []        # (publication time, step id)
    run.node.create_subscription(
        Observation, topics.OBSERVATION,
        lambda m: stamps.append((m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec,
                                 m.step_id)), monitor_qos())
    t_begin = time.monotonic()
    marks: dict[str, float] = {}
    samples: list[tuple[float, int]] = []
    sizes: dict = {}

    def check() -> None:
        if run.supervisor.dead():
            raise GraphError("; ".join(describe_exit(p) for p in run.supervisor.dead()))
        if time.monotonic() - t_begin > timeout:
            raise GraphError(f"the graph made only {mon.last_step_id} steps in {timeout} s")

    try:
        while True:
            run.spin_once(0.1)
            check()
            if not stamps:
                continue
            last_time, last_step = stamps[-1]
            if "t0" not in marks and last_step >= warmup:
                marks["t0"], marks["s0"] = last_time, last_step
            if "t0" in marks:
                samples.append((last_time, last_step))
                if (seconds is not None and last_time - marks["t0"] >= seconds) or \
                        (seconds is None and last_step >= warmup + steps):
                    break
        if bytes_steps:
            sizes = bytes_per_step(run, bytes_steps, check)
    finally:
        codes = run.stop()
    callbacks = {}
    world_step = None
    for p in run.supervisor.processes:
        for line in p.tail:                 # composed: one process prints all five lines
            w = WORLD_STEPS.search(line)
            if w:
                world_step = {"world": w.group(1), "steps": int(w.group(2)),
                              "mean_us": int(w.group(3)), "cpu_mean_us": int(w.group(4))}
                continue
            m = CALLBACKS.search(line)
            if m and not line.startswith("SUMMARY"):
                who = line.split(":", 1)[0].split("]")[-1].strip() if composed else p.label
                callbacks[who] = {"calls": int(m.group(1)), "mean_us": int(m.group(2)),
                                  "total_s": float(m.group(3))}
    t_end, s_end = samples[-1]
    seconds_measured = t_end - marks["t0"]
    counted = s_end - int(marks["s0"])
    rate = counted / seconds_measured
    step_us = 1e6 / rate
    compute_us = sum(c["mean_us"] for c in callbacks.values())
    out = {"steps": counted, "warmup": warmup, "seed": seed, "maze": maze or "default",
           "composed": composed, "seconds": round(seconds_measured, 3),
           "steps_per_s": round(rate, 1), "step_us": round(step_us),
           "callbacks": callbacks, "callbacks_us_per_step": compute_us,
           "messaging_us_per_step": round(step_us - compute_us),
           "missed_observations": mon.missed, "exit_codes": codes,
           "world": world or "grid", "world_step": world_step}
    if seconds is not None:
        t_q = marks["t0"] + 0.75 * seconds_measured
        t1, s1 = next((t, s) for t, s in samples if t >= t_q)
        out["last_quarter_steps_per_s"] = round((s_end - s1) / max(t_end - t1, 1e-9), 1)
        out["last_step"] = s_end
    if sizes:
        out["bytes"] = sizes
    return out


def bytes_per_step(run, steps: int, check, settle: float = 1.0,
                   limit: float = 10.0) -> dict:
    """CDR bytes a step of the running graph publishes, per topic and in all: raw
    subscriptions (the recorder's QoS rule) to every topic with a publisher, counted over
    ``steps`` steps after ``settle`` seconds of matching. A topic published at a fixed
    rate (map, markers, pose) counts what it sent during those steps."""
    from tmgwr_agent.bag import definitions
    from tmgwr_agent.bag import qos as bag_qos
    from tmgwr_common import topics

    node = run.node
    counts: dict[str, list[int]] = {}
    subs = []
    for topic, types in node.get_topic_names_and_types():
        infos = node.get_publishers_info_by_topic(topic)
        if topic in ("/rosout", "/parameter_events") or len(types) != 1 or not infos:
            continue
        offered = [bag_qos.profile_to_dict(i.qos_profile) for i in infos]
        counts[topic] = [0, 0]

        def on_msg(data: bytes, c=counts[topic]) -> None:
            c[0] += 1
            c[1] += len(data)

        subs.append(node.create_subscription(
            definitions.import_message(types[0]), topic, on_msg,
            bag_qos.subscription_qos(offered, 1000), raw=True))
    end = time.monotonic() + settle
    while time.monotonic() < end:
        run.spin_once(0.05)
        check()
    for c in counts.values():
        c[0] = c[1] = 0
    seen = counts.get(node.resolve_topic_name(topics.OBSERVATION), [0, 0])  # one a step
    t0 = time.monotonic()
    while seen[0] < steps and time.monotonic() - t0 < limit:
        run.spin_once(0.05)
        check()
    n = max(seen[0], 1)
    for sub in subs:
        node.destroy_subscription(sub)
    per_topic = {t: round(b / n) for t, (_, b) in sorted(counts.items()) if b}
    return {"steps": n, "bytes_per_step": sum(per_topic.values()), "per_topic": per_topic}


# ------------------------------------------------------------------------------ (c) in-process
def in_process_rate(steps: int, warmup: int = 200, seed: int = 0,
                    maze: str | None = None) -> dict:
    """Steps/s of the same loop in one process (what each node does, in order)."""
    import numpy as np

    from maze_sim.maze import Maze, maze_file
    from maze_sim.world import GridWorld
    from tmgwr_agent.core.agent import TMGWRAgent
    from tmgwr_agent.world_senses import maze_senses

    path = maze_file(maze) if maze else maze_file()
    m = Maze.from_file(path)
    world = GridWorld(m, goal="G", seed=seed)
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(seed))
    agent.set_goal(world.goal, world.goal_observation())
    obs, _ = world.reset()
    agent.begin_episode(obs, world.cell)
    times = []
    t0 = 0.0
    for n in range(warmup + steps):
        if n == warmup:
            t0 = time.perf_counter()
        t = time.perf_counter()
        a = agent.act()
        obs, _, terminated, truncated, info = world.step(a)
        agent.observe(obs, info)
        if terminated or truncated:
            obs, _ = world.reset()
            agent.begin_episode(obs, world.cell)
        if n >= warmup:
            times.append(time.perf_counter() - t)
    seconds = time.perf_counter() - t0
    return {"steps": steps, "warmup": warmup, "seed": seed, "seconds": round(seconds, 3),
            "steps_per_s": round(steps / seconds, 1),
            "step_us_median": round(1e6 * statistics.median(times), 1)}


# ------------------------------------------------------------------------------ (e) two hosts
LINK_SUBNET = "10.231.0"       # host A .1, host B .2 (/30): private to the two namespaces

FASTDDS_LINK_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<!-- One host of tmgwr_agent.graph.bench.TwoHosts: UDPv4 on the link address only (no
     shared memory, no loopback, no other interface), tools/fastdds_localhost.xml's fast
     discovery announcements. -->
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor>
      <transport_id>tmgwr_link</transport_id>
      <type>UDPv4</type>
      <interfaceWhiteList><address>{address}</address></interfaceWhiteList>
    </transport_descriptor>
  </transport_descriptors>
  <participant profile_name="tmgwr_link" is_default_profile="true">
    <rtps>
      <userTransports><transport_id>tmgwr_link</transport_id></userTransports>
      <useBuiltinTransports>false</useBuiltinTransports>
      <builtin>
        <discovery_config>
          <leaseDuration><sec>10</sec></leaseDuration>
          <leaseAnnouncement><sec>0</sec><nanosec>500000000</nanosec></leaseAnnouncement>
          <initialAnnouncements>
            <count>10</count>
            <period><sec>0</sec><nanosec>100000000</nanosec></period>
          </initialAnnouncements>
        </discovery_config>
      </builtin>
    </rtps>
  </participant>
</profiles>
"""


def netns_unavailable() -> str | None:
    """Why two network namespaces cannot be made here (None: they can)."""
    if shutil.which("ip") is None:
        return "no 'ip' command (iproute2) to create network namespaces"
    if os.geteuid() != 0:
        return "creating network namespaces needs root (CAP_NET_ADMIN)"
    probe = f"tmgwr-probe-{os.getpid()}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f"'ip netns add' failed: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


class TwoHosts:
    """Two hosts on one link, on this machine: network namespaces A and B joined by a veth
    pair (``LINK_SUBNET``.1 and .2, /30), each with only its loopback and its end of the
    link. :meth:`command` runs a command on a host with what a ROS user sets on a LAN
    (docs/graph.md, More than one host): ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``,
    ``ROS_STATIC_PEERS`` = the other host, and a Fast DDS profile limited to the link
    address (no shared memory, so nothing crosses between them but the link). The
    namespaces (and with them the veth pair) go in :meth:`close`. Root only."""

    _count = 0

    def __init__(self):
        TwoHosts._count += 1
        tag = f"{os.getpid() % 100000}{TwoHosts._count % 100}"
        self.ns = (f"tmgwr-{tag}-a", f"tmgwr-{tag}-b")
        self.links = (f"tg{tag}a", f"tg{tag}b")           # <= 15 characters
        self.addresses = (f"{LINK_SUBNET}.1", f"{LINK_SUBNET}.2")
        self.dir = Path(tempfile.mkdtemp(prefix="tmgwr-hosts-"))
        self.profiles = tuple(self.dir / f"host_{h}.xml" for h in "ab")
        try:
            for i in range(2):
                self._ip("netns", "add", self.ns[i])
            self._ip("link", "add", self.links[0], "type", "veth", "peer", "name",
                     self.links[1])
            for i in range(2):
                self._ip("link", "set", self.links[i], "netns", self.ns[i])
                self._ip("-n", self.ns[i], "addr", "add", f"{self.addresses[i]}/30", "dev",
                         self.links[i])
                self._ip("-n", self.ns[i], "link", "set", "lo", "up")
                self._ip("-n", self.ns[i], "link", "set", self.links[i], "up")
                self.profiles[i].write_text(FASTDDS_LINK_PROFILE.format(
                    address=self.addresses[i]))
        except BaseException:
            self.close()
            raise

    @staticmethod
    def _ip(*args: str) -> None:
        done = subprocess.run(["ip", *args], capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"ip {' '.join(args)}: {done.stderr.strip()}")

    def command(self, host: int, argv: list[str]) -> list[str]:
        """``argv`` run on host 0 (A) or 1 (B), discovering only the other host's address."""
        return ["ip", "netns", "exec", self.ns[host], "env",
                f"FASTRTPS_DEFAULT_PROFILES_FILE={self.profiles[host]}",
                "ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET",
                f"ROS_STATIC_PEERS={self.addresses[1 - host]}", *argv]

    def link_bytes(self) -> int:
        """Bytes sent both ways over the link so far (host A's end: tx + rx)."""
        done = subprocess.run(["ip", "-n", self.ns[0], "-s", "-j", "link", "show",
                               self.links[0]], capture_output=True, text=True, check=True)
        stats = json.loads(done.stdout)[0]["stats64"]
        return int(stats["tx"]["bytes"]) + int(stats["rx"]["bytes"])

    def close(self) -> None:
        for ns in self.ns:                  # deleting a namespace deletes its veth end
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        shutil.rmtree(self.dir, ignore_errors=True)

    def __enter__(self) -> "TwoHosts":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def two_host_run(steps: int, seed: int = 0, agent_seed: int | None = None,
                 goal: str | None = None, maze: str | None = None,
                 trajectory_path: str | Path | None = None, timeout: float = 300.0,
                 env: dict | None = None) -> dict:
    """maze_sim on host A, the four agent nodes (one process each) on host B
    (:class:`TwoHosts`) for ``steps`` steps: the simulator's SUMMARY (steady steps/s after
    its first 200 steps), the bytes over the link per step, the exit codes."""
    from tmgwr_agent.graph.supervisor import (
        GRAPH_NODES,
        GraphError,
        GraphSupervisor,
        NodeSpec,
        executable_path,
    )

    sim = {"max_steps": steps, "exit_when_done": True, "seed": seed, "start_delay": 2.0}
    if goal is not None:
        sim["goal"] = goal
    if maze is not None:
        sim["maze"] = maze
    if trajectory_path is not None:
        sim["trajectory_path"] = str(trajectory_path)
    agent = {"action_selector": {"seed": seed if agent_seed is None else agent_seed}}
    with TwoHosts() as hosts:
        specs = []
        for package, exe in GRAPH_NODES:
            params = sim if exe == "maze_sim" else agent.get(exe, {})
            cmd = NodeSpec(package, exe, (), params).command()
            cmd[0] = str(executable_path(package, exe))
            specs.append(NodeSpec(package, exe, argv=hosts.command(
                0 if exe == "maze_sim" else 1, cmd)))
        sup = GraphSupervisor(specs, env=env, echo=False)
        before = hosts.link_bytes()
        try:
            sup.start(ready_timeout=120.0)
            sim_proc = sup.process("maze_sim")
            try:
                sim_proc.proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                raise GraphError(sim_proc.describe(f"two hosts: {steps} steps not done "
                                                   f"within {timeout:.0f} s")) from None
            sim_proc._reader.join(timeout=2.0)
            link = hosts.link_bytes() - before
            summary = next((json.loads(line[8:]) for line in reversed(sim_proc.tail)
                            if line.startswith("SUMMARY ")), None)
            if summary is None or sim_proc.returncode() != 0:
                raise GraphError(sim_proc.describe("two hosts: maze_sim ended without its "
                                                   "SUMMARY"))
        finally:
            codes = sup.stop(sigint_timeout=5.0)
    return {"steps": summary["steps"], "seconds": summary["seconds"],
            "steps_per_s": summary["steady_steps_per_s"] or summary["steps_per_s"],
            "link_bytes_per_step": round(link / summary["steps"]),
            "hosts": {"A": "maze_sim", "B": ", ".join(e for _, e in GRAPH_NODES[1:])},
            "discovery": "ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET, ROS_STATIC_PEERS=<other "
                         "host>, Fast DDS UDPv4 on the link address only",
            "summary": summary, "exit_codes": codes}


# ------------------------------------------------------------------------------ (f) mazes
def large_maze_file(directory: Path, seed: int = 0) -> Path:
    """The generated 51 x 51 maze of the core's ``step_large`` bench (about 1300 cells)."""
    import numpy as np

    from maze_sim.maze import generate_maze
    path = directory / f"generated_51x51_seed{seed}.txt"
    path.write_text(generate_maze(51, 51, np.random.default_rng(seed)))
    return path


def open_maze_file(directory: Path, size: int = 200) -> Path:
    """A ``size`` x ``size`` open field inside a wall border, S and G in opposite corners."""
    rows = ["#" * size] + ["#" + "." * (size - 2) + "#" for _ in range(size - 2)] + ["#" * size]
    rows[1] = "#S" + rows[1][2:]
    rows[size - 2] = rows[size - 2][:size - 2] + "G#"
    path = directory / f"open_{size}x{size}.txt"
    path.write_text("\n".join(rows) + "\n")
    return path


# ------------------------------------------------------------------------------ all
def run(args=None) -> dict:
    """(a)-(f) in one run; ``args`` may carry ``ring_laps``, ``graph_steps``,
    ``graph_seed``, ``maze``, ``large_seconds``, ``bytes_steps``. Returns the dict the
    experiments bench merges (``ratios``: every figure against the ring of 5; ``errors``:
    the parts that failed)."""
    laps = int(_opt(args, "ring_laps", 2000))
    steps = int(_opt(args, "graph_steps", 2000))
    seed = int(_opt(args, "graph_seed", 0))
    maze = _opt(args, "maze", None)
    large_seconds = float(_opt(args, "large_seconds", 25.0))
    bytes_steps = int(_opt(args, "bytes_steps", 200))
    out: dict = {"errors": {}}

    def part(key: str, what: str, fn):
        say(f"  {what} ...")
        try:
            out[key] = fn()
        except Exception as exc:  # noqa: BLE001 -- recorded and said, the others still run
            out["errors"][key] = f"{type(exc).__name__}: {exc}"
            say(f"  {what}: FAILED: {exc}", sys.stderr)
            return None
        return out[key]

    say(f"graph bench: rings of 5 and 2 processes ({laps} laps); graph, composed, two hosts "
        f"({steps} steps, seed {seed}); large mazes ({large_seconds:g} s each)")
    r5 = part("ring5", "ring of 5", lambda: ring(5, laps))
    r2 = part("ring2", "ring of 2", lambda: ring(2, laps))
    if r5 and r2:
        say(f"  rings: 5 processes {r5['laps_per_s']} laps/s ({r5['hop_ms']} ms a hop), "
            f"2 processes {r2['laps_per_s']} laps/s")
    g = part("graph", "graph, 5 processes", lambda: graph_rate(
        steps, seed=seed, maze=maze, bytes_steps=bytes_steps))
    if g:
        say(f"  graph: {g['steps_per_s']} steps/s ({g['step_us']} us a step: "
            f"{g['callbacks_us_per_step']} us in the nodes' callbacks, "
            f"{g['messaging_us_per_step']} us messaging and executors), "
            f"{g.get('bytes', {}).get('bytes_per_step')} bytes a step")
    pm = part("graph_pointmaze", "graph on PointMaze, 5 processes", lambda: graph_rate(
        steps, seed=seed, maze=maze, world="pointmaze"))
    if pm:
        ws = pm.get("world_step") or {}
        say(f"  graph on PointMaze: {pm['steps_per_s']} steps/s ({pm['step_us']} us a step, "
            f"of which the physics {ws.get('mean_us')} us in maze_sim)")
    c = part("composed", "composed graph, 1 process", lambda: graph_rate(
        steps, seed=seed, maze=maze, composed=True))
    if c:
        say(f"  composed: {c['steps_per_s']} steps/s")
    why = netns_unavailable()
    if why is None:
        h = part("two_hosts", "two hosts (network namespaces)", lambda: two_host_run(
            steps + 200, seed=seed, maze=maze))
        if h:
            say(f"  two hosts: {h['steps_per_s']} steps/s, {h['link_bytes_per_step']} bytes "
                "a step over the link")
    else:
        out["two_hosts"] = {"skipped": why}
        say(f"  two hosts: skipped ({why})")
    with tempfile.TemporaryDirectory(prefix="tmgwr-bench-mazes-") as tmp:
        mazes = {"large": large_maze_file(Path(tmp), seed),
                 "open200": open_maze_file(Path(tmp), 200)}
        for key, path in mazes.items():
            m = part(f"graph_{key}", f"graph on {path.name} ({large_seconds:g} s)",
                     lambda p=path: graph_rate(None, seed=seed, maze=str(p),
                                               seconds=large_seconds,
                                               bytes_steps=bytes_steps))
            if m:
                say(f"  graph on {path.name}: {m['steps_per_s']} steps/s (last quarter "
                    f"{m['last_quarter_steps_per_s']}, step {m['last_step']}), "
                    f"{m.get('bytes', {}).get('bytes_per_step')} bytes a step")
    ip = part("in_process", "in-process loop", lambda: in_process_rate(steps, seed=seed,
                                                                        maze=maze))
    if ip:
        say(f"  in-process: {ip['steps_per_s']} steps/s ({ip['step_us_median']} us median)")
    ratios: dict = {}
    if r5:
        ring_rate = r5["laps_per_s"]
        for key, name in (("graph", "graph_over_ring"), ("composed", "composed_over_ring"),
                          ("two_hosts", "two_hosts_over_ring"),
                          ("graph_large", "large_graph_over_ring"),
                          ("graph_pointmaze", "pointmaze_graph_over_ring"),
                          ("graph_open200", "open200_graph_over_ring")):
            if out.get(key, {}).get("steps_per_s"):
                ratios[name] = round(out[key]["steps_per_s"] / ring_rate, 3)
        for key in ("graph_large", "graph_open200"):
            if out.get(key, {}).get("last_quarter_steps_per_s"):
                ratios[f"{key.split('_')[1]}_last_quarter_over_ring"] = round(
                    out[key]["last_quarter_steps_per_s"] / ring_rate, 3)
    if g and c:
        ratios["composed_over_graph"] = round(c["steps_per_s"] / g["steps_per_s"], 3)
    out.update({
        "ring5_laps_per_s": r5 and r5["laps_per_s"], "ring2_laps_per_s": r2 and r2["laps_per_s"],
        "graph_steps_per_s": g and g["steps_per_s"],
        "in_process_steps_per_s": ip and ip["steps_per_s"],
        "graph_over_ring": ratios.get("graph_over_ring"), "target_graph_over_ring": 0.6,
        "target_composed_over_ring": 1.5, "ratios": ratios,
        "bytes_per_step": {k: out[k]["bytes"]["bytes_per_step"]
                           for k in ("graph", "graph_large", "graph_open200")
                           if out.get(k, {}).get("bytes")},
        "cpus": os.cpu_count(), "load_avg_1min": round(os.getloadavg()[0], 2),
    })
    if not out["errors"]:
        del out["errors"]
    say("  ratios to the ring of 5: " + ", ".join(f"{k} {v}" for k, v in ratios.items()))
    return out


def main(argv: list[str] | None = None) -> int:
    import argparse
    ap = argparse.ArgumentParser(prog="python -m tmgwr_agent.graph.bench", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ring-laps", type=int, default=2000)
    ap.add_argument("--graph-steps", type=int, default=2000)
    ap.add_argument("--graph-seed", type=int, default=0)
    ap.add_argument("--maze")
    ap.add_argument("--large-seconds", type=float, default=25.0,
                    help="seconds of the graph on each large maze")
    ap.add_argument("--bytes-steps", type=int, default=200,
                    help="steps over which bytes per step are counted")
    ap.add_argument("--json", help="also write the result here")
    args = ap.parse_args(argv)
    result = run(args)
    text = json.dumps(result, indent=2)
    if args.json:
        Path(args.json).write_text(text + "\n")
    say("BENCH " + json.dumps(result))
    return 1 if result.get("errors") else 0


if __name__ == "__main__":
    sys.exit(main())
