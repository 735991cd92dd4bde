"""Where the map learner keeps its maps, and which files it agrees to read or write
(docs/graph.md, Maps on disk). ROS-free: the node passes in its domain and namespace.

* A map is addressed by a **name**, never a path: :func:`map_file_name` accepts 1 to
  :data:`MAX_NAME` characters of ``[A-Za-z0-9_.-]``, no leading ``.`` and no ``..``; the
  file is ``NAME.npz`` (``NAME`` when it already ends in ``.npz``) in one directory, the
  store's.
* The directory (:func:`default_map_dir`): the graph's run directory under ``./tmgwr up``
  (it passes ``map_dir``), else the graph's directory of :mod:`tmgwr_common.checkpoint`
  (``$ROS_HOME/tmgwr/<graph>``, ``ROS_HOME`` defaulting to ``~/.ros``, ``<graph>`` naming
  the ROS domain and the namespace), so graphs in other domains or namespaces never share
  a file. :meth:`MapStore.lock` holds an ``flock`` on
  ``DIR/.lock`` for the learner's life: a second learner on the same directory is refused.
* Writes (:meth:`MapStore.save`) go through :meth:`SensorimotorMap.save` into a private
  temporary directory inside the store, are stamped with :data:`FORMAT_VERSION`, synced,
  then moved over the target with ``os.replace`` (atomic; a crash leaves the old file or
  the new one, and a temporary folder that the next learner's :meth:`MapStore.lock`
  removes). The target must be absent or a regular file that is a map of ours: a
  symbolic link, a directory, a FIFO or any other file is never replaced.
* A learner that starts fresh (not from its checkpoint) first renames the map an earlier
  run saved under its ``map_name`` to ``NAME.<UTC mtime>.npz``
  (:meth:`MapStore.keep_previous`): a new run never overwrites the previous run's map, and
  ``map_name`` still names the current run's (what ``load_map`` with an empty name reads).
* Reads (:func:`read_map`) open the file without following a final symbolic link and
  without blocking (a FIFO or device is refused, not waited on), accept only a regular
  file of at most :data:`MAX_BYTES`, check every array header before any array is
  allocated (:mod:`tmgwr_common.npz_check`), and validate the whole content
  (:func:`validate_state`: format version, keys, dtypes, array shapes, index ranges,
  finite values) before :meth:`SensorimotorMap.load` builds the map from those very bytes.

Every refusal raises :class:`MapStoreError` (a ValueError) saying why; the caller keeps
running.
"""

from __future__ import annotations

import os
import re
import shutil
import stat
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

from tmgwr_agent.core.sensorimotor_map import MapConfig, SensorimotorMap
from tmgwr_common import safe_files
from tmgwr_common.checkpoint import graph_dir
from tmgwr_common.npz_check import read_npz

FORMAT_VERSION = 1
"""Version of the map file layout this module reads and writes: the arrays of
:meth:`SensorimotorMap.state_dict` plus ``step_id`` and ``run_id``. Stored as the member
``tmgwr_map_format``; a file without it (written by ``SensorimotorMap.save`` directly)
is read as version 1 when its arrays are exactly those."""
FORMAT_KEY = "tmgwr_map_format"
SUFFIX = ".npz"
MAX_NAME = 100                       # characters of a map name
MAX_BYTES = 256 << 20                # a map file, and its arrays uncompressed
NAME_RULE = re.compile(r"[A-Za-z0-9_.-]+")
SAVING = ".saving-"                  # temporary folders of saves (removed by lock())

_ARRAYS = {           # name -> (dtype kind, number of dimensions)
    "w": ("f", 2), "c": ("f", 2), "h": ("f", 1), "alive": ("b", 1), "out": ("i", 2),
    "E": ("f", 2), "a": ("f", 3), "age": ("i", 2), "terminal": ("b", 1), "meta": ("i", 1),
    "step_id": ("iu", 0), "run_id": ("iu", 0), "motion": ("f", 2), "x_prev": ("f", 1),
    "won": ("f", 1),
}
_OPTIONAL = {"terminal", "motion", "x_prev", "won", FORMAT_KEY}   # absent from older maps


class MapStoreError(ValueError):
    """A name, file or content refused; the message says which and why."""


# ----------------------------------------------------------------------------- names
def map_file_name(name: str) -> str:
    """The file name of map ``name`` (``NAME.npz``), or MapStoreError saying why the name
    is refused."""
    if not isinstance(name, str) or not name:
        raise MapStoreError("empty map name")
    if len(name) > MAX_NAME:
        raise MapStoreError(f"map name of {len(name)} characters: at most {MAX_NAME}")
    if "/" in name or "\\" in name:
        raise MapStoreError(f"map name {name!r} contains a path separator: give a name "
                            "(letters, digits, '_', '-', '.'), not a path; maps live in "
                            "the learner's map directory")
    if ".." in name:
        raise MapStoreError(f"map name {name!r} contains '..'")
    if name.startswith("."):
        raise MapStoreError(f"map name {name!r} starts with '.'")
    if not NAME_RULE.fullmatch(name):
        bad = sorted({ch for ch in name if not NAME_RULE.fullmatch(ch)})
        raise MapStoreError(f"map name {name!r} contains {''.join(bad)!r}: only letters, "
                            "digits, '_', '-' and '.' are allowed")
    return name if name.endswith(SUFFIX) else name + SUFFIX


def default_map_dir(domain_id: int | str | None = None, namespace: str = "/") -> Path:
    """The learner's maps, when ``map_dir`` is not given: the graph's own directory,
    ``$ROS_HOME/tmgwr/domain<ID>[_<namespace>]`` (:func:`tmgwr_common.checkpoint.graph_dir`,
    where the other nodes keep their checkpoints; ``domain_id`` None: ``$ROS_DOMAIN_ID``)."""
    return graph_dir(domain_id, namespace)


# ----------------------------------------------------------------------------- reading
def _read_regular(path: str, dir_fd: int | None = None) -> bytes:
    """The bytes of the map file ``path`` (:func:`safe_files.read_regular`)."""
    try:
        return safe_files.read_regular(path, dir_fd, MAX_BYTES, "map", MapStoreError)
    except FileNotFoundError:
        raise MapStoreError(f"{path}: no such map") from None


def load_arrays(data: bytes, what: str) -> dict[str, np.ndarray]:
    """The arrays of a map file's bytes, every array header checked before anything is
    allocated (:func:`tmgwr_common.npz_check.read_npz`: no pickles, plain dtypes, sizes
    within :data:`MAX_BYTES`)."""
    return read_npz(data, what, MAX_BYTES, MapStoreError, "map")


def validate_state(s: dict[str, np.ndarray], what: str = "map") -> None:
    """Refuse (MapStoreError) anything :meth:`SensorimotorMap.load` should not build a
    live map from: another format version, missing or unknown arrays, a wrong dtype or
    shape, a link or winner index out of range or to a dead node, a value not finite, a
    reliability outside [0, 1], a negative age."""
    def bad(text: str):
        raise MapStoreError(f"{what}: {text}: refused")

    if FORMAT_KEY in s:
        v = s[FORMAT_KEY]
        if v.shape != () or v.dtype.kind not in "iu" or int(v) != FORMAT_VERSION:
            bad(f"map format version {v.tolist()!r}, this learner reads {FORMAT_VERSION}")
    missing = sorted(set(_ARRAYS) - _OPTIONAL - set(s))
    unknown = sorted(set(s) - set(_ARRAYS) - _OPTIONAL)
    if missing:
        bad(f"not a saved map (no {', '.join(missing)})")
    if unknown:
        bad(f"unknown arrays {', '.join(unknown)} (not map format {FORMAT_VERSION})")
    for name, (kinds, ndim) in _ARRAYS.items():
        if name in s and (s[name].dtype.kind not in kinds or s[name].ndim != ndim):
            bad(f"array {name} is {s[name].dtype}[{s[name].ndim}-d], expected "
                f"{ndim}-d of kind {kinds!r}")
    n, k = s["out"].shape
    dim, action_dim = s["w"].shape[1], s["a"].shape[2]
    if k < 1 or dim < 1 or action_dim < 1:
        bad(f"empty dimension (degree {k}, dim {dim}, action dim {action_dim})")
    shapes = {"w": (n, dim), "c": (n, dim), "h": (n,), "alive": (n,), "E": (n, k),
              "a": (n, k, action_dim), "age": (n, k), "terminal": (n,), "meta": (3,),
              "won": (n,)}
    for name, shape in shapes.items():
        if name in s and s[name].shape != shape:
            bad(f"array {name} has shape {s[name].shape}, expected {shape} "
                f"({n} nodes, {k} links per node, dim {dim})")
    # (motion and x_prev: optional, ignored if of another shape)
    for name in ("w", "c", "h", "won", "E", "a", "motion", "x_prev"):
        if name in s and not np.isfinite(s[name]).all():
            bad(f"array {name} holds {int((~np.isfinite(s[name])).sum())} values that are "
                "not finite")
    if ((s["E"] < 0) | (s["E"] > 1)).any():
        bad("a reliability E outside [0, 1]")
    if (s["age"] < 0).any():
        bad("a negative link age")
    if "won" in s and (s["won"] < 1).any():    # (a node's first sample is its insertion)
        bad("a node's count of samples won below 1")
    out, alive = s["out"], s["alive"]
    if ((out < -1) | (out >= n)).any():
        bad(f"a link target outside [-1, {n})")
    src, slot = np.nonzero(out >= 0)
    if len(src) and not (alive[src].all() and alive[out[src, slot]].all()):
        bad("a link from or to a dead node")
    version, prev, winner = (int(v) for v in s["meta"])
    if version < 0:
        bad(f"map version {version} < 0")
    for label, i in (("previous winner", prev), ("winner", winner)):
        if not -1 <= i < n or i >= 0 and not alive[i]:
            bad(f"{label} {i} is not a live node of {n}")
    if int(s["step_id"]) < -1 or int(s["run_id"]) < 0:
        bad(f"step {int(s['step_id'])} / run {int(s['run_id'])} out of range")


def read_map(path: str | os.PathLike, config: MapConfig = MapConfig(),
             dir_fd: int | None = None) -> tuple[SensorimotorMap, int, int]:
    """(map, step_id, run_id) of the map file at ``path`` (relative to ``dir_fd`` when
    given), validated completely first; MapStoreError says why it is refused."""
    what = str(path)
    data = _read_regular(what, dir_fd)
    validate_state(load_arrays(data, what), what)
    # SensorimotorMap.load reads a path: give it these very bytes, in a private directory
    tmp = tempfile.mkdtemp(prefix="tmgwr-map-")
    try:
        copy = Path(tmp) / "map.npz"
        copy.write_bytes(data)
        try:
            return SensorimotorMap.load(copy, config, with_run=True)
        except ValueError as exc:
            raise MapStoreError(f"{what}: not a saved map ({exc})") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def is_our_map(path: str, dir_fd: int | None = None) -> bool:
    """Whether ``path`` is a regular file holding a valid map (one we may replace)."""
    try:
        validate_state(load_arrays(_read_regular(path, dir_fd), path), path)
    except MapStoreError:
        return False
    return True


def _exists(fname: str, dir_fd: int) -> bool:
    try:
        os.stat(fname, dir_fd=dir_fd, follow_symlinks=False)
    except FileNotFoundError:
        return False
    return True


# ----------------------------------------------------------------------------- the store
class MapStore:
    """The one directory a learner reads and writes maps in (see the module docstring)."""

    def __init__(self, directory: str | os.PathLike):
        try:
            d = Path(directory).expanduser()
            d.mkdir(mode=0o700, parents=True, exist_ok=True)
            self.directory = d.resolve(strict=True)
            self._dir_fd = os.open(self.directory, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        except (OSError, RuntimeError) as exc:       # RuntimeError: ~nosuchuser
            raise MapStoreError(f"map directory {directory}: {exc}") from None
        self._lock_fd: int | None = None

    def close(self) -> None:
        for fd in (self._lock_fd, self._dir_fd):
            if fd is not None and fd >= 0:
                os.close(fd)
        self._lock_fd = None
        self._dir_fd = -1

    def lock(self) -> None:
        """Hold ``DIR/.lock`` for this process's life; MapStoreError when another live
        process holds it (two learners would overwrite each other's maps)."""
        import fcntl
        fd = os.open(".lock", os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o600,
                     dir_fd=self._dir_fd)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.read(fd, 64).decode(errors="replace").strip() or "?"
            os.close(fd)
            raise MapStoreError(f"map directory {self.directory} is in use by another "
                                f"map_learner (pid {holder}); give this one its own "
                                "map_dir, namespace or ROS_DOMAIN_ID") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        self._lock_fd = fd
        for tmp in self.directory.glob(SAVING + "*"):   # a kill in the middle of a save
            if tmp.is_dir() and not tmp.is_symlink():
                shutil.rmtree(tmp, ignore_errors=True)

    def path(self, name: str) -> Path:
        return self.directory / map_file_name(name)

    def load(self, name: str, config: MapConfig = MapConfig()
             ) -> tuple[SensorimotorMap, int, int]:
        """(map, step_id, run_id) of map ``name`` of this store, validated."""
        fname = map_file_name(name)
        try:
            return read_map(fname, config, dir_fd=self._dir_fd)
        except MapStoreError as exc:
            raise MapStoreError(str(exc).replace(fname, str(self.directory / fname), 1)) \
                from None

    def keep_previous(self, name: str) -> Path | None:
        """Rename map ``name`` (a map of ours, left by an earlier run) to
        ``NAME.<its UTC mtime>.npz``, so that this run's save does not replace it; returns
        the new path, None when there is no such map. Called by a learner that starts
        fresh (not from its checkpoint)."""
        fname = map_file_name(name)
        try:
            st = os.stat(fname, dir_fd=self._dir_fd, follow_symlinks=False)
        except FileNotFoundError:
            return None
        if not stat.S_ISREG(st.st_mode) or not is_our_map(fname, self._dir_fd):
            return None                   # save() refuses it, saying why
        stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime(st.st_mtime))
        kept, n = map_file_name(f"{name}.{stamp}"), 1
        while _exists(kept, self._dir_fd):
            n += 1
            kept = map_file_name(f"{name}.{stamp}-{n}")
        try:
            os.rename(fname, kept, src_dir_fd=self._dir_fd, dst_dir_fd=self._dir_fd)
            os.fsync(self._dir_fd)
        except OSError as exc:
            raise MapStoreError(f"cannot keep {self.directory / fname} as {kept}: "
                                f"{exc.strerror or exc}") from None
        return self.directory / kept

    def save(self, m: SensorimotorMap, name: str, step_id: int = -1, run_id: int = 0) -> Path:
        """Write ``m`` as map ``name`` atomically; returns the path. Refused when the target
        exists and is not a map of ours (a link, a FIFO, someone's file)."""
        fname = map_file_name(name)
        target = self.directory / fname
        try:
            st = os.stat(fname, dir_fd=self._dir_fd, follow_symlinks=False)
        except FileNotFoundError:
            st = None
        if st is not None:
            if not stat.S_ISREG(st.st_mode):
                raise MapStoreError(f"{target} is {safe_files.kind(st.st_mode)}: not replaced")
            if not is_our_map(fname, self._dir_fd):
                raise MapStoreError(f"{target} exists and is not a tmgwr map: not replaced "
                                    "(choose another name)")
        tmp = tempfile.mkdtemp(prefix=SAVING, dir=self.directory)    # mode 0700
        try:
            written = m.save(Path(tmp) / "map.npz", step_id, run_id)
            with zipfile.ZipFile(written, "a") as z:             # the format version
                with z.open(FORMAT_KEY + ".npy", "w") as f:
                    np.lib.format.write_array(f, np.array(FORMAT_VERSION, dtype=np.int64))
            fd = os.open(written, os.O_RDONLY | os.O_CLOEXEC)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(written, fname, dst_dir_fd=self._dir_fd)
            os.fsync(self._dir_fd)
        except OSError as exc:
            raise MapStoreError(f"cannot write {target}: {exc.strerror or exc}") from None
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return target
