"""A seeded suite of generated mazes, each with named goals and validated events.

``suite("braided:10", seed=0)`` (or ``"all:3"``, or ``"rooms:5,open:5"``) returns
:class:`SuiteMaze` objects; ``generate(family, index, seed)`` one of them. The same
``(family, index, seed)`` always gives the same text: the generator draws from
``numpy.random.SeedSequence([seed, crc32(family), index, attempt])`` and, when a draw
fails :func:`validate`, moves on to the next ``attempt`` (deterministic retries). The
text is the project's maze format (docs/mazes.md, Maze format), so ``sm.write(dir)`` gives a
file every experiment can load with ``--maze``. An experiment over a suite::

    for sm in suite(spec, seed):                  # spec "FAMILY[:N]" from --suite
        path = sm.write(out_dir)
        env_change.run(str(path), agents, trials, seed, event=sm.block_event)  # if set
        # openings: sm.open_event; goal-change: goals=sm.goal_sequence

Families (free cells, the size an agent has to map):

``braided`` (about 70-210)
    A perfect maze carved by a recursive backtracker or by Kruskal's algorithm (long
    corridors versus many short dead ends), then a share of 0.08-0.2 of the remaining inner walls
    knocked out: loops, so that a blocked corridor has a way round it.
``rooms`` (about 50-330)
    2 x 2 to 3 x 3 rooms of random sizes joined by one-cell doors (a spanning tree of
    doors plus extra ones; the 2 x 2 case has all four doors: Sutton, Precup & Singh's
    four rooms). Shortest paths are wide inside a room and one cell wide at a door.
``open`` (about 50-230)
    An open field with random rectangular obstacles (a share of 0.15-0.28 of it); pockets that the
    obstacles cut off are filled. Shortest paths are many and wide.
``blocking`` (about 40-130)
    Sutton & Barto's blocking maze (Fig. 8.4) with random size, wall height, start
    column, a few stray obstacles, mirrored or transposed: a wall across the field with a
    gap at the goal's end. The block event closes that gap (lowercase cells) and opens
    the other end of the wall (uppercase cells), so the detour is long; in about a third
    of the mazes the far gap is already open and the event only closes the near one.
``shortcut`` (about 30-130)
    Sutton & Barto's shortcut maze (Fig. 8.5) drawn the same way: the wall's gap is at
    the far end; the opening event opens a cell of the wall's goal-side half (uppercase),
    a strictly shorter route.
``large`` (about 1000-1300)
    41 x 61-class mazes: braided ones at even indices, 5-7 x 7-9 grids of rooms at odd
    indices, kept between 1000 and 1300 free cells (:data:`MAX_FREE_CELLS`).

Start and goal (``braided``, ``rooms``, ``open``, ``large``): ``S`` is drawn among the
cells farthest (at least 0.8 of the maximum BFS distance) from a random cell, ``G`` among the
cells farthest from ``S``: a long route, different each time.

Named goals for goal-change (``SuiteMaze.goals`` = ``1``-``4``), as the paper's section
5.2.1 places them: ``1`` and ``2`` near the start (0.15-0.45 of the largest BFS distance
from S), ``3`` and ``4`` far (0.65-1), never on S, G or an event cell, at least a sixth
of that distance apart, and no named goal on any shortest path from S to another one
(goal-change keeps the previous goal terminal, so a goal on the way would end the
episode before the agent could reach the new one).

Events: ``a`` (:data:`BLOCK_EVENT`) is always a block, ``b`` (:data:`OPEN_EVENT`) always an
opening. ``braided``, ``rooms``, ``open`` and ``large`` get both (each is checked against
the layout before any event); ``blocking`` gets ``a``, ``shortcut`` gets ``b``.

* Block (why: the agent learnt *one* optimal route, and we do not know which, so the
  block must cut all of them, and the goal must stay reachable for the agent to adapt).
  Its cells are a *distance layer of the shortest-path DAG*: the cells ``c`` with
  ``dS(c) + dG(c) = d(S, G)`` and ``dS(c) = k``. Every shortest path visits exactly one
  cell of each layer, so walling a layer closes every shortest path; a layer of width 1
  is a cell that all shortest paths share (a corridor cell, a door). Among the layers
  with ``k`` in the middle seven tenths of the route, we take the narrowest ones (at most
  :data:`MAX_BLOCK_WIDTH` cells) whose closing leaves G and every named goal reachable,
  and among (up to 24 of) those one whose detour adds at least a fifth of the route if
  there is one (a block that costs two steps tests little), else the longest detour;
  ties drawn at random. A layer is a cut of the DAG but not always the smallest one; it
  is cheap, exact and easy to check.
* Opening (why: a shortcut is only news if it beats the route the agent knows): a
  straight run of 1 (``open``: up to 3) inner wall cells whose removal makes the S-G
  distance strictly shorter (no shorter run inside it does), drawn at random among
  those that save at least a fifth of the route, or among those that save the most when
  none does.

:func:`validate` re-checks all of it from the text alone (parse, goals, every old
shortest path closed, detour, strict shortening, sizes) and raises :class:`SuiteError`.
Only numpy and the standard library; no ROS.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from maze_sim.maze import FREE, WALL, Maze, MazeError, bfs_distances

Cell = tuple[int, int]

FAMILIES: tuple[str, ...] = ("braided", "rooms", "open", "blocking", "shortcut", "large")
DEFAULT_N = 10
BLOCK_EVENT, OPEN_EVENT = "a", "b"
GOALS: tuple[str, ...] = ("1", "2", "3", "4")      # 1, 2 near the start; 3, 4 far
MAX_FREE_CELLS = 1300
LARGE_MIN_FREE = 1000
MAX_BLOCK_WIDTH = 4
MAX_ATTEMPTS = 100

_DIRS = ((-1, 0), (1, 0), (0, -1), (0, 1))


class SuiteError(ValueError):
    """A bad suite spec, or a generated maze that breaks a suite rule (names the maze)."""


class _Retry(Exception):
    """This draw cannot be completed; the generator moves on to the next attempt."""


@dataclass(frozen=True, eq=True)
class SuiteMaze:
    """One generated maze and what the experiments need to know about it."""

    name: str                       # "braided-03"
    family: str
    index: int
    seed: int
    text: str                       # the maze file (docs/mazes.md, Maze format)
    goals: tuple[str, ...]          # named goals for goal-change, near ones first
    block_event: str | None         # closes every shortest S-G path, leaves a detour
    open_event: str | None          # opens a strictly shorter S-G path
    shortest: dict = field(default_factory=dict)   # {"before": d, "a": d_after_a, ...}
    info: dict = field(default_factory=dict)       # family parameters, attempt number

    __hash__ = None  # type: ignore[assignment]

    @property
    def events(self) -> tuple[str, ...]:
        return tuple(e for e in (self.block_event, self.open_event) if e)

    @property
    def goal_sequence(self) -> tuple[str, ...]:
        """The goal-change order, like the paper's 1, 2, 3, 4, 1."""
        return self.goals + self.goals[:1]

    @property
    def free_cells(self) -> int:
        return sum(ch != WALL and not ("A" <= ch <= "Z" and ch not in "SG")
                   for ch in self.text if ch != "\n")

    def maze(self) -> Maze:
        return Maze.from_text(self.text, source=self.name)

    def write(self, directory: str | Path) -> Path:
        """Write ``NAME.txt`` into ``directory`` (created if needed); returns the path."""
        path = Path(directory) / f"{self.name}.txt"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(self.text)
        return path


# ---------------------------------------------------------------------------- public API
def parse_spec(spec: str) -> list[tuple[str, int]]:
    """``"FAMILY[:N]"``, ``"all[:N]"`` or a comma list of them -> ``[(family, n), ...]``."""
    out: list[tuple[str, int]] = []
    for part in spec.split(","):
        part = part.strip()
        name, _, count = part.partition(":")
        name = name.strip().lower()
        if name != "all" and name not in FAMILIES:
            raise SuiteError(f"unknown maze family {name!r} in suite spec {spec!r} "
                             f"(families: {', '.join(FAMILIES)}, or all)")
        n = DEFAULT_N
        if count:
            try:
                n = int(count)
            except ValueError:
                n = -1
            if n < 1:
                raise SuiteError(f"suite spec {spec!r}: the count after ':' must be a "
                                 f"positive integer, got {count!r}")
        for fam in (FAMILIES if name == "all" else (name,)):
            out.append((fam, n))
    return out


def suite(spec: str, seed: int = 0, first: int = 0) -> list[SuiteMaze]:
    """The mazes of ``spec`` (see :func:`parse_spec`), indices ``first .. first+N-1`` of
    each family (a disjoint ``first`` gives a held-out split with the same seed)."""
    return [generate(fam, first + i, seed) for fam, n in parse_spec(spec) for i in range(n)]


def generate(family: str, index: int, seed: int = 0) -> SuiteMaze:
    """Maze ``index`` of ``family`` for ``seed``: deterministic, validated."""
    if family not in FAMILIES:
        raise SuiteError(f"unknown maze family {family!r} (families: {', '.join(FAMILIES)})")
    if index < 0 or seed < 0:
        raise SuiteError(f"index and seed must be >= 0, got index {index}, seed {seed}")
    fam_id = zlib.crc32(family.encode())
    last = "no attempt"
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng(np.random.SeedSequence([seed, fam_id, index, attempt]))
        try:
            draft = _BUILDERS[family](rng, index)
            sm = _complete(draft, rng, family, index, seed, attempt)
            validate(sm)
            return sm
        except (_Retry, SuiteError, MazeError) as exc:
            last = str(exc)
    raise SuiteError(f"{family}-{index:02d} (seed {seed}): no valid maze in {MAX_ATTEMPTS} "
                     f"attempts; last problem: {last}")


def validate(sm: SuiteMaze) -> Maze:
    """Check a suite maze from its text alone; returns the parsed :class:`Maze`.

    Raises :class:`SuiteError` naming the maze when: the text does not parse; S, G or a
    named goal is missing or unreachable, or a free cell is unreachable; the goals break
    the near/far and not-on-the-way rules; the block event leaves a shortest S-G path of
    the old layout open, leaves G or a goal unreachable, or does not lengthen the route;
    the opening event closes a cell or does not make the route strictly shorter; the maze
    has more than :data:`MAX_FREE_CELLS` free cells.
    """
    def fail(msg: str):
        raise SuiteError(f"{sm.name}: {msg}")

    try:
        maze = Maze.from_text(sm.text, source=sm.name)
    except MazeError as exc:
        raise SuiteError(f"{sm.name}: does not parse: {exc}") from exc
    if "G" not in maze.goals:
        fail("no default goal 'G'")
    for g in sm.goals:
        if g not in maze.goals:
            fail(f"named goal {g!r} is not in the maze")
    walls, start, goal = maze.walls, maze.start, maze.goals["G"]
    ds = bfs_distances(walls, start)
    if np.any(~walls & (ds < 0)):
        r, c = np.argwhere(~walls & (ds < 0))[0]
        fail(f"free cell (row {r}, col {c}) cannot be reached from S")
    n_free = int((~walls).sum())
    if n_free > MAX_FREE_CELLS:
        fail(f"{n_free} free cells, more than {MAX_FREE_CELLS}")
    d = int(ds[goal])
    if d < 4:
        fail(f"S and G are only {d} steps apart")
    _check_goals(maze, sm.goals, ds, fail)
    declared = set(sm.events)
    if set(maze.events) != declared:
        fail(f"events in the text {sorted(maze.events)} differ from the declared "
             f"{sorted(declared)}")
    if sm.block_event:
        _check_block(maze, sm.block_event, sm.goals, ds, fail)
    if sm.open_event:
        ev = maze.events[sm.open_event]
        if ev["block"]:
            fail(f"opening event {sm.open_event!r} also closes cells")
        d_new = maze.shortest_path_length(start, goal, maze.walls_after([sm.open_event]))
        if not 0 <= d_new < d:
            fail(f"opening event {sm.open_event!r} does not shorten the S-G path "
                 f"({d} -> {d_new} steps)")
    return maze


def shortest_path_dag(walls: np.ndarray, start: Cell, goal: Cell
                      ) -> tuple[np.ndarray, np.ndarray, int]:
    """``(on, dS, d)``: the cells on some shortest start-goal path, BFS distances from
    start, and the path length (``on`` all False when goal is unreachable)."""
    ds, dg = bfs_distances(walls, start), bfs_distances(walls, goal)
    d = int(ds[goal])
    on = (ds >= 0) & (dg >= 0) & (ds + dg == d)
    return on, ds, d


def open_shortest_path(walls_before: np.ndarray, walls_after: np.ndarray, start: Cell,
                       goal: Cell) -> bool:
    """Whether some shortest path of ``walls_before`` uses no cell that is a wall in
    ``walls_after`` (walks the shortest-path DAG layer by layer)."""
    on, ds, d = shortest_path_dag(walls_before, start, goal)
    if d < 0 or walls_after[start]:
        return False
    rows, cols = walls_before.shape
    frontier = {start}
    for k in range(d):
        nxt = set()
        for r, c in frontier:
            for dr, dc in _DIRS:
                n = (r + dr, c + dc)
                if 0 <= n[0] < rows and 0 <= n[1] < cols and on[n] and ds[n] == k + 1 \
                        and not walls_after[n]:
                    nxt.add(n)
        frontier = nxt
    return goal in frontier


# ---------------------------------------------------------------------------- validation
def _check_goals(maze: Maze, names, ds, fail) -> None:
    cells = [maze.goals[g] for g in names]
    dist = [int(ds[c]) for c in cells]
    half = len(names) // 2
    if half and max(dist[:half]) >= min(dist[half:]):
        fail(f"goals {names[:half]} (at {dist[:half]} steps from S) are not nearer than "
             f"goals {names[half:]} (at {dist[half:]})")
    from_goal = {g: bfs_distances(maze.walls, maze.goals[g]) for g in names}
    for x in names:
        for y in names:
            if x != y and ds[maze.goals[x]] + from_goal[x][maze.goals[y]] == ds[maze.goals[y]]:
                fail(f"goal {x!r} lies on a shortest path from S to goal {y!r}")


def _check_block(maze: Maze, e: str, goals, ds, fail) -> None:
    start, goal = maze.start, maze.goals["G"]
    ev = maze.events[e]
    if not ev["block"]:
        fail(f"block event {e!r} closes no cell")
    after = maze.walls_after([e])
    if open_shortest_path(maze.walls, after, start, goal):
        fail(f"block event {e!r} leaves a shortest S-G path of the old layout open")
    d_new = bfs_distances(after, start)
    if d_new[goal] < 0:
        fail(f"block event {e!r} leaves no detour: G cannot be reached")
    if d_new[goal] <= ds[goal]:
        fail(f"block event {e!r} does not lengthen the route ({ds[goal]} -> {d_new[goal]})")
    for g in goals:
        if d_new[maze.goals[g]] < 0:
            fail(f"block event {e!r} cuts goal {g!r} off")


# ---------------------------------------------------------------------------- drafts
@dataclass
class _Draft:
    """A family's layout before goals and generic events are added."""

    walls: np.ndarray
    info: dict
    start: Cell | None = None
    goal: Cell | None = None
    block: tuple[list[Cell], list[Cell]] | None = None   # (cells closed, walls opened)
    opening: list[Cell] | None = None
    want_block: bool = True
    want_open: bool = True
    open_max_len: int = 1


def _complete(dr: _Draft, rng, family: str, index: int, seed: int, attempt: int
              ) -> SuiteMaze:
    walls = dr.walls
    if dr.start is None:
        dr.start, dr.goal = _far_pair(walls, rng)
    start, goal = dr.start, dr.goal
    forbidden = set(dr.block[0]) if dr.block else set()
    goals = _place_goals(walls, start, goal, forbidden, rng)
    block = dr.block
    if block is None and dr.want_block:
        block = (_layer_cut(walls, start, goal, set(goals.values()), rng), [])
    opening = dr.opening
    if opening is None and dr.want_open:
        opening = _opening(walls, start, goal, dr.open_max_len, rng)

    chars = np.where(walls, WALL, FREE).astype("<U1")
    chars[start], chars[goal] = "S", "G"
    for name, cell in goals.items():
        chars[cell] = name
    shortest = {"before": int(bfs_distances(walls, start)[goal])}
    if block:
        after = walls.copy()
        for c in block[0]:
            chars[c], after[c] = BLOCK_EVENT, True
        for c in block[1]:
            chars[c], after[c] = BLOCK_EVENT.upper(), False
        shortest[BLOCK_EVENT] = int(bfs_distances(after, start)[goal])
    if opening:
        after = walls.copy()
        for c in opening:
            chars[c], after[c] = OPEN_EVENT.upper(), False
        shortest[OPEN_EVENT] = int(bfs_distances(after, start)[goal])
    text = "\n".join("".join(row) for row in chars) + "\n"
    info = dict(dr.info, rows=int(walls.shape[0]), cols=int(walls.shape[1]),
                attempt=attempt)
    return SuiteMaze(name=f"{family}-{index:02d}", family=family, index=index, seed=seed,
                     text=text, goals=tuple(sorted(goals)),
                     block_event=BLOCK_EVENT if block else None,
                     open_event=OPEN_EVENT if opening else None,
                     shortest=shortest, info=info)


def _far_pair(walls: np.ndarray, rng) -> tuple[Cell, Cell]:
    free = np.argwhere(~walls)
    x = tuple(free[rng.integers(len(free))])
    s = _draw_far(bfs_distances(walls, x), rng)
    g = _draw_far(bfs_distances(walls, s), rng)
    return s, g


def _draw_far(dist: np.ndarray, rng, frac: float = 0.8) -> Cell:
    cand = np.argwhere(dist >= frac * dist.max())
    r, c = cand[rng.integers(len(cand))]
    return int(r), int(c)


def _place_goals(walls, start, goal, forbidden, rng, tries: int = 20) -> dict[str, Cell]:
    """Goals 1, 2 near S and 3, 4 far (sequential random draws, ``tries`` times)."""
    for _ in range(tries - 1):
        try:
            return _draw_goals(walls, start, goal, forbidden, rng)
        except _Retry:
            pass
    return _draw_goals(walls, start, goal, forbidden, rng)


def _draw_goals(walls, start, goal, forbidden, rng) -> dict[str, Cell]:
    ds = bfs_distances(walls, start)
    far = ds.max()
    sep = max(2, far // 6)
    ok = (ds >= 0)
    ok[start] = ok[goal] = False
    for c in forbidden:
        ok[c] = False
    bands = ((0.15, 0.45), (0.15, 0.45), (0.65, 1.0), (0.65, 1.0))
    chosen: list[Cell] = []
    for lo, hi in bands:
        cand = np.argwhere(ok & (ds >= max(2, lo * far)) & (ds <= hi * far))
        if not len(cand):
            raise _Retry("no room for the named goals")
        r, c = cand[rng.integers(len(cand))]
        cell = (int(r), int(c))
        chosen.append(cell)
        dx = bfs_distances(walls, cell)
        # Later goals: apart from this one, not on its shortest paths from S and not
        # having it on theirs.
        ok &= (dx >= sep) & (ds[cell] + dx != ds) & (ds + dx != ds[cell])
    near = sorted(chosen[:2], key=lambda c: (ds[c], c))
    far_ = sorted(chosen[2:], key=lambda c: (ds[c], c))
    return dict(zip(GOALS, near + far_))


def _layer_cut(walls, start, goal, keep: set, rng, sample: int = 24) -> list[Cell]:
    on, ds, d = shortest_path_dag(walls, start, goal)
    lo, hi = max(2, math.ceil(0.15 * d)), min(d - 2, math.floor(0.85 * d))
    layers = []
    for k in range(lo, hi + 1):
        cells = [(int(r), int(c)) for r, c in np.argwhere(on & (ds == k))]
        if len(cells) <= MAX_BLOCK_WIDTH and not keep.intersection(cells):
            layers.append((len(cells), rng.random(), cells))
    layers.sort()
    # The narrowest layers first; among (at most ``sample`` of) them prefer a detour of
    # at least a fifth of the route (a block that barely costs anything tests little).
    want = max(4, math.ceil(0.2 * d))
    scored = []
    for width, tie, cells in layers:
        if scored and (width > scored[0][0] or len(scored) >= sample):
            break
        after = walls.copy()
        for c in cells:
            after[c] = True
        dn = bfs_distances(after, start)
        if dn[goal] >= 0 and all(dn[c] >= 0 for c in keep):
            scored.append((width, -min(int(dn[goal]) - d, want), tie, cells))
    if not scored:
        raise _Retry("no distance layer of the shortest-path DAG blocks with a detour")
    return min(scored)[3]


def _opening(walls, start, goal, max_len: int, rng) -> list[Cell]:
    ds, dg = bfs_distances(walls, start), bfs_distances(walls, goal)
    d = int(ds[goal])
    rows, cols = walls.shape
    big = 10 ** 9

    def best_nb(dist, r, c):
        m = big
        for dr, dc in _DIRS:
            v = dist[r + dr, c + dc]
            if v >= 0 and v < m:
                m = v
        return m

    inner = np.zeros_like(walls)
    inner[1:-1, 1:-1] = walls[1:-1, 1:-1]
    cands: dict[tuple, int] = {}
    for r0, c0 in np.argwhere(inner):
        for vr, vc in ((0, 1), (1, 0)):
            run = []
            for i in range(max_len):
                r, c = int(r0) + i * vr, int(c0) + i * vc
                if not inner[r, c]:
                    break
                run.append((r, c))
                # Enter the run at cell p, walk along it to cell q, leave: an upper bound
                # on the new distance (a real path), exact for a single cell.
                ins = [best_nb(ds, *p) for p in run]
                outs = [best_nb(dg, *q) for q in run]
                new = min(ins[p] + 2 + abs(p - q) + outs[q]
                          for p in range(len(run)) for q in range(len(run)))
                if new < d:
                    cands.setdefault(tuple(run), d - new)
    # Keep the minimal runs: drop a run that contains a shorter one that also works.
    runs = sorted(run for run in cands
                  if not any(run[i:j] in cands for i in range(len(run))
                             for j in range(i + 1, len(run) + 1) if j - i < len(run)))
    if not runs:
        raise _Retry("no wall opening shortens the route")
    want = max(2, min(max(cands[run] for run in runs), math.ceil(0.2 * d)))
    good = [run for run in runs if cands[run] >= want]
    return list(good[rng.integers(len(good))])


# ---------------------------------------------------------------------------- carvers
def _perfect_maze(rows: int, cols: int, rng, carver: str) -> np.ndarray:
    """Walls of a perfect maze on odd dimensions; cells at odd (row, col)."""
    grid = np.ones((rows, cols), dtype=bool)
    cells = [(r, c) for r in range(1, rows - 1, 2) for c in range(1, cols - 1, 2)]
    if carver == "dfs":
        stack = [cells[rng.integers(len(cells))]]
        grid[stack[0]] = False
        while stack:
            r, c = stack[-1]
            nbrs = [(r + dr, c + dc) for dr, dc in ((-2, 0), (2, 0), (0, -2), (0, 2))
                    if 0 < r + dr < rows - 1 and 0 < c + dc < cols - 1
                    and grid[r + dr, c + dc]]
            if not nbrs:
                stack.pop()
                continue
            nr, nc = nbrs[rng.integers(len(nbrs))]
            grid[(r + nr) // 2, (c + nc) // 2] = grid[nr, nc] = False
            stack.append((nr, nc))
        return grid
    # Kruskal: shuffle the inner walls between cells, knock out those joining two trees.
    parent = {c: c for c in cells}

    def root(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for c in cells:
        grid[c] = False
    between = _inner_walls(grid)
    for i in rng.permutation(len(between)):
        (r, c), a, b = between[i]
        ra, rb = root(a), root(b)
        if ra != rb:
            parent[ra] = rb
            grid[r, c] = False
    return grid


def _inner_walls(grid: np.ndarray) -> list[tuple[Cell, Cell, Cell]]:
    """Wall cells between two cells of a lattice maze, with the two cells."""
    rows, cols = grid.shape
    out = []
    for r in range(1, rows - 1):
        for c in range(1, cols - 1):
            if not grid[r, c]:
                continue
            if r % 2 == 1 and c % 2 == 0:
                out.append(((r, c), (r, c - 1), (r, c + 1)))
            elif r % 2 == 0 and c % 2 == 1:
                out.append(((r, c), (r - 1, c), (r + 1, c)))
    return out


def _braid(grid: np.ndarray, fraction: float, rng) -> np.ndarray:
    between = _inner_walls(grid)
    for i in rng.permutation(len(between))[: int(round(fraction * len(between)))]:
        grid[between[i][0]] = False
    return grid


def _odd(rng, lo: int, hi: int) -> int:
    return int(rng.choice(np.arange(lo, hi + 1, 2)))


def _rooms(rng, heights, widths, extra_door_p: float) -> np.ndarray:
    """A grid of rooms (interiors ``heights[i] x widths[j]``) joined by one-cell doors:
    a random spanning tree of doors plus each other door with ``extra_door_p``."""
    nr, nc = len(heights), len(widths)
    r0 = np.concatenate([[1], 1 + np.cumsum([h + 1 for h in heights])])
    c0 = np.concatenate([[1], 1 + np.cumsum([w + 1 for w in widths])])
    grid = np.ones((int(r0[-1]), int(c0[-1])), dtype=bool)
    for i in range(nr):
        for j in range(nc):
            grid[r0[i]:r0[i] + heights[i], c0[j]:c0[j] + widths[j]] = False
    doors = []   # (room a, room b, door cell)
    for i in range(nr):
        for j in range(nc):
            if j + 1 < nc:
                doors.append(((i, j), (i, j + 1),
                              (int(r0[i] + rng.integers(heights[i])), int(c0[j + 1] - 1))))
            if i + 1 < nr:
                doors.append(((i, j), (i + 1, j),
                              (int(r0[i + 1] - 1), int(c0[j] + rng.integers(widths[j])))))
    parent = {(i, j): (i, j) for i in range(nr) for j in range(nc)}

    def root(x):
        while parent[x] != x:
            x = parent[x]
        return x

    for k in rng.permutation(len(doors)):
        a, b, cell = doors[k]
        ra, rb = root(a), root(b)
        if ra != rb:
            parent[ra] = rb
            grid[cell] = False
        elif rng.random() < extra_door_p:
            grid[cell] = False
    return grid


# ---------------------------------------------------------------------------- families
def _braided(rng, index: int) -> _Draft:
    rows, cols = _odd(rng, 11, 17), _odd(rng, 15, 25)
    carver = str(rng.choice(["dfs", "kruskal"]))
    loops = float(rng.uniform(0.08, 0.2))
    walls = _braid(_perfect_maze(rows, cols, rng, carver), loops, rng)
    return _Draft(walls, {"carver": carver, "loop_fraction": round(loops, 3)})


def _rooms_family(rng, index: int) -> _Draft:
    nr, nc = [(2, 2), (2, 3), (3, 2), (3, 3)][rng.integers(4)]
    heights = [int(h) for h in rng.integers(3, 7, nr)]
    widths = [int(w) for w in rng.integers(3, 8, nc)]
    extra = 1.0 if (nr, nc) == (2, 2) else 0.5
    return _Draft(_rooms(rng, heights, widths, extra),
                  {"rooms": [nr, nc], "heights": heights, "widths": widths})


def _open(rng, index: int) -> _Draft:
    rows, cols = int(rng.integers(9, 16)), int(rng.integers(13, 24))
    walls = np.ones((rows, cols), dtype=bool)
    walls[1:-1, 1:-1] = False
    density = float(rng.uniform(0.15, 0.28))
    area = (rows - 2) * (cols - 2)
    while walls[1:-1, 1:-1].sum() < density * area:
        h, w = int(rng.integers(1, 3)), int(rng.integers(1, 5))
        if rng.random() < 0.5:
            h, w = w, h
        r, c = int(rng.integers(1, rows - 1)), int(rng.integers(1, cols - 1))
        walls[r:min(r + h, rows - 1), c:min(c + w, cols - 1)] = True
    _fill_pockets(walls)
    return _Draft(walls, {"obstacle_density": round(density, 3)}, open_max_len=3)


def _fill_pockets(walls: np.ndarray) -> None:
    """Wall up every free cell outside the largest connected region (in place)."""
    seen = np.zeros_like(walls)
    best = None
    for r, c in np.argwhere(~walls):
        if seen[r, c]:
            continue
        region = bfs_distances(walls, (int(r), int(c))) >= 0
        seen |= region
        if best is None or region.sum() > best.sum():
            best = region
    walls |= ~best


def _wall_field(rng, shortcut: bool) -> _Draft:
    """Sutton & Barto's blocking (``shortcut=False``) or shortcut maze, randomised.

    Drawn with G in the top right, the wall on row ``rw``; then mirrored / transposed.
    """
    h, w = int(rng.integers(5, 10)), int(rng.integers(8, 17))
    rw = int(rng.integers(3, h - 1))           # rows 1..rw-1 above, rw+1..h below
    walls = np.ones((h + 2, w + 2), dtype=bool)
    walls[1:-1, 1:-1] = False
    walls[rw, 1:w + 1] = True
    start = (h, int(rng.integers(max(1, w // 3), max(2, 2 * w // 3) + 1)))
    goal = (1, w - int(rng.integers(0, 2)))
    info = {"wall_row": rw, "field": [h, w]}
    block = opening = None
    if not shortcut:
        near = [(rw, w)]
        far = [(rw, 1)]
        detour_open = bool(rng.random() < 1 / 3)
        walls[near[0]] = False
        if detour_open:
            walls[far[0]] = False
        block = (near, [] if detour_open else far)
        info["far_gap_open"] = detour_open
    else:
        walls[rw, 1] = False
        col = w if rng.random() < 0.5 else int(rng.integers(w // 2 + 1, w + 1))
        opening = [(rw, col)]
        info["opening_col"] = col
    keep = {start, goal, *(block[0] + block[1] if block else []), *(opening or [])}
    for _ in range(int(rng.integers(0, 4))):       # a few stray obstacles
        cell = (int(rng.integers(1, h + 1)), int(rng.integers(1, w + 1)))
        if cell not in keep and cell[0] != rw:
            walls[cell] = True
    # Random symmetry of the rectangle (cells move with the walls).
    flip_r, flip_c, transpose = (bool(rng.random() < 0.5) for _ in range(3))
    rows, cols = walls.shape

    def tf(cell: Cell) -> Cell:
        r, c = cell
        if flip_r:
            r = rows - 1 - r
        if flip_c:
            c = cols - 1 - c
        return (c, r) if transpose else (r, c)

    if flip_r:
        walls = walls[::-1]
    if flip_c:
        walls = walls[:, ::-1]
    if transpose:
        walls = walls.T
    walls = np.ascontiguousarray(walls)
    if block:
        block = ([tf(c) for c in block[0]], [tf(c) for c in block[1]])
    if opening:
        opening = [tf(c) for c in opening]
    info["symmetry"] = [flip_r, flip_c, transpose]
    if np.any(~walls & (bfs_distances(walls, tf(start)) < 0)):
        raise _Retry("a stray obstacle cut a pocket off")
    return _Draft(walls, info, start=tf(start), goal=tf(goal), block=block,
                  opening=opening, want_block=not shortcut, want_open=shortcut)


def _blocking(rng, index: int) -> _Draft:
    return _wall_field(rng, shortcut=False)


def _shortcut(rng, index: int) -> _Draft:
    return _wall_field(rng, shortcut=True)


def _large(rng, index: int) -> _Draft:
    if index % 2 == 0:
        rows, cols = _odd(rng, 37, 41), _odd(rng, 57, 61)
        carver = str(rng.choice(["dfs", "kruskal"]))
        loops = float(rng.uniform(0.05, 0.12))
        walls = _braid(_perfect_maze(rows, cols, rng, carver), loops, rng)
        info = {"kind": "braided", "carver": carver, "loop_fraction": round(loops, 3)}
    else:
        nr, nc = int(rng.integers(5, 8)), int(rng.integers(7, 10))
        heights = [int(x) for x in rng.integers(3, 6, nr)]
        widths = [int(x) for x in rng.integers(3, 7, nc)]
        walls = _rooms(rng, heights, widths, 0.3)
        info = {"kind": "rooms", "rooms": [nr, nc], "heights": heights, "widths": widths}
    n = int((~walls).sum())
    if not LARGE_MIN_FREE <= n <= MAX_FREE_CELLS:
        raise _Retry(f"{n} free cells, outside {LARGE_MIN_FREE}-{MAX_FREE_CELLS}")
    return _Draft(walls, info)


_BUILDERS = {"braided": _braided, "rooms": _rooms_family, "open": _open,
             "blocking": _blocking, "shortcut": _shortcut, "large": _large}


def main(argv: list[str] | None = None) -> int:
    """``python -m maze_sim.suite SPEC [--seed N] [--out DIR]``: print or write a suite."""
    import argparse

    p = argparse.ArgumentParser(prog="python -m maze_sim.suite", description=main.__doc__)
    p.add_argument("spec", help="FAMILY[:N], all[:N] or a comma list; families: "
                   + ", ".join(FAMILIES))
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", help="write NAME.txt files here instead of printing")
    a = p.parse_args(argv)
    try:
        mazes = suite(a.spec, a.seed)
    except SuiteError as exc:
        p.error(str(exc))
    for sm in mazes:
        line = (f"{sm.name}: {sm.free_cells} free cells, shortest {sm.shortest}, "
                f"block {sm.block_event}, open {sm.open_event}, info {sm.info}")
        if a.out:
            print(f"{sm.write(a.out)}  {line}")
        else:
            print(line + "\n" + sm.text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
