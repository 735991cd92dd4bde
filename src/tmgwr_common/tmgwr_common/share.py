"""Where the installed data lives: the one way the project finds its data files (mazes).

Every package installs its own data into its ament share directory (``colcon build``; the
pip-only bootstrap builds the same workspace): ``share/maze_sim/mazes/*.txt``, the launch
file. Nothing reads them from the source tree. (Hyperparameters have no shipped file:
their defaults are the specs of :mod:`tmgwr_common.params`.)
"""

from __future__ import annotations

from pathlib import Path


class DataFileError(FileNotFoundError):
    """A data file that is not where it was looked for; the message lists the places."""


def share_dir(package: str) -> Path:
    """The installed share directory of ``package`` (ament index)."""
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

    try:
        return Path(get_package_share_directory(package))
    except (PackageNotFoundError, LookupError, ValueError) as exc:
        raise DataFileError(
            f"package {package!r} is not installed in AMENT_PREFIX_PATH "
            f"(build the workspace: tools/bootstrap.sh, then source tools/env.sh): {exc}"
        ) from None


def share_file(package: str, *parts: str) -> Path:
    """``share/<package>/<parts...>``; refused with the path when it is missing."""
    path = share_dir(package).joinpath(*parts)
    if not path.is_file():
        raise DataFileError(f"{path}: no such file in the installed {package} package")
    return path


def resolve_data_file(path: str | Path, package: str, subdir: str) -> Path:
    """A data file given as a path (absolute or relative to the working directory), or by
    name in ``share/<package>/<subdir>``."""
    p = Path(path).expanduser()
    candidates = [p if p.is_absolute() else Path.cwd() / p]
    if not p.is_absolute():
        candidates.append(share_dir(package) / subdir / p.name)
    for c in candidates:
        if c.is_file():
            return c
    raise DataFileError(
        f"file {str(path)!r} not found (looked in: {', '.join(str(c) for c in candidates)})"
    )
