"""The paper's experiments (sections 5.2, 6; docs/experiments.md), one idea per module.

* :mod:`.runner` -- training episodes, greedy rollouts, the convergence test (ten
  consecutive optimal greedy paths) and the step caps that keep every run finite;
* :mod:`.stats` -- the ``STAT`` dictionaries of the JSON (``null`` for failed trials);
* :mod:`.parallel` -- per-trial seeds and the process pool (same JSON whatever ``--jobs``);
* :mod:`.goal_change`, :mod:`.env_change`, :mod:`.sample_complexity`, :mod:`.timing` --
  the four scenarios (Tables 3-6, Figs 5-7);
* :mod:`.plots` -- the matching figures (matplotlib, Agg);
* :mod:`.bench` -- ``./tmgwr bench``: step time of the TMGWR core and CPU seconds to
  convergence;
* :mod:`.cli` -- ``./tmgwr experiment | demo | bench``.

Nothing here imports rclpy: the experiments run the ROS-free core in-process.
"""
