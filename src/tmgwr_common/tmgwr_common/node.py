"""What every node of the graph shares: QoS profiles, parameters, flat arrays, main().

* QoS (chosen on purpose):
  - :data:`STEP_QOS` for the per-step ring (observation, features, state, motivation,
    action): reliable (a lost message would stall the lockstep ring until the simulator
    resends), volatile (a late joiner must not replay old steps), keep-last 10 (lockstep
    has one message in flight; the depth only absorbs the simulator's resends).
  - :data:`LATCHED_QOS` for state a late joiner needs at once (map, markers, grid, goal):
    reliable, transient local, keep-last 1 (only the newest snapshot matters).
  - :data:`SENSOR_QOS` for the pose stream: best effort keep-last 1 (a viewer wants the
    newest pose; a dropped one is harmless).
* Parameters: :func:`declare_specs` turns the core's :class:`~tmgwr_common.params.Param`
  declarations into ROS 2 parameters with a ParameterDescriptor (description, type, range)
  whose defaults come from ``config/tmgwr_agent.yaml``; every value is then checked by the
  core's own rule, so an invalid value stops the node at start with the parameter's name.
* Arrays: per-step messages carry flat numeric arrays; :func:`f64` etc. build the
  ``array.array`` rclpy stores from a numpy array in one memcpy, :func:`np_f64` etc. read
  them back without a Python loop.
* :func:`run`: the Jazzy ``main()`` idiom (init, spin an executor (:func:`make_executor`), shutdown
  hook, destroy, try_shutdown), exiting 2 with the error when the node cannot start.
"""

from __future__ import annotations

import array
import sys
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from tmgwr_common.params import Param, ParamError, load_yaml

# ----------------------------------------------------------------------------- QoS
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSProfile,  # noqa: E402
                       ReliabilityPolicy)

STEP_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                        reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE)


# ----------------------------------------------------------------------------- config
def config_defaults(file: str = "tmgwr_agent.yaml", section: str = "tmgwr") -> dict[str, Any]:
    """The values of ``share/tmgwr_agent/config/<file>`` section ``section``."""
    from tmgwr_common.share import share_file

    return load_yaml(share_file("tmgwr_agent", "config", file), section)


# ----------------------------------------------------------------------------- parameters
def descriptor(p: Param):
    """A read-only ParameterDescriptor with the Param's description, type and range.

    ROS ranges are closed; an open bound (e.g. ``(0, 1]``) is stated in the description
    and enforced by :meth:`Param.check` right after declaration.
    """
    from rcl_interfaces.msg import (FloatingPointRange, IntegerRange,
                                    ParameterDescriptor, ParameterType)
    d = ParameterDescriptor(name=p.name, description=p.description, read_only=True)
    if p.choices is not None:
        d.type = ParameterType.PARAMETER_STRING
        d.additional_constraints = "one of: " + ", ".join(p.choices)
    elif isinstance(p.default, bool):
        d.type = ParameterType.PARAMETER_BOOL
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


def declare_specs(node, specs: Iterable[Param], defaults: Mapping[str, Any] | None = None,
                  section: str | None = None) -> dict[str, Any]:
    """Declare each Param on ``node``; returns the checked values.

    The default is, in order: a ``<section>.<name>`` value of a ``--params-file`` in the
    config/ layout (``/**: ros__parameters: tmgwr: {...}``), ``defaults`` (the config
    file), the Param's own. ``-p name:=value`` overrides it. Raises ParamError naming the
    first invalid parameter.
    """
    from rclpy.exceptions import (InvalidParameterTypeException,
                                  InvalidParameterValueException)
    defaults = dict(defaults or {})
    overrides = getattr(node, "_parameter_overrides", {}) or {}
    values: dict[str, Any] = {}
    where = f"node '{node.get_name()}'"
    for p in specs:
        src = where + " (config default)"
        default = defaults.get(p.name, p.default)
        if section and f"{section}.{p.name}" in overrides:
            default = overrides[f"{section}.{p.name}"].value
            src = where + f" (parameter file '{section}.{p.name}')"
        default = _check(p, default, src)
        if not p.integer and isinstance(default, int) and not isinstance(default, bool) \
                and p.choices is None and not isinstance(p.default, (bool, str)):
            default = float(default)
        try:
            param = node.declare_parameter(p.name, default, descriptor(p))
        except (InvalidParameterValueException, InvalidParameterTypeException) as exc:
            raise ParamError(f"{where}: invalid parameter '{p.name}': {exc}") from None
        values[p.name] = _check(p, param.value, where)
    return values


def _check(p: Param, value: Any, where: str) -> Any:
    """Param.check, plus free-form string parameters (paths, names)."""
    if isinstance(p.default, str) and p.choices is None:
        if isinstance(value, int) and not isinstance(value, bool):
            value = str(value)
        if not isinstance(value, str):
            raise ParamError(f"{where}: parameter '{p.name}' must be a string, got {value!r}")
        return value
    return p.check(value, where)


# ----------------------------------------------------------------------------- arrays
def f64(a) -> array.array:
    return array.array("d", np.ascontiguousarray(a, dtype=np.float64).tobytes())


def i32(a) -> array.array:
    return array.array("i", np.ascontiguousarray(a, dtype=np.int32).tobytes())


def u8(a) -> array.array:
    return array.array("B", np.ascontiguousarray(a, dtype=np.uint8).tobytes())


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


def run(factory: Callable[[], Any], name: str, args=None) -> int:
    """Init rclpy, build the node, spin it; exit code 2 when it cannot start.

    A node may define ``on_shutdown()`` (called once after spinning stops, for any reason:
    Ctrl-C, SIGTERM via rclpy's handler, ``rclpy.shutdown``) and ``finished`` (spinning
    stops when it becomes true).
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException

    rclpy.init(args=args if args is not None else sys.argv)
    node = None
    code = 0
    try:
        try:
            node = factory()
        except (ParamError, ValueError, OSError) as exc:
            print(f"[{name}] cannot start: {exc}", file=sys.stderr, flush=True)
            return 2
        executor = make_executor()
        executor.add_node(node)
        try:
            # spin() is spin_once() in a loop; looping ourselves lets a node finish.
            while rclpy.ok() and not getattr(node, "finished", False):
                executor.spin_once(timeout_sec=0.2)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        finally:
            executor.shutdown(timeout_sec=0.5)
        code = int(getattr(node, "exit_code", 0))
    finally:
        if node is not None:
            hook = getattr(node, "on_shutdown", None)
            if hook is not None:
                try:
                    hook()
                except Exception as exc:  # noqa: BLE001 -- still shut down cleanly
                    print(f"[{name}] shutdown hook failed: {exc}", file=sys.stderr, flush=True)
                    code = code or 1
            node.destroy_node()
        rclpy.try_shutdown()
    return code
