"""tmgwr_common.lockstep.Lockstep without ROS: the (run_id, step_id) rules of its docstring.

Each case is one way the ring used to freeze for ever (a node dropping every step id not
above the newest it had seen) or a way it must not be derailed.
"""

from __future__ import annotations

from tmgwr_common.lockstep import Lockstep


class Pub:
    def __init__(self):
        self.sent = []

    def publish(self, msg):
        self.sent.append(msg)


class Log:
    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(("info", text))

    def warning(self, text):
        self.lines.append(("warn", text))


def make(**kw):
    pub, log = Pub(), Log()
    return Lockstep(pub, logger=log, **kw), pub, log


def step(ls, run, sid):
    """Feed (run, sid); the output computed is (run, sid, 'new')."""
    ls.on_step(run, sid, lambda: (run, sid, "new"), answer_again=lambda: (run, sid, "again"))


def test_a_run_is_followed_step_by_step_and_a_resend_answered_from_cache():
    ls, pub, log = make()
    for sid in (0, 1, 1, 2):
        step(ls, 7, sid)
    assert pub.sent == [(7, 0, "new"), (7, 1, "new"), (7, 1, "new"), (7, 2, "new")]
    assert log.lines == [("info", "following run 7 from step 0")]


def test_a_restarted_simulator_is_followed_from_its_first_step():
    ls, pub, log = make()
    for sid in range(50):
        step(ls, 7, sid)
    step(ls, 9, 0)                      # the new simulator's step 0
    step(ls, 9, 1)
    assert pub.sent[-2:] == [(9, 0, "new"), (9, 1, "new")]
    assert ("info", "maze_sim restarted (run 7 -> 9): following the new run from step 0") \
        in log.lines


def test_run_zero_is_ignored_with_one_warning_per_period():
    ls, pub, log = make()
    step(ls, 7, 3)
    for _ in range(5):
        step(ls, 0, 999999999)          # `ros2 topic pub` with the default run_id
    step(ls, 7, 4)
    assert pub.sent == [(7, 3, "new"), (7, 4, "new")]
    warnings = [t for k, t in log.lines if k == "warn"]
    assert len(warnings) == 1 and "run_id 0" in warnings[0]


def test_a_map_of_another_run_is_restored_and_the_new_run_followed():
    ls, pub, log = make(last_step=123456, run_id=5)      # saved by an earlier run
    step(ls, 9, 0)
    assert pub.sent == [(9, 0, "new")]
    assert ls.run_id == 9 and ls.last_step == 0


def test_a_map_of_the_same_run_answers_its_last_step_again():
    ls, pub, _ = make(last_step=40, run_id=9)            # the learner restarted mid-run
    step(ls, 9, 40)                                      # the simulator's resend
    step(ls, 9, 41)
    assert pub.sent == [(9, 40, "again"), (9, 41, "new")]


def test_a_stray_step_of_the_current_run_is_undone_by_the_next_real_step():
    ls, pub, log = make()
    step(ls, 7, 10)
    step(ls, 7, 999999999)              # a stray carrying this run's id
    step(ls, 7, 11)                     # the simulator goes on: followed, with a warning
    step(ls, 7, 12)
    assert pub.sent[-2:] == [(7, 11, "new"), (7, 12, "new")]
    assert any(k == "warn" and "not the simulator's" in t for k, t in log.lines)


def test_an_older_run_is_dropped_unless_its_simulator_keeps_resending_alone():
    ls, pub, log = make()
    step(ls, 9, 5)
    step(ls, 7, 100)                    # in flight from a replaced simulator: dropped
    step(ls, 9, 6)                      # the newer run goes on
    step(ls, 7, 100)                    # not a lone resend (run 9 was accepted between)
    assert pub.sent == [(9, 5, "new"), (9, 6, "new")]
    step(ls, 7, 100)                    # resent again, nothing else came: follow run 7
    assert pub.sent[-1] == (7, 100, "new") and ls.run_id == 7
    assert any("run 7 resends step 100" in t for _, t in log.lines)


def test_a_stray_with_a_larger_run_id_is_undone_by_the_simulators_resend():
    ls, pub, _ = make()
    step(ls, 9, 5)
    step(ls, 2 ** 64 - 1, 0)            # a forged newer run: followed at once
    step(ls, 9, 6)                      # dropped once (an older run)...
    step(ls, 9, 6)                      # ...and followed when the simulator resends it
    assert pub.sent[-1] == (9, 6, "new") and ls.run_id == 9


def test_the_episode_monitor_follows_a_restarted_simulator():
    from types import SimpleNamespace

    from tmgwr_agent.episodes import EpisodeMonitor

    def obs(run, sid, episode, start=False, terminal=False):
        return SimpleNamespace(run_id=run, step_id=sid, episode=episode, episode_start=start,
                               row=1, col=1, terminal=terminal, goal_reached=terminal,
                               previous_goal_reached=False)

    mon = EpisodeMonitor()
    for m in [obs(7, 0, 0, start=True), obs(7, 1, 0), obs(7, 2, 0, terminal=True),
              obs(7, 3, 1, start=True), obs(7, 4, 1),          # killed mid-episode
              obs(9, 0, 0, start=True), obs(9, 1, 0), obs(9, 2, 0, terminal=True),
              obs(7, 5, 1)]:                                    # late, of the old run
        mon.on_observation(m)
    assert [(e.outcome, e.steps) for e in mon.episodes] == [("goal", 2), ("cut", 1),
                                                             ("goal", 2)]
    assert (mon.run_id, mon.runs, mon.last_step_id) == (9, 2, 2)
