"""Running the ROS 2 node graph from the pip-only environment (docs/graph.md).

* :mod:`.supervisor` -- start the five nodes (and the recorder) as separate processes,
  wait until each is ready, forward their output, stop them in reverse order.
* :mod:`.clients` -- one-shot service calls to a running graph (``/set_goal``, cells,
  events, reset) and the Observation subscription of the episode monitor
  (:mod:`tmgwr_agent.episodes`).
* :mod:`.cli` -- ``./tmgwr up | goal | cell | event | reset``.
* :mod:`.demo` -- the scripted scenario of ``make demo`` over the real graph.
* :mod:`.ring`, :mod:`.bench` -- the ceiling of a lockstep ring of processes and the graph's
  own rate (``make bench``).

Nothing here imports rclpy at module level except the modules that run as ROS processes
(:mod:`.ring`), so ``./tmgwr --help`` stays fast.
"""
