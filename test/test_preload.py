"""Nodes load their numba kernels from the on-disk cache before their ready line (issue 24:
a restarted node's first steps loaded them, after the ready line, and delayed the ring's
rejoin). Runs in a fresh interpreter: this one may have loaded kernels already."""

from __future__ import annotations

import json
import subprocess
import sys

from ros_helpers import ROOT

CHECK = r"""
import json
from tmgwr_agent.core import kernels
from tmgwr_agent.nodes.preload import load_cached_kernels
listed = {name for name, d in kernels.KERNELS.items() if d._cache._cache_file._load_index()}
before = {name for name, d in kernels.KERNELS.items() if d.signatures}
loaded = load_cached_kernels()
after = {name for name, d in kernels.KERNELS.items() if d.signatures}
print(json.dumps({"listed": sorted(listed), "before": sorted(before), "after": sorted(after),
                  "loaded": loaded, "again": load_cached_kernels()}))
"""


def test_every_cached_kernel_is_loaded_without_a_call():
    env_py = ROOT / ".venv" / "bin" / "python"
    out = subprocess.run([str(env_py if env_py.exists() else sys.executable), "-c", CHECK],
                         capture_output=True, text=True, timeout=300, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    assert r["listed"], "the numba cache is empty: run tools/bootstrap.sh"
    assert not r["before"], r["before"]            # nothing loaded at import
    assert set(r["listed"]) <= set(r["after"]), set(r["listed"]) - set(r["after"])
    assert r["loaded"] >= len(r["listed"]) and r["again"] == 0, r
