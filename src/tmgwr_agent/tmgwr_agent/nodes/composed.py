"""``ros2 run tmgwr_agent composed``: the five nodes (and optionally the recorder) in one
process, on one executor, as a component container runs components.

rclpy cannot load C++ components, so this entry point does what a container would: it
builds the very node classes the five executables build (``maze_sim``,
``sensory_preprocessor``, ``map_learner``, ``motivation_estimator``, ``action_selector``,
with ``--record`` the ``recorder`` first), with their own names, parameters, topics and
services, and spins them all on one executor. Tools see the same graph as with five
processes (``ros2 node list``, the topics of docs/graph.md "Topics and services"); only the
messages no longer cross a process boundary (one DDS participant: Fast DDS delivers them
inside the process, no socket).

Parameters: the ROS arguments are the context's, so they reach every node of the process.
``-p name:=value`` is given to every node that declares ``name`` (the others drop a name
another node of the graph declares, as with a shared ``/**`` file); ``-p node:name:=value``
(rcl's node-qualified form) or a ``--params-file`` section per node reaches one node only::

    composed --ros-args -p maze_sim:seed:=0 -p action_selector:seed:=1 -p goal:=2
    composed --record --ros-args -p recorder:output_dir:=runs/x

Executor: ``--executor single`` (rclpy's SingleThreadedExecutor) or ``events`` (the
experimental EventsExecutor), default ``TMGWR_EXECUTOR`` as for every node
(:func:`tmgwr_common.node.make_executor`). The process stops when maze_sim finishes
(``exit_when_done``) with its exit code, on Ctrl-C or SIGTERM (which, as in every node's
process, only ask the loop to stop: :class:`tmgwr_common.node.StopSignals`); every node's
``on_shutdown`` then runs (the learner, a managed node, takes its ``shutdown`` transition
and saves its map; the recorder finishes its bag last).
"""

from __future__ import annotations

import argparse
import gc
import sys
from typing import Any, Callable

from tmgwr_common.node import (
    EXECUTORS,
    STOP,
    end_node,
    freeze_startup_objects,
    guard_teardown,
    make_executor,
    params_files,
    spin_until,
)
from tmgwr_common.params import ParamError, read_params_file

NAME = "composed"


def node_factories(record: bool) -> list[tuple[str, Callable[[], Any]]]:
    """(name, class) of the nodes in start order: the recorder first (it subscribes before
    anything is published), the simulator last (its first observation finds the ring
    matched)."""
    from maze_sim.node import MazeSimNode
    from tmgwr_agent.nodes.action_selector import ActionSelectorNode
    from tmgwr_agent.nodes.map_learner import MapLearnerNode
    from tmgwr_agent.nodes.motivation_estimator import MotivationEstimatorNode
    from tmgwr_agent.nodes.sensory_preprocessor import SensoryPreprocessorNode

    out: list[tuple[str, Callable[[], Any]]] = []
    if record:
        from tmgwr_agent.nodes.recorder import Recorder
        out.append(("recorder", Recorder))
    out += [("sensory_preprocessor", SensoryPreprocessorNode),
            ("map_learner", MapLearnerNode),
            ("motivation_estimator", MotivationEstimatorNode),
            ("action_selector", ActionSelectorNode),
            ("maze_sim", MazeSimNode)]
    return out


def _executor(kind: str | None):
    if kind is None:
        return make_executor()
    if kind == "events":
        from rclpy.experimental import EventsExecutor
        return EventsExecutor()
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor()


class _Aside:
    """One node spun by a SingleThreadedExecutor in a thread of its own."""

    def __init__(self, node):
        import threading

        from rclpy.executors import SingleThreadedExecutor
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(node)
        self.running = True
        self.thread = threading.Thread(target=self._spin, name="recorder", daemon=True)
        self.thread.start()

    def _spin(self) -> None:
        import rclpy
        from rclpy.executors import ExternalShutdownException
        try:
            while self.running and rclpy.ok():
                self.executor.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:
            pass

    def stop(self) -> None:
        self.running = False
        self.thread.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=0.5)


def _recorder_aside(executor, nodes) -> _Aside | None:
    """rclpy 7.1.6's EventsExecutor fails on a raw subscription whose callback takes the
    message info (``SystemError: null argument to internal routine``), which is how the
    recorder gets its timestamps: with that executor the recorder spins on its own
    SingleThreadedExecutor, in its own thread (its writer is still used by one thread)."""
    from rclpy.executors import SingleThreadedExecutor
    recorder = dict(nodes).get("recorder")
    if recorder is None or isinstance(executor, SingleThreadedExecutor):
        return None
    return _Aside(recorder)


def run_composed(record: bool, executor_kind: str | None, args: list[str]) -> int:
    """init, build every node, spin them on one executor, shut down: the Jazzy main()
    idiom of :func:`tmgwr_common.node.run` for several nodes; exit code 2 when one cannot
    start (the nodes built so far are destroyed)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    stop = STOP.install()        # Ctrl-C / SIGTERM only ask the loop to stop (as one node)
    try:
        for f in params_files(args):
            read_params_file(f)
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except (ParamError, RuntimeError) as exc:
        print(f"[{NAME}] cannot start: {exc}", file=sys.stderr, flush=True)
        return 2
    nodes: list[tuple[str, Any]] = []
    code = 0
    try:
        for name, factory in node_factories(record):
            try:
                nodes.append((name, factory()))
            except (ParamError, ValueError, OSError) as exc:
                print(f"[{NAME}] cannot start {name}: {exc}", file=sys.stderr, flush=True)
                return 2
        executor = _executor(executor_kind)
        aside = _recorder_aside(executor, nodes)
        for name, node in nodes:
            if aside is None or name != "recorder":
                executor.add_node(node)
        print(f"{NAME} ready: {', '.join(n for n, _ in nodes)} in one process on one "
              f"{type(executor).__name__}"
              + (" (the recorder on a SingleThreadedExecutor thread of its own: rclpy's "
                 "EventsExecutor cannot run its raw subscriptions)" if aside else ""),
              flush=True)
        sim = nodes[-1][1]
        freeze_startup_objects()
        try:
            finishing = [n for _, n in nodes if hasattr(n, "finished")]
            spin_until(executor, lambda: stop.received or any(n.finished for n in finishing))
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            executor.shutdown(timeout_sec=0.5)
            if aside is not None:
                aside.stop()
        code = int(getattr(sim, "exit_code", 0))
    finally:
        for name, node in reversed(nodes):      # the simulator first, the recorder last
            try:
                end_node(node)                  # the learner: its shutdown transition
            except Exception as exc:  # noqa: BLE001 -- still shut the others down
                print(f"[{NAME}] {name}: shutdown hook failed: {exc}", file=sys.stderr,
                      flush=True)
                code = code or 1
            node.destroy_node()
        disarm = guard_teardown(NAME, code)
        gc.collect()        # a node whose constructor raised, as tmgwr_common.node.run does
        rclpy.try_shutdown()
        disarm()
        stop.ignore_from_now()
    return code


def main(args=None) -> None:
    argv = list(sys.argv if args is None else args)
    from rclpy.utilities import remove_ros_args
    ap = argparse.ArgumentParser(
        prog="composed", description=__doc__.split("\n\n")[1],
        epilog="ROS arguments follow --ros-args (parameters, --params-file, remapping).")
    ap.add_argument("--record", action="store_true",
                    help="also run the recorder in this process (its parameters: "
                         "-p recorder:output_dir:=DIR ...)")
    ap.add_argument("--executor", choices=EXECUTORS,
                    help="executor of the process (default: TMGWR_EXECUTOR, else events)")
    try:
        rest = remove_ros_args(argv)[1:]
    except RuntimeError as exc:          # RCLInvalidROSArgsError: a malformed -p rule
        print(f"[{NAME}] cannot start: {exc}", file=sys.stderr, flush=True)
        raise SystemExit(2) from None
    opts = ap.parse_args(rest)
    raise SystemExit(run_composed(opts.record, opts.executor, argv))


if __name__ == "__main__":
    main()
