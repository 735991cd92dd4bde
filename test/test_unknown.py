"""The model of the unknown (core/unknown.py, Eq. 5') is a plug-in of the motivation
estimator: one registry names the models the ``unknown`` parameter offers, the estimator
provides what :class:`ModelOfUnknown` lists, and the outcome memory saves under the
checkpoint keys it always had (test_resume loads older checkpoints)."""

import numpy as np
import pytest

from tmgwr_agent.core.frame import LearntFrame, SensorFrame
from tmgwr_agent.core.motivation import MotivationConfig, MotivationEstimator
from tmgwr_agent.core.outcome import EPISODE_START, Outcome
from tmgwr_agent.core.unknown import UNKNOWN, ModelOfUnknown
from tmgwr_common.params import ParamError

PRIMITIVES = np.array([[0, 1], [0, -1], [-1, 0], [1, 0]], float)

#: The outcome memory's checkpoint keys (MotivationEstimator.state_dict before the move).
KEYS = {"tried", "bump_t", "closed_t", "bump_e", "succ", "closed_e", "goal_seen", "clock",
        "delta", "delta_sq", "moves", "episode", "route", "retests", "wall_tests",
        "wall_opened", "route_due", "sel", "chain", "goals_told", "break_t",
        "changes", "changed", "q_change", "waited", "carry", "allowance"}


@pytest.mark.parametrize("name, frame, options", [("none", SensorFrame, False),
                                                  ("grid", SensorFrame, True),
                                                  ("learnt", LearntFrame, True)])
def test_the_unknown_parameter_chooses_a_model_from_one_registry(name, frame, options):
    assert list(UNKNOWN) == ["none", "grid", "learnt"]
    est = MotivationEstimator(MotivationConfig(unknown=name), primitives=PRIMITIVES)
    assert type(est.frame) is frame and est.value_unknown is options
    assert isinstance(est, ModelOfUnknown)


def test_a_model_not_in_the_registry_is_refused_by_name():
    with pytest.raises(ParamError, match="unknown.*'bogus'"):
        MotivationConfig(unknown="bogus")


def test_the_outcome_memory_saves_under_its_checkpoint_keys_and_loads_back():
    est = MotivationEstimator(primitives=PRIMITIVES)
    w = np.array([[0.0, 0.0], [-1.0, 0.0], [-1.0, 1.0]])
    est.record(-1, 0, True, EPISODE_START, w)
    est.record(0, 1, True, Outcome(action=2), w)                  # LEFT from 0 led to 1
    est.record(1, 1, False, Outcome(action=2, bumped=True), w)    # LEFT from 1 bumped
    est.record(1, 2, True, Outcome(action=0), w)                  # UP from 1 led to 2
    d = est.state_dict()
    assert set(d) == KEYS
    again = MotivationEstimator(primitives=PRIMITIVES)
    again.load_state_dict(d)
    d2 = again.state_dict()
    for k in KEYS:
        np.testing.assert_array_equal(np.asarray(d2[k]), np.asarray(d[k]), err_msg=k)
    assert d["succ"][0, 2] == 1 and d["bump_t"][1, 2] >= 0 and d["clock"] == 3
