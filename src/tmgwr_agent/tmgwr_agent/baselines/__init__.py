"""The baseline agents the TMGWR agent is compared with (docs/experiments.md).

* :mod:`.q_learning` -- tabular Q-learning, the paper's model-free agent (Eq. 8, Table 2);
* :mod:`.model_based` -- value iteration with the transition model T(s, a, s') of the
  original maze hard-coded, the paper's model-based agent (Eq. 9, 11, Table 2);
* :mod:`.dyna_q_plus` -- Dyna-Q+ (Sutton & Barto 2018, section 8.3), a model-learning
  agent the paper does not have: Q-learning plus a learnt model and an exploration bonus;
* :mod:`.rmax` -- R-max: a tabular model learnt online, value iteration and optimism about
  untried pairs (not in the paper; TMGWR without the map);
* :mod:`.freespace` -- the free-space assumption planner (D* Lite behaviour): told its
  cell, the grid's geometry and the goal cell, it plans through unknown cells and
  remembers the walls it bumped into (not in the paper).

All of them are tabular over maze cells (the state is the cell the world reports, or the
discretised sensation under a sensor transform: q_learning and dyna_q_plus only) and
explore like the TMGWR agent (R-max and the free-space planner with epsilon starting at
0): :class:`~tmgwr_agent.core.exploration.EpsilonGreedy` with one ``explores()`` draw per
``act``, the random walk of section 5.1 when exploring or when
the agent has no greedy opinion, and ``walk.observe(action, bumped)`` after every step.
Each agent's hyperparameters are one config dataclass (``QLearningConfig``,
``ModelBasedConfig``, ``DynaQPlusConfig``, ``RMaxConfig``, ``FreeSpaceConfig``; the
agent class's ``Config``) that extends
:class:`~tmgwr_agent.core.exploration.ExplorationConfig`, the exploration parameters every
agent shares (the same names, defaults and ranges as the TMGWR agent's).
"""
