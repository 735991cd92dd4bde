"""One node a place (SensorimotorMap merge, core/sensorimotor_map.py), against the real core.

What must hold: after every learning step of an agent with noisy sensors no two live nodes
lie within the GWR matching radius of each other (and without the merge they do: the
duplicates of issue 28); a merge joins the links of one action into one place by the
rule stated in the module (E summed up to 1), frees the slot and keeps the links in
(``inn``) exact; the graph's path, a replica fed the step's MapChange (through the
message's fields) and an estimator that applies the change's merges before it records
the step, holds the same map and the same outcome memory as the in-process agent after
every step.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from small_mazes import SMALL
from test_map_replica import as_message, evolve

from maze_sim import GridWorld, Maze
from maze_sim.maze import maze_file
from tmgwr_agent.core.agent import TMGWRAgent
from tmgwr_agent.core.motivation import MotivationEstimator
from tmgwr_agent.core.outcome import EPISODE_START, Outcome
from tmgwr_agent.core.sensorimotor_map import MapConfig, SensorimotorMap, survivor
from tmgwr_agent.map_replica import APPLIED, ChangeEncoder, MapChange, Replica
from tmgwr_agent.world_senses import maze_senses

LEFT, RIGHT = np.array([-1.0, 0.0]), np.array([1.0, 0.0])


def close_pairs(m: SensorimotorMap) -> np.ndarray:
    """Pairs (i, j), i < j, of live nodes within the matching radius, d as the map
    measures it."""
    idx = np.flatnonzero(m.alive[: m.n])
    w, c = m.w[idx], m.c[idx]
    c = c @ m.Sc.T if len(m.Sc) else c          # the context in primitive steps
    d = (1 - m.alpha_c) * ((w[:, None] - w[None]) ** 2).sum(-1) \
        + m.alpha_c * ((c[:, None] - c[None]) ** 2).sum(-1)
    i, j = np.nonzero(np.triu(d < math.log(m.a_T) ** 2, 1))
    return np.stack([idx[i], idx[j]], axis=1)


@pytest.mark.parametrize("merge", [True, False])
def test_no_two_nodes_of_one_place_with_noisy_sensors(merge):
    maze = Maze.from_file(maze_file())
    merged, duplicates = 0, 0
    for k, agent in evolve(maze, 3000, seed=4, config={"merge": merge}, noise=0.2):
        m = agent.map
        merged += len(m.merges)
        pairs = close_pairs(m)
        duplicates += bool(len(pairs))
        if merge:
            assert not len(pairs), (k, pairs)
    if merge:
        assert merged > 0, "the run never merged: it tests nothing"
    else:
        assert duplicates > 0, "without the merge the run has no duplicates to test"


def hand_map() -> SensorimotorMap:
    """Nodes 0 (x=0), 1 (x=-1), 2 (x=-1.3): the links of LEFT from 0 split between 1 and 2
    (E 0.75 and 0.48), 2 -> 0 by RIGHT, 1 -> 2 within the place."""
    m = SensorimotorMap(dim=2, config=MapConfig(alpha_c=0.0))
    for x in ((0.0, 0.0), (-1.0, 0.0), (-1.3, 0.0)):
        m._insert(np.array(x), np.array(x))
    m.out[0, :2], m.E[0, :2], m.a[0, :2] = (1, 2), (0.75, 0.48), (LEFT, LEFT)
    m.out[2, 0], m.E[2, 0], m.a[2, 0], m.age[2, 0] = 0, 0.9, RIGHT, 5
    m.out[1, 0], m.E[1, 0], m.a[1, 0] = 2, 0.6, LEFT
    m.h[:3] = (0.1, 0.2, 1.0)
    m.rebuild_in_links()
    return m


def test_a_merge_joins_the_links_of_one_place():
    m = hand_map()
    pos, version = m.log.pos, m.version
    m._merge(1, 2)
    assert not m.alive[2] and (m.out[2] < 0).all() and m.merges == [(1, 2)]
    assert m.version == version + 1
    np.testing.assert_allclose(m.w[1], (-1.15, 0.0))
    assert m.h[1] == 1.0                                   # the fresher habituation
    # 0 -> {1, 2} by LEFT: one link, E summed (capped at 1)
    row = {int(t): (e, tuple(a)) for t, e, a in zip(m.out[0], m.E[0], m.a[0]) if t >= 0}
    assert row == {1: (1.0, tuple(LEFT))}
    # 2 -> 0 became 1 -> 0; 1 -> 2 (within the place) is gone
    row = {int(t): (e, tuple(a)) for t, e, a in zip(m.out[1], m.E[1], m.a[1]) if t >= 0}
    assert row == {0: (0.9, tuple(RIGHT))}
    kept = [set(r[r >= 0].tolist()) for r in m.inn[: m.n]]
    m.rebuild_in_links()
    assert kept == [set(r[r >= 0].tolist()) for r in m.inn[: m.n]]
    assert {0, 1, 2} <= set(m.log.since(pos).tolist())
    # different actions into one place: the more reliable link stays
    m = hand_map()
    m.a[0, 1] = RIGHT
    m._merge(1, 2)
    assert {int(t): e for t, e in zip(m.out[0], m.E[0]) if t >= 0} == {1: 0.75}


def bump_map(spread: float, mean: float = 0.1) -> SensorimotorMap:
    """Nodes 0 at x=0 (the last winner, sensed at x=0.03) and 1 at x=0.07, beyond the
    matching radius of each other; primitive 0 (RIGHT by a cell, 0.1) has made 10 moves of
    mean displacement ``mean`` and spread ``spread`` (mean squared deviation)."""
    m = SensorimotorMap(dim=2, config=MapConfig(alpha_c=0.0),
                        primitives=np.array([[0.1, 0.0], [-0.1, 0.0]]))
    for x in ((0.0, 0.0), (0.07, 0.0)):
        m._insert(np.array(x), np.array(x))
    m.h[:2] = (0.1, 0.2)
    m.motion[0] = (10, mean, 0.0, 10 * spread)
    m.prev = m.winner = 0
    m.x_prev[:] = (0.03, 0.0)
    return m


@pytest.mark.parametrize("spread, mean, dx", [
    (0.0016, 0.1, 0.01),     # noise of 0.2 cell, within the scatter of a stay
    (0.0016, 0.1, 0.045),    # displaced beyond the scatter: it may have moved
    (1e-8, 0.05, 0.01),      # no noise (PointMaze's physics): a partial move
    (0.0, 0.1, 0.01),        # no scatter at all
])
def test_the_winners_of_a_bump_are_two_nodes(spread, mean, dx):
    """The bump's second sample wins node 1, beyond the radius of node 0's place: one
    sample that far out does not tell whether the two are one place (the module
    docstring), so nothing is merged and the bump is learnt by Eq. 1-2 as a link."""
    m = bump_map(spread, mean)
    winner = m.experience(np.array([0.03 + dx, 0.0]), Outcome(action=0, bumped=True))
    assert m.merges == [] and winner == 1 and m.alive[:2].all()
    # a move adds to the primitive's statistics; a bump does not
    assert m.motion[0, 0] == 10
    m.experience(np.array([0.13, 0.0]), Outcome(action=0))
    assert m.motion[0, 0] == 11


def test_under_a_place_radius_a_bump_merges_no_two_nodes():
    """As above, the place radius measured (``a_place < a_T``): the bump's second sample
    lies beyond the radius of node 0's place and wins node 1, though the two samples'
    mean is node 0's (not a bump from another place)."""
    m = bump_map(0.0016)
    m._place_radius()
    m.x_prev[:] = (0.025, 0.02)
    x = np.array([0.04, 0.045])
    assert m.a_place < m.a_T and m.bump_place(0, x) == -1
    winner = m.experience(x, Outcome(action=0, bumped=True))
    assert winner == 1 and m.merges == [] and m.alive[:2].all()


def elsewhere_map(spread: float) -> SensorimotorMap:
    """Node 0 at the origin, whose RIGHT (a cell, 0.1) has led to node 2 at x=0.1, and node
    1 a cell below it; RIGHT has made 10 moves of mean displacement a cell and spread
    ``spread``. The last input was sensed a cell below the origin (node 1's place), where
    node 0 won it."""
    m = SensorimotorMap(dim=2, config=MapConfig(alpha_c=0.0),
                        primitives=np.array([LEFT, RIGHT]))
    for x in ((0.0, 0.0), (0.0, 0.1), (0.1, 0.0)):
        m._insert(np.array(x), np.array(x))
    m.out[0, 0], m.E[0, 0], m.a[0, 0] = 2, 1.0, RIGHT
    m.h[:3] = (0.1, 0.1, 0.1)
    m.won[:3] = 100.0                  # settled at the means of many samples
    m.rebuild_in_links()
    m.motion[1] = (10, 0.1, 0.0, 10 * spread)
    m.prev = m.winner = 0
    m._place_radius()
    m.x_prev[:] = (0.0, 0.09)
    return m


def test_a_bump_taken_at_another_place_than_the_nodes_moves_is_that_places():
    """Node 0 won a sample of the place below it; RIGHT, which moves from node 0's place,
    bumps there: not evidence that node 0's link closed, nor a stay within one node."""
    m = elsewhere_map(0.0016)                      # noise of 0.2 cell
    assert m.bumped_elsewhere(0, 1)
    winner = m.experience(np.array([0.0, 0.1]), Outcome(action=1, bumped=True))
    assert winner == 1 and m.merges == [] and m.alive[:3].all()    # two places
    assert m.bump_from == 1                        # the bump is the place it was taken at
    assert not (m.out[0] == 1).any()               # no link made by a bump
    assert m.E[0, 0] == pytest.approx(1.0 - m.alpha)   # Eq. 1-2: a bump at node 0
    # taken where node 0's moves start, the bump is node 0's; its second sample won
    # node 1, a cell away: the two stay two
    m = elsewhere_map(0.0016)
    m.x_prev[:] = (0.0, 0.03)
    assert not m.bumped_elsewhere(0, 1)
    assert m.experience(np.array([0.0, 0.06]), Outcome(action=1, bumped=True)) == 1
    assert m.bump_from is None and m.merges == [] and m.alive[:3].all()


@pytest.mark.parametrize("spread", [
    0.0,        # no scatter
    1e-33,      # a grid sensed exactly: rounding only
    1e-13,      # PointMaze's physics
    0.001,      # noise of 0.16 cell: a scatter inside GWR's radius
    0.004,      # moves hardly stand out of the scatter
])
def test_a_bump_is_elsewhere_only_when_the_moves_stand_out_of_their_scatter(spread):
    m = elsewhere_map(spread)
    assert not m.bumped_elsewhere(0, 1)
    m.experience(np.array([0.0, 0.1]), Outcome(action=1, bumped=True))
    assert m.bump_from is None                              # node 0's own bump:
    assert (m.out[0] == 1).any() and m.merges == []         # a link (Eq. 1-2)


def test_the_agent_records_a_bump_taken_elsewhere_at_its_place():
    """The agent's outcome memory notes the bump on the node of the place it was taken
    at, and never on the node whose moves it would contradict."""
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(0))
    agent.map = m = elsewhere_map(0.0016)
    m.primitives = agent.senses.primitives
    m.a[0, 0] = m.primitives[1]
    agent.winner = 0
    agent.motivation.record(-1, 0, False, EPISODE_START, m.w)
    agent.motivation.record(0, 2, False, Outcome(action=1), m.w)
    agent.step(np.array([0.0, 0.1]) / agent.preprocessor.gain, Outcome(action=1, bumped=True))
    mo = agent.motivation
    assert mo.bump_t[0, 1] < 0 and mo.succ[0, 1] == 2       # node 0's move stands
    assert mo.tried[1, 1] and mo.bump_t[1, 1] >= 0          # the wall of node 1's place


def test_a_bump_is_of_the_place_of_the_mean_of_its_two_samples():
    """The agent stands a cell below the origin (node 1's place), but its last sample
    scattered to within node 0's moves (not elsewhere for node 0); RIGHT bumps and the
    next sample is node 1's. The mean of the two samples lies at node 1's place: the bump
    is node 1's, not a break of node 0's move to node 2, and the two places stay two."""
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(0))
    agent.map = m = elsewhere_map(0.0016)          # noise of 0.2 cell
    m.primitives = agent.senses.primitives
    m.a[0, 0] = m.primitives[1]
    m.x_prev[:] = (0.0, 0.045)
    assert not m.bumped_elsewhere(0, 1)            # one sample alone: node 0's bump
    agent.winner = 0
    agent.motivation.record(-1, 0, False, EPISODE_START, m.w)
    agent.motivation.record(0, 2, False, Outcome(action=1), m.w)
    agent.step(np.array([0.0, 0.12]) / agent.preprocessor.gain, Outcome(action=1, bumped=True))
    assert m.bump_from == 1 and m.merges == [] and m.alive[:3].all()
    mo = agent.motivation
    assert mo.bump_t[0, 1] < 0 and mo.succ[0, 1] == 2 and not mo.broken   # no break
    assert mo.tried[1, 1] and mo.bump_t[1, 1] >= 0          # the wall of node 1's place


@pytest.mark.parametrize("spread", [0.0, 1e-33, 0.001])
def test_without_a_place_radius_a_bump_is_its_first_samples(spread):
    """No sensing scatter beyond GWR's radius: the winner of the sample before the bump
    is the bump's node, whatever the mean of the two samples."""
    m = elsewhere_map(spread)
    m.x_prev[:] = (0.0, 0.045)
    assert m.bump_place(0, np.array([0.0, 0.12])) == -1


@pytest.mark.parametrize("spread, winner", [
    (0.0016, 2),    # noise of 0.2 cell: within the radius of the place RIGHT leads to
    (0.0, 3),       # no noise: the nearest node, as GWR
    (1e-33, 3),     # a grid sensed exactly (rounding only): the nearest node
    (0.001, 3),     # a scatter inside GWR's radius: the nearest node
])
def test_a_sample_within_the_place_the_links_predict_is_that_place(spread, winner):
    """RIGHT from node 0 has led to node 2 (x=0.1); it senses x=0.145, within the radius of
    node 2's place, though node 3 (x=0.175) is nearer."""
    m = elsewhere_map(spread)
    m._insert(np.array([0.175, 0.0]), np.array([0.175, 0.0]))
    m.h[3] = 0.1
    m.motion[0] = m.motion[1] * (1, -1, 1, 1)           # LEFT: the opposite move
    m._place_radius()
    m.x_prev[:] = (0.0, 0.0)
    assert m.experience(np.array([0.145, 0.0]), Outcome(action=1)) == winner
    assert m.alive[:4].all() and not m.inserted


@pytest.mark.parametrize("spread, prev, inserts", [
    (0.0016, 0, False),   # noise of 0.2 cell: the tail of the place RIGHT leads to
    (0.0016, 1, True),    # no link of RIGHT from node 1: nothing predicts the place
    (0.0, 0, True),       # no noise: GWR's test alone
])
def test_a_sample_nearest_the_place_the_links_predict_inserts_no_node(spread, prev, inserts):
    """RIGHT from node 0 has led to node 2 (x=0.1); it senses x=0.16, beyond the radius of
    node 2's place (0.057 under this noise) and nearest node 2: the tail of that place's
    scatter, not a new place, when the links predict node 2."""
    m = elsewhere_map(spread)
    m.motion[0] = m.motion[1] * (1, -1, 1, 1)           # LEFT: the opposite move
    m._place_radius()
    m.prev = m.winner = prev
    m.x_prev[:] = m.w[prev]
    winner = m.experience(np.array([0.16, 0.0]), Outcome(action=1))
    assert m.inserted == inserts
    assert (winner == 2) != inserts and m.alive[:3].all()


@pytest.mark.parametrize("spread, mean, inserts", [
    (0.0016, 0.1, False),   # noise of 0.2 cell: a sample 0.055 off is noise on the place
    (0.0, 0.1, True),       # no noise: GWR's radius, 0.051
    (1e-8, 0.05, True),     # PointMaze's physics: far below GWR's radius
    (0.003, 0.1, True),     # moves hardly stand out of the scatter: no place radius
])
def test_a_place_is_as_wide_as_the_sensing_scatter(spread, mean, inserts):
    m = bump_map(spread, mean)
    m.motion[1] = m.motion[0]
    m.motion[1, 1] *= -1                    # LEFT: the opposite move, the same scatter
    m._place_radius()
    assert m.a_place == (m.a_T if inserts else pytest.approx(math.exp(-math.sqrt(0.0032))))
    m.begin_episode()
    m.experience(np.array([0.0, 0.0]), EPISODE_START)
    m.experience(np.array([0.0, 0.055]), Outcome(action=0))
    assert m.inserted == inserts


@pytest.mark.parametrize("spread, mean", [
    (0.0016, True),     # noise of 0.2 cell: the place radius is the scatter's
    (0.0, False),       # no noise: GWR's radius and rate
    (0.003, False),     # moves hardly stand out of the scatter: no place radius
])
def test_under_noise_a_node_is_the_mean_of_the_samples_it_won(spread, mean):
    """A node inserted at one sample of its place then wins the place's next samples:
    under a place radius its weight is their mean (GWR's rate keeps much of the first
    sample's offset), its count the samples it won; a merge adds the counts."""
    m = SensorimotorMap(dim=2, config=MapConfig(alpha_c=0.0),
                        primitives=np.array([LEFT, RIGHT]))
    m.motion[1] = (10, 0.1, 0.0, 10 * spread)
    m._place_radius()
    xs = 0.01 * np.random.default_rng(0).normal(size=(40, 2))   # within GWR's radius
    for x in xs:
        m.step(x, None)
    assert m.size == 1 and m.won[0] == len(xs)
    assert np.allclose(m.w[0], xs.mean(axis=0), atol=1e-12) == mean
    m._insert(np.array([0.5, 0.0]), np.zeros(2))
    m._merge(0, 1)
    assert m.won[0] == len(xs) + 1


def test_the_map_stays_near_one_node_a_cell_under_noise():
    """Sensor noise of 0.2 cell on a small maze: with the place radius the map holds fewer
    than 1.75 nodes a free cell after 3,000 steps (the rule is tested alone above)."""
    maze = Maze.from_text(SMALL)
    for _, agent in evolve(maze, 3000, seed=0, noise=0.2):
        pass
    free = sum(ch not in "#\n" for ch in SMALL)
    assert agent.map.size < 1.75 * free, (agent.map.size, free)


def test_the_estimator_moves_its_memory_to_the_kept_node():
    est = MotivationEstimator(primitives=np.array([[0, 1], [0, -1], [-1, 0], [1, 0]], float))
    w = np.array([[0.0, 0.0], [-1.0, 0.0], [-1.3, 0.0]])
    est.record(-1, 0, True, EPISODE_START, w)
    est.record(0, 2, True, Outcome(action=2), w)           # LEFT from 0 led to 2
    est.record(2, 2, False, Outcome(action=0, bumped=True), w)    # up from 2 bumped
    est.record(2, 1, True, Outcome(action=3), w)           # RIGHT from 2 led to 1
    est.record(1, 1, False, Outcome(action=3, bumped=True), w)    # RIGHT from 1 bumped
    est.merge([(1, 2)])
    assert est.succ[0, 2] == 1                             # where LEFT led: the kept node
    assert est.tried[1, 0] and est.bump_t[1, 0] >= 0       # 2's wall, untried from 1
    assert est.bump_t[1, 3] >= 0 and est.succ[1, 3] == -1  # 1's own outcome stays
    assert not est.tried[2].any() and (est.succ[2] < 0).all()
    assert est._winner == 1
    assert survivor(2, [(1, 2)]) == 1 and survivor(0, [(1, 2)]) == 0


def test_the_graph_path_holds_the_agents_map_and_memory_after_merges():
    """What the estimator node does with each step's state (nodes/motivation_estimator.py
    motivate): apply the change to its replica, the change's merges to its memory, then
    record the step from the survivor of the previous winner."""
    maze = Maze.from_file(maze_file())
    world = GridWorld(maze, goal="G", seed=6, sensor_noise=0.2)
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(6))
    est = MotivationEstimator(agent.motivation.config, primitives=agent.senses.primitives)
    encoder, replica = ChangeEncoder(map_id=5), Replica()
    agent.set_goal(world.goal, world.goal_observation())
    obs, _ = world.reset()
    outcome, merged, info = EPISODE_START, 0, None
    for k in range(2500):
        prev = agent.winner
        if outcome.episode_start:
            agent.begin_episode(obs, world.cell)
        else:
            agent.observe(obs, info)
        m = agent.map
        c = encoder.encode(m, run_id=1, step_id=k)
        assert np.array_equal(c.merges, np.asarray(m.merges, dtype=np.int64).reshape(-1, 2))
        assert replica.apply(MapChange.of_fields(as_message(c), c.version, 1, k)) == APPLIED
        assert replica.equals(m), k
        merges = replica.take_merges()
        assert np.array_equal(merges, c.merges) and not len(replica.take_merges())
        merged += len(merges)
        est.merge(merges)
        est.follow_goal(agent.motivation.goal_x)
        if m.bump_from is not None:         # a bump taken elsewhere (nodes/map_learner.py)
            prev = m.bump_from
        est.record(-1 if outcome.episode_start else survivor(prev, merges), m.winner,
                   m.inserted, outcome, replica.snapshot().w)
        est.update(replica.snapshot(), skip=agent.walk_next)
        mine, theirs = est.state_dict(), agent.motivation.state_dict()
        for name in ("tried", "bump_t", "closed_t", "bump_e", "succ", "closed_e", "delta"):
            a, b = mine[name], theirs[name]
            if name == "delta" and a.shape != b.shape:
                continue                    # (sized by the first update's map)
            n = min(len(a), len(b), m.n)
            assert np.array_equal(a[:n], b[:n]), (k, name)
        obs, _, terminated, truncated, info = world.step(agent.act())
        outcome = Outcome.of_step(info)
        if terminated or truncated:
            obs, _ = world.reset()
            outcome = EPISODE_START
    assert merged > 0, "the run never merged: it tests nothing"


@pytest.mark.ros
@pytest.mark.timeout(400)
def test_the_graph_with_noisy_sensors_walks_the_in_process_agents_cells(ros_domain,
                                                                          tmp_path):
    """The five nodes over DDS with sensor noise (merges on the way, carried by the
    MapChange of each step): cell for cell the in-process TMGWRAgent loop."""
    from ros_helpers import parse_json_line
    from test_nodes import MAZE, start_graph, stop_graph

    from tmgwr_agent.experiments.lockstep import read_trajectory, run_reference

    steps, noise = 2000, 0.2
    traj = tmp_path / "trajectory.txt"
    procs = start_graph(ros_domain, tmp_path, sim_args=[
        "-p", f"max_steps:={steps}", "-p", "exit_when_done:=true",
        "-p", f"sensor_noise:={noise}", "-p", f"trajectory_path:={traj}"])
    try:
        summary = parse_json_line(procs["maze_sim"].wait(timeout=300), "SUMMARY ")
    finally:
        stop_graph(procs)
    assert summary["steps"] == steps
    graph, _ = read_trajectory(traj)
    ref, _ = run_reference(MAZE, steps, goal="2", world_seed=0, agent_seed=1,
                           sensor_noise=noise)
    first = next((i for i, (a, b) in enumerate(zip(graph, ref)) if a != b), None)
    assert first is None and len(graph) == steps, \
        f"graph and in-process differ from step {first}"
    # the run merged nodes (what this test is about): the in-process twin says so
    maze = Maze.from_file(MAZE)
    world = GridWorld(maze, "2", noise, seed=0)
    agent = TMGWRAgent(maze_senses(), np.random.default_rng(1))
    agent.set_goal(world.goal, world.goal_observation())
    obs, _ = world.reset()
    agent.begin_episode(obs, world.cell)
    merged = 0
    for _ in range(steps - 1):
        obs, _, terminated, truncated, info = world.step(agent.act())
        agent.observe(obs, info)
        merged += len(agent.map.merges)
        if terminated or truncated:
            obs, _ = world.reset()
            agent.begin_episode(obs, world.cell)
    assert merged > 0, "no merge in the run: it tests nothing"
