"""Package boundaries of the colcon workspace (src/).

- Every ament_python package runs tmgwr_common.package_checks from its
  test/test_package_xml.py (imports declared in package.xml, setup.py inside the package,
  the install complete); here they run against the repository's install/.
- The workspace's dependency graph: tmgwr_common <- maze_sim <- tmgwr_agent, no cycle, and
  maze_sim does not declare tmgwr_agent (so, by the checker, it cannot import it either;
  .importlinter states the same contract for the Python imports).
- A fresh workspace (a copy of src/ only) passes ``colcon build`` and ``colcon test``, in
  the environment tools/bootstrap.sh builds with. The rosidl package tmgwr_interfaces, most
  of the build's time, is not built a second time: the repository's own build of it (what
  ``make bootstrap`` builds from src/, from scratch in a clean clone, before the tests run)
  is the underlay, so on a loaded CI machine the test stays well inside its timeouts (a
  full second build hit 360 s at load 6-13). ``TMGWR_FRESH_FULL=1`` builds every package
  again. By hand (the full build)::

      W=$(mktemp -d) && cp -r src "$W" && cd "$W" && VENV=<repo>/.venv &&
      env -u PYTHONPATH -u _ROS_WHEELS_BOOTSTRAP_COMPLETE VIRTUAL_ENV=$VENV \\
          PATH=$VENV/bin:$PATH AMENT_PREFIX_PATH=$VENV CMAKE_PREFIX_PATH=$VENV \\
          sh -c "colcon build --cmake-args -DPython3_EXECUTABLE=$VENV/bin/python &&
                 colcon test && colcon test-result --verbose"
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from ros_helpers import ROOT

SRC = ROOT / "src"
CHECKER = "test/test_package_xml.py"


def _package_xml(pkg_dir: Path):
    root = ET.parse(pkg_dir / "package.xml").getroot()
    deps = {e.text.strip() for tag in ("depend", "exec_depend", "build_depend", "test_depend")
            for e in root.findall(tag)}
    build_type = root.findtext("export/build_type", default="").strip()
    return root.findtext("name").strip(), deps, build_type


PACKAGES = {}
for _xml in sorted(SRC.glob("*/package.xml")):
    _name, _deps, _type = _package_xml(_xml.parent)
    PACKAGES[_name] = (_xml.parent, _deps, _type)
PYTHON_PACKAGES = sorted(n for n, (_, _, t) in PACKAGES.items() if t == "ament_python")


def test_workspace_packages():
    assert set(PACKAGES) == {"tmgwr_common", "maze_sim", "tmgwr_agent", "tmgwr_interfaces"}
    assert PYTHON_PACKAGES == ["maze_sim", "tmgwr_agent", "tmgwr_common"]


def test_every_python_package_runs_the_shared_checks():
    for pkg in PYTHON_PACKAGES:
        text = (PACKAGES[pkg][0] / CHECKER).read_text(encoding="utf-8")
        assert "check_package(" in text, f"src/{pkg}/{CHECKER} does not run check_package"


@pytest.mark.parametrize("pkg", PYTHON_PACKAGES)
def test_package_checks(pkg):
    """What `colcon test` runs in each package, against the repository's install/ (make
    test bootstraps first)."""
    from tmgwr_common.package_checks import check_package

    check_package(PACKAGES[pkg][0])


def test_dependency_graph_has_no_cycle_and_maze_sim_stays_below_the_agent():
    inside = {n: deps & set(PACKAGES) for n, (_, deps, _) in PACKAGES.items()}
    assert inside["tmgwr_common"] == set()
    assert "tmgwr_agent" not in inside["maze_sim"]
    assert {"maze_sim", "tmgwr_common", "tmgwr_interfaces"} <= inside["tmgwr_agent"]
    # topological order exists (colcon refuses a cycle)
    done: set[str] = set()
    while len(done) < len(inside):
        ready = {n for n, deps in inside.items() if n not in done and deps <= done}
        assert ready, f"dependency cycle among {sorted(set(inside) - done)}"
        done |= ready


# --------------------------------------------------------------------------- fresh workspace
def _build_env(venv: Path) -> dict[str, str]:
    """tools/bootstrap.sh's build_env: the venv as the only underlay, no source trees."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "COLCON_PREFIX_PATH", "AMENT_CURRENT_PREFIX",
                        "_ROS_WHEELS_BOOTSTRAP_COMPLETE", "LD_LIBRARY_PATH")
           and not k.startswith("PYTEST_")}
    env.update(VIRTUAL_ENV=str(venv), PATH=f"{venv / 'bin'}:{os.environ.get('PATH', '')}",
               AMENT_PREFIX_PATH=str(venv), CMAKE_PREFIX_PATH=str(venv),
               PYTHONDONTWRITEBYTECODE="1", MAKEFLAGS=f"-j{os.cpu_count() or 2}")
    return env


REUSED = "tmgwr_interfaces"      # built once, by make bootstrap (see the module docstring)
STEP_TIMEOUT = 600               # seconds per colcon step on a loaded 2-core machine


def _underlay(env: dict[str, str], package: str) -> dict[str, str]:
    """``env`` with the repository's installed ``package`` as an underlay (its colcon
    package.bash: AMENT_PREFIX_PATH, CMAKE_PREFIX_PATH, PYTHONPATH, LD_LIBRARY_PATH)."""
    script = ROOT / "install" / package / "share" / package / "package.bash"
    if not script.is_file():
        pytest.skip(f"{script} missing: run tools/bootstrap.sh")
    proc = subprocess.run(["bash", "-c", 'source "$1" >&2 && env -0', "env", str(script)],
                          env=env, capture_output=True, timeout=60, check=True)
    out = {}
    for item in proc.stdout.split(b"\0"):
        if b"=" in item:
            key, _, value = item.partition(b"=")
            out[key.decode()] = value.decode(errors="surrogateescape")
    return out


@pytest.mark.slow
@pytest.mark.timeout(3 * STEP_TIMEOUT + 120)
def test_fresh_workspace_colcon_build_and_test(tmp_path):
    venv = ROOT / ".venv"
    colcon = venv / "bin" / "colcon"
    if not colcon.exists():
        pytest.skip(f"{colcon} missing: run tools/bootstrap.sh")
    shutil.copytree(SRC, tmp_path / "src",
                    ignore=shutil.ignore_patterns("__pycache__", ".pytest_cache"))
    env = _build_env(venv)
    skip: list[str] = []
    if os.environ.get("TMGWR_FRESH_FULL") != "1":
        env, skip = _underlay(env, REUSED), ["--packages-skip", REUSED]
    handlers = ["--event-handlers", "console_direct-", "desktop_notification-",
                "terminal_title-"]
    steps = [
        ("build", [str(colcon), "build", *handlers, *skip,
                   "--cmake-args", f"-DPython3_EXECUTABLE={venv / 'bin' / 'python'}"]),
        ("test", [str(colcon), "test", *handlers, *skip]),
        ("test-result", [str(colcon), "test-result", "--verbose"]),
    ]
    timings = {}
    for step, cmd in steps:
        t0 = time.monotonic()
        proc = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=STEP_TIMEOUT)
        timings[step] = round(time.monotonic() - t0, 1)
        out = proc.stdout + proc.stderr
        assert proc.returncode == 0, f"colcon {step} failed ({timings}):\n{out[-6000:]}"
    summary = [line for line in proc.stdout.splitlines() if line.startswith("Summary:")]
    assert summary and " 0 errors, 0 failures" in summary[-1], proc.stdout
    n_tests = int(summary[-1].split()[1])
    assert n_tests >= len(PYTHON_PACKAGES), summary   # one package check each
    for pkg in PYTHON_PACKAGES:
        assert (tmp_path / "build" / pkg / "pytest.xml").is_file(), f"no tests ran for {pkg}"
    print(f"fresh workspace: {timings}, {summary[-1]}", file=sys.stderr)
