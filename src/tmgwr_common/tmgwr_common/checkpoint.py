"""Checkpoints: what a node needs to continue a run after any stop, SIGKILL included
(README, Continuing a run). ROS-free; maze_sim and the agent nodes both use it, so it lives
here (``maze_sim`` may not import ``tmgwr_agent``).

* **Who.** Each node that owns state writes its own checkpoint: maze_sim (the counters:
  episode, step, goal, the maze layout after edits, the noise generator), map_learner (the
  map and the step it last learnt), motivation_estimator (the outcome memory of Eq. 5':
  tried primitives, bump ages, the forward model) and action_selector (epsilon, the random
  walk, its generator). The sensory preprocessor holds nothing that outlives an episode.
* **When.** After the step whose id is a multiple of ``checkpoint_period`` (the same step
  ids in every node, so a set of checkpoints is at most one period apart), and at every
  clean stop (SIGINT/SIGTERM: the node's ``on_shutdown``). A period's checkpoint is taken
  when its step is done and written in the background (:class:`Checkpointer`); a SIGKILL
  loses at most the steps since the last period, and those of one more period when it
  comes while that period's write is still under way (a few milliseconds).
* **Where.** ``checkpoint_dir``: the run's directory under ``./tmgwr up``; else the map
  learner's ``map_dir`` for the learner and, for every node, the graph's directory
  ``$ROS_HOME/tmgwr/domain<ID>[_<namespace>]`` (:func:`graph_dir`, the default ``map_dir``).
  One file per node, ``<node>.ckpt.npz`` (a node name, never a path).
* **How.** Written in a private temporary directory inside that directory
  (``.ckpt-<node>-*``: one a kill leaves behind is removed when the node starts again),
  synced, then renamed over the target (``os.replace``: a kill leaves the old checkpoint
  or the new one, never half of one). A target that is a link, a FIFO, a directory or
  any file that is not this node's checkpoint is never replaced. Read without following a
  final link and without blocking, regular files only, size bounded, every array header
  checked before anything is allocated (:mod:`tmgwr_common.npz_check`: no pickles, plain
  dtypes, sizes), then checked completely (format version, node, fingerprint such as the
  maze or the map's dimensions, arrays and their dtypes, finite values) before the node
  uses it. Every refusal raises
  :class:`CheckpointError` saying why; :class:`Checkpointer` logs it and the node runs on
  (a refused checkpoint is not overwritten: its node then keeps no checkpoint).
* **Resuming.** With ``resume`` true a node starts from its own checkpoint when there is
  one (none: it starts fresh, and says so). Each node resumes from its own latest
  checkpoint; when they are from different steps (a kill between two nodes' writes of the
  same period) the difference is at most ``checkpoint_period`` steps of experience, and the
  lockstep resynchronises them: the resumed simulator starts a new run id
  (``tmgwr_common.lockstep``) with a new episode, its step ids continuing its own counter.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import re
import shutil
import signal
import stat
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from tmgwr_common import safe_files
from tmgwr_common.npz_check import read_npz
from tmgwr_common.params import Param

FORMAT_VERSION = 1
META_KEY = "tmgwr_checkpoint"        # the member holding the JSON metadata (uint8 bytes)
SUFFIX = ".ckpt.npz"
MAX_BYTES = 256 << 20                # a checkpoint file, and its arrays uncompressed
NODE_RULE = re.compile(r"[A-Za-z0-9_]{1,64}")

#: The parameters of every node that keeps a checkpoint (declared once, here).
CHECKPOINT_SPECS = (
    Param("checkpoint_dir", "", "directory of this node's checkpoint <node>.ckpt.npz "
          "(empty: map_learner's map_dir, else $ROS_HOME/tmgwr/domain<ROS_DOMAIN_ID>"
          "[_<namespace>]; ./tmgwr up passes the run's directory)"),
    Param("checkpoint_period", 100, "write the checkpoint after every step whose id is a "
          "multiple of this (and at every clean stop); 0: only at a clean stop", low=0,
          high=1e12, integer=True),
    Param("resume", False, "start from this node's checkpoint in checkpoint_dir when there "
          "is one (none: start fresh, saying so); ./tmgwr up sets it"),
)

#: An array schema: name -> (accepted dtype kinds, number of dimensions).
Schema = Mapping[str, tuple[str, int]]


class CheckpointError(ValueError):
    """A checkpoint refused (name, file or content); the message says which and why."""


# ----------------------------------------------------------------------------- places
def ros_home() -> Path:
    """``$ROS_HOME``, else ``~/.ros`` (what rcl itself uses for logs)."""
    home = os.environ.get("ROS_HOME")
    return Path(home) if home else Path.home() / ".ros"


def graph_key(domain_id: int | str, namespace: str = "/") -> str:
    """A directory name unique per graph: ``domain<ID>`` plus the namespace
    (``/a/b`` -> ``domain7_a_b``)."""
    ns = "_".join(part for part in namespace.split("/") if part)
    return f"domain{int(domain_id)}" + (f"_{ns}" if ns else "")


def graph_dir(domain_id: int | str | None = None, namespace: str = "/") -> Path:
    """``$ROS_HOME/tmgwr/<graph_key>``: the directory of a graph not run by ``./tmgwr up``
    (``domain_id`` None: ``$ROS_DOMAIN_ID``, else 0)."""
    if domain_id is None:
        domain_id = os.environ.get("ROS_DOMAIN_ID") or 0
    return ros_home() / "tmgwr" / graph_key(domain_id, namespace)


def file_name(node: str) -> str:
    if not isinstance(node, str) or not NODE_RULE.fullmatch(node):
        raise CheckpointError(f"checkpoint of {node!r}: a node name is 1-64 letters, digits "
                              "or '_'")
    return node + SUFFIX


# ----------------------------------------------------------------------------- files
def read_regular(path: str, dir_fd: int | None = None) -> bytes:
    """The bytes of the checkpoint file ``path`` (:func:`safe_files.read_regular`)."""
    return safe_files.read_regular(path, dir_fd, MAX_BYTES, "checkpoint", CheckpointError)


def decode(data: bytes, what: str) -> tuple[dict, dict[str, np.ndarray]]:
    """(metadata, arrays) of a checkpoint file's bytes, every array header checked before
    anything is allocated (:func:`tmgwr_common.npz_check.read_npz`: no pickles, plain
    dtypes, sizes within :data:`MAX_BYTES`)."""
    arrays = read_npz(data, what, MAX_BYTES, CheckpointError, "checkpoint")
    raw = arrays.pop(META_KEY, None)
    if raw is None or raw.dtype != np.uint8 or raw.ndim != 1:
        raise CheckpointError(f"{what}: not a checkpoint (no {META_KEY} member)")
    try:
        meta = json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise CheckpointError(f"{what}: unreadable checkpoint metadata ({exc})") from None
    if not isinstance(meta, dict):
        raise CheckpointError(f"{what}: checkpoint metadata is not a mapping")
    return meta, arrays


def check_arrays(arrays: Mapping[str, np.ndarray], schema: Schema, what: str) -> None:
    """Exactly the arrays of ``schema``, each of its dtype kind and dimensions, every
    float finite."""
    missing = sorted(set(schema) - set(arrays))
    unknown = sorted(set(arrays) - set(schema))
    if missing or unknown:
        raise CheckpointError(f"{what}: arrays " + ", ".join(
            ([f"missing {', '.join(missing)}"] if missing else [])
            + ([f"unknown {', '.join(unknown)}"] if unknown else [])) + ": refused")
    for name, (kinds, ndim) in schema.items():
        a = arrays[name]
        if a.dtype.kind not in kinds or a.ndim != ndim:
            raise CheckpointError(f"{what}: array {name} is {a.dtype}[{a.ndim}-d], expected "
                                  f"{ndim}-d of kind {kinds!r}: refused")
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise CheckpointError(f"{what}: array {name} holds values that are not finite: "
                                  "refused")


# ----------------------------------------------------------------------------- the store
@dataclass
class Checkpoint:
    """One node's checkpoint as read back."""

    node: str
    step_id: int
    run_id: int
    saved_at: float                    # wall clock (s) of the write
    state: dict                        # plain numbers, strings, lists (JSON)
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    path: Path | None = None

    def describe(self) -> str:
        age = max(0.0, time.time() - self.saved_at)
        return (f"{self.path} (step {self.step_id} of run {self.run_id}, written "
                f"{age:.0f} s ago)")


class CheckpointStore:
    """The checkpoint file of one node in one directory (see the module docstring).

    ``fingerprint``: what must match for a checkpoint to be used (e.g. the maze, the map's
    dimensions); stored with every write, compared on every read."""

    def __init__(self, directory: str | os.PathLike, node: str,
                 fingerprint: Mapping[str, Any] | None = None):
        self.node = node
        self.fname = file_name(node)
        self.fingerprint = json.loads(json.dumps(dict(fingerprint or {})))
        try:
            d = Path(directory).expanduser()
            d.mkdir(mode=0o700, parents=True, exist_ok=True)
            self.directory = d.resolve(strict=True)
            self._dir_fd = os.open(self.directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        except (OSError, RuntimeError) as exc:       # RuntimeError: ~nosuchuser
            raise CheckpointError(f"checkpoint directory {directory}: {exc}") from None
        self._written: tuple[int, int, int] | None = None   # (ino, mtime_ns, size) we wrote
        self._remove_stale()

    @property
    def _tmp_prefix(self) -> str:
        return f".ckpt-{self.node}-"

    def _remove_stale(self) -> None:
        """Remove this node's temporary folders a kill left in the middle of a write (no
        other process writes this node's checkpoint here: the names say whose they are)."""
        for tmp in self.directory.glob(self._tmp_prefix + "*"):
            if tmp.is_dir() and not tmp.is_symlink():
                shutil.rmtree(tmp, ignore_errors=True)

    @property
    def path(self) -> Path:
        return self.directory / self.fname

    def close(self) -> None:
        if self._dir_fd >= 0:
            os.close(self._dir_fd)
            self._dir_fd = -1

    # -- reading
    def load(self, schema: Schema | None = None) -> Checkpoint | None:
        """This node's checkpoint, checked (format, node, fingerprint, ``schema``); None
        when there is none; CheckpointError says why one is refused."""
        what = str(self.path)
        try:
            data = read_regular(self.fname, self._dir_fd)
        except FileNotFoundError:
            return None
        meta, arrays = decode(data, what)
        if meta.get("format") != FORMAT_VERSION:
            raise CheckpointError(f"{what}: checkpoint format {meta.get('format')!r}, this "
                                  f"node reads {FORMAT_VERSION}: refused")
        if meta.get("node") != self.node:
            raise CheckpointError(f"{what}: a checkpoint of {meta.get('node')!r}, not of "
                                  f"{self.node!r}: refused")
        theirs = meta.get("fingerprint", {})
        diff = [k for k in sorted(set(theirs) | set(self.fingerprint))
                if theirs.get(k) != self.fingerprint.get(k)]
        if diff:
            k = diff[0]
            raise CheckpointError(
                f"{what}: written for {k} = {_short(theirs.get(k))}, this node has {k} = "
                f"{_short(self.fingerprint.get(k))}: refused (another run's checkpoint? give "
                "this node another checkpoint_dir)")
        try:
            step_id, run_id = int(meta["step_id"]), int(meta["run_id"])
            saved_at, state = float(meta["saved_at"]), meta["state"]
        except (KeyError, TypeError, ValueError) as exc:
            raise CheckpointError(f"{what}: incomplete checkpoint metadata ({exc})") from None
        if not isinstance(state, dict) or step_id < -1 or run_id < 0:
            raise CheckpointError(f"{what}: step {step_id} / run {run_id} out of range")
        if schema is not None:
            check_arrays(arrays, schema, what)
        for name, a in arrays.items():
            if a.dtype.kind not in "biuf" or a.dtype.kind == "f" and not np.isfinite(a).all():
                raise CheckpointError(f"{what}: array {name} ({a.dtype}) is not numeric or "
                                      "holds values that are not finite: refused")
        return Checkpoint(self.node, step_id, run_id, saved_at, state, arrays, self.path)

    def _ours(self) -> bool:
        """Whether the existing target is this node's checkpoint (ours to replace)."""
        try:
            st = os.stat(self.fname, dir_fd=self._dir_fd, follow_symlinks=False)
        except FileNotFoundError:
            return True
        if not stat.S_ISREG(st.st_mode):
            raise CheckpointError(f"{self.path} is {safe_files.kind(st.st_mode)}: not replaced")
        if self._written == (st.st_ino, st.st_mtime_ns, st.st_size):
            return True
        try:
            meta, _ = decode(read_regular(self.fname, self._dir_fd), str(self.path))
        except (CheckpointError, FileNotFoundError):
            meta = {}
        if meta.get("node") != self.node:
            raise CheckpointError(f"{self.path} exists and is not a checkpoint of "
                                  f"{self.node!r}: not replaced")
        return True

    # -- writing
    def save(self, step_id: int, run_id: int, state: Mapping[str, Any],
             arrays: Mapping[str, np.ndarray] | None = None) -> Path:
        """Write the checkpoint atomically (see the module docstring); returns its path."""
        return self.write(self.contents(step_id, run_id, state, arrays))

    def contents(self, step_id: int, run_id: int, state: Mapping[str, Any],
                 arrays: Mapping[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
        """What :meth:`write` writes, taken now: the state as JSON text and copies of the
        arrays, so the node may change its own at once."""
        meta = {"format": FORMAT_VERSION, "node": self.node, "step_id": int(step_id),
                "run_id": int(run_id), "saved_at": time.time(),
                "fingerprint": self.fingerprint, "state": dict(state)}
        members = {k: np.array(v, copy=True) for k, v in (arrays or {}).items()}
        members[META_KEY] = np.frombuffer(json.dumps(meta).encode("utf-8"), dtype=np.uint8)
        return members

    def write(self, members: Mapping[str, np.ndarray]) -> Path:
        """Write :meth:`contents` atomically (see the module docstring); returns the path."""
        self._ours()
        tmp = tempfile.mkdtemp(prefix=self._tmp_prefix, dir=self.directory)   # mode 0700
        try:
            written = Path(tmp) / self.fname
            with open(written, "wb") as f:
                np.savez(f, **members)
                f.flush()
                os.fsync(f.fileno())
            os.replace(written, self.fname, dst_dir_fd=self._dir_fd)
            os.fsync(self._dir_fd)
            st = os.stat(self.fname, dir_fd=self._dir_fd, follow_symlinks=False)
            self._written = (st.st_ino, st.st_mtime_ns, st.st_size)
        except OSError as exc:
            raise CheckpointError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return self.path


def _short(value: Any) -> str:
    text = json.dumps(value)
    return text if len(text) <= 60 else text[:57] + "..."


# ----------------------------------------------------------------------------- in a node
#: What a node hands the checkpointer: () -> (state (JSON-able dict), arrays).
Snapshot = Callable[[], tuple[Mapping[str, Any], Mapping[str, np.ndarray]]]


class Checkpointer:
    """One node's checkpoints (resume at start, write every period and at a clean stop),
    with every refusal logged and the node running on.

    The checkpoint of a period (:meth:`step`) is taken in the node's thread, when its step
    is done, and written to disk by a thread of its own, so the lockstep ring does not wait
    for the disk (the writes with their two fsyncs took 14 % of a composed graph's wall time
    on a loaded machine when the nodes waited for them). One write is in flight at most: the
    next one, a clean stop's (:meth:`stop`) and a direct :meth:`save` wait for it first, so
    checkpoints reach the disk in step order, and a kill leaves the older or the newer one.

    ``params``: the node's values of :data:`CHECKPOINT_SPECS`; ``logger``: anything with
    ``info``, ``warning`` and ``error`` (an rclpy logger); ``default_dir``: the directory
    when ``checkpoint_dir`` is empty (default :func:`graph_dir` of ``namespace``)."""

    def __init__(self, node: str, params: Mapping[str, Any], logger,
                 fingerprint: Mapping[str, Any] | None = None, namespace: str = "/",
                 default_dir: str | os.PathLike | None = None):
        self.node = node
        self.logger = logger
        self.period = int(params["checkpoint_period"])
        self.resume_wanted = bool(params["resume"])
        directory = params["checkpoint_dir"] or default_dir or graph_dir(None, namespace)
        self.store: CheckpointStore | None = None
        self.last_saved = (0, -2)             # (run, step) of the last write or resume
        self.refused = ""                     # why checkpoints are off ("" = on)
        self._queue: queue.Queue | None = None   # to the writer thread (made at first use)
        try:
            self.store = CheckpointStore(directory, node, fingerprint)
        except CheckpointError as exc:
            self._off(str(exc))

    def _off(self, why: str) -> None:
        self.refused = why
        self.logger.error(f"{why}; this node keeps no checkpoint")

    def resume(self, schema: Schema | None = None,
               check: Callable[[Checkpoint], None] | None = None) -> Checkpoint | None:
        """The checkpoint to start from (``resume`` true and a valid one exists), after
        ``check`` (which raises CheckpointError for a content refused); else None, logged."""
        if not self.resume_wanted or self.store is None:
            return None
        try:
            ck = self.store.load(schema)
            if ck is not None and check is not None:
                check(ck)
        except CheckpointError as exc:
            self._off(f"resume: {exc}; starting fresh, the checkpoint is kept as it is")
            self.store = None
            return None
        if ck is None:
            self.logger.info(f"resume: no checkpoint {self.store.path} yet: starting fresh")
            return None
        self.last_saved = (ck.run_id, ck.step_id)
        self.logger.info(f"resuming from checkpoint {ck.describe()}")
        return ck

    def due(self, step_id: int, run_id: int) -> bool:
        return (self.store is not None and self.period > 0 and step_id > 0
                and step_id % self.period == 0 and (run_id, step_id) != self.last_saved)

    def step(self, step_id: int, run_id: int, snapshot: Snapshot) -> None:
        """After a step: when ``step_id`` is a multiple of the period (once), take the
        checkpoint now and write it in the background (class docstring)."""
        if self.due(step_id, run_id):
            self.save(step_id, run_id, snapshot, self.logger.warning, wait=False)

    def wait(self) -> None:
        """Until the checkpoint being written, if any, is on disk (or refused)."""
        if self._queue is not None:
            self._queue.join()

    def close(self) -> None:
        """Finish the write in flight, end the writer thread, release the directory."""
        self.wait()
        if self._queue is not None:
            self._queue.put(None)
            self._queue = None
        if self.store is not None:
            self.store.close()

    def _writer(self, jobs: queue.Queue) -> None:
        while (job := jobs.get()) is not None:
            try:
                self._write(*job)
            finally:
                jobs.task_done()

    def stop(self, step_id: int, run_id: int, snapshot: Snapshot) -> str:
        """At a clean stop (rclpy may be shut down already: printed, not logged). A second
        SIGINT or SIGTERM during the write (a terminal's Ctrl-C reaches the node and then
        ``ros2 launch`` forwards it again) is ignored until the checkpoint is written."""
        with _stop_signals_ignored():
            return self._stop(step_id, run_id, snapshot)

    def _stop(self, step_id: int, run_id: int, snapshot: Snapshot) -> str:
        if self.store is None:
            text = f"{self.node}: no checkpoint written ({self.refused or 'none kept'})"
        elif step_id < 0:
            text = f"{self.node}: no step done, checkpoint left as it was"
        else:
            path = self.save(step_id, run_id, snapshot, lambda t: None)
            text = (f"{self.node}: checkpoint at step {step_id} written to {path}" if path
                    else f"{self.node}: checkpoint NOT written: {self.refused}")
        print(text, flush=True)
        return text

    def save(self, step_id: int, run_id: int, snapshot: Snapshot,
             warn: Callable[[str], None], wait: bool = True) -> Path | None:
        """Take the checkpoint of ``step_id`` now and write it: at once (``wait``; returns
        the path, None when refused) or in the background (returns None)."""
        self.wait()
        state, arrays = snapshot()
        contents = self.store.contents(step_id, run_id, state, arrays)
        self.last_saved = (run_id, step_id)
        if wait:
            return self._write(contents, warn)
        if self._queue is None:
            self._queue = queue.Queue()
            threading.Thread(target=self._writer, args=(self._queue,), daemon=True,
                             name=f"{self.node} checkpoints").start()
        self._queue.put((contents, warn))
        return None

    def _write(self, contents, warn: Callable[[str], None]) -> Path | None:
        try:
            return self.store.write(contents)
        except CheckpointError as exc:
            self.refused = str(exc)
            warn(f"checkpoint not written: {exc}")
            return None


@contextlib.contextmanager
def _stop_signals_ignored():
    """SIGINT and SIGTERM ignored inside (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    saved = {sig: signal.signal(sig, signal.SIG_IGN) for sig in (signal.SIGINT,
                                                                  signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


# ----------------------------------------------------------------------------- core state
def split_state(d: Mapping[str, Any]) -> tuple[dict, dict[str, np.ndarray]]:
    """A core's ``state_dict()`` as (plain values, arrays): numpy arrays go to the arrays,
    everything else (numbers, strings, lists) to the JSON state."""
    arrays = {k: v for k, v in d.items() if isinstance(v, np.ndarray)}
    state = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in d.items()
             if k not in arrays}
    return state, arrays


def joined_state(ck: Checkpoint) -> dict[str, Any]:
    """The inverse of :func:`split_state`: what a core's ``load_state_dict`` takes."""
    return {**ck.state, **ck.arrays}
