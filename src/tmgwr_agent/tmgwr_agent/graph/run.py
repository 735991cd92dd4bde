"""One run of the graph: the supervised node processes plus an in-process observer.

:class:`GraphRun` is what ``./tmgwr up``, the demo and the bench share: it decides where
to record, starts the recorder and the five nodes (:mod:`.supervisor`), and runs a small
rclpy node in this process with the :class:`~tmgwr_agent.episodes.EpisodeMonitor` on the
Observation topic (created before the nodes start, so it sees the run from its first step)
and clients for the graph's services. The caller drives it with :meth:`GraphRun.spin_once`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Mapping

from tmgwr_agent.episodes import EpisodeMonitor
from tmgwr_agent.graph.clients import call, subscribe_monitor
from tmgwr_agent.graph.output import say
from tmgwr_agent.graph.supervisor import (
    GraphError,
    GraphSupervisor,
    ManagedProcess,
    default_run_dir,
    graph_specs,
    install_stop_handlers,
)


def describe_exit(p: ManagedProcess) -> str:
    return p.describe(f"node '{p.label}' died (exit code {p.returncode()})")


class GraphRun:
    def __init__(self, maze: str | None = None, seed: int | None = None,
                 goal: str | None = None, world: str | None = None, record: bool = True,
                 record_dir: str | Path | None = None, echo=True,
                 node_params: Mapping[str, Mapping[str, object]] | None = None,
                 params_files=(), run_dir: str | Path | None = None,
                 namespace: str = ""):
        """``run_dir``: the run's directory (maps, checkpoints; default: the recording's);
        a resumed run records into a new bag inside it (graph.resume)."""
        self.record_dir: Path | None = None
        if record:
            self.record_dir = Path(record_dir) if record_dir else default_run_dir()
        self.run_dir = Path(run_dir) if run_dir is not None else self.record_dir
        self.namespace = "/" + namespace.strip("/")
        self.specs = graph_specs(maze=maze, seed=seed, goal=goal, world=world,
                                 record_dir=self.record_dir,
                                 node_params=node_params, params_files=params_files,
                                 run_dir=self.run_dir, namespace=namespace)
        self.supervisor = GraphSupervisor(self.specs, env=os.environ, echo=echo)
        self.monitor = EpisodeMonitor()
        self.node = None
        self.executor = None

    def start(self, on_stop_signal=None, ready_timeout: float = 90.0) -> None:
        """Observer first, then the processes; ``on_stop_signal`` takes over SIGINT and
        SIGTERM once everything is up (before that Ctrl-C aborts the start)."""
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        if self.record_dir is not None:
            self.record_dir.parent.mkdir(parents=True, exist_ok=True)
        # our own signal handling: the nodes must be stopped in order, not this context first
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("tmgwr_graph_observer", namespace=self.namespace)
        subscribe_monitor(self.node, self.monitor)
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        try:
            self.supervisor.start(ready_timeout=ready_timeout)
        except BaseException:
            self._shutdown_ros()
            raise
        if on_stop_signal is not None:
            install_stop_handlers(on_stop_signal)

    def start_or_exit_code(self, tool: str, on_stop_signal=None) -> int | None:
        """:meth:`start`, saying why on stderr when it fails: None when the graph is up,
        else the exit code for ``tool`` (1: the graph did not start, 130: Ctrl-C)."""
        import sys
        try:
            self.start(on_stop_signal=on_stop_signal)
        except GraphError as exc:
            say(f"{tool}: the graph did not start: {exc}", sys.stderr)
            return 1
        except KeyboardInterrupt:
            say(f"{tool}: interrupted during start-up; nodes stopped", sys.stderr)
            return 130
        return None

    def spin_once(self, timeout: float = 0.1) -> None:
        self.executor.spin_once(timeout_sec=timeout)

    def call(self, srv_type, name: str, request, timeout: float = 10.0):
        """A service call from the observer node (its executor completes the future);
        ``name`` resolves in the graph's namespace (``topics.of_node`` for a private one)."""
        return call(self.node, srv_type, name, request, timeout, executor=self.executor)

    def _shutdown_ros(self) -> None:
        import rclpy
        if self.executor is not None:
            self.executor.shutdown(timeout_sec=0.5)
            self.executor = None
        if self.node is not None:
            self.node.destroy_node()
            self.node = None
        rclpy.try_shutdown()

    def stop(self) -> dict[str, int | None]:
        """Stop the nodes in reverse order (recorder last), then the observer."""
        codes = self.supervisor.stop()
        self._shutdown_ros()
        return codes
