"""The maze text format (docs/mazes.md, Maze format) and grid geometry.

One row per line, all rows the same length::

    #  wall                 .  free
    S  start (exactly one)  G  the default goal
    1-9  named goal cells (free)
    a-z  free cells that become walls when event a-z fires (blocking)
    A-Z  (other than S, G) walls that open when event a-z fires (shortcuts)

Coordinates are ``(row, col)`` from the top left, row 0 at the top. A malformed file
is refused with a :class:`MazeError` naming the line and column of the first problem.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

Cell = tuple[int, int]

#: Actions in the order of their indices. Motor vectors are (d_row, d_col).
ACTIONS: tuple[str, ...] = ("up", "down", "left", "right")
ACTION_VECTORS = np.array([(-1, 0), (1, 0), (0, -1), (0, 1)], dtype=float)
N_ACTIONS = len(ACTIONS)

WALL, FREE = "#", "."
_GOAL_NAMES = "G123456789"


class MazeError(ValueError):
    """A maze that cannot be used; the message names the source, line and column."""

    def __init__(self, message: str, source: str = "<maze>", line: int | None = None,
                 column: int | None = None):
        where = source
        if line is not None:
            where += f":{line}"
            if column is not None:
                where += f":{column}"
        super().__init__(f"{where}: {message}")
        self.source, self.line, self.column = source, line, column


@dataclass
class Maze:
    """A parsed maze. ``walls[r, c]`` is the layout *before* any event fires."""

    walls: np.ndarray                       # bool (rows, cols)
    start: Cell
    goals: dict[str, Cell]                  # "G", "1".."9"
    events: dict[str, dict[str, list[Cell]]] = field(default_factory=dict)
    # events[e] = {"block": [cells that become walls], "open": [walls that open]}
    source: str = "<maze>"

    # ------------------------------------------------------------------ parsing
    @classmethod
    def from_text(cls, text: str, source: str = "<maze>") -> "Maze":
        lines = text.splitlines()
        while lines and not lines[-1].strip():
            lines.pop()
        if not lines:
            raise MazeError("the maze is empty", source)
        width = len(lines[0])
        if width == 0:
            raise MazeError("the first row is empty", source, 1, 1)
        walls = np.zeros((len(lines), width), dtype=bool)
        start: Cell | None = None
        goals: dict[str, Cell] = {}
        events: dict[str, dict[str, list[Cell]]] = {}
        for r, line in enumerate(lines):
            if len(line) != width:
                raise MazeError(f"row has {len(line)} characters, expected {width} "
                                "(all rows must be the same length)", source, r + 1,
                                min(len(line), width) + 1)
            for c, ch in enumerate(line):
                if ch == WALL:
                    walls[r, c] = True
                elif ch == FREE:
                    pass
                elif ch == "S":
                    if start is not None:
                        raise MazeError(f"second start 'S' (the first is at line "
                                        f"{start[0] + 1}, column {start[1] + 1})",
                                        source, r + 1, c + 1)
                    start = (r, c)
                elif ch in _GOAL_NAMES:
                    if ch in goals:
                        raise MazeError(f"goal {ch!r} appears twice", source, r + 1, c + 1)
                    goals[ch] = (r, c)
                elif "a" <= ch <= "z":
                    events.setdefault(ch, {"block": [], "open": []})["block"].append((r, c))
                elif "A" <= ch <= "Z":
                    walls[r, c] = True
                    events.setdefault(ch.lower(), {"block": [], "open": []})["open"].append((r, c))
                else:
                    raise MazeError(f"unknown character {ch!r} (expected one of "
                                    "'#', '.', 'S', 'G', '1'-'9', 'a'-'z', 'A'-'Z')",
                                    source, r + 1, c + 1)
        if start is None:
            raise MazeError("no start cell 'S'", source)
        maze = cls(walls=walls, start=start, goals=goals, events=events, source=source)
        maze._check_reachable()
        return maze

    @classmethod
    def from_file(cls, path: str | Path) -> "Maze":
        path = Path(path)
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise MazeError(f"cannot read maze file: {exc.strerror}", str(path)) from exc
        return cls.from_text(decode_text(data, str(path)), source=str(path))

    def _check_reachable(self) -> None:
        dist = bfs_distances(self.walls, self.start)
        for name, (r, c) in sorted(self.goals.items()):
            if dist[r, c] < 0:
                raise MazeError(f"goal {name!r} cannot be reached from the start",
                                self.source, r + 1, c + 1)

    # ------------------------------------------------------------------ geometry
    @property
    def shape(self) -> tuple[int, int]:
        return self.walls.shape  # type: ignore[return-value]

    def free_cells(self, walls: np.ndarray | None = None) -> list[Cell]:
        w = self.walls if walls is None else walls
        return [(int(r), int(c)) for r, c in zip(*np.nonzero(~w))]

    def goal_cell(self, goal: str | Cell) -> Cell:
        """A goal given by name ('G', '1'..'9') or as a (row, col) cell."""
        if isinstance(goal, str):
            if goal not in self.goals:
                known = ", ".join(sorted(self.goals)) or "none"
                raise MazeError(f"no goal named {goal!r} (goals: {known})", self.source)
            return self.goals[goal]
        r, c = int(goal[0]), int(goal[1])
        self.check_free(r, c)
        return (r, c)

    def check_free(self, r: int, c: int, walls: np.ndarray | None = None) -> None:
        w = self.walls if walls is None else walls
        rows, cols = w.shape
        if not (0 <= r < rows and 0 <= c < cols):
            raise MazeError(f"cell (row {r}, col {c}) is outside the {rows}x{cols} maze",
                            self.source)
        if w[r, c]:
            raise MazeError(f"cell (row {r}, col {c}) is a wall", self.source)

    def walls_after(self, fired: Iterable[str]) -> np.ndarray:
        """The wall layout after the given events have fired (in order)."""
        w = self.walls.copy()
        for e in fired:
            ev = self.events.get(e)
            if ev is None:
                known = ", ".join(sorted(self.events)) or "none"
                raise MazeError(f"no event named {e!r} (events: {known})", self.source)
            for r, c in ev["block"]:
                w[r, c] = True
            for r, c in ev["open"]:
                w[r, c] = False
        return w

    def shortest_path_length(self, a: Cell, b: Cell, walls: np.ndarray | None = None) -> int:
        """BFS path length in steps from a to b, or -1 when b cannot be reached."""
        d = bfs_distances(self.walls if walls is None else walls, a)
        return int(d[b])


def decode_text(data: bytes, source: str = "<maze>") -> str:
    """UTF-8 ``data`` as text, or a :class:`MazeError` naming the line and column of the
    first byte that is not UTF-8."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        start = data.rfind(b"\n", 0, exc.start) + 1
        line = data.count(b"\n", 0, exc.start) + 1
        column = len(data[start:exc.start].decode("utf-8")) + 1
        raise MazeError(f"not UTF-8 text (byte 0x{data[exc.start]:02x}): a maze is a text "
                        "file of '#', '.', 'S', 'G', '1'-'9', 'a'-'z', 'A'-'Z'", source,
                        line, column) from None


def bfs_distances(walls: np.ndarray, source: Cell) -> np.ndarray:
    """Steps from ``source`` to every cell (4-connected); -1 for walls and unreachable."""
    rows, cols = walls.shape
    dist = np.full((rows, cols), -1, dtype=int)
    if walls[source]:
        return dist
    dist[source] = 0
    queue = deque([source])
    while queue:
        r, c = queue.popleft()
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            nr, nc = r + dr, c + dc
            if 0 <= nr < rows and 0 <= nc < cols and not walls[nr, nc] and dist[nr, nc] < 0:
                dist[nr, nc] = dist[r, c] + 1
                queue.append((nr, nc))
    return dist


def move(walls: np.ndarray, cell: Cell, action: int) -> tuple[Cell, bool]:
    """The cell reached by ``action`` from ``cell`` and whether the move bumped."""
    dr, dc = ACTION_VECTORS[action]
    r, c = cell[0] + int(dr), cell[1] + int(dc)
    rows, cols = walls.shape
    if not (0 <= r < rows and 0 <= c < cols) or walls[r, c]:
        return cell, True
    return (r, c), False


def generate_maze(rows: int, cols: int, rng: np.random.Generator, loop_fraction: float = 0.1,
                  ) -> str:
    """A random perfect maze (recursive backtracker) with some walls knocked out for loops.

    ``rows`` and ``cols`` must be odd. S is placed top left, G bottom right. Used by the
    benchmarks and tests for mazes that are not the default one.
    """
    if rows % 2 == 0 or cols % 2 == 0 or rows < 5 or cols < 5:
        raise ValueError("rows and cols must be odd and at least 5")
    grid = np.ones((rows, cols), dtype=bool)
    stack = [(1, 1)]
    grid[1, 1] = False
    while stack:
        r, c = stack[-1]
        nbrs = [(r + dr, c + dc) for dr, dc in ((-2, 0), (2, 0), (0, -2), (0, 2))
                if 0 < r + dr < rows - 1 and 0 < c + dc < cols - 1 and grid[r + dr, c + dc]]
        if not nbrs:
            stack.pop()
            continue
        nr, nc = nbrs[rng.integers(len(nbrs))]
        grid[(r + nr) // 2, (c + nc) // 2] = False
        grid[nr, nc] = False
        stack.append((nr, nc))
    inner = [(r, c) for r in range(1, rows - 1) for c in range(1, cols - 1)
             if grid[r, c] and ((r % 2 == 1) != (c % 2 == 1))]
    for i in rng.permutation(len(inner))[: int(loop_fraction * len(inner))]:
        grid[inner[i]] = False
    chars = np.where(grid, WALL, FREE).astype("<U1")
    chars[1, 1] = "S"
    chars[rows - 2, cols - 2] = "G"
    return "\n".join("".join(row) for row in chars) + "\n"


#: The paper's 13 x 17 maze (section 5.1), installed in share/maze_sim/mazes.
DEFAULT_MAZE = "paper_13x17.txt"


def maze_file(name_or_path: str | Path = DEFAULT_MAZE) -> Path:
    """A maze file given as a path, or by name among the mazes maze_sim installs."""
    from tmgwr_common.share import resolve_data_file

    return resolve_data_file(name_or_path, "maze_sim", "mazes")
