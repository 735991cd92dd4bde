"""What the agent senses of its last action besides the observation (Table 1).

The TMGWR agent never sees cells or rewards: after each action it senses its new position
(the observation), its touch sensor (``bumped``), whether it sensed the goal, and whether
the episode ended there (it is then moved back to the start, not walked). The in-process
agent reads these from the simulator's ``StepInfo``; the nodes read them from the step
messages. Both build an :class:`Outcome`, so every rule that depends on them is written
once, here or in the core method that takes an Outcome.
"""

from __future__ import annotations

from typing import NamedTuple


class Outcome(NamedTuple):       # a tuple: built every step, cheaply
    action: int = -1              # motor primitive executed; -1: the episode starts here
    bumped: bool = False          # touch sensor: the move was blocked
    goal_reached: bool = False    # the goal was sensed
    episode_over: bool = False    # the episode ended here (terminated or truncated)
    truncated: bool = False       # ... cut by a step limit, not by the task

    @property
    def episode_start(self) -> bool:
        return self.action < 0

    @property
    def ends_episode(self) -> bool:
        """The episode ended here by the task (at the goal or short of it), not by a step
        limit: the node is a terminal state of the world (absorbing in Eq. 5 unless it
        represents the current goal)."""
        return self.episode_over and not self.truncated

    @classmethod
    def of_step(cls, info) -> Outcome:
        """From the simulator's ``maze_sim.world.StepInfo`` (truncation is not a
        termination: ``info.terminated`` is the task's end only)."""
        return cls(info.action, info.bumped, info.reached_goal, info.terminated)


#: The outcome of being placed at the start of an episode.
EPISODE_START = Outcome()
