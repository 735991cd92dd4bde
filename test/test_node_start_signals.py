"""A node's process installs its stop request (tmgwr_common.stop) before it imports numpy,
rclpy or numba: ``ros2 launch`` sends SIGINT to every node as soon as one fails, often while
the others still import, and a node caught inside ``import rclpy`` printed a
KeyboardInterrupt traceback (a launch whose sensory_preprocessor refused its parameters
file, CI of 2026-11-28). Checked in a fresh interpreter that takes the installed
executable's name, ``<prefix>/lib/<package>/<executable>``: an import hook reads the SIGINT
handler at the first import of each heavy module."""

import subprocess
import sys

import pytest

PROBE = r"""
import importlib, signal, sys
sys.argv[0] = "/opt/x/lib/{package}/{executable}"
HEAVY = ("numpy", "rclpy", "numba")
seen = {{}}

class Probe:
    def find_spec(self, name, path=None, target=None):
        if name in HEAVY and name not in seen:
            seen[name] = signal.getsignal(signal.SIGINT) is not signal.default_int_handler
        return None

sys.meta_path.insert(0, Probe())
importlib.import_module("{module}")
from tmgwr_common.stop import STOP
assert STOP.installed, "not installed"
assert signal.getsignal(signal.SIGINT) == STOP._handler
bad = [m for m, ok in seen.items() if not ok]
assert "numpy" in seen and "rclpy" in seen, seen
assert not bad, "imported before the stop request: " + ", ".join(bad)
print("ok", sorted(seen))
"""


@pytest.mark.timeout(120)
@pytest.mark.parametrize("package, executable, module", [
    ("maze_sim", "maze_sim", "maze_sim.node"),
    ("tmgwr_agent", "sensory_preprocessor", "tmgwr_agent.nodes.sensory_preprocessor"),
    ("tmgwr_agent", "map_learner", "tmgwr_agent.nodes.map_learner"),
    ("tmgwr_agent", "motivation_estimator", "tmgwr_agent.nodes.motivation_estimator"),
    ("tmgwr_agent", "action_selector", "tmgwr_agent.nodes.action_selector"),
    ("tmgwr_agent", "recorder", "tmgwr_agent.nodes.recorder"),
])
def test_a_node_installs_its_stop_request_before_its_heavy_imports(package, executable,
                                                                    module):
    code = PROBE.format(package=package, executable=executable, module=module)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=100)
    assert r.returncode == 0 and r.stdout.startswith("ok"), r.stdout + r.stderr


def test_a_tool_that_imports_the_nodes_keeps_its_own_ctrl_c():
    """Not started as a node's executable (pytest, ``./tmgwr up``): nothing is installed."""
    code = ("import signal, tmgwr_common.node, maze_sim.node\n"
            "from tmgwr_common.stop import STOP\n"
            "assert not STOP.installed\n"
            "assert signal.getsignal(signal.SIGINT) is signal.default_int_handler\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=100)
    assert r.returncode == 0, r.stdout + r.stderr
