"""No message moves a node ahead of the simulator for good (issue 24, point 1).

The real ``ros2 topic pub`` sends strays on each of the five per-step topics (huge, zero
and other-run ids, once and repeated) and on the world's latched sensor declaration
(another run's, a second one of the current run: ``strays.strays``) into a running graph.
After each, the ring must make at least 200 steps within 30 s: a liveness floor that a ring
answered only after each resend (about 1 step/s, what one stray action once caused for
good) cannot meet, and loose for a loaded machine (the ring makes about 100 steps/s). The
rate after / before each stray is measured by ``test/measure_strays.py``, never asserted
here.
"""

from __future__ import annotations

import pytest
from ros_helpers import require_ros2, spawn_python
from strays import STEP_MONITOR, newest_step, publish, seconds_to, strays
from test_lockstep_graph import run_of
from test_nodes import start_graph, stop_graph

pytestmark = [pytest.mark.ros, pytest.mark.slow]

FLOOR_STEPS, FLOOR_SECONDS = 200, 30.0


@pytest.mark.timeout(900)
def test_no_stray_on_a_step_topic_slows_the_ring_for_good(ros_domain, tmp_path):
    require_ros2()
    procs = start_graph(ros_domain, tmp_path)
    monitor = procs["monitor"] = spawn_python(STEP_MONITOR, domain=ros_domain, name="monitor")
    try:
        run = run_of(procs["maze_sim"])
        monitor.wait_for_line("MONITOR READY", timeout=60)
        assert seconds_to(monitor, run, FLOOR_STEPS, 90) is not None, monitor.output
        for stray in strays(run):
            publish(ros_domain, stray)
            start = newest_step(monitor, run)
            took = seconds_to(monitor, run, start + FLOOR_STEPS, FLOOR_SECONDS, since=start)
            dead = [n for n, p in procs.items() if not p.running()]
            assert not dead, procs[dead[0]].describe(f"{dead[0]} died after stray {stray}")
            assert took is not None, procs["maze_sim"].describe(
                f"after stray {stray}: {newest_step(monitor, run, start) - start} steps in "
                f"{FLOOR_SECONDS:.0f} s")
            print(f"stray {stray}: {FLOOR_STEPS} steps in {took:.1f} s")
    finally:
        stop_graph(procs)
