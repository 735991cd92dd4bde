"""A move whose winner lies farther from where the primitive's mean move leads than half a
step changes no link when the map has a node at that place or the move started at another
node's place (sensorimotor_map.py, "A move between other places"); otherwise, or without
noise, the transition is Eq. 1-2's."""

from __future__ import annotations

import numpy as np
import pytest

from tmgwr_agent.core.outcome import Outcome
from tmgwr_agent.core.sensorimotor_map import MapConfig, SensorimotorMap

UP, RIGHT = np.array([0.0, 1.0]), np.array([1.0, 0.0])
SPREAD = 0.0016       # mean squared deviation of a move's displacement: noise of 0.2 cell


def diagonal_map(spread: float = SPREAD, right_cell: bool = True) -> SensorimotorMap:
    """Node 0 at the origin, whose RIGHT (a cell, 0.1) has led to node 1 at (0.1, 0)
    (reliability 1); node 2 at (0.1, 0.1), a diagonal cell; both primitives made 10 moves
    of a cell with mean squared deviation ``spread``. The last input was node 0's.
    ``right_cell`` False: node 1 is gone (no node, no link, where RIGHT leads)."""
    m = SensorimotorMap(dim=2, config=MapConfig(alpha_c=0.0),
                        primitives=np.array([UP, RIGHT]))
    for x in ((0.0, 0.0), (0.1, 0.0), (0.1, 0.1)):
        m._insert(np.array(x), np.array(x))
    m.h[:3] = (0.1, 0.1, 0.1)
    m.won[:3] = 20
    if right_cell:
        m.out[0, 0], m.E[0, 0], m.a[0, 0] = 1, 1.0, RIGHT
    else:
        m.alive[1] = False
        m.log.touch(1)
    m.rebuild_in_links()
    m.motion[0] = (10, 0.0, 0.1, 10 * spread)
    m.motion[1] = (10, 0.1, 0.0, 10 * spread)
    m._place_radius()
    m.prev = m.winner = 0
    m.x_prev[:] = (0.0, 0.01)
    return m


def test_a_move_into_a_diagonal_place_changes_no_link():
    """RIGHT moved, and its sample, scattered beyond the radius of node 1's place, won node
    2 a diagonal cell away: a move by RIGHT from node 0's place does not reach node 2's
    (more than half a step off), so no link is made to it and node 0's RIGHT link keeps its
    reliability (before, the credit rule halved it and a link 0 -> 2 of E 1 was made)."""
    m = diagonal_map()
    assert m.a_place < m.a_T
    winner = m.experience(np.array([0.1, 0.07]), Outcome(action=1))
    assert winner == 2 and not m.inserted
    assert not (m.out[0] == 2).any()
    assert m.out[0, 0] == 1 and m.E[0, 0] == pytest.approx(1.0, abs=1e-12)


def test_a_move_into_its_place_still_learns():
    """A sample that wins node 1 from afar (still within half a step of where RIGHT leads)
    is an ordinary transition: the link is traversed and its age restarts."""
    m = diagonal_map()
    m.age[0, 0] = 5
    winner = m.experience(np.array([0.1, -0.03]), Outcome(action=1))
    assert winner == 1
    assert m.out[0, 0] == 1 and m.E[0, 0] == pytest.approx(1.0) and m.age[0, 0] == 0


def test_from_its_place_to_no_node_it_is_learnt():
    """No node lies within half a step of where RIGHT leads from node 0 (a place the map
    lacks) and the samples put the move's start at node 0's place: the transition 0 -> 2
    is the only link the map can make there, and is made."""
    m = diagonal_map(right_cell=False)
    winner = m.experience(np.array([0.1, 0.07]), Outcome(action=1))
    assert winner == 2 and (m.out[0] == 2).any()


def test_a_move_from_another_place_changes_no_link():
    """No node where RIGHT leads from node 0, but the move's two samples put its start at
    node 3's place, the cell above node 0 (``x_prev`` scattered into node 0): the sample
    that won node 0 is not where the move started, so no link 0 -> 2 is made."""
    m = diagonal_map(right_cell=False)
    m._insert(np.array([0.0, 0.1]), np.array([0.0, 0.1]))
    m.h[3], m.won[3] = 0.1, 20
    m.x_prev[:] = (0.0, 0.06)
    winner = m.experience(np.array([0.1, 0.1]), Outcome(action=1))
    assert winner == 2 and not (m.out[0] == 2).any()


def test_without_scatter_the_rule_is_off():
    """No scatter (GWR's radius stands): the same sample is a transition 0 -> 2 as in Eq.
    1-2, a new link and the RIGHT link to node 1 blamed."""
    m = diagonal_map(spread=0.0)
    assert m.a_place == m.a_T
    winner = m.experience(np.array([0.1, 0.07]), Outcome(action=1))
    assert winner == 2
    assert (m.out[0] == 2).any()
    assert m.E[0, 0] < 1.0
