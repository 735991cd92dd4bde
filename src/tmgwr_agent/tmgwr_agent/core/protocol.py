"""The interface every agent (TMGWR and the baselines) offers to the experiment loop.

The loop is the same for all agents, in-process and over ROS::

    obs, _ = world.reset()
    agent.begin_episode(obs, cell, learn=True)  # no link/transition from the last episode
    while True:
        action = agent.act(explore=True)        # epsilon-greedy, section 5.1 / Eq. 7
        obs, _, terminated, truncated, info = world.step(action)
        agent.observe(obs, info, learn=True)    # learn from (previous, action, now);
                                                # Eq. 7 decays epsilon at the goal
        if terminated or truncated: break

A greedy rollout (convergence checks) calls ``begin_episode(..., learn=False)``,
``act(explore=False)`` and ``observe(..., learn=False)``: epsilon 0 and no learning.

What each agent may use is part of the comparison (Table 1): the TMGWR agent uses only the
sensed ``obs`` vector (of the dimension its :class:`~tmgwr_agent.core.senses.Senses`
declare), ``info.bumped`` (a touch sensor) and the goal *observation*; the tabular agents
use ``cell`` (their state: the world's cell, or under a sensor transform the discretised
sensation, never the true cell) and the outcome flags of ``info`` for their rewards; the
model-based agent is also handed the original maze as its transition model.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

#: The tabular agents' state: a world's cell index (the TMGWR agent never reads it).
Cell = Any
#: What a step did besides the observation: ``action``, ``bumped``, ``reached_goal``,
#: ``terminated`` (the simulator's ``maze_sim.world.StepInfo``, or any object with them).
StepInfo = Any


class Agent(Protocol):
    name: str

    def set_goal(self, goal_cell: Cell, goal_obs: np.ndarray) -> None:
        """A new goal (cell for the tabular agents, observation for TMGWR)."""

    def begin_episode(self, obs: np.ndarray, cell: Cell, learn: bool = True) -> None:
        """The first observation of an episode (the agent was teleported here)."""

    def act(self, explore: bool = True) -> int:
        """The action for the current observation."""

    def observe(self, obs: np.ndarray, info: StepInfo, learn: bool = True) -> None:
        """The outcome of the last action (when learning, epsilon decays by Eq. 7 if it
        reached the goal)."""

    @property
    def epsilon(self) -> float:
        """The current exploration probability."""
