"""Episodes from a stream of Observations, without ROS.

:class:`EpisodeMonitor` is fed one Observation at a time (any object with the message's
fields: ``step_id``, ``episode``, ``episode_start``, ``row``, ``col``, ``terminal``,
``goal_reached``, ``previous_goal_reached``) and turns the stream into episodes: how many
steps each took and whether it ended at the goal, the previous goal, or was cut short.
The live graph feeds it from the Observation topic
(:func:`tmgwr_agent.graph.clients.subscribe_monitor`: ``./tmgwr up`` prints it, the demo
decides with it, the bench times steps with it); the offline bag report feeds it the
recorded messages, so both state the same figures.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field


@dataclass
class EpisodeRecord:
    episode: int
    steps: int                 # actions taken in the episode
    outcome: str               # "goal", "previous_goal", "cut" (truncated / reset)
    end_step: int              # step_id of the episode's last observation
    start_cell: tuple[int, int] = (-1, -1)
    end_cell: tuple[int, int] = (-1, -1)


@dataclass
class EpisodeMonitor:
    """Episodes from the stream of Observations (one per lockstep step).

    Every Observation goes through :meth:`on_observation`. ``steps`` counts actions
    (observations that are not an episode's first). An episode ends with a ``terminal``
    observation; one whose end was never seen (a reset, the monitor joining late) is
    closed as ``cut`` when the next episode starts. Step ids count within a run
    (``run_id``, ``tmgwr_common.lockstep``): a newer run (the simulator restarted) starts
    the count again, an older one is ignored; run 0 (recordings made before run ids) is
    taken as the current run.
    """

    episodes: list[EpisodeRecord] = field(default_factory=list)
    last_step_id: int = -1
    first_step_id: int = -1
    first_time: float = 0.0
    last_time: float = 0.0
    seen: int = 0
    missed: int = 0            # gaps in step_id after the first message
    run_id: int = 0            # the run followed (0: none seen)
    runs: int = 0              # runs seen (more than 1: the simulator restarted)
    _episode: int = -1
    _steps: int = 0
    _start_cell: tuple[int, int] = (-1, -1)
    _closed: bool = True
    on_episode: object = None  # callable(EpisodeRecord) or None

    def on_observation(self, msg) -> None:
        now = time.perf_counter()
        sid = int(msg.step_id)
        run = int(getattr(msg, "run_id", 0))
        if run and run != self.run_id:
            if run < self.run_id:
                return      # a message of a simulator that was replaced
            if self.runs and not self._closed and self._episode >= 0:
                self._close("cut", self.last_step_id, (-1, -1))
                self._episode = -1
            self.run_id, self.runs, self.last_step_id = run, self.runs + 1, -1
            if self.first_step_id >= 0:          # the rate counts from the new run's start
                self.first_step_id, self.first_time = sid, now
        if sid <= self.last_step_id:
            return          # the simulator resent an observation nobody answered yet
        if self.first_step_id < 0:
            self.first_step_id, self.first_time = sid, now
        elif sid > self.last_step_id + 1:
            self.missed += sid - self.last_step_id - 1
        self.last_step_id, self.last_time = sid, now
        self.seen += 1
        cell = (int(msg.row), int(msg.col))
        if msg.episode_start or int(msg.episode) != self._episode:
            if not self._closed and self._episode >= 0:
                self._close("cut", sid - 1, cell)
            self._episode, self._steps, self._start_cell = int(msg.episode), 0, cell
            self._closed = False
        if not msg.episode_start:
            self._steps += 1
        if msg.terminal and not self._closed:
            outcome = ("goal" if msg.goal_reached else
                       "previous_goal" if msg.previous_goal_reached else "cut")
            self._close(outcome, sid, cell)

    def _close(self, outcome: str, end_step: int, cell: tuple[int, int]) -> None:
        rec = EpisodeRecord(self._episode, self._steps, outcome, end_step, self._start_cell, cell)
        self.episodes.append(rec)
        self._closed = True
        if callable(self.on_episode):
            self.on_episode(rec)

    # -------------------------------------------------------------- summaries
    def rate(self) -> float:
        """Steps per second over what this monitor saw."""
        dt = self.last_time - self.first_time
        return (self.last_step_id - self.first_step_id) / dt if dt > 0 else 0.0

    def since(self, step_id: int) -> list[EpisodeRecord]:
        """Episodes that ended after ``step_id``."""
        return [e for e in self.episodes if e.end_step > step_id]

    def reliable(self, optimal: int, streak: int = 3, slack: float = 1.5,
                 after_step: int = -1) -> bool:
        """The last ``streak`` episodes (ended after ``after_step``) all reached the goal
        within ``slack`` times the shortest path."""
        eps = self.since(after_step)
        last = eps[-streak:]
        return len(last) == streak and all(
            e.outcome == "goal" and e.steps <= slack * optimal for e in last)
