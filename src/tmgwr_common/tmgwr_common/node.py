"""What every node of the graph shares: QoS profiles, parameters, flat arrays, main().

* QoS (chosen on purpose):
  - :data:`STEP_QOS` for the per-step ring (observation, features, state, motivation,
    action): reliable (a lost message would stall the lockstep ring until the simulator
    resends), volatile (a late joiner must not replay old steps), keep-last
    :data:`STEP_DEPTH` (lockstep has one message in flight, but a reliable keep-last
    writer drops a sample a starved bystander reader, the recorder, has not acknowledged
    once its history is full: the depth is how long such a reader may be starved of CPU
    without losing a step; it costs only memory and never slows the ring).
  - :data:`LATCHED_QOS` for state a late joiner needs at once (map, markers, grid, goal):
    reliable, transient local, keep-last 1 (only the newest snapshot matters).
  - :data:`SENSOR_QOS` for the pose stream: best effort keep-last 1 (a viewer wants the
    newest pose; a dropped one is harmless).
* Parameters: :func:`declare_parameters` turns the core's config dataclasses (and the
  nodes' own :class:`~tmgwr_common.params.Param` tuples) into ROS 2 parameters with a
  ParameterDescriptor (description, type, range) and the spec's default; every value is
  then checked by the core's own rule, so an invalid value stops the node at start with
  the parameter's name, and so does a name that no node of the graph knows.
* Arrays: per-step messages carry flat numeric arrays; :func:`f64` etc. build the
  ``array.array`` rclpy stores from a numpy array in one memcpy, :func:`np_f64` etc. read
  them back without a Python loop (from rclpy's arrays or :mod:`tmgwr_common.cdr`'s).
* Per-step messages: :func:`subscribe_decoded` takes them serialized and reads them with
  :mod:`tmgwr_common.cdr`; the nodes publish the bytes that module writes.
* :func:`run`: the Jazzy ``main()`` idiom (init, spin an executor (:func:`make_executor`), shutdown
  hook, destroy, try_shutdown), exiting 2 with the error when the node cannot start. SIGINT
  and SIGTERM (:class:`StopSignals`) only ask the loop to stop, so Ctrl-C ends every node
  with exit code 0 and no traceback.
"""

from __future__ import annotations

# first: in a node's own process the stop request is installed before the imports below
from tmgwr_common.stop import STOP, StopSignals, started_by_ros2_run  # noqa: F401

# isort: split
import array
import faulthandler
import gc
import math
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

# ----------------------------------------------------------------------------- QoS
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

from tmgwr_common.params import (
    Config,
    Param,
    ParamError,
    graph_parameter_names,
    make_config,
    read_params_file,
    specs,
    unknown_name_message,
)

#: History of the per-step topics, writers and readers (issue 24: with 10, a recorder
#: starved of CPU beside a busy-loop load lost whole runs of steps on every topic).
STEP_DEPTH = 1000
STEP_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=STEP_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                        reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE)


# ----------------------------------------------------------------------------- parameters
#: Options every node of the graph is created with (``Node(name, **NODE_OPTIONS)``): its
#: parameter overrides (``--params-file``, ``-p``, launch) are declared at once, so
#: :func:`declare_parameters` sees every name it was given (public rclpy API) and can
#: refuse one that no node of the graph knows.
NODE_OPTIONS = {"automatically_declare_parameters_from_overrides": True}

#: Parameters rclpy itself declares or reads on every node.
ROS_PARAMETERS = ("use_sim_time", "start_type_description_service")
ROS_PARAMETER_PREFIXES = ("qos_overrides.",)


def descriptor(p: Param):
    """A read-only ParameterDescriptor with the Param's description, type and range.

    ROS ranges are closed; an open bound (e.g. ``(0, 1]``) is stated in the description
    and enforced by :meth:`Param.check` right after declaration.
    """
    from rcl_interfaces.msg import (
        FloatingPointRange,
        IntegerRange,
        ParameterDescriptor,
        ParameterType,
    )
    d = ParameterDescriptor(name=p.name, description=p.description, read_only=True)
    if p.choices is not None:
        d.type = ParameterType.PARAMETER_STRING
        d.additional_constraints = "one of: " + ", ".join(p.choices)
    elif isinstance(p.default, bool):
        d.type = ParameterType.PARAMETER_BOOL
    elif isinstance(p.default, tuple):
        d.type = ParameterType.PARAMETER_STRING_ARRAY
    elif isinstance(p.default, str):
        # free-form text (paths, names): `-p goal:=2` arrives as an integer; accept it
        d.dynamic_typing = True
    elif p.integer:
        d.type = ParameterType.PARAMETER_INTEGER
        lo = -2 ** 63 if p.low is None else int(p.low) + (1 if p.low_open else 0)
        hi = 2 ** 63 - 1 if p.high is None else int(p.high) - (1 if p.high_open else 0)
        d.integer_range = [IntegerRange(from_value=lo, to_value=hi, step=0)]
        d.additional_constraints = f"integer in {p.range_text()}"
    else:
        d.type = ParameterType.PARAMETER_DOUBLE
        big = sys.float_info.max
        d.floating_point_range = [FloatingPointRange(
            from_value=-big if p.low is None else float(p.low),
            to_value=big if p.high is None else float(p.high), step=0.0)]
        d.additional_constraints = f"in {p.range_text()}"
    return d


def declare_parameters(node, *groups: type[Config] | Iterable[Param]):
    """Declare the parameters of ``groups`` on ``node`` (created with
    :data:`NODE_OPTIONS`), each with its descriptor; returns, per group, the config (for
    a Config class) or the dict of checked values (for a Param tuple), a single result
    for a single group.

    A value comes from ``-p name:=value`` or a ``--params-file``, else it is the spec's
    default. An invalid value raises ParamError naming it. Then every other name the node
    was given is checked: one that belongs to another node of the graph (a ``/**`` file is
    shared by all of them) is dropped from this node, one that no node knows is refused,
    naming the nearest known name and the parameter file that holds it.
    """
    where = f"node '{node.get_name()}'"
    results = []
    declared: set[str] = set()
    for group in groups:
        values = {p.name: _declare(node, p, where) for p in specs(group)}
        declared.update(values)
        results.append(make_config(group, values, where) if isinstance(group, type)
                       else values)
    _drop_foreign_parameters(node, declared, where)
    return results[0] if len(results) == 1 else tuple(results)


def _declare(node, p: Param, where: str) -> Any:
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
    if node.has_parameter(p.name):       # declared from its override: add the descriptor
        node.undeclare_parameter(p.name)
    try:
        param = node.declare_parameter(p.name, p.check(p.default), descriptor(p))
    except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
        raise ParamError(f"{where}: invalid parameter '{p.name}': {exc}") from None
    return p.check(param.value, where)


def _drop_foreign_parameters(node, declared: set[str], where: str) -> None:
    given = [n for n in node.list_parameters([], 0).names
             if n not in declared and n not in ROS_PARAMETERS
             and not n.startswith(ROS_PARAMETER_PREFIXES)]
    if not given:
        return
    known = graph_parameter_names() | declared
    for name in given:
        if name not in known:
            files = [str(f) for f in params_files(sys.argv) if _holds(f, name)]
            origin = f"set in {', '.join(files)}" if files else ""
            raise ParamError(unknown_name_message(name, known, where, origin))
        node.undeclare_parameter(name)   # another node's parameter: not this node's to show


def params_files(argv: Sequence[str]) -> list[Path]:
    """The ``--params-file`` arguments of the ROS arguments in ``argv``."""
    files, in_ros = [], False
    for i, a in enumerate(argv):
        if a == "--ros-args":
            in_ros = True
        elif a == "--":
            in_ros = False
        elif in_ros and a == "--params-file" and i + 1 < len(argv):
            files.append(Path(argv[i + 1]))
    return files


def _holds(path: Path, name: str) -> bool:
    try:
        return any(name in values for values in read_params_file(path).values())
    except ParamError:
        return False


# ----------------------------------------------------------------------------- arrays
def f64(a) -> array.array:
    return array.array("d", np.ascontiguousarray(a, dtype=np.float64).tobytes())


def i32(a) -> array.array:
    return array.array("i", np.ascontiguousarray(a, dtype=np.int32).tobytes())


def u8(a) -> array.array:
    return array.array("B", np.ascontiguousarray(a, dtype=np.uint8).tobytes())


def subscribe_decoded(node, msg_class, topic: str, callback: Callable[[Any], None], qos,
                      **kwargs):
    """Subscribe ``callback`` to ``topic`` as rclpy delivers serialized messages
    (``raw=True``), handing it the fields read by :mod:`tmgwr_common.cdr` instead of an
    rclpy message object (docs/benchmarks.md: the conversion costs more than the step)."""
    return node.create_subscription(msg_class, topic,
                                    decoded(msg_class, callback, node.get_logger().warning),
                                    qos, raw=True, **kwargs)


def decoded(msg_class, callback: Callable[[Any], None],
            warn: Callable[[str], None]) -> Callable[[bytes], None]:
    """The raw callback of :func:`subscribe_decoded`: ``callback(fields)`` for each
    serialized message; bytes that are not a ``msg_class`` (a publisher of another layout
    under the same type name) are dropped, said at most every 10 s, and the node runs on."""
    from tmgwr_common.cdr import codec
    read = codec(msg_class).read
    said = [-math.inf]

    def handler(data: bytes) -> None:
        try:
            fields = read(data)
        except ValueError as exc:
            now = time.monotonic()
            if now - said[0] >= 10.0:
                said[0] = now
                warn(f"dropped {len(data)} bytes on a {msg_class.__name__} topic: {exc}")
            return
        callback(fields)
    return handler


def np_f64(a) -> np.ndarray:
    """A writable float64 copy of a message array (numba kernels take writable arrays)."""
    return np.frombuffer(a, dtype=np.float64).copy()


def np_i64(a) -> np.ndarray:
    return np.frombuffer(a, dtype=np.int32).astype(np.int64)


def np_bool(a) -> np.ndarray:
    return np.frombuffer(a, dtype=np.uint8).astype(bool)


# ----------------------------------------------------------------------------- timing
class CallbackTimer:
    """Time spent in a node's per-step callback (for 'where the time goes'): wall time,
    and the thread's CPU time (the difference is time the OS gave to other processes)."""

    def __init__(self):
        self.n = 0
        self.total = 0.0
        self.cpu = 0.0
        self.pub = 0.0
        self._t0 = self._c0 = 0.0

    def __enter__(self):
        self._t0 = time.perf_counter()
        self._c0 = time.thread_time()
        return self

    def __exit__(self, *exc):
        self.total += time.perf_counter() - self._t0
        self.cpu += time.thread_time() - self._c0
        self.n += 1

    def publish(self, publisher, msg) -> None:
        """publisher.publish(msg), its wall time counted apart (conversion to C,
        serialization and the middleware's write)."""
        t0 = time.perf_counter()
        publisher.publish(msg)
        self.pub += time.perf_counter() - t0

    def summary(self) -> str:
        k = 1e6 / self.n if self.n else 0.0
        return (f"{self.n} step callbacks, mean {k * self.total:.0f} us, total "
                f"{self.total:.2f} s, cpu mean {k * self.cpu:.0f} us, of which publish "
                f"{k * self.pub:.0f} us")


# ----------------------------------------------------------------------------- main
EXECUTORS = ("single", "events")


def make_executor():
    """The executor every node spins, chosen by ``TMGWR_EXECUTOR`` (default ``events``,
    measured faster here).

    ``single``: rclpy's SingleThreadedExecutor (rebuilds its wait set in Python on every
    spin; the parameter and type-description services of a node are part of it).
    ``events``: rclpy.experimental.EventsExecutor (C++ event queue; Jazzy ships it as
    experimental).
    """
    import os
    kind = os.environ.get("TMGWR_EXECUTOR", "events")
    if kind not in EXECUTORS:
        raise ParamError(f"TMGWR_EXECUTOR={kind!r}: expected one of {list(EXECUTORS)}")
    if kind == "events":
        from rclpy.experimental import EventsExecutor
        return EventsExecutor()
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor()


def wait_for_acknowledgments(node, timeout: float = 1.0) -> bool:
    """Wait (at most ``timeout`` s in all) until every reliable subscriber acknowledged what
    ``node``'s publishers sent. A DataWriter destroyed with samples in flight drops them: a
    subscriber that had not yet received the node's last message (the recorder, busy or
    late under load) never gets it. True when everything was acknowledged."""
    from rclpy.duration import Duration
    deadline = time.monotonic() + timeout
    done = True
    for pub in list(node.publishers):
        left = deadline - time.monotonic()
        try:
            done = pub.wait_for_all_acked(Duration(nanoseconds=max(0, int(left * 1e9)))) \
                and done
        except Exception:  # noqa: BLE001 -- a publisher already destroyed, a context gone
            pass
    return done


#: Seconds the DDS teardown after a node's end (acknowledgments, destroy_node,
#: rclpy.shutdown; well under 1 s normally) may take before the process exits without it.
TEARDOWN_LIMIT = 3.0
#: Seconds after TEARDOWN_LIMIT at which the C library's own timers (:mod:`native_exit`)
#: end a process whose hung teardown holds the GIL, so that no Python thread can run (the
#: sum stays under the 5 s ``ros2 launch`` waits after a SIGINT before its SIGTERM).
NATIVE_GRACE = 1.0


def guard_teardown(name: str, code: int, limit: float = TEARDOWN_LIMIT,
                   grace: float = NATIVE_GRACE) -> Callable[[], None]:
    """Bound the teardown that follows a node's end; returns the call that disarms it.

    The node's state is saved by then (:func:`end_node`); what is left is the middleware's.
    Fast DDS can hang there for good (a destruction deadlock: eProsima/Fast-DDS#6193; seen
    here inside ``destroy_node`` after a Ctrl-C). If the teardown takes longer than
    ``limit`` s, the process says so, prints where each thread was and exits with the
    node's own ``code``: from a Python thread when the interpreter is free; else (the hung
    call holds the GIL, as rclpy's calls into the middleware do) the interpreter-free
    dump of :mod:`faulthandler` prints the Python threads and the C library's timers of
    :mod:`tmgwr_common.native_exit` print the reason and exit with ``code``, ``grace`` s
    after the limit. Without those timers (not Linux) faulthandler's watchdog exits, with
    code 1."""
    from tmgwr_common import native_exit

    def say(late: float, how: str) -> str:
        return (f"[{name}] DDS teardown did not finish within {late:.1f} s of the node's end "
                f"(its state is saved): exiting with code {code} without it{how}")

    def cut():
        print(say(limit, "; the threads were at:"), file=sys.stderr, flush=True)
        faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
        sys.stdout.flush()
        os._exit(code)

    sys.stdout.flush()
    sys.stderr.flush()
    timer = threading.Timer(limit, cut)
    timer.daemon = True
    timer.start()
    try:
        cancel_native = native_exit.arm(
            limit + grace, code, say(limit + grace / 2, " (a C call holds the Python "
                                     "interpreter; its threads follow on stderr)"),
            say_before=grace / 2)
        faulthandler.dump_traceback_later(limit + grace * 0.6, exit=False)
    except OSError:
        cancel_native = None
        faulthandler.dump_traceback_later(limit + grace, exit=True)

    def disarm():
        timer.cancel()
        faulthandler.cancel_dump_traceback_later()
        if cancel_native is not None:
            cancel_native()
    return disarm


def end_node(node) -> None:
    """A node's end once spinning stopped: a managed (lifecycle) node takes its ``shutdown``
    transition (:func:`tmgwr_common.lifecycle.end`: its ``on_shutdown(state)`` runs), any
    other node runs its ``on_shutdown()`` hook when it has one. Raises when that failed."""
    from rclpy.lifecycle import LifecycleNodeMixin
    if isinstance(node, LifecycleNodeMixin):
        from tmgwr_common.lifecycle import end
        end(node)
        return
    hook = getattr(node, "on_shutdown", None)
    if hook is not None:
        hook()


def spin_until(executor, done: Callable[[], bool], ok_period: float = 0.1) -> None:
    """``executor.spin_once()`` until ``done()`` or the context is shut down.

    ``rclpy.ok()`` is asked at most every ``ok_period`` s, not after every callback: it
    takes a lock that the EventsExecutor's own thread holds while it works, and waiting
    for it was a visible share of a composed graph's wall time when it was asked after
    every callback."""
    import rclpy
    next_ok = 0.0
    while not done():
        now = time.monotonic()
        if now >= next_ok:
            if not rclpy.ok():
                return
            next_ok = now + ok_period
        executor.spin_once(timeout_sec=0.2)


def freeze_startup_objects() -> None:
    """Exclude every object alive now (modules, numba's compiled kernels, the node) from
    the garbage collector's future passes (``gc.freeze``, Python's documented way to keep
    long-lived startup objects out of collections). A full collection of a node's ~70,000
    startup objects took 50-70 ms here, a stall of the whole lockstep ring each time one
    ran; after the freeze a collection visits only what was made since."""
    gc.collect()
    gc.freeze()


def run(factory: Callable[[], Any], name: str, args=None,
        executor_factory: Callable[[], Any] | None = None) -> int:
    """Init rclpy, build the node, spin it; returns the exit code. A node that cannot
    start (its constructor raises ParamError, ValueError or OSError) ends the process with
    code 2 right after its bounded teardown (:func:`guard_teardown`).

    A node may define ``on_shutdown()`` (called once after spinning stops, for any reason:
    Ctrl-C or SIGTERM (:class:`StopSignals`), ``rclpy.shutdown``; a lifecycle node takes its
    ``shutdown`` transition instead, :func:`end_node`) and ``finished`` (spinning
    stops when it becomes true). ``executor_factory`` overrides :func:`make_executor`.
    Before the node is destroyed its reliable subscribers get (a bounded time) to
    acknowledge its last messages (:func:`wait_for_acknowledgments`).
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    args = list(args if args is not None else sys.argv)
    stop = STOP.install()
    if stop.received:
        print(f"[{name}] stopped ({stop.received}) before it started", flush=True)
        stop.ignore_from_now()
        return 0
    try:
        for f in params_files(args):     # rcl's own parse error names neither file nor line
            read_params_file(f)
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except (ParamError, RuntimeError) as exc:    # RCLError is a RuntimeError
        print(f"[{name}] cannot start: {exc}", file=sys.stderr, flush=True)
        return 2
    node = None
    code = 0
    refused = False
    try:
        try:
            node = factory()
        except (ParamError, ValueError, OSError) as exc:
            print(f"[{name}] cannot start: {exc}", file=sys.stderr, flush=True)
            code, refused = 2, True
            return code
        executor = (executor_factory or make_executor)()
        executor.add_node(node)
        freeze_startup_objects()
        try:
            # spin() is spin_once() in a loop; looping ourselves lets a node finish.
            spin_until(executor, lambda: stop.received or getattr(node, "finished", False))
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            executor.shutdown(timeout_sec=0.5)
        code = int(getattr(node, "exit_code", 0))
    finally:
        if node is not None:
            try:
                end_node(node)
            except Exception as exc:  # noqa: BLE001 -- still shut down cleanly
                print(f"[{name}] shutdown hook failed: {exc}", file=sys.stderr, flush=True)
                code = code or 1
        disarm = guard_teardown(name, code)
        if node is not None:
            wait_for_acknowledgments(node)
            node.destroy_node()
        # A node whose constructor raised (a refused start) still holds its DDS entities
        # until a collection: destroyed here, under the guard and before the context
        # shuts down, not later by the interpreter's exit, where nothing bounds a hang.
        gc.collect()
        rclpy.try_shutdown()
        if refused:
            # Nothing ran and nothing is to be saved: the process ends here, still under
            # the guard. The interpreter's own exit would destroy whatever the refused
            # constructor left (DDS entities it still holds, a thread it started), and
            # nothing bounds that (CI: maze_sim said why it could not start, then never
            # exited, and ros2 launch waited for it).
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
        disarm()
        stop.ignore_from_now()
    return code
