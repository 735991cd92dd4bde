"""Smoke tests of the real ROS 2 environment: the venv, the colcon workspace, and DDS
between separate processes (own ROS_DOMAIN_ID, LOCALHOST discovery)."""

from __future__ import annotations

import glob
import math
import os
import subprocess
import time

import pytest
from ros_helpers import ROOT, base_env, parse_json_line, spawn_python, unexpected_errors

pytestmark = pytest.mark.ros


# --------------------------------------------------------------------------- environment
def test_fresh_process_imports_generated_types_and_source_trees():
    code = r"""
import json, os
import rclpy
from tmgwr_interfaces.msg import (Observation, Action, Features, SensorimotorState, MapNode,
                                  MapLink, SensorimotorMap, MotivationField)
from tmgwr_interfaces.srv import SetGoal, SetCell, FireEvent, SaveMap, LoadMap
from std_srvs.srv import Trigger
import maze_sim, tmgwr_agent, tmgwr_common, tmgwr_interfaces
from ament_index_python.packages import get_package_prefix, get_package_share_directory
print("RESULT " + json.dumps({
    "interfaces": tmgwr_interfaces.__file__,
    "tmgwr_common": list(tmgwr_common.__path__),
    "maze_sim": list(maze_sim.__path__),
    "tmgwr_agent": list(tmgwr_agent.__path__),
    "actions": [Action.UP, Action.DOWN, Action.LEFT, Action.RIGHT],
    "prefix": get_package_prefix("tmgwr_agent"),
    "share": get_package_share_directory("tmgwr_interfaces"),
    "save_map_response_path": SaveMap.Response(path="x").path,
}))
"""
    env = base_env()
    proc = subprocess.run([str(ROOT / ".venv/bin/python"), "-c", code], env=env,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    res = parse_json_line(proc.stdout, "RESULT ")
    assert res["interfaces"].startswith(str(ROOT / "install"))
    # the ROS-free core is imported from src/, not from the installed copy
    assert res["tmgwr_common"] == [str(ROOT / "src/tmgwr_common/tmgwr_common")]
    assert res["maze_sim"] == [str(ROOT / "src/maze_sim/maze_sim")]
    assert res["tmgwr_agent"][0] == str(ROOT / "src/tmgwr_agent/tmgwr_agent")
    assert res["actions"] == [0, 1, 2, 3]
    assert res["prefix"] == str(ROOT / "install/tmgwr_agent")
    assert res["share"] == str(ROOT / "install/tmgwr_interfaces/share/tmgwr_interfaces")
    assert res["save_map_response_path"] == "x"


def test_environment_variables():
    env = base_env()
    assert env["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert env["RMW_IMPLEMENTATION"] == "rmw_fastrtps_cpp"
    assert os.path.isfile(env["FASTRTPS_DEFAULT_PROFILES_FILE"])
    prefixes = env["AMENT_PREFIX_PATH"].split(":")
    # the workspace overlays the venv (the wheels' prefix)
    assert prefixes.index(str(ROOT / "install/tmgwr_agent")) < prefixes.index(str(ROOT / ".venv"))
    # the source trees come first, the shared package first of all (tools/env.sh)
    assert env["PYTHONPATH"].split(":")[:3] == [str(ROOT / "src/tmgwr_common"),
                                                str(ROOT / "src/maze_sim"),
                                                str(ROOT / "src/tmgwr_agent")]


def test_ros2_run_layout():
    """`ros2 run <pkg> <exe>` resolves install/<pkg>/lib/<pkg>/<exe>: the contract names."""
    expected = {
        "tmgwr_common": [],
        "maze_sim": ["maze_sim"],
        "tmgwr_agent": ["sensory_preprocessor", "map_learner", "motivation_estimator",
                        "action_selector", "recorder"],
    }
    for pkg, exes in expected.items():
        index = ROOT / "install" / pkg / "share/ament_index/resource_index/packages"
        assert (index / pkg).is_file()
        assert (ROOT / "install" / pkg / "share" / pkg / "package.xml").is_file()
        for exe in exes:
            path = ROOT / "install" / pkg / "lib" / pkg / exe
            assert path.is_file() and os.access(path, os.X_OK), path


def test_cmake_include_path_fix_applied():
    leftovers = [p for p in glob.glob(str(ROOT / ".venv/share/*/cmake/*.cmake"))
                 if "/opt/python/" in open(p, encoding="utf-8", errors="replace").read()]
    assert leftovers == []


def test_bootstrap_second_run_is_a_noop():
    t0 = time.monotonic()
    proc = subprocess.run([str(ROOT / "tools/bootstrap.sh"), "--status"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "up to date" in proc.stderr
    assert time.monotonic() - t0 < 5


# --------------------------------------------------------------------------- pub/sub
PUBLISHER = r"""
import sys, time
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.qos import QoSProfile, ReliabilityPolicy
from tmgwr_interfaces.msg import Observation

N = int(sys.argv[1])
rclpy.init()
node = rclpy.create_node('smoke_observation_publisher')
pub = node.create_publisher(Observation, 'smoke/observation',
                            QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
msgs = []
for k in range(N):
    m = Observation()
    m.header.stamp.sec = 1_700_000_000 + k
    m.header.stamp.nanosec = 999_999_999 - k
    m.header.frame_id = 'maze/\u00e9t\u00e9'
    m.step_id = 2**64 - 1 - k
    m.episode = 2**32 - 1 - k
    m.sensors = [k + 0.1, -0.0, 1e-300, 1.7976931348623157e308, float('inf'), float('-inf')]
    m.bumped = bool(k % 2)
    m.goal_reached = k == N - 1
    m.previous_goal_reached = k == 0
    m.row = -(2**31) + k
    m.col = 2**31 - 1 - k
    msgs.append(m)
print('PUBLISHER READY', flush=True)
try:
    # Keep cycling through the N messages until stopped: a volatile subscription that matched
    # late still gets every one of them.
    i = 0
    while rclpy.ok():
        try:
            pub.publish(msgs[i % N])
        except Exception:
            if rclpy.ok():
                raise
            break       # the stop's SIGINT shut the context down between ok() and publish
        i += 1
        time.sleep(0.02)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
finally:
    node.destroy_node()
    rclpy.try_shutdown()
"""

SUBSCRIBER = r"""
import json, sys, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from tmgwr_interfaces.msg import Observation

N = int(sys.argv[1])
got = {}
def cb(m):
    got.setdefault(m.step_id, {
        'stamp': [m.header.stamp.sec, m.header.stamp.nanosec], 'frame_id': m.header.frame_id,
        'step_id': m.step_id, 'episode': m.episode, 'sensors': [x.hex() for x in m.sensors],
        'bumped': m.bumped, 'goal_reached': m.goal_reached,
        'previous_goal_reached': m.previous_goal_reached, 'row': m.row, 'col': m.col})

rclpy.init()
node = rclpy.create_node('smoke_observation_subscriber')
node.create_subscription(Observation, 'smoke/observation', cb,
                         QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE))
ex = SingleThreadedExecutor()
ex.add_node(node)
print('SUBSCRIBER READY', flush=True)
t0 = time.monotonic()
first = None
while len(got) < N and time.monotonic() - t0 < 40:
    ex.spin_once(timeout_sec=0.1)
    if got and first is None:
        first = time.monotonic() - t0
print('RESULT ' + json.dumps({'messages': sorted(got.values(), key=lambda d: -d['step_id']),
                              'first_after_s': first}), flush=True)
ex.shutdown()
node.destroy_node()
rclpy.try_shutdown()
sys.exit(0 if len(got) == N else 3)
"""


def _expected_observations(n):
    out = []
    for k in range(n):
        out.append({
            "stamp": [1_700_000_000 + k, 999_999_999 - k], "frame_id": "maze/\u00e9t\u00e9",
            "step_id": 2**64 - 1 - k, "episode": 2**32 - 1 - k,
            "sensors": [x.hex() for x in (k + 0.1, -0.0, 1e-300, 1.7976931348623157e308,
                                          math.inf, -math.inf)],
            "bumped": bool(k % 2), "goal_reached": k == n - 1, "previous_goal_reached": k == 0,
            "row": -(2**31) + k, "col": 2**31 - 1 - k})
    return out


@pytest.mark.timeout(120)
def test_observation_pubsub_between_processes(ros_domain):
    n = 5
    sub = spawn_python(SUBSCRIBER, str(n), domain=ros_domain, name="subscriber")
    pub = spawn_python(PUBLISHER, str(n), domain=ros_domain, name="publisher")
    with sub, pub:
        sub.wait_for_line("SUBSCRIBER READY", timeout=30)
        pub.wait_for_line("PUBLISHER READY", timeout=30)
        out = sub.wait(timeout=60)
        pub.stop()
        assert pub.proc.returncode == 0, pub.describe("publisher did not shut down cleanly")
    res = parse_json_line(out, "RESULT ")
    assert res["messages"] == _expected_observations(n)
    assert unexpected_errors(out) == [], sub.describe("errors in subscriber output")
    assert unexpected_errors(pub.output) == [], pub.describe("errors in publisher output")


# --------------------------------------------------------------------------- service
SERVER = r"""
import math
import rclpy
from rclpy.executors import ExternalShutdownException
from tmgwr_interfaces.srv import SetGoal

ROWS, COLS = 13, 17
def handle(req, resp):
    x, y = req.goal.x, req.goal.y
    if not (math.isfinite(x) and math.isfinite(y)):
        resp.accepted, resp.message = False, 'goal is not finite'
    elif not (0 <= x < COLS and 0 <= y < ROWS):
        resp.accepted, resp.message = False, f'goal ({x}, {y}) is outside the maze'
    else:
        resp.accepted, resp.message = True, f'goal set to row {int(y)} col {int(x)}'
    return resp

rclpy.init()
node = rclpy.create_node('smoke_set_goal_server')
node.create_service(SetGoal, 'set_goal', handle)
print('SERVER READY', flush=True)
try:
    rclpy.spin(node)
except (KeyboardInterrupt, ExternalShutdownException):
    pass
finally:
    node.destroy_node()
    rclpy.try_shutdown()
"""

CLIENT = r"""
import json, sys, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from tmgwr_interfaces.srv import SetGoal

rclpy.init()
node = rclpy.create_node('smoke_set_goal_client')
cli = node.create_client(SetGoal, 'set_goal')
ex = SingleThreadedExecutor()
ex.add_node(node)
t0 = time.monotonic()
if not cli.wait_for_service(timeout_sec=30):
    print('service not available after 30 s', flush=True)
    sys.exit(4)
discovered = time.monotonic() - t0
results = []
for x, y in [(16.0, 12.0), (17.0, 0.0), (float('nan'), 1.0), (3.0, 4.0)]:
    req = SetGoal.Request()
    req.goal.x, req.goal.y = x, y
    fut = cli.call_async(req)
    t = time.monotonic()
    # not spin_until_future_complete (rclpy#1374)
    while not fut.done() and time.monotonic() - t < 10:
        ex.spin_once(timeout_sec=0.05)
    if not fut.done():
        print(f'no response for goal {(x, y)} within 10 s', flush=True)
        sys.exit(5)
    r = fut.result()
    results.append([r.accepted, r.message, (time.monotonic() - t) * 1000])
print('RESULT ' + json.dumps({'results': results, 'discovered_s': discovered}), flush=True)
ex.shutdown()
node.destroy_node()
rclpy.try_shutdown()
"""


@pytest.mark.timeout(120)
def test_set_goal_service_round_trip_between_processes(ros_domain):
    server = spawn_python(SERVER, domain=ros_domain, name="set_goal_server")
    with server:
        server.wait_for_line("SERVER READY", timeout=30)
        client = spawn_python(CLIENT, domain=ros_domain, name="set_goal_client")
        with client:
            out = client.wait(timeout=60)
        server.stop()
        assert server.proc.returncode == 0, server.describe("server did not shut down cleanly")
    res = parse_json_line(out, "RESULT ")
    got = [r[:2] for r in res["results"]]
    assert got == [
        [True, "goal set to row 12 col 16"],
        [False, "goal (17.0, 0.0) is outside the maze"],
        [False, "goal is not finite"],
        [True, "goal set to row 4 col 3"],
    ]
    assert unexpected_errors(out) == [], client.describe("errors in client output")


@pytest.mark.timeout(120)
def test_domains_isolate(ros_domain):
    """A server in one domain is invisible from another domain."""
    from ros_helpers import allocate_domain, release_domain
    other = allocate_domain()
    try:
        server = spawn_python(SERVER, domain=ros_domain, name="server_domain_a")
        probe = (r"""
import rclpy, sys
from tmgwr_interfaces.srv import SetGoal
rclpy.init(); node = rclpy.create_node('probe')
cli = node.create_client(SetGoal, 'set_goal')
print('FOUND' if cli.wait_for_service(timeout_sec=3.0) else 'NOT FOUND', flush=True)
node.destroy_node(); rclpy.try_shutdown()
""")
        with server:
            server.wait_for_line("SERVER READY", timeout=30)
            with spawn_python(probe, domain=other, name="probe_domain_b") as p:
                out = p.wait(timeout=30)
        assert "NOT FOUND" in out
    finally:
        release_domain(other)


# --------------------------------------------------------------------------- DDS sockets
NODE_THAT_WAITS = r"""
import time, rclpy
from std_msgs.msg import UInt64
rclpy.init()
node = rclpy.create_node("socket_probe")
node.create_publisher(UInt64, "probe", 10)
node.create_subscription(UInt64, "probe", lambda m: None, 10)
print("NODE UP", flush=True)
time.sleep(60)
"""


def udp_sockets(pid: int) -> list[tuple[str, int]]:
    """(address, port) of every UDP socket process ``pid`` holds (/proc/net/udp, IPv4)."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[len("socket:["):-1])
    found = []
    with open("/proc/net/udp") as f:
        for line in f.read().splitlines()[1:]:
            fields = line.split()
            if fields[9] in inodes:
                hexip, hexport = fields[1].split(":")
                ip = ".".join(str(int(hexip[i:i + 2], 16)) for i in (6, 4, 2, 0))
                found.append((ip, int(hexport, 16)))
    return found


def test_with_localhost_discovery_participants_bind_unicast_to_loopback(ros_domain):
    """Issue 24: with ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST the participants still bound
    their unicast sockets to 0.0.0.0. tools/fastdds_localhost.xml's interface allowlist
    binds them to 127.0.0.1: every socket on the domain's RTPS ports (7400 + 250 x domain
    ... + 249: discovery and user unicast) of a node is on loopback."""
    p = spawn_python(NODE_THAT_WAITS, domain=ros_domain, name="socket_probe")
    with p:
        p.wait_for_line("NODE UP", timeout=60)
        time.sleep(1.0)
        sockets = udp_sockets(p.proc.pid)
        p.stop()
    base = 7400 + 250 * ros_domain
    rtps = [(ip, port) for ip, port in sockets if base <= port < base + 250]
    assert len(rtps) >= 2, sockets                 # discovery and user unicast at least
    assert all(ip == "127.0.0.1" for ip, _ in rtps), sockets
