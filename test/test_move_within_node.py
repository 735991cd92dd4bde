"""A move the touch sensor says was not blocked, whose two samples one node won, changes
no link (sensorimotor_map.py, "A move within one node"); a bump with one winner is still
Eq. 1-2's self transition."""

from __future__ import annotations

import numpy as np
import pytest

from tmgwr_agent.core.outcome import Outcome
from tmgwr_agent.core.sensorimotor_map import MapConfig, SensorimotorMap

LEFT, RIGHT = np.array([-1.0, 0.0]), np.array([1.0, 0.0])
SPREAD = 0.0016       # mean squared deviation of a move's displacement: noise of 0.2 cell


def stretched_map() -> SensorimotorMap:
    """Node 0 at the origin, whose RIGHT (a cell, 0.1) has led to node 1 at x=0.1 (link
    reliability 1), and node 2 a cell to the left; both primitives have made 10 moves of
    a cell with the scatter of 0.2 cell of noise. The last input, sensed at x=-0.03, was
    node 0's."""
    m = SensorimotorMap(dim=2, config=MapConfig(alpha_c=0.0),
                        primitives=np.array([LEFT, RIGHT]))
    for x in ((0.0, 0.0), (0.1, 0.0), (-0.1, 0.0)):
        m._insert(np.array(x), np.array(x))
    m.out[0, 0], m.E[0, 0], m.a[0, 0] = 1, 1.0, RIGHT
    m.h[:3] = (0.1, 0.1, 0.1)
    m.rebuild_in_links()
    m.motion[0] = (10, -0.1, 0.0, 10 * SPREAD)
    m.motion[1] = (10, 0.1, 0.0, 10 * SPREAD)
    m._place_radius()
    m.prev = m.winner = 0
    m.x_prev[:] = (-0.03, 0.0)
    return m


def test_a_move_one_node_won_twice_changes_no_link():
    """RIGHT moved (the touch sensor says so) and node 0 won both samples: the map cannot
    see which link the move took, so none changes (before, the credit rule lowered node
    0's RIGHT link by alpha as for a bump). A bump that stayed at node 0 still does."""
    for bumped, x, E in ((False, 0.03, 1.0), (True, -0.02, 0.48)):
        m = stretched_map()
        assert m.a_place < m.a_T and not m.bumped_elsewhere(0, 1)
        age = m.age[0, 0]
        winner = m.experience(np.array([x, 0.0]), Outcome(action=1, bumped=bumped))
        assert winner == 0 and not m.inserted and m.merges == [], bumped
        assert m.out[0, 0] == 1 and m.E[0, 0] == pytest.approx(E, abs=1e-12), bumped
        assert not (m.out[0] == 0).any(), bumped        # no link of a node to itself
        assert m.age[0, 0] == age + bumped, bumped      # ageing: a bump's only
