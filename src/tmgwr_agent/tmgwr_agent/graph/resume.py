"""``./tmgwr up --resume RUN``: which run directory, with which settings (docs/graph.md,
Continuing a run).

A run directory (``runs/<UTC stamp>/``, or ``--record-dir DIR``) holds the recording, the
maps and the nodes' checkpoints (``<node>.ckpt.npz``, :mod:`tmgwr_common.checkpoint`), and
``graph.json``: the settings ``up`` started the graph with (maze, goal, seed, parameter
files, composed). ``--resume RUN`` takes a directory, or the stamp of one under ``runs/``,
starts the graph again with those settings (a conflicting ``--maze``, ``--goal`` or
``--seed`` is refused; ``--params-file`` replaces the files) and every node that keeps a
checkpoint continues from it. The recording goes on in a new bag inside the run
directory, ``RUN/resumed_<N>/``, since a bag is never appended to. A directory without
``graph.json`` (e.g. ``$ROS_HOME/tmgwr/domain0``, where a graph started without
``./tmgwr up`` or with ``--no-record`` keeps its checkpoints) is resumed with the settings
given on the command line.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from tmgwr_common.checkpoint import SUFFIX, CheckpointError, decode, read_regular

RUN_FILE = "graph.json"
SETTINGS = ("maze", "goal", "seed", "params_files", "composed", "world")


class ResumeError(ValueError):
    """RUN is not a run to resume, or the command line contradicts it; says why."""


def find_run(run: str, root: str | Path | None = None) -> Path:
    """The run directory ``run`` names: a directory, else ``runs/<run>`` under the
    repository (``TMGWR_ROOT``) or the current directory."""
    base = Path(root) if root else Path(os.environ.get("TMGWR_ROOT", Path.cwd()))
    for candidate in (Path(run).expanduser(), base / "runs" / run):
        if candidate.is_dir():
            path = candidate.resolve()
            if (path / RUN_FILE).is_file() or any(path.glob("*" + SUFFIX)):
                return path
            raise ResumeError(f"{path} is not a run to resume: no {RUN_FILE} and no "
                              f"checkpoint (*{SUFFIX})")
    raise ResumeError(f"no run {run!r}: neither a directory nor {base / 'runs' / run}")


def write_settings(run_dir: Path, settings: dict[str, Any]) -> None:
    """``RUN/graph.json`` (atomically; only the keys of SETTINGS)."""
    run_dir.mkdir(parents=True, exist_ok=True)
    tmp = run_dir / (RUN_FILE + ".tmp")
    tmp.write_text(json.dumps({k: settings.get(k) for k in SETTINGS}, indent=1) + "\n")
    tmp.replace(run_dir / RUN_FILE)


def read_settings(run_dir: Path) -> dict[str, Any]:
    path = run_dir / RUN_FILE
    if not path.is_file():
        return {}
    try:
        saved = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise ResumeError(f"{path}: unreadable ({exc})") from None
    if not isinstance(saved, dict):
        raise ResumeError(f"{path}: not a settings object")
    return {k: saved.get(k) for k in SETTINGS}


def merged_settings(run_dir: Path, given: dict[str, Any]) -> dict[str, Any]:
    """The run's settings, completed by what the command line gives (``None`` / empty =
    not given; a maze as its resolved path); a maze, goal or seed that differs from the
    run's is refused."""
    saved = read_settings(run_dir)
    out = dict(saved)
    for key in SETTINGS:
        value = given.get(key)
        if value in (None, [], (), False):
            continue
        if key == "seed" and saved and saved.get(key) is None:
            raise ResumeError(f"--seed {value}: the run was started without a seed "
                              f"({run_dir / RUN_FILE}): a resumed run keeps its settings")
        if key in ("maze", "goal", "seed", "world") and saved.get(key) is not None:
            if str(value) != str(saved[key]):
                raise ResumeError(f"--{key} {value} differs from the run's {key} "
                                  f"{saved[key]} ({run_dir / RUN_FILE}): a resumed run keeps "
                                  "its settings")
        out[key] = value
    return out


def check_checkpoints(run_dir: Path) -> None:
    """Refuse (ResumeError, naming the file and why) a run whose checkpoints a node would
    refuse to read (:func:`tmgwr_common.checkpoint.decode`: array headers checked before
    anything is allocated), before any node starts."""
    fd = os.open(run_dir, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    try:
        for path in sorted(run_dir.glob("*" + SUFFIX)):
            try:
                decode(read_regular(path.name, fd), str(path))
            except FileNotFoundError:
                continue
            except CheckpointError as exc:
                raise ResumeError(f"{exc} (remove or replace it to resume)") from None
    finally:
        os.close(fd)


def resumed_bag_dir(run_dir: Path) -> Path:
    """``RUN/resumed_<N>/``, the first N not taken."""
    n = 1
    while (run_dir / f"resumed_{n}").exists():
        n += 1
    return run_dir / f"resumed_{n}"
