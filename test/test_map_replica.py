"""Per-step map changes (tmgwr_agent.map_replica) against the real core, no ROS.

What must hold: a replica fed every step's change equals the learner's map bit for bit
after every step (maps grown by the real agent on several mazes, with goal changes, maze
events, node deletions and link-degree growth), and value iteration on the replica gives
the same potentials as on the map, exactly; a missed change is detected as a gap, a resent one as
current; a whole map resynchronises the replica, an older one is ignored; a new map
starts with the whole map; a change survives the message's field types (int32 ids,
uint8 flags, as rclpy's arrays and as rosbags' numpy arrays); a step's change is a few
rows once the map is built.
"""

from __future__ import annotations

import array
from types import SimpleNamespace

import numpy as np
import pytest

from maze_sim import GridWorld, Maze
from maze_sim.maze import maze_file
from maze_sim.suite import generate
from maze_sim.world import EditRefused
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.core.motivation import MotivationEstimator
from tmgwr_agent.core.sensorimotor_map import SensorimotorMap
from tmgwr_agent.map_replica import (
    APPLIED,
    CURRENT,
    FULL,
    GAP,
    ROWS,
    STALE,
    ChangeEncoder,
    MapChange,
    Replica,
)
from tmgwr_agent.world_senses import maze_senses

OPEN = """\
##########
#S.......#
#........#
#........#
#........#
#.......G#
##########
"""


def as_message(c: MapChange, numpy_arrays: bool = False) -> SimpleNamespace:
    """The fields of a tmgwr_interfaces/MapChange as the nodes fill them (rclpy stores
    array.array) or as rosbags decodes them (numpy arrays)."""
    def arr(code, a, dtype):
        a = np.ascontiguousarray(a, dtype=dtype).ravel()
        return a if numpy_arrays else array.array(code, a.tobytes())
    return SimpleNamespace(
        map_id=c.map_id, base_sequence=c.base, sequence=c.sequence, n_slots=c.n,
        degree=c.degree, dim=c.dim, slots=arr("i", c.slots, np.int32),
        alive=arr("B", c.alive, np.uint8), terminal_nodes=arr("B", c.terminal, np.uint8),
        weights=arr("d", c.w, np.float64), link_targets=arr("i", c.out, np.int32),
        link_reliability=arr("d", c.E, np.float64), merges=arr("i", c.merges, np.int32))


def evolve(maze: Maze, steps: int, seed: int, goals=(), events=(), config=None,
           noise: float = 0.0):
    """The in-process agent on ``maze``; yields (step, agent) after every learning step.
    ``goals`` / ``events``: {step: goal} / {step: event} applied on the way; ``config``:
    the agent's parameter overrides, ``noise``: the simulator's sensor noise."""
    world = GridWorld(maze, goal="G", seed=seed, sensor_noise=noise)
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(seed), config)
    agent.set_goal(world.goal, world.goal_observation())
    obs, _ = world.reset()
    agent.begin_episode(obs, world.cell)
    yield 0, agent
    pending = []                    # events due; one the world refuses (it would wall in
    for k in range(1, steps):       # the agent where it stands) is fired a step later
        if k in goals:
            world.set_goal(goals[k])
            agent.set_goal(world.goal, world.goal_observation())
        if k in events:
            pending.append(events[k])
        for event in list(pending):
            try:
                world.fire_event(event)
                pending.remove(event)
            except EditRefused as exc:
                assert "the agent" in str(exc), exc
        obs, _, terminated, truncated, info = world.step(agent.act())
        agent.observe(obs, info)
        if terminated or truncated:
            obs, _ = world.reset()
            agent.begin_episode(obs, world.cell)
        yield k, agent
    assert not pending, f"events {pending} never applied"


# (maze, goal changes, events, agent overrides, sensor noise)
CASES = {
    "paper": lambda: (Maze.from_file(maze_file()), {1500: "2"}, {}, None, 0.0),
    "rooms": lambda: (Maze.from_text((sm := generate("rooms", 1, 0)).text),
                      {1200: sm.goals[0]}, {1800: sm.block_event}, None, 0.0),
    "braided": lambda: (Maze.from_text((sm := generate("braided", 2, 0)).text),
                        {900: sm.goals[2]}, {1600: sm.block_event}, None, 0.0),
    # noisy sensors and short-lived links: nodes deleted and their slots reused
    "churn": lambda: (Maze.from_text(OPEN), {}, {}, {"max_age": 3}, 0.3),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_replica_equals_the_map_after_every_step(case):
    maze, goals, events, config, noise = CASES[case]()
    encoder = ChangeEncoder(map_id=7)
    replica, from_numpy = Replica(), Replica()
    estimators = None
    rows, deleted, reused = [], False, False
    for k, agent in evolve(maze, 2500, seed=3, goals=goals, events=events, config=config,
                           noise=noise):
        m = agent.map
        c = encoder.encode(m, run_id=1, step_id=k)
        assert (c.base, c.sequence) == ((FULL, 1) if k == 0 else (k, k + 1))
        msg = as_message(c)
        assert replica.apply(MapChange.of_fields(msg, c.version, 1, k)) == APPLIED
        assert from_numpy.apply(MapChange.of_fields(as_message(c, True), c.version)) == APPLIED
        assert replica.equals(m) and from_numpy.equals(m) and encoder.sent.equals(m), k
        assert (replica.run_id, replica.step_id) == (1, k)
        # Eq. 4-5 on the replica: what they give on the map itself, bit for bit
        if estimators is None:
            estimators = [MotivationEstimator(agent.motivation.config,
                                              primitives=agent.senses.primitives)
                          for _ in range(2)]
        V = []
        for est, on in zip(estimators, (m, replica.snapshot())):
            est.follow_goal(agent.motivation.goal_x)
            V.append(est.update(on).view(np.int64))
        assert np.array_equal(*V) and estimators[0].goal_node == estimators[1].goal_node, k
        rows.append(len(c.slots))
        reused |= deleted and m.inserted and m.winner < m.n - 1
        deleted |= bool((~m.alive[: m.n]).any())
    if case == "churn":
        assert deleted and reused, "the case covers less than it should"
    # once the map is built a step changes a handful of rows, not the map
    late = rows[len(rows) // 2:]
    assert np.mean(late) < 8 and np.mean(late) < 0.2 * replica.n, (np.mean(late), replica.n)


@pytest.mark.parametrize("case", ["paper", "churn"])
def test_the_maps_change_log_lists_every_row_a_step_changed(case):
    """The map's RowLog (what the estimator reads instead of comparing every row) lists,
    after every step, each row whose weights, alive flag, links, reliabilities or terminal
    flag changed: goal changes, deleted nodes and reused slots included; or, rarely, says
    it no longer knows (it forgets its oldest rows). A replica's log lists the slots of
    each change it applied. The map's links in (``inn``) are the reverse of its links."""
    maze, goals, events, config, noise = CASES[case]()
    replica, encoder = Replica(), ChangeEncoder(map_id=3)
    before, pos, rpos, forgot = None, 0, 0, 0
    for k, agent in evolve(maze, 1500, seed=5, goals=goals, events=events, config=config,
                           noise=noise):
        m = agent.map
        replica.apply(encoder.encode(m))
        if before is not None:
            n = max(m.n, len(before["alive"]))
            changed = set()
            for name in ("w", "alive", "out", "E", "terminal"):
                empty = ROWS[name][1]
                a, b = (_rows_of(before[name], n, empty),
                        _rows_of(getattr(m, name)[: m.n], n, empty))
                changed |= set(np.flatnonzero((a != b).any(axis=1)).tolist())
            for log, at in ((m.log, pos), (replica.log, rpos)):
                logged = log.since(at)
                if logged is None:          # the log forgot its oldest rows: allowed
                    forgot += 1
                else:
                    assert changed <= set(logged.tolist()), k
        pos, rpos = m.log.pos, replica.log.pos
        if k % 50 == 0:             # the links in (inn), kept by the link kernels
            kept = [set(r[r >= 0].tolist()) for r in m.inn[: m.n]]
            m.rebuild_in_links()
            assert kept == [set(r[r >= 0].tolist()) for r in m.inn[: m.n]], k
        before = {name: getattr(m, name)[: m.n].copy()
                  for name in ("w", "alive", "out", "E", "terminal")}
    assert forgot < 10                        # (once every few thousand rows)
    m.load_state_dict(m.state_dict())
    assert m.log.since(pos) is None           # a loaded map: every row may have changed


def _rows_of(a: np.ndarray, n: int, empty) -> np.ndarray:
    """``a`` as n rows of 64 columns, the rows and columns it lacks ``empty`` (as the map
    allocates them: widening the rows or adding slots changes no row's content)."""
    b = np.full((n, 64), float(empty))
    b[: len(a), : a[0].size if len(a) else 0] = a.reshape(len(a), -1)
    return b


def test_widened_link_rows_and_reused_slots_replicate_exactly():
    """A node linked to six others (K grows 4 -> 8); then a walk between it and one of
    them ages the other links away (max_age) and removes their nodes; a new node takes
    the lowest freed slot."""
    m = SensorimotorMap(dim=2)
    enc, r = ChangeEncoder(map_id=3), Replica()
    steps = [(np.zeros(2), None)]
    for t in np.linspace(0.0, 2 * np.pi, 7)[:-1]:     # out to each neighbour and back
        a = np.array([np.cos(t), np.sin(t)])
        steps += [(0.5 * a, a), (np.zeros(2), -a)]
    right = np.array([1.0, 0.0])
    steps += [(0.5 * right, right), (np.zeros(2), -right)] * (m.max_age + 5)
    steps += [(np.array([0.0, -0.5]), np.array([0.0, -1.0]))]
    widened = removed = reused = False
    for x, action in steps:
        free = np.flatnonzero(~m.alive[: m.n])
        m.step(x, action)
        assert r.apply(enc.encode(m)) == APPLIED and r.equals(m)
        widened |= m.out.shape[1] > 4
        removed |= bool(len(free))
        reused |= len(free) > 0 and m.inserted and m.winner == free[0]
    assert widened and removed and reused, (m.out.shape, m.alive[: m.n])


def some_changes(n=30, seed=1):
    maze = Maze.from_file(maze_file())
    encoder = ChangeEncoder(map_id=11)
    changes = [encoder.encode(a.map, 1, k) for k, a in evolve(maze, n, seed)]
    return encoder, changes


def test_gaps_are_detected_and_a_whole_map_resynchronises():
    encoder, changes = some_changes()
    r = Replica()
    assert r.apply(changes[1]) == GAP           # joined late: no state yet
    assert r.apply(changes[0]) == APPLIED and r.sequence == 1
    assert r.apply(changes[1]) == APPLIED
    assert r.apply(changes[1]) == CURRENT       # a resent step
    assert r.apply(changes[3]) == GAP           # changes[2] was missed
    assert r.sequence == 2 and r.status(changes[3]) == GAP
    whole = encoder.snapshot()                  # the newest whole map (state 30)
    assert whole.full and whole.sequence == len(changes)
    assert r.apply(whole) == APPLIED and r.sequence == whole.sequence
    assert r.equals(encoder.sent)
    assert r.apply(whole) == CURRENT
    old = Replica()
    for c in changes[:10]:
        old.apply(c)
    assert r.apply(old.full_change()) == STALE  # an older whole map never goes back
    assert r.apply(changes[-1]) == CURRENT
    # a change of another map (the learner restarted or loaded one) is a gap ...
    other = ChangeEncoder(map_id=12)
    m2 = SensorimotorMap(dim=2)
    m2.step(np.array([0.5, 0.5]), None)
    first = other.encode(m2)
    m2.step(np.array([0.6, 0.5]), np.array([0.0, 1.0]))
    second = other.encode(m2)
    assert r.apply(second) == GAP
    # ... until its whole map, which the first change of a map is
    assert first.full and r.apply(first) == APPLIED and r.apply(second) == APPLIED
    assert r.equals(m2) and r.map_id == 12


def test_a_change_no_learner_sends_is_named():
    """Issue 24: a stray SensorimotorState with default fields (map id 0, base 0: a whole
    map of no slots) wiped the estimator's replica, then crashed it."""
    _, changes = some_changes(5)
    assert all(c.problem() is None for c in changes)
    empty = MapChange.of_fields(SimpleNamespace(
        map_id=0, base_sequence=0, sequence=0, n_slots=0, degree=0, dim=0, slots=[],
        alive=[], terminal_nodes=[], weights=[], link_targets=[], link_reliability=[]), 0)
    assert "map id 0" in empty.problem()
    c = changes[-1]
    for change, why in ((dict(n=0), "a slot outside [0, 0)"),
                        (dict(alive=c.alive[:-1]), "alive"),
                        (dict(out=np.full_like(c.out, c.n)), "a link target outside"),
                        (dict(sequence=-1), "state -1")):
        assert why in MapChange(**{**c.__dict__, **change}).problem(), (change, why)


def test_changes_only_list_what_changed_and_shrinking_sends_the_whole_map():
    m = SensorimotorMap(dim=2)
    enc = ChangeEncoder(map_id=1)
    m.step(np.array([0.0, 0.0]), None)
    assert len(enc.encode(m).slots) == m.n == 1
    assert len(enc.encode(m).slots) == 0        # nothing changed: an empty change
    m.step(np.array([0.0, 0.5]), np.array([0.0, 1.0]))       # a new node and a link
    c = enc.encode(m)
    assert c.slots.tolist() == [0, 1] and c.n == 2 and not c.full
    m.w[0, 0] = -0.0                            # bitwise: -0.0 is a change
    assert enc.encode(m).slots.tolist() == [0]
    state = m.state_dict()
    small = SensorimotorMap(dim=2)
    state = {k: v[:1] if k != "meta" else v for k, v in state.items()}
    small.load_state_dict(state)
    assert enc.encode(small).full                # fewer slots: the whole map again
    with pytest.raises(ValueError):
        ChangeEncoder(map_id=0)


# --------------------------------------------------------------------------- over DDS
@pytest.mark.ros
@pytest.mark.timeout(240)
def test_a_restarted_estimator_resynchronises_its_replica_and_the_ring_goes_on(ros_domain,
                                                                              tmp_path):
    """The estimator stopped mid-run and started again: its first state's change does not
    follow its (empty) replica; it logs the gap, asks for a whole map, resynchronises from
    /sensorimotor_snapshot and the ring goes on reaching the goal."""
    from ros_helpers import ros2_run
    from test_nodes import goals_reached, start_graph, stop_graph, wait_until

    # one latched snapshot only, step 0's: with the default period the restarted estimator
    # needs no resync when it stopped at a step 500 m or 500 m + 1 (the latched snapshot is
    # then its next state's base or that state itself), and no gap is logged
    procs = start_graph(ros_domain, tmp_path, sim_args=["-p", "resend_period:=0.5"],
                        learner_args=["-p", "snapshot_period:=1000000000"])
    sim = procs["maze_sim"]
    try:
        wait_until(lambda: len(goals_reached(sim)) >= 3, 120, "goal x3", procs)
        procs["motivation_estimator"].stop()
        before = len(goals_reached(sim))
        procs["motivation_estimator"] = est = ros2_run(
            "tmgwr_agent", "motivation_estimator", domain=ros_domain, name="estimator2")
        gap = est.wait_for_line("does not follow the replica", timeout=60)
        wait_until(lambda: any("map replica (re)synchronised" in line
                               for line in est.lines[est.lines.index(gap):]), 60,
                   "the replica resynchronised after the gap", procs)
        wait_until(lambda: len(goals_reached(sim)) >= before + 2, 120, "goal after restart",
                   procs)
    finally:
        stop_graph(procs)
