"""The ROS-free core of the agent: one module per box of Fig. 1a, composed by
:class:`tmgwr_agent.core.agent.TMGWRAgent`; the ROS 2 nodes in :mod:`tmgwr_agent.nodes` wrap
the same objects."""
