"""The import contracts in ``.importlinter`` hold: ``lint-imports`` passes.

They state the architecture: tmgwr_common is the base the two packages share, maze_sim
imports nothing of the agent, ``tmgwr_agent.core`` imports no ROS and none of the tooling,
the offline bag tools do not import the graph runner or the nodes, and no package has an
import cycle between its modules. Run the same check by hand with ``lint-imports`` from the
repository root (after ``source tools/env.sh``).
"""

import os
import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = [ROOT / "src" / p for p in ("tmgwr_common", "maze_sim", "tmgwr_agent")]


def test_import_contracts_hold():
    exe = shutil.which("lint-imports")
    assert exe, "lint-imports not found: import-linter is pinned in requirements/python.txt"
    env = dict(os.environ)
    # the source trees, not an installed copy, are what is checked
    env["PYTHONPATH"] = os.pathsep.join([*map(str, SOURCES), env.get("PYTHONPATH", "")])
    proc = subprocess.run([exe, "--no-cache", "--no-logo",
                           "--config", str(ROOT / ".importlinter")],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
