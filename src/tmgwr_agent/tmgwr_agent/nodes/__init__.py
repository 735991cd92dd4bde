"""The ROS 2 nodes of the graph (DESIGN.md section 2): thin shells around the core.

One module per node; :mod:`.common` holds what they share (QoS, parameters, flat arrays,
``main``). Each per-step callback calls the same core objects, in the same order, as
:class:`tmgwr_agent.agent.TMGWRAgent` does in-process (see :mod:`tmgwr_agent.reference`).
"""
