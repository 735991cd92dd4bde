"""Start the node graph as separate processes, watch it, stop it cleanly.

What ``ros2 launch`` would do on a real install, for the pip-only environment (no
``launch`` package on PyPI): each node is the installed console script that ``ros2 run``
starts (``install/<pkg>/lib/<pkg>/<exe>``), given ``--ros-args --params-file FILE`` for
the user's parameter files (checked here first) and ``-p name:=value`` overrides.

* :meth:`GraphSupervisor.start` starts the processes in order (the recorder first, so it
  sees everything), waits for each to print a line containing ``ready``, and raises
  :class:`GraphError` with the process's output when one exits or stays silent.
* Each process's stdout and stderr are read by a thread, kept (the last lines, for error
  reports) and, with ``echo``, forwarded line by line prefixed with ``[name]``.
* :meth:`GraphSupervisor.dead` reports processes that exited while the graph runs.
* :meth:`GraphSupervisor.stop` stops them in reverse order: SIGINT (rclpy shuts down
  cleanly: the learner saves its map, the recorder closes its file), then SIGTERM, then
  SIGKILL after timeouts.

Children run in their own session (a terminal's Ctrl-C reaches only the supervisor, which
then stops them in order) and get SIGTERM from the kernel if the supervisor itself dies
(``PR_SET_PDEATHSIG``), so no node outlives it.
"""

from __future__ import annotations

import collections
import ctypes
import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable, Mapping, Sequence

from tmgwr_agent.graph.output import say
from tmgwr_common.params import check_params_file

READY = re.compile(r"\bready\b", re.IGNORECASE)
RECORDER_READY = re.compile(r"\bready\b|\brecording\b.* to ", re.IGNORECASE)

#: The five nodes of Fig. 1a in data-flow order (contract names: docs/graph.md).
GRAPH_NODES: tuple[tuple[str, str], ...] = (
    ("maze_sim", "maze_sim"),
    ("tmgwr_agent", "sensory_preprocessor"),
    ("tmgwr_agent", "map_learner"),
    ("tmgwr_agent", "motivation_estimator"),
    ("tmgwr_agent", "action_selector"),
)


#: The nodes that keep a checkpoint (tmgwr_common.checkpoint; docs/graph.md, Continuing a run).
CHECKPOINTED = ("maze_sim", "map_learner", "motivation_estimator", "action_selector")


class GraphError(RuntimeError):
    """A node could not be started or died; the message names it and shows its output."""


@dataclass
class NodeSpec:
    """One process of the graph: ``ros2 run <package> <executable> --ros-args ...``."""

    package: str
    executable: str
    params_files: Sequence[str | Path] = ()
    params: Mapping[str, object] = field(default_factory=dict)
    name: str = ""                       # label for output; default: the executable
    ready: re.Pattern = READY
    argv: Sequence[str] = ()             # a plain command instead of the package executable
    namespace: str = ""                  # ROS namespace (-r __ns:=...); "" = the root
    #: the spec a restart (graph.respawn) uses, given this one and the restart's number
    on_respawn: Callable[["NodeSpec", int], "NodeSpec"] | None = None

    @property
    def label(self) -> str:
        return self.name or self.executable

    def command(self) -> list[str]:
        if self.argv:
            return list(self.argv)
        cmd = [str(executable_path(self.package, self.executable))]
        ros_args: list[str] = []
        if self.namespace.strip("/"):
            ros_args += ["-r", f"__ns:=/{self.namespace.strip('/')}"]
        for f in self.params_files:
            ros_args += ["--params-file", str(f)]
        for key, value in self.params.items():
            ros_args += ["-p", f"{key}:={format_param(value)}"]
        return cmd + (["--ros-args", *ros_args] if ros_args else [])


def stop_process_group(proc: subprocess.Popen, sigint_timeout: float = 8.0,
                       sigterm_timeout: float = 4.0, sigkill_timeout: float = 5.0) -> int | None:
    """Stop a process started in its own session: SIGINT to its process group (rclpy
    shuts down cleanly), then SIGTERM, then SIGKILL, each after the previous one's timeout.
    Returns the exit code (None if even SIGKILL did not end it in time)."""
    for sig, timeout in ((signal.SIGINT, sigint_timeout), (signal.SIGTERM, sigterm_timeout),
                         (signal.SIGKILL, sigkill_timeout)):
        if proc.poll() is not None:
            break
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            continue
    return proc.poll()


def format_param(value: object) -> str:
    """A value as the ``-p name:=value`` syntax reads it (YAML)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        # quoted so that e.g. "1" or "true" stay strings and paths with ':' survive
        return "'" + value.replace("'", "''") + "'"
    return str(value)


def executable_path(package: str, executable: str) -> Path:
    """What ``ros2 run`` resolves: ``<prefix of package>/lib/<package>/<executable>``."""
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix
    try:
        prefix = Path(get_package_prefix(package))
    except PackageNotFoundError:
        raise GraphError(f"package '{package}' is not installed (AMENT_PREFIX_PATH="
                         f"{os.environ.get('AMENT_PREFIX_PATH', '')!r}); run tools/bootstrap.sh "
                         "and source tools/env.sh (./tmgwr does both)") from None
    path = prefix / "lib" / package / executable
    if not os.access(path, os.X_OK):
        raise GraphError(f"{path} missing: '{package} {executable}' is not built "
                         "(tools/bootstrap.sh --rebuild after adding a console script)")
    return path


def default_run_dir(root: str | Path | None = None) -> Path:
    """``runs/<UTC timestamp>/`` under the repository (or the current directory)."""
    base = Path(root) if root else Path(os.environ.get("TMGWR_ROOT", Path.cwd()))
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%SZ")
    path = base / "runs" / stamp
    n = 1
    while path.exists():                  # two runs in the same second
        n += 1
        path = base / "runs" / f"{stamp}-{n}"
    return path


try:   # resolved here, in the parent: the child only calls it between fork and exec
    _prctl = ctypes.CDLL("libc.so.6", use_errno=True).prctl
except (OSError, AttributeError):
    _prctl = None


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when the supervisor dies (PR_SET_PDEATHSIG)."""
    if _prctl is not None:
        _prctl(1, int(signal.SIGTERM))


class ManagedProcess:
    """A started node: its Popen, output reader thread, readiness and recent output."""

    def __init__(self, spec: NodeSpec, env: Mapping[str, str],
                 sink: Callable[[str], None] | None, keep: int = 200):
        self.spec = spec
        self.label = spec.label
        self.cmd = spec.command()
        self.ready = threading.Event()
        self.ready_at = 0.0                   # time.monotonic() of the ready line
        self.tail: collections.deque[str] = collections.deque(maxlen=keep)
        self._sink = sink
        self.proc = subprocess.Popen(
            self.cmd, env=dict(env), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True, errors="replace", bufsize=1,
            start_new_session=True, preexec_fn=_die_with_parent)
        self.pid = self.proc.pid
        self._reader = threading.Thread(target=self._read, name=f"out-{self.label}",
                                        daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            line = line.rstrip("\n")
            self.tail.append(line)
            if not self.ready.is_set() and self.spec.ready.search(line):
                self.ready_at = time.monotonic()
                self.ready.set()
            if self._sink is not None:
                self._sink(f"[{self.label}] {line}")

    def returncode(self) -> int | None:
        return self.proc.poll()

    def output(self) -> str:
        return "\n".join(self.tail)

    def describe(self, why: str) -> str:
        return (f"{why}\n  command: {' '.join(self.cmd)}\n  exit code: {self.proc.poll()}\n"
                f"  last output:\n    " + "\n    ".join(list(self.tail)[-30:] or ["(none)"]))

    def stop(self, sigint_timeout: float = 8.0, sigterm_timeout: float = 4.0) -> int | None:
        """SIGINT, then SIGTERM, then SIGKILL (to the process group) after the timeouts."""
        stop_process_group(self.proc, sigint_timeout, sigterm_timeout)
        self._reader.join(timeout=2.0)
        return self.proc.poll()


class GraphSupervisor:
    """Start, watch and stop a list of node processes (see the module docstring)."""

    def __init__(self, specs: Sequence[NodeSpec], env: Mapping[str, str] | None = None,
                 echo: bool | Callable[[str], None] = True):
        self.specs = list(specs)
        self.env = dict(os.environ if env is None else env)
        self.env.setdefault("PYTHONUNBUFFERED", "1")
        if echo is True:
            self._sink: Callable[[str], None] | None = _print_line
        elif echo is False:
            self._sink = None
        else:
            self._sink = echo
        self.processes: list[ManagedProcess] = []
        self.stopped: dict[str, int | None] = {}

    # ------------------------------------------------------------------ start
    def start(self, ready_timeout: float = 60.0, parallel: bool = True,
              wait_ready: bool = True) -> None:
        """Start every process and wait until each printed its ``ready`` line.

        With ``parallel`` all are started at once (discovery overlaps) and then awaited in
        order; otherwise each is awaited before the next starts. On failure everything
        started so far is stopped and GraphError raised.
        """
        try:
            for spec in self.specs:
                p = ManagedProcess(spec, self.env, self._sink)
                self.processes.append(p)
                if not parallel and wait_ready:
                    self._await_ready(p, ready_timeout)
            if parallel and wait_ready:
                deadline = time.monotonic() + ready_timeout
                for p in self.processes:
                    self._await_ready(p, max(0.1, deadline - time.monotonic()))
        except BaseException:
            self.stop()
            raise

    def _await_ready(self, p: ManagedProcess, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while not p.ready.wait(0.1):
            for q in self.processes:           # any process dying fails the start
                if q.returncode() is not None:
                    q._reader.join(timeout=2.0)
                    raise GraphError(q.describe(f"node '{q.label}' exited during start-up"))
            if time.monotonic() > deadline:
                raise GraphError(p.describe(f"node '{p.label}' printed no 'ready' line "
                                            f"within {timeout:.0f} s"))

    # ------------------------------------------------------------------ watch
    def dead(self) -> list[ManagedProcess]:
        """Processes that have exited (while they should run)."""
        return [p for p in self.processes if p.returncode() is not None]

    def pids(self) -> dict[str, int]:
        return {p.label: p.pid for p in self.processes}

    def process(self, label: str) -> ManagedProcess:
        for p in self.processes:
            if p.label == label:
                return p
        raise KeyError(label)

    # ------------------------------------------------------------------ stop
    def stop(self, sigint_timeout: float = 8.0) -> dict[str, int | None]:
        """Stop in reverse start order; returns each process's exit code."""
        for p in reversed(self.processes):
            if p.label not in self.stopped:
                self.stopped[p.label] = p.stop(sigint_timeout=sigint_timeout)
        return dict(self.stopped)

    def __enter__(self) -> "GraphSupervisor":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def _print_line(line: str) -> None:
    say(line)


# ---------------------------------------------------------------------- the graph itself
#: The nodes that declare ``world`` (tmgwr_common.params.WORLD_PARAM): the simulator hosts
#: it, the agent nodes take its senses (motor primitives, resolution).
WORLD_NODES = ("maze_sim", "sensory_preprocessor", "map_learner", "motivation_estimator",
               "action_selector")


def graph_specs(maze: str | None = None, seed: int | None = None, goal: str | None = None,
                world: str | None = None, record_dir: str | Path | None = None,
                node_params: Mapping[str, Mapping[str, object]] | None = None,
                params_files: Sequence[str | Path] = (),
                run_dir: str | Path | None = None,
                namespace: str = "") -> list[NodeSpec]:
    """The recorder (when ``record_dir``) and the five nodes, with parameter files and
    overrides. ``maze``, ``seed`` and ``goal`` are the simulator's (and, for the seed, the
    action selector's) parameters; ``world`` that of :data:`WORLD_NODES`; ``node_params``
    adds overrides per executable;
    ``params_files`` (ROS 2 parameter files, ``/**`` or per-node sections) go to every node
    of the five, checked first (a malformed file or an unknown name raises ParamError).
    Without them every node runs on its specs' defaults. ``run_dir`` (default
    ``record_dir``): the run's directory, for the learner's maps and the checkpoints of the
    nodes that keep one (``resume`` on: a node restarted with these parameters, or the
    graph started again on this directory, continues from its checkpoint). ``namespace``
    puts every node in that ROS namespace (``__ns:=``), so graphs run side by side in one
    domain."""
    node_params = node_params or {}
    if run_dir is None:
        run_dir = record_dir
    run_dir = Path(run_dir) if run_dir is not None else None
    files = [Path(f).expanduser().resolve() for f in params_files]
    for f in files:               # refused here, with file and line, not by each node
        check_params_file(f)
    specs: list[NodeSpec] = []
    if record_dir is not None:
        # The recorder logs "recording ... to DIR" once its writer is open.
        specs.append(NodeSpec("tmgwr_agent", "recorder", (),
                              {"output_dir": str(record_dir), **node_params.get("recorder", {})},
                              ready=RECORDER_READY, namespace=namespace,
                              on_respawn=_recorder_respawn))
    for package, exe in GRAPH_NODES:
        params: dict[str, object] = {}
        if exe == "maze_sim":
            if maze is not None:
                from maze_sim.maze import maze_file
                try:
                    params["maze"] = str(maze_file(maze).resolve())
                except FileNotFoundError as exc:
                    raise GraphError(f"--maze: {exc}") from None
            if goal is not None:
                params["goal"] = str(goal)
            if record_dir is not None:
                # the first step waits until the recorder has matched every ring publisher
                # (recorder_ready), then start_delay lets the ring's nodes match each other
                params["await_recorder"] = True
                params["start_delay"] = 1.0
        if exe == "map_learner" and run_dir is not None:
            params["map_dir"] = str(run_dir.resolve())             # the run's own maps
        if exe in CHECKPOINTED and run_dir is not None:
            params["checkpoint_dir"] = str(run_dir.resolve())
            params["resume"] = True
        if world is not None and exe in WORLD_NODES:
            params["world"] = str(world)
        if seed is not None and exe in ("maze_sim", "action_selector"):
            params["seed"] = int(seed)
        params.update(node_params.get(exe, {}))
        specs.append(NodeSpec(package, exe, files, params, namespace=namespace,
                              on_respawn=_resume_respawn if exe in CHECKPOINTED else None))
    return specs


def _recorder_respawn(spec: NodeSpec, n: int) -> NodeSpec:
    """A restarted recorder writes a new bag inside the killed one's directory (a bag is
    never appended to)."""
    out = Path(str(spec.params["output_dir"])) / f"respawned_{n}"
    return replace(spec, params={**spec.params, "output_dir": str(out)})


def _resume_respawn(spec: NodeSpec, n: int) -> NodeSpec:   # noqa: ARG001
    """A restarted node continues from its checkpoint (its own default directory when the
    run has none: ``up --no-record``); a restarted simulator steps at once (the recorder's
    subscriptions, what ``start_delay`` waits for, are already there)."""
    params = {**spec.params, "resume": True}
    if "start_delay" in params:
        params["start_delay"] = 0.0
    return replace(spec, params=params)


COMPOSED_READY = re.compile(r"\bcomposed ready\b")


def composed_specs(specs: Sequence[NodeSpec]) -> list[NodeSpec]:
    """The nodes of ``specs`` (:func:`graph_specs`) as one ``tmgwr_agent composed`` process
    (all on one executor, :mod:`tmgwr_agent.nodes.composed`): each node's overrides become
    node-qualified ``-p node:name:=value``, a recorder joins with ``--record``."""
    params = {f"{s.executable}:{k}": v for s in specs for k, v in s.params.items()}
    files = next((s.params_files for s in specs if s.params_files), ())
    cmd = NodeSpec("tmgwr_agent", "composed", files, params).command()
    if any(s.executable == "recorder" for s in specs):
        cmd.insert(1, "--record")

    def respawn(spec: NodeSpec, n: int) -> NodeSpec:
        again = [s.on_respawn(s, n) if s.on_respawn else s for s in specs]
        return replace(composed_specs(again)[0], on_respawn=spec.on_respawn)

    return [NodeSpec("tmgwr_agent", "composed", argv=cmd, ready=COMPOSED_READY,
                     on_respawn=respawn)]


def install_stop_handlers(callback: Callable[[], None]) -> None:
    """Turn SIGINT and SIGTERM into ``callback()`` (once; a second signal is ignored
    while the graph stops, so stopping in order is not cut short)."""
    fired = {"n": 0}

    def handler(signum, frame):           # noqa: ARG001
        fired["n"] += 1
        if fired["n"] == 1:
            callback()
        else:
            print("graph: stopping, please wait (nodes get SIGTERM/SIGKILL after timeouts)",
                  file=sys.stderr, flush=True)

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
