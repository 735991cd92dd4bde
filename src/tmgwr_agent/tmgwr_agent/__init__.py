"""tmgwr_agent: the TMGWR-based goal-directed agent of Ezenkwu & Starkey (2022).

ROS-free core in ``core`` (one module per box of Fig. 1a): ``preprocessor``,
``sensorimotor_map``, ``motivation``, ``action_selector``, composed by
``core.agent.TMGWRAgent``; the comparison agents in ``baselines``; the paper's experiments
in ``experiments`` (``python -m tmgwr_agent.cli``). The ROS 2 nodes that wrap the core live
in ``nodes``; ``graph`` runs them, ``bag`` reads and writes their recordings.
"""
