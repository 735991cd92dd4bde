"""The recorder's gap counting (tmgwr_agent.bag.gaps) on real serialized messages (no
DDS): the (run_id, step_id) read from the CDR bytes equals the message's, in every per-step
type; a jump in step ids is a gap of exactly the steps between; resends are not gaps; runs
are counted apart."""

from __future__ import annotations

import pytest

from tmgwr_agent.bag.gaps import StepGaps, header_step

RUN = 1795460338380569546


def message(type_name: str, run_id: int, step_id: int, frame_id: str = "maze") -> bytes:
    from rclpy.serialization import serialize_message

    import tmgwr_interfaces.msg as msgs
    m = getattr(msgs, type_name)(run_id=run_id, step_id=step_id)
    m.header.frame_id = frame_id
    m.header.stamp.sec, m.header.stamp.nanosec = 1795460338, 123
    return serialize_message(m)


@pytest.mark.parametrize("type_name", ["Observation", "Features", "SensorimotorState",
                                       "MotivationField", "Action"])
def test_step_ids_are_read_from_the_bytes_of_every_per_step_type(type_name):
    for frame in ("", "m", "maze", "a_longer_frame_id"):       # every alignment
        for run, step in ((RUN, 0), (1, 2 ** 63 + 5), (0, 999999999)):
            assert header_step(message(type_name, run, step, frame)) == (run, step)


def test_gaps_resends_and_runs():
    g = StepGaps()
    for step in (0, 1, 2, 2, 3, 7, 8, 20):                   # 2 resent; 4-6, 9-19 missing
        g.add("/action", message("Action", RUN, step))
    for step in (0, 1, 2):                                    # a restarted simulator
        g.add("/action", message("Action", RUN + 1, step))
    g.add("/observation", message("Observation", RUN, 0))
    r = g.topics["/action"][RUN]
    assert (r.first, r.last, r.received, r.resent, r.missing) == (0, 20, 8, 1, 14)
    assert r.ranges == [(4, 6), (9, 19)]
    assert g.topics["/action"][RUN + 1].missing == 0
    assert g.missing == 14
    assert "14 steps MISSING" in g.summary() and "/action 14" in g.summary()
    assert g.topic_lines("/action")[0] == \
        f"run {RUN}: steps 0-20, 14 MISSING in 2 gaps (4-6, 9-19), 1 resent"
    d = g.as_dict()["/action"][str(RUN)]
    assert d["missing"] == 14 and d["ranges"] == [[4, 6], [9, 19]] and not d["ranges_cut"]


def test_a_gap_is_returned_when_it_happens():
    g = StepGaps()
    assert g.add("/features", message("Features", RUN, 5)) is None
    assert g.add("/features", message("Features", RUN, 6)) is None
    assert g.add("/features", message("Features", RUN, 10)) == (RUN, 7, 9)
    assert g.summary().startswith("step gaps: 3 steps MISSING")
    assert StepGaps().summary() == "step gaps: no per-step message recorded"
