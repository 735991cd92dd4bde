"""The generated maze suite (maze_sim.suite): determinism, validity of every family,
events checked independently of the generator (path counting over the old layout, BFS on
``Maze.walls_after``), goal placement, sizes, generation time, and ``validate`` refusing
hand-made bad mazes."""

import dataclasses

import numpy as np
import pytest

from maze_sim.maze import Maze, bfs_distances
from maze_sim.suite import (
    FAMILIES,
    MAX_FREE_CELLS,
    SuiteError,
    SuiteMaze,
    generate,
    parse_spec,
    suite,
    validate,
)

INDICES = range(5)


@pytest.fixture(scope="module")
def mazes():
    return {(f, i): generate(f, i, seed=7) for f in FAMILIES for i in INDICES}


def count_shortest_paths(walls, start, goal, closed):
    """Number of shortest start-goal paths of ``walls`` that avoid every ``closed`` cell
    (dynamic programming over BFS distance; independent of the suite's own check)."""
    ds, dg = bfs_distances(walls, start), bfs_distances(walls, goal)
    d = ds[goal]
    count = np.zeros(walls.shape, dtype=object)
    count[start] = 0 if closed[start] else 1
    rows, cols = walls.shape
    for k in range(1, d + 1):
        for r, c in np.argwhere((ds == k) & (ds + dg == d)):
            if closed[r, c]:
                continue
            for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
                nr, nc = r + dr, c + dc
                if 0 <= nr < rows and 0 <= nc < cols and ds[nr, nc] == k - 1:
                    count[r, c] += count[nr, nc]
    return count[goal]


# ---------------------------------------------------------------------------- determinism
def test_same_seed_same_text_other_index_or_seed_other_maze():
    for fam in FAMILIES:
        a = generate(fam, 3, seed=11)
        assert generate(fam, 3, seed=11) == a
        assert generate(fam, 4, seed=11).text != a.text
        assert generate(fam, 3, seed=12).text != a.text
        assert a.name == f"{fam}-03" and a.family == fam and a.index == 3


def test_suite_spec_and_first_index():
    assert parse_spec("braided") == [("braided", 10)]
    assert parse_spec("all:2") == [(f, 2) for f in FAMILIES]
    assert parse_spec("rooms:3, open:1") == [("rooms", 3), ("open", 1)]
    ms = suite("rooms:3", seed=5)
    assert [m.name for m in ms] == ["rooms-00", "rooms-01", "rooms-02"]
    assert ms[1] == generate("rooms", 1, seed=5)
    held_out = suite("rooms:2", seed=5, first=3)
    assert [m.name for m in held_out] == ["rooms-03", "rooms-04"]
    for bad, words in (("mazes:3", "unknown maze family"), ("braided:0", "positive"),
                       ("braided:x", "positive"), ("all:-1", "positive")):
        with pytest.raises(SuiteError, match=words):
            parse_spec(bad)


def test_all_3_generates_every_family_once_per_index():
    ms = suite("all:3", seed=0)
    assert len(ms) == 3 * len(FAMILIES)
    assert len({m.name for m in ms}) == len(ms)


# ---------------------------------------------------------------------------- validity
@pytest.mark.parametrize("family", FAMILIES)
def test_every_family_valid(family, mazes):
    for i in INDICES:
        sm = mazes[family, i]
        maze = validate(sm)
        assert sm.free_cells == int((~maze.walls).sum()) <= MAX_FREE_CELLS
        d = maze.shortest_path_length(maze.start, maze.goals["G"])
        assert sm.shortest["before"] == d
        for e in sm.events:
            assert sm.shortest[e] == maze.shortest_path_length(
                maze.start, maze.goals["G"], maze.walls_after([e]))


def test_which_events_each_family_has(mazes):
    for (fam, i), sm in mazes.items():
        maze = sm.maze()
        if fam == "blocking":
            assert (sm.block_event, sm.open_event) == ("a", None)
            ev = maze.events["a"]
            # S&B: the old gap closes; unless the far gap is already open, the far end
            # of the same wall opens (same row or same column).
            if not sm.info["far_gap_open"]:
                cells = ev["block"] + ev["open"]
                assert ev["open"]
                assert len({r for r, _ in cells}) == 1 or len({c for _, c in cells}) == 1
            else:
                assert not ev["open"]
        elif fam == "shortcut":
            assert (sm.block_event, sm.open_event) == (None, "b")
        else:
            assert (sm.block_event, sm.open_event) == ("a", "b")
        assert set(maze.events) == set(sm.events)


def test_block_closes_every_shortest_path_and_leaves_a_detour(mazes):
    n = 0
    for sm in mazes.values():
        if not sm.block_event:
            continue
        maze = sm.maze()
        start, goal = maze.start, maze.goals["G"]
        after = maze.walls_after([sm.block_event])
        closed = after & ~maze.walls
        assert closed.any()
        assert count_shortest_paths(maze.walls, start, goal, np.zeros_like(closed)) >= 1
        assert count_shortest_paths(maze.walls, start, goal, closed) == 0, sm.name
        d_old = maze.shortest_path_length(start, goal)
        d_new = maze.shortest_path_length(start, goal, walls=after)
        assert d_new > d_old, sm.name                 # a detour, strictly longer
        dn = bfs_distances(after, start)
        for name in sm.goals:
            assert dn[maze.goals[name]] >= 0, (sm.name, name)
        n += 1
    assert n >= 20


def test_opening_makes_the_route_strictly_shorter(mazes):
    n = 0
    for sm in mazes.values():
        if not sm.open_event:
            continue
        maze = sm.maze()
        ev = maze.events[sm.open_event]
        assert ev["open"] and not ev["block"]
        assert all(maze.walls[c] for c in ev["open"])
        start, goal = maze.start, maze.goals["G"]
        d_new = maze.shortest_path_length(start, goal, maze.walls_after([sm.open_event]))
        assert 0 <= d_new < maze.shortest_path_length(start, goal), sm.name
        n += 1
    assert n >= 20


def test_goals_two_near_two_far_none_on_the_way_to_another(mazes):
    for sm in mazes.values():
        maze = sm.maze()
        assert sm.goals == ("1", "2", "3", "4")
        assert sm.goal_sequence == ("1", "2", "3", "4", "1")
        cells = [maze.goals[g] for g in sm.goals]
        assert len(set(cells + [maze.start, maze.goals["G"]])) == 6
        ds = bfs_distances(maze.walls, maze.start)
        dist = [ds[c] for c in cells]
        assert max(dist[:2]) < min(dist[2:]), (sm.name, dist)
        assert min(dist[2:]) >= 0.65 * ds.max() - 1e-9
        for x, cx in zip(sm.goals, cells):
            walled = maze.walls.copy()
            walled[cx] = True                # with x a wall, y is still as near
            dx = bfs_distances(walled, maze.start)
            for y, cy in zip(sm.goals, cells):
                if y != x:
                    assert dx[cy] == ds[cy], (sm.name, x, y)
        # No goal on an event cell (S, G and goals are their own characters) and every
        # free cell reachable in the trained layout.
        for e in sm.events:
            assert not set(maze.events[e]["block"]) & set(cells)
        assert (bfs_distances(maze.walls, maze.start)[~maze.walls] >= 0).all()


def test_sizes_per_family(mazes):
    free = {f: [mazes[f, i].free_cells for i in INDICES] for f in FAMILIES}
    assert all(1000 <= n <= 1300 for n in free["large"]), free["large"]
    assert {mazes["large", i].info["kind"] for i in INDICES} == {"braided", "rooms"}
    for f in ("braided", "rooms", "open", "blocking", "shortcut"):
        assert all(30 <= n <= 450 for n in free[f]), (f, free[f])


def test_write_round_trip(tmp_path):
    sm = generate("open", 2, seed=3)
    path = sm.write(tmp_path / "suite")
    assert path.name == "open-02.txt"
    maze = Maze.from_file(path)
    assert np.array_equal(maze.walls, sm.maze().walls)
    assert maze.events == sm.maze().events


def test_unknown_family_or_negative_index():
    with pytest.raises(SuiteError, match="unknown maze family"):
        generate("spiral", 0, 0)
    with pytest.raises(SuiteError, match=">= 0"):
        generate("braided", -1, 0)


# ---------------------------------------------------------------------------- validate refuses
# S (1,1) to G (1,11): 10 steps along row 1; event a at (1,6) closes it, the detour over
# row 3 takes 14. Goals in dead-end pockets below row 3 at 4, 6 (near), 10, 12 (far) steps.
HAND = ("#############\n"
        "#S....a....G#\n"
        "#.#########.#\n"
        "#...........#\n"
        "##1#2###3#4##\n"
        "#############\n")


def hand(text, block="a", open_=None, goals=("1", "2", "3", "4")):
    return SuiteMaze(name="hand", family="braided", index=0, seed=0, text=text,
                     goals=goals, block_event=block, open_event=open_)


def test_validate_accepts_a_hand_made_maze_and_refuses_its_breakages():
    maze = validate(hand(HAND))
    ds = bfs_distances(maze.walls, maze.start)
    assert [ds[maze.goals[g]] for g in "1234"] == [4, 6, 10, 12]
    assert maze.shortest_path_length(maze.start, maze.goals["G"],
                                     maze.walls_after(["a"])) == 14

    off_route = HAND.replace("#S....a....G#", "#S.........G#").replace(
        "#...........#", "#.....a.....#")
    with pytest.raises(SuiteError, match="leaves a shortest S-G path of the old layout open"):
        validate(hand(off_route))

    no_detour = HAND.replace("#...........#", "#.....#.....#")
    with pytest.raises(SuiteError, match="no detour"):
        validate(hand(no_detour))

    useless_opening = HAND.replace("##1#2###3#4##", "##1#2#B#3#4##")
    with pytest.raises(SuiteError, match="does not shorten"):
        validate(hand(useless_opening, open_="b"))

    with pytest.raises(SuiteError, match="differ from the declared"):
        validate(hand(HAND, block=None))

    with pytest.raises(SuiteError, match="not nearer"):
        validate(hand(HAND, goals=("1", "3", "2", "4")))

    on_the_way = HAND.replace("#...........#", "#...2.......#").replace(
        "##1#2###3#4##", "##1#####3#4##")
    with pytest.raises(SuiteError, match="goal '2' lies on a shortest path from S to goal '3'"):
        validate(hand(on_the_way))

    with pytest.raises(SuiteError, match="does not parse"):
        validate(hand(HAND.replace("#S", "#.", 1)))

    # A generated maze with its block letters erased fails too.
    sm = generate("braided", 0, seed=1)
    with pytest.raises(SuiteError, match="differ from the declared"):
        validate(dataclasses.replace(sm, text=sm.text.replace("a", ".")))
