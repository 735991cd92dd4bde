"""Helpers for tests that run real ROS 2 processes (rclpy over Fast DDS, one machine).

Every ROS test should run its processes in a ROS_DOMAIN_ID of its own, so that parallel
pytest runs (two clones, CI beside a developer) and leftovers of an earlier test never see
each other, and with LOCALHOST discovery so nothing leaves the machine.

Use from a test module in test/ (test/ is on sys.path under pytest's default import mode)::

    from ros_helpers import ROOT, spawn_python, spawn_module, ros2_run

    def test_talk(ros_domain):                  # fixture (conftest.py): a free domain id
        sub = spawn_python(SUB_CODE, domain=ros_domain, name='sub')
        pub = spawn_python(PUB_CODE, domain=ros_domain, name='pub')
        with sub, pub:                          # both are stopped at the end, whatever happens
            sub.wait_for_line('READY', timeout=20)
            out = sub.wait(timeout=30)          # exit 0 expected; stdout+stderr returned
        ...

- ``ros_env(domain)``: the environment a ROS process needs: tools/env.sh sourced once per
  session in a bash subprocess (venv, install/setup.bash, LD_LIBRARY_PATH, source trees first
  on PYTHONPATH, LOCALHOST discovery, Fast DDS profile), plus ROS_DOMAIN_ID and
  PYTHONUNBUFFERED=1. It does not depend on how pytest itself was started.
- ``allocate_domain()`` / ``release_domain()``: a domain id in 1..101 not held by any other
  cooperating process on this machine (an flock'ed file per id under the temp dir), starting
  from a hash of the pytest worker name and pid. The ``ros_domain`` fixture wraps them.
- ``spawn_python(code, *args)``, ``spawn_module('pkg.mod', *args)``,
  ``ros2_run('pkg', 'executable', *args)`` (what ``ros2 run`` would start: the console script
  in install/<pkg>/lib/<pkg>/): each returns a started ``RosProcess``.
- ``RosProcess``: stdout and stderr merged and collected by a thread;
  ``wait_for_line(regex, timeout)`` returns the first matching line (and raises with the whole
  output when the process exits or the time runs out first); ``wait(timeout, check=True)``;
  ``stop()`` sends SIGINT, then SIGTERM, then SIGKILL to the process group; ``output``.
  Every failure message names the process, its command, its domain and its full output.
- ``parse_json_line(output, prefix)``: the JSON after the last line starting with prefix.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
import warnings
import zlib
from pathlib import Path
from typing import Iterable, Mapping, Sequence

ROOT = Path(__file__).resolve().parent.parent
VENV_PYTHON = ROOT / ".venv" / "bin" / "python"
ENV_SCRIPT = ROOT / "tools" / "env.sh"

DOMAIN_MIN, DOMAIN_MAX = 1, 101          # Fast DDS on Linux: ids above ~101 clash with ports
_LOCK_DIR = Path(tempfile.gettempdir()) / "tmgwr-ros-domains"

# Harmless Fast DDS noise that may appear in a process's output (the shared-memory
# transport's `RTPS_TRANSPORT_SHM Error ... open_and_lock_file failed`; delivery goes on).
HARMLESS_OUTPUT = (re.compile(r"RTPS_TRANSPORT_SHM Error"),)


# --------------------------------------------------------------------------- environment
_BASE_ENV: dict[str, str] | None = None


def base_env() -> dict[str, str]:
    """The environment after ``source tools/env.sh`` (computed once per process)."""
    global _BASE_ENV
    if _BASE_ENV is None:
        if not (ROOT / "install" / "setup.bash").is_file():
            raise RuntimeError(f"{ROOT}/install/setup.bash missing: run {ROOT}/tools/bootstrap.sh")
        proc = subprocess.run(
            ["bash", "-c", 'source "$1" >&2 && env -0', "env", str(ENV_SCRIPT)],
            capture_output=True, env=os.environ.copy(), timeout=60)
        if proc.returncode != 0:
            err = proc.stderr.decode(errors="replace")
            raise RuntimeError(f"sourcing {ENV_SCRIPT} failed:\n{err}")
        env = {}
        for item in proc.stdout.split(b"\0"):
            if b"=" in item:
                key, _, value = item.partition(b"=")
                env[key.decode()] = value.decode(errors="surrogateescape")
        _BASE_ENV = env
    return dict(_BASE_ENV)


def ros_env(domain: int, extra: Mapping[str, str] | None = None) -> dict[str, str]:
    """Environment for a ROS process in ``domain`` (LOCALHOST discovery, unbuffered output)."""
    env = base_env()
    env["ROS_DOMAIN_ID"] = str(int(domain))
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["PYTHONUNBUFFERED"] = "1"
    env.pop("ROS_LOCALHOST_ONLY", None)   # deprecated in Jazzy, conflicts with the range
    if extra:
        env.update(extra)
    return env


# --------------------------------------------------------------------------- domain ids
_held: dict[int, int] = {}               # domain id -> fd of its held lock file


def allocate_domain() -> int:
    """Reserve a ROS_DOMAIN_ID no other cooperating process on this machine holds."""
    import fcntl

    _LOCK_DIR.mkdir(parents=True, exist_ok=True)
    try:
        os.chmod(_LOCK_DIR, 0o1777)
    except OSError:
        pass
    span = DOMAIN_MAX - DOMAIN_MIN + 1
    worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    start = zlib.crc32(f"{worker}:{os.getpid()}".encode()) % span
    avoid = os.environ.get("ROS_DOMAIN_ID", "0")
    for i in range(span):
        domain = DOMAIN_MIN + (start + i) % span
        if str(domain) == avoid or domain in _held:
            continue
        fd = os.open(_LOCK_DIR / f"{domain}.lock", os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        _held[domain] = fd
        return domain
    raise RuntimeError(f"no free ROS_DOMAIN_ID in {DOMAIN_MIN}..{DOMAIN_MAX}")


def release_domain(domain: int) -> None:
    fd = _held.pop(domain, None)
    if fd is not None:
        os.close(fd)                     # closing drops the flock


# --------------------------------------------------------------------------- processes
# what ``ros2 service call`` prints once it has the response
SERVICE_ANSWERED = r"^response:\n.+"


class RosProcess:
    """A child process whose merged output is collected in the background."""

    def __init__(self, cmd: Sequence[str], env: Mapping[str, str], name: str = "",
                 cwd: str | os.PathLike | None = None):
        self.cmd = list(cmd)
        self.name = name or Path(self.cmd[0]).name
        self.domain = env.get("ROS_DOMAIN_ID", "?")
        self._lines: list[str] = []
        self._cond = threading.Condition()
        self._eof = False
        self.proc = subprocess.Popen(
            self.cmd, env=dict(env), cwd=str(cwd or ROOT), stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, errors="replace",
            bufsize=1, start_new_session=True)
        self._reader = threading.Thread(target=self._read, name=f"reader-{self.name}", daemon=True)
        self._reader.start()

    # -- output
    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._cond:
                self._lines.append(line.rstrip("\n"))
                self._cond.notify_all()
        with self._cond:
            self._eof = True
            self._cond.notify_all()

    @property
    def output(self) -> str:
        with self._cond:
            return "\n".join(self._lines)

    @property
    def lines(self) -> list[str]:
        with self._cond:
            return list(self._lines)

    def describe(self, why: str) -> str:
        rc = self.proc.poll()
        return (f"{why}\n--- process {self.name!r} (pid {self.proc.pid}, "
                f"ROS_DOMAIN_ID={self.domain}, exit code {rc}) ---\n"
                f"command: {' '.join(self.cmd)}\n--- output ---\n"
                f"{self.output}\n--- end of {self.name!r} ---")

    def wait_for_line(self, pattern: str, timeout: float = 30.0) -> str:
        """First output line matching regex ``pattern``; AssertionError on exit or timeout."""
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout
        seen = 0
        with self._cond:
            while True:
                for line in self._lines[seen:]:
                    if regex.search(line):
                        return line
                seen = len(self._lines)
                if self._eof:
                    raise AssertionError(
                        self.describe(f"{self.name} exited before printing /{pattern}/"))
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(
                        self.describe(f"no /{pattern}/ from {self.name} within {timeout} s"))
                self._cond.wait(min(left, 0.5))

    def wait(self, timeout: float = 30.0, check: bool = True, done: str | None = None,
             teardown: float = 20.0) -> str:
        """Wait for exit; returns the output. With check, a non-zero exit or timeout raises.

        ``done``: a regex of the command's verdict (``ros2 lifecycle set`` prints
        "Transitioning successful"). A command that printed its verdict and then has not
        exited ``teardown`` s later hangs in its own DDS teardown (Fast DDS destruction,
        eProsima/Fast-DDS#6193; the ``ros2`` CLI is upstream code, our nodes bound theirs
        with tmgwr_common.native_exit). It is stopped, :attr:`hung_after_verdict` is set,
        a warning names it, and the output counts as its answer."""
        self.hung_after_verdict = False
        regex = re.compile(done, re.M) if done else None
        deadline = time.monotonic() + timeout
        verdict_at = None
        while self.proc.poll() is None:
            now = time.monotonic()
            if regex is not None and regex.search(self.output):
                verdict_at = verdict_at or now
                if now - verdict_at > teardown:
                    self.stop()
                    self.hung_after_verdict = True
                    warnings.warn(f"{self.name} printed its verdict, then hung over "
                                  f"{teardown} s in its teardown; stopped", stacklevel=2)
                    return self.output
            if now > deadline:
                self.stop()
                raise AssertionError(
                    self.describe(f"{self.name} did not exit within {timeout} s"))
            time.sleep(0.1)
        self._reader.join(timeout=5)
        if check and self.proc.returncode != 0:
            raise AssertionError(self.describe(f"{self.name} exited with {self.proc.returncode}"))
        return self.output

    def running(self) -> bool:
        return self.proc.poll() is None

    def stop(self, grace: float = 5.0) -> int | None:
        """SIGINT (rclpy shuts down cleanly), then SIGTERM, then SIGKILL, to the process group."""
        from tmgwr_agent.graph.supervisor import stop_process_group
        stop_process_group(self.proc, grace, 3.0, 3.0)
        self._reader.join(timeout=5)
        return self.proc.returncode

    def __enter__(self) -> 'RosProcess':
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def _python() -> str:
    return str(VENV_PYTHON) if VENV_PYTHON.exists() else sys.executable


def spawn_python(code: str, *args: str, domain: int, name: str = "python",
                 env: Mapping[str, str] | None = None) -> RosProcess:
    """Run ``python -c code args...`` in the ROS environment of ``domain``."""
    return RosProcess([_python(), "-u", "-c", code, *args], ros_env(domain, env), name=name)


def spawn_module(module: str, *args: str, domain: int, name: str = "",
                 env: Mapping[str, str] | None = None) -> RosProcess:
    """Run ``python -m module args...`` (modules resolve to the source trees)."""
    return RosProcess([_python(), "-u", "-m", module, *args], ros_env(domain, env),
                      name=name or module.rsplit(".", 1)[-1])


def ros2_run(package: str, executable: str, *args: str, domain: int, name: str = "",
             env: Mapping[str, str] | None = None) -> RosProcess:
    """Start what ``ros2 run package executable args...`` starts (the colcon-installed script)."""
    path = ROOT / "install" / package / "lib" / package / executable
    if not path.is_file():
        raise FileNotFoundError(f"{path} missing: is {package}/{executable} declared in setup.py "
                                f"and the workspace built (tools/bootstrap.sh)?")
    return RosProcess([str(path), *args], ros_env(domain, env), name=name or executable)


def stop_all(processes: Iterable[RosProcess]) -> None:
    for p in processes:
        p.stop()


def graph_up_pids(up: RosProcess, timeout: float = 120.0) -> dict[str, int]:
    """The pid of each process ``./tmgwr up`` started, from its ``graph up in
    ROS_DOMAIN_ID=...`` line (waited for)."""
    line = up.wait_for_line(r"^graph up in ROS_DOMAIN_ID=", timeout=timeout)
    return {name: int(pid) for name, pid in re.findall(r"(\w+) \(pid (\d+)\)", line)}


def parse_json_line(output: str, prefix: str):
    """The JSON value after ``prefix`` on the last output line starting with it."""
    for line in reversed(output.splitlines()):
        if line.startswith(prefix):
            return json.loads(line[len(prefix):])
    raise AssertionError(f"no line starting with {prefix!r} in output:\n{output}")


def unexpected_errors(output: str) -> list[str]:
    """Output lines that look like DDS / rcl errors, minus the known harmless ones."""
    bad = []
    output = re.sub(r"\x1b\[[0-9;]*m", "", output)     # Fast DDS colours its log lines
    for line in output.splitlines():
        if re.search(r"\b(Error|ERROR|XMLPARSER|Traceback)\b", line) and \
                not any(h.search(line) for h in HARMLESS_OUTPUT):
            bad.append(line)
    return bad


# --------------------------------------------------------------------------- the ros2 CLI
def ros2_command() -> str | None:
    """The real ``ros2`` command (installed into .venv by .ci/run from ../shared/ros2-tools),
    or None."""
    import shutil
    path = ROOT / ".venv" / "bin" / "ros2"
    return str(path) if path.exists() else shutil.which("ros2", path=base_env().get("PATH"))


def require_ros2() -> str:
    """:func:`ros2_command`, or skip the test saying why."""
    import pytest
    ros2 = ros2_command()
    if ros2 is None:
        pytest.skip("no `ros2` command here (../shared/ros2-tools not installed)")
    return ros2


def ros2_cli(*args: str, domain: int, name: str = "",
             env: Mapping[str, str] | None = None) -> RosProcess:
    """``ros2 ARGS...`` (the real command line) in the ROS environment of ``domain``."""
    return RosProcess([require_ros2(), *args], ros_env(domain, env),
                      name=name or "ros2 " + " ".join(args[:2]))
