"""Restart a node of a running graph that dies, with a delay and a limit (``./tmgwr up``).

What launch's ``respawn`` / ``respawn_delay`` does for ``ros2 launch`` (the launch file
uses those, with the same limit: ``agent.launch.py``), for the processes of a
:class:`~tmgwr_agent.graph.supervisor.GraphSupervisor`:

* A node that exits with a non-zero code while the graph runs (a crash, SIGKILL) is started
  again after ``delay`` seconds with the same command. Every node that keeps a checkpoint
  runs with ``resume`` on (the run's directory under ``./tmgwr up``), so it continues from
  its own checkpoint and rejoins the lockstep (tmgwr_common.lockstep: a restarted simulator
  starts a new run id that every node follows; a restarted agent node answers the
  simulator's next resend).
* A node that exits with code 0 ended on purpose (a lifecycle ``shutdown`` of the learner,
  maze_sim's ``exit_when_done``): it is not restarted, and the graph stops saying so.
* A node that dies more than ``max_deaths`` times within ``window`` seconds is not started
  again: :meth:`Respawner.watch` raises :class:`GraphError` naming the node, how often it
  died, and its last output, and the caller stops the graph.
* Once a restarted node prints its ready line, :meth:`Respawner.watch` reports how long
  the ring took to turn again: two new steps seen by the observer after that line (one full
  lap through the restarted node).

A restarted recorder writes a new bag, ``<bag>/respawned_<N>/`` (a bag is never appended
to; the killed one needs ``./tmgwr recover``): the spec's ``on_respawn`` says how.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

from tmgwr_agent.graph.supervisor import GraphError, GraphSupervisor, ManagedProcess

#: The defaults of ``./tmgwr up`` and the launch file (one place).
RESPAWN_DELAY = 1.0          # seconds between a death and the restart
RESPAWN_MAX_DEATHS = 5       # deaths of one node allowed within the window
RESPAWN_WINDOW = 60.0        # seconds


@dataclass(frozen=True)
class RespawnPolicy:
    delay: float = RESPAWN_DELAY
    max_deaths: int = RESPAWN_MAX_DEATHS
    window: float = RESPAWN_WINDOW

    def __post_init__(self):
        if self.delay < 0 or self.window <= 0 or self.max_deaths < 0:
            raise ValueError(f"respawn policy {self}: delay >= 0, window > 0 and "
                             "max_deaths >= 0 expected")


@dataclass
class _Pending:
    index: int               # position in supervisor.processes
    due: float               # time.monotonic() of the restart


@dataclass
class _Rejoin:
    label: str
    pid: int
    process: ManagedProcess
    steps_at_ready: int = -1
    ready_at: float = 0.0


@dataclass
class Respawner:
    """Watches ``supervisor``'s processes; ``steps`` (a callable) counts the steps the
    observer has seen so far (``EpisodeMonitor.seen``), for the rejoin time."""

    supervisor: GraphSupervisor
    policy: RespawnPolicy = field(default_factory=RespawnPolicy)
    steps: Callable[[], int] = lambda: 0
    deaths: dict[str, list[float]] = field(default_factory=dict)
    restarts: dict[str, int] = field(default_factory=dict)
    rejoin_times: list[tuple[str, float]] = field(default_factory=list)
    _pending: dict[str, _Pending] = field(default_factory=dict)
    _rejoining: list[_Rejoin] = field(default_factory=list)

    def watch(self, now: float | None = None) -> list[str]:
        """Handle deaths, due restarts and rejoins; returns the lines to print. Raises
        GraphError when a node died too often (the caller stops the graph)."""
        now = time.monotonic() if now is None else now
        lines: list[str] = []
        procs = self.supervisor.processes
        for i, p in enumerate(procs):
            if p.label in self._pending or p.returncode() is None:
                continue
            times = [t for t in self.deaths.get(p.label, []) if now - t <= self.policy.window]
            times.append(now)
            self.deaths[p.label] = times
            p._reader.join(timeout=1.0)
            died = f"node '{p.label}' died (exit code {p.returncode()})"
            if p.returncode() == 0:
                # it ended on purpose (a lifecycle shutdown, maze_sim's exit_when_done)
                raise GraphError(p.describe(f"{died}: it ended by itself, so it is not "
                                            "restarted; the graph stops"))
            if len(times) > self.policy.max_deaths:
                raise GraphError(p.describe(
                    f"{died}: {len(times)} deaths within {self.policy.window:g} s, more "
                    f"than the limit of {self.policy.max_deaths} (--respawn-limit); not "
                    "restarting it: the graph stops"))
            last = (list(p.tail) or ["(no output)"])[-1]
            lines.append(f"{died}; last output: {last}\n  restarting it in "
                         f"{self.policy.delay:g} s (death {len(times)} of at most "
                         f"{self.policy.max_deaths} within {self.policy.window:g} s)")
            self._pending[p.label] = _Pending(i, now + self.policy.delay)
        for label, pending in list(self._pending.items()):
            if now < pending.due:
                continue
            del self._pending[label]
            n = self.restarts.get(label, 0) + 1
            self.restarts[label] = n
            old = procs[pending.index]
            spec = old.spec.on_respawn(old.spec, n) if old.spec.on_respawn else old.spec
            new = ManagedProcess(spec, self.supervisor.env, self.supervisor._sink)
            procs[pending.index] = new
            self._rejoining.append(_Rejoin(label, new.pid, new))
            lines.append(f"node '{label}' restarted (pid {new.pid}, restart {n})")
        for r in list(self._rejoining):
            if r.process.returncode() is not None:
                self._rejoining.remove(r)          # died again: handled above next time
                continue
            if r.steps_at_ready < 0:
                if r.process.ready.is_set():
                    r.steps_at_ready, r.ready_at = self.steps(), r.process.ready_at
                continue
            if self.steps() >= r.steps_at_ready + 2:
                dt = now - r.ready_at
                self.rejoin_times.append((r.label, dt))
                self._rejoining.remove(r)
                lines.append(f"node '{r.label}' rejoined: the ring turned again "
                             f"{dt:.2f} s after its ready line")
        return lines

    def waiting(self) -> bool:
        """A restart is pending or a restarted node has not rejoined yet."""
        return bool(self._pending or self._rejoining)
