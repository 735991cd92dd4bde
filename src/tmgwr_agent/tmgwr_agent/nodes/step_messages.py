"""What the per-step messages carry of the agent's last action, as the core's Outcome.

Features, SensorimotorState and MotivationField pass on the simulator's flags of the step
(episode start, executed action, bump, goal reached, episode over); every agent node turns
them into the same :class:`~tmgwr_agent.core.outcome.Outcome` the in-process agent builds
from ``StepInfo``.
"""

from __future__ import annotations

from tmgwr_agent.core.outcome import EPISODE_START, Outcome


def outcome_of(msg) -> Outcome:
    if msg.episode_start:
        return EPISODE_START
    return Outcome(action=int(msg.action), bumped=bool(msg.bumped),
                   goal_reached=bool(msg.goal_reached), episode_over=bool(msg.terminal),
                   truncated=bool(getattr(msg, "truncated", False)))
