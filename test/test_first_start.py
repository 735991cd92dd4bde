"""Fast first start (issue 10, item 8): the numba kernels are compiled into their on-disk
cache once (``python -m tmgwr_agent.warmup``, run by tools/bootstrap.sh), and a process
that finds the cache empty says so before it compiles.

Each case uses its own empty ``NUMBA_CACHE_DIR``, so the repository's cache is never touched.
"""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NOTICE = "compiling numba kernels, first start only"
MAKE_CORE = ("from tmgwr_agent.core.sensorimotor_map import SensorimotorMap\n"
             "from tmgwr_agent.core.motivation import MotivationEstimator\n"
             "SensorimotorMap(2); MotivationEstimator(primitives=[[0.0, 1.0]])\n")


def python(args, cache: Path, timeout=300):
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    path = [str(ROOT / "src" / p) for p in ("tmgwr_common", "maze_sim", "tmgwr_agent")]
    env["PYTHONPATH"] = os.pathsep.join(path + [env.get("PYTHONPATH", "")])
    return subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True,
                          timeout=timeout)


def test_an_empty_cache_is_announced_once(tmp_path):
    r = python(["-c", MAKE_CORE], tmp_path / "empty")
    assert r.returncode == 0, r.stderr
    assert r.stderr.count(NOTICE) == 1, r.stderr    # once per process, not per object


def test_warm_up_compiles_every_kernel_then_first_starts_are_silent(tmp_path):
    cache = tmp_path / "cache"
    r = python(["-m", "tmgwr_agent.warmup", "--quiet"], cache)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "compiling the numba kernels (once, about" in r.stdout
    assert "compiled and cached" in r.stdout
    # a second warm-up finds everything cached and, quiet, prints nothing
    r = python(["-m", "tmgwr_agent.warmup", "--quiet"], cache)
    assert r.returncode == 0 and r.stdout == "" and r.stderr == "", r.stdout + r.stderr
    # every kernel has a cached version, and a node's core says nothing about compiling
    r = python(["-c", "from tmgwr_agent.core import kernels\n"
                "assert not kernels.uncached(), kernels.uncached()\n" + MAKE_CORE], cache)
    assert r.returncode == 0, r.stderr
    assert NOTICE not in r.stderr
