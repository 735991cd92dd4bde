"""The five nodes as real processes over DDS (each test its own ROS_DOMAIN_ID).

What must hold: the graph reaches the goal; /set_goal is refused outside the maze,
in a wall and when not finite, the estimator stays up, and an accepted goal is reached;
the same seeds give the same cells over the graph as the in-process TMGWRAgent loop for
>= 2000 steps including that goal change; the agent finds the detour after an event fired
through the service; a map_learner stopped with SIGINT and restarted from its saved map
continues with the same map; every node refuses an invalid parameter, naming it.
"""

from __future__ import annotations

import ast
import json
import re
import time

import numpy as np
import pytest
from ros_helpers import ROOT, parse_json_line, ros2_run, spawn_python

pytestmark = pytest.mark.ros

MAZE = ROOT / "src" / "maze_sim" / "mazes" / "paper_13x17.txt"
AGENT_NODES = ("sensory_preprocessor", "map_learner", "motivation_estimator",
               "action_selector")

# A service client: argv[1] = JSON list of [service, type, request fields].
CALL = r"""
import json, sys, time
import rclpy
from geometry_msgs.msg import Point
from std_srvs.srv import Trigger
from tmgwr_interfaces.srv import SetGoal, FireEvent, SaveMap, LoadMap, SetCell
types = {"SetGoal": SetGoal, "FireEvent": FireEvent, "SaveMap": SaveMap, "LoadMap": LoadMap,
         "SetCell": SetCell, "Trigger": Trigger}
rclpy.init()
node = rclpy.create_node("test_client")
results = []
for name, typ, fields in json.loads(sys.argv[1]):
    srv = types[typ]
    cli = node.create_client(srv, name)
    if not cli.wait_for_service(timeout_sec=30):
        raise SystemExit(f"{name} not available")
    req = srv.Request()
    if typ == "SetGoal":
        req.goal = Point(x=float(fields["x"]), y=float(fields["y"]), z=0.0)
    else:
        for k, v in fields.items():
            setattr(req, k, v)
    fut = cli.call_async(req)
    t0 = time.monotonic()
    while not fut.done() and time.monotonic() - t0 < 30:
        rclpy.spin_once(node, timeout_sec=0.1)
    r = fut.result()
    results.append({k: getattr(r, k) for k in r.get_fields_and_field_types()})
print("RESULT " + json.dumps(results), flush=True)
node.destroy_node()
rclpy.shutdown()
"""

# Prints the latched map (run and step it belongs to, node ids and weights, link count) once
# it arrives.
MAP_ECHO = r"""
import ast
import json
import rclpy
from rclpy.qos import QoSProfile, DurabilityPolicy, ReliabilityPolicy
from tmgwr_interfaces.msg import SensorimotorMap
rclpy.init()
node = rclpy.create_node("test_map_echo")
qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                 reliability=ReliabilityPolicy.RELIABLE)
def show(m):
    print("MAP " + json.dumps({"run_id": m.run_id, "step_id": m.step_id,
                               "nodes": [[n.id, list(n.weight)] for n in m.nodes],
                               "links": len(m.links)}), flush=True)
node.create_subscription(SensorimotorMap, "/map", show, qos)
print("ECHO READY", flush=True)
rclpy.spin(node)
"""


def start_graph(domain, tmp_path, sim_args=(), learner_args=(), seed=1, goal="2"):
    """The five executables as `ros2 run` starts them; returns {name: RosProcess}."""
    procs = {}
    per_node = {"map_learner": ["-p", f"map_path:={tmp_path / 'map.npz'}", *learner_args],
                "action_selector": ["-p", f"seed:={seed}"]}
    for name in AGENT_NODES:
        procs[name] = ros2_run("tmgwr_agent", name, "--ros-args", *per_node.get(name, []),
                               domain=domain)
    procs["maze_sim"] = ros2_run("maze_sim", "maze_sim", "--ros-args", "-p", f"goal:={goal}",
                                 "-p", "seed:=0", "-p", "start_delay:=1.5", *sim_args,
                                 domain=domain)
    for p in procs.values():
        p.wait_for_line("ready", timeout=60)
    return procs


def stop_graph(procs):
    for p in procs.values():
        p.stop()


def call(domain, calls, timeout=60):
    p = spawn_python(CALL, json.dumps(calls), domain=domain, name="client")
    with p:
        return parse_json_line(p.wait(timeout=timeout), "RESULT ")


def call_past_the_agent(domain, calls, tries=10):
    """call(), again while an edit was refused only because the agent stood in its way
    (maze_sim never walls in the agent or its last route; the agent moves on)."""
    for _ in range(tries):
        res = call(domain, calls)
        if not any(not r["accepted"] and "the agent" in r["message"] for r in res):
            break
        time.sleep(0.2)
    return res


def goals_reached(sim, cell=None):
    pat = re.compile(r"goal \((\d+), (\d+)\) reached in (\d+) steps \(step (\d+)\)")
    out = []
    for line in sim.lines:
        m = pat.search(line)
        if m and (cell is None or (int(m[1]), int(m[2])) == tuple(cell)):
            out.append(int(m[4]))
    return out


def wait_until(pred, timeout, what, procs):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if pred():
            return
        dead = [n for n, p in procs.items() if not p.running()]
        if dead:
            raise AssertionError(procs[dead[0]].describe(f"{dead[0]} died waiting for {what}"))
        time.sleep(0.2)
    raise AssertionError(procs["maze_sim"].describe(f"timed out waiting for {what}"))


# --------------------------------------------------------------------------- parameters
def test_each_node_refuses_an_invalid_parameter(ros_domain):
    bad = {("tmgwr_agent", "sensory_preprocessor"): "feature_scale:=-1.0",
           ("tmgwr_agent", "map_learner"): "alpha:=7.0",
           ("tmgwr_agent", "motivation_estimator"): "gamma:=1.5",
           ("tmgwr_agent", "action_selector"): "eps_min:=2.0",
           ("maze_sim", "maze_sim"): "sensor_noise:=-0.5"}
    procs = {exe: (arg.split(":=")[0], ros2_run(pkg, exe, "--ros-args", "-p", arg,
                                                 domain=ros_domain))
             for (pkg, exe), arg in bad.items()}
    for exe, (param, p) in procs.items():
        with p:
            out = p.wait(timeout=60, check=False)
            assert p.proc.returncode == 2, p.describe(f"{exe} did not exit with code 2")
            assert f"'{param}'" in out and "cannot start" in out, out
            assert "ready" not in out


def test_parameters_default_to_specs_and_follow_params_file_and_overrides(ros_domain,
                                                                          tmp_path):
    """Defaults come from the config dataclasses (no shipped file); a ``/**`` file in the
    ROS layout overrides them, ``-p`` overrides the file; a key of another node in the
    shared file is accepted (and not shown by this node)."""
    from tmgwr_agent.core.motivation import MotivationConfig
    params_file = tmp_path / "p.yaml"
    params_file.write_text("/**:\n  ros__parameters:\n    gamma: 0.5\n    beta: 0.25\n"
                           "    a_T: 0.9\n    seed: 3\n")
    runs = {"default": [], "file": ["--params-file", str(params_file)],
            "both": ["--params-file", str(params_file), "-p", "gamma:=0.9"]}
    procs = {k: ros2_run("tmgwr_agent", "motivation_estimator", "--ros-args", *a,
                         domain=ros_domain, name=k) for k, a in runs.items()}
    seen = {}
    for k, p in procs.items():
        with p:
            line = p.wait_for_line("motivation_estimator ready", timeout=60)
            seen[k] = ast.literal_eval(line.split("ready: ", 1)[1])   # its parameter dict
    assert seen["default"] == MotivationConfig().as_dict()
    assert (seen["file"]["gamma"], seen["file"]["beta"]) == (0.5, 0.25)
    assert "a_T" not in seen["file"]
    assert (seen["both"]["gamma"], seen["both"]["beta"]) == (0.9, 0.25)


def test_unknown_parameter_names_stop_the_node_naming_the_nearest(ros_domain, tmp_path):
    """A typo given with -p or in a parameter file stops the node at start (exit code 2),
    naming the key, the nearest known name and the file; an old-layout file (values nested
    under 'tmgwr:') is refused with how to convert it; a malformed file names its line."""
    typo = tmp_path / "typo.yaml"
    typo.write_text("/**:\n  ros__parameters:\n    gama: 0.9\n")
    old = tmp_path / "old.yaml"
    old.write_text("/**:\n  ros__parameters:\n    tmgwr:\n      gamma: 0.9\n")
    broken = tmp_path / "broken.yaml"
    broken.write_text("/**:\n  ros__parameters:\n    gamma: [0.9\n")
    cases = {
        "p": (("tmgwr_agent", "motivation_estimator"), ["-p", "gama:=0.9"],
              ["unknown parameter 'gama'", "did you mean 'gamma'"]),
        "file": (("tmgwr_agent", "action_selector"), ["--params-file", str(typo)],
                 ["unknown parameter 'gama'", str(typo), "did you mean 'gamma'"]),
        "sim": (("maze_sim", "maze_sim"), ["-p", "sede:=1"],
                ["unknown parameter 'sede'", "did you mean 'seed'"]),
        "old": (("tmgwr_agent", "map_learner"), ["--params-file", str(old)],
                [str(old), "old layout", "tmgwr:", "'gamma: ...' directly under"]),
        "broken": (("tmgwr_agent", "sensory_preprocessor"), ["--params-file", str(broken)],
                   [f"{broken}:4:", "malformed parameter file"]),
    }
    procs = {k: ros2_run(pkg, exe, "--ros-args", *args, domain=ros_domain, name=k)
             for k, ((pkg, exe), args, _) in cases.items()}
    for k, p in procs.items():
        with p:
            out = p.wait(timeout=60, check=False)
            assert p.proc.returncode == 2, p.describe(f"{k}: did not exit with code 2")
            assert "cannot start" in out and "ready" not in out, out
            assert "Traceback" not in out, out
            for text in cases[k][2]:
                assert text in out, (k, text, out)


# --------------------------------------------------------------------------- the run
@pytest.mark.timeout(240)
def test_goal_change_by_service_and_same_cells_as_in_process(ros_domain, tmp_path):
    """3000 lockstep steps over DDS, a /set_goal change on the way, cell for cell the
    in-process TMGWRAgent loop; the refused /set_goal requests leave the estimator up."""
    from tmgwr_agent.experiments.lockstep import read_trajectory, run_reference

    steps = 3000
    traj = tmp_path / "trajectory.txt"
    procs = start_graph(ros_domain, tmp_path, sim_args=[
        "-p", f"max_steps:={steps}", "-p", "exit_when_done:=true",
        "-p", f"trajectory_path:={traj}"])
    sim = procs["maze_sim"]
    try:
        # the graph reaches goal 2, several times (epsilon decays, Eq. 7)
        wait_until(lambda: len(goals_reached(sim, (1, 11))) >= 3, 120, "goal 2 x3", procs)
        res = call(ros_domain, [
            ["/set_goal", "SetGoal", {"x": 40, "y": 2}],              # outside
            ["/set_goal", "SetGoal", {"x": 0, "y": 0}],               # a wall
            ["/set_goal", "SetGoal", {"x": float("nan"), "y": 2}],    # not finite
            ["/set_goal", "SetGoal", {"x": 15, "y": 2}],              # goal 1, row 2 col 15
        ])
        assert [r["accepted"] for r in res] == [False, False, False, True], res
        assert "outside" in res[0]["message"]
        assert "wall" in res[1]["message"]
        assert "not finite" in res[2]["message"]
        assert procs["motivation_estimator"].running()   # refusals leave the node up
        summary = parse_json_line(sim.wait(timeout=180), "SUMMARY ")
    finally:
        stop_graph(procs)
    assert summary["steps"] == steps
    assert procs["motivation_estimator"].proc.returncode in (0, -2), \
        procs["motivation_estimator"].describe("estimator did not stop cleanly")
    [(k, cell)] = summary["goal_changes"]
    assert cell == [2, 15]
    graph, changes = read_trajectory(traj)
    assert changes == [(k, (2, 15))] and len(graph) == steps
    ref, _ = run_reference(MAZE, steps, goal="2", world_seed=0, agent_seed=1,
                           goal_changes=changes)
    first = next((i for i, (a, b) in enumerate(zip(graph, ref)) if a != b), None)
    # what a divergence needs to be explained: the goal change's step, and every line of
    # the nodes about resends, held steps, resyncs and solves without the selector's draw
    why = [ln for p in procs.values() for ln in p.lines
           if re.search(r"resend|without its draw|does not follow|synchronised|restarted", ln)]
    assert first is None, f"graph and in-process differ from step {first} (goal change " \
                          f"at step {k}): {graph[first:first + 3]} vs " \
                          f"{ref[first:first + 3]}\n" + "\n".join(why[-40:])
    # The step k the change lands on depends on DDS and service timing. The agent reaches
    # goal 1 after it over the graph exactly when the in-process agent does (same cells):
    # for most k it does, but a change late in some episodes leaves it searching past the
    # last step (the goal change into unvisited space of the agent issue; the lockstep
    # twin shows it for k = 1404..1438 with these seeds). So: the same outcome, and the
    # in-process agent reaches goal 1 for a change at the usual point (after 3 goals).
    reached = [s for s in goals_reached(sim, (2, 15)) if s > k]
    ref_reached = [s for s, _, r, c in ref if s > k and (r, c) == (2, 15)]
    assert bool(reached) == bool(ref_reached), sim.describe("graph and in-process disagree")
    usual, _ = run_reference(MAZE, steps, goal="2", world_seed=0, agent_seed=1,
                             goal_changes=[(850, (2, 15))])
    assert [s for s, _, r, c in usual if s > 850 and (r, c) == (2, 15)], "goal 1 not reached"


@pytest.mark.timeout(200)
def test_detour_after_event_and_learner_restart_from_saved_map(ros_domain, tmp_path):
    # resends every 10 s: the restarted learner shows its loaded map before the ring resumes
    procs = start_graph(ros_domain, tmp_path, sim_args=["-p", "resend_period:=10.0"])
    sim = procs["maze_sim"]
    echo = None
    try:
        wait_until(lambda: len(goals_reached(sim)) >= 10, 120, "goal 2 x10", procs)
        res = call_past_the_agent(ros_domain, [
            ["/maze_sim/set_cell", "SetCell", {"row": 20, "col": 1, "blocked": True}],
            ["/maze_sim/set_cell", "SetCell", {"row": 11, "col": 5, "blocked": True}],
            ["/maze_sim/set_cell", "SetCell", {"row": 11, "col": 5, "blocked": False}],
            ["/maze_sim/fire_event", "FireEvent", {"event": "q"}],
            ["/maze_sim/fire_event", "FireEvent", {"event": "a"}]])
        assert [r["accepted"] for r in res] == [False, True, True, False, True], res
        assert "outside" in res[0]["message"] and "no event named 'q'" in res[3]["message"]
        fired_at = int(sim.wait_for_line(r"event 'a' fired").split("step ")[1].split(":")[0])
        # the old path is cut at (6, 3); the agent finds the detour (>= 46 steps)
        wait_until(lambda: len([s for s in goals_reached(sim) if s > fired_at]) >= 2, 90,
                   "goal 2 after event a", procs)

        # SIGINT the learner: it saves its map; restart it from that file
        learner = procs["map_learner"]
        learner.stop()
        line = next(ln for ln in learner.lines if "map_learner: saved" in ln)
        n_nodes, n_links = (int(v) for v in re.findall(r"saved (\d+) nodes, (\d+) links", line)[0])
        with np.load(tmp_path / "map.npz") as d:
            saved = {k: d[k] for k in d.files}
        assert int(saved["alive"].sum()) == n_nodes and int((saved["out"] >= 0).sum()) == n_links
        before = len(goals_reached(sim))
        echo = spawn_python(MAP_ECHO, domain=ros_domain, name="map_echo")
        echo.wait_for_line("ECHO READY", timeout=60)
        procs["map_learner"] = ros2_run(
            "tmgwr_agent", "map_learner", "--ros-args", "-p",
            f"initial_map:={tmp_path / 'map.npz'}", "-p", f"map_path:={tmp_path / 'map2.npz'}",
            domain=ros_domain)
        procs["map_learner"].wait_for_line(f"started from .*{n_nodes} nodes, {n_links} links",
                                           timeout=60)
        snap = json.loads(echo.wait_for_line("^MAP ", timeout=60)[4:])
        # the learner continues the ring with the same map
        wait_until(lambda: len(goals_reached(sim)) >= before + 2, 90, "goal after restart",
                   procs)
        res = call(ros_domain, [
            ["/map_learner/save_map", "SaveMap", {"name": "on_request"}],    # names, in
            ["/map_learner/load_map", "LoadMap", {"name": "missing"}]])      # its map_dir
        assert res[0]["success"] and res[0]["path"] == str(tmp_path / "on_request.npz"), res
        assert not res[1]["success"] and "missing.npz" in res[1]["message"], res
        with np.load(tmp_path / "on_request.npz") as d:
            assert int(d["step_id"]) > int(saved["step_id"])    # it went on learning
    finally:
        stop_graph(procs)
        if echo is not None:
            echo.stop()
    # The first map the echo sees is the saved one; or, when the ring resumed before the
    # echo's subscription matched the restarted publisher (the latched topic keeps only its
    # newest sample: seen once in CI, step 2557 for 2556), that map after a step or two,
    # which moves only the winner's neighbourhood within the GWR's radius.
    alive = np.flatnonzero(saved["alive"])
    ids = [n[0] for n in snap["nodes"]]
    w = {n[0]: n[1] for n in snap["nodes"]}
    late = snap["step_id"] - int(saved["step_id"])
    assert 0 <= late <= 2, (snap["step_id"], int(saved["step_id"]))
    if late == 0:
        assert ids == alive.tolist()
        assert np.array_equal(np.array([w[i] for i in ids]), saved["w"][alive])
        assert snap["links"] == n_links
    else:
        assert set(alive.tolist()) <= set(ids) and len(ids) - len(alive) <= late
        np.testing.assert_allclose(np.array([w[i] for i in alive]), saved["w"][alive],
                                   atol=0.02)
        assert abs(snap["links"] - n_links) <= 4 * late
