"""What the per-step messages carry besides the map: the step's outcome; and the map change.

Features, SensorimotorState and MotivationField pass on the simulator's flags of the step
(episode start, executed action, bump, goal reached, episode over); every agent node turns
them into the same :class:`~tmgwr_agent.core.outcome.Outcome` the in-process agent builds
from ``StepInfo``.

SensorimotorState (per step) and SensorimotorSnapshot (latched) carry the map as a
``tmgwr_interfaces/MapChange`` (:mod:`tmgwr_agent.map_replica`): :func:`fill_change`
writes one, :func:`change_of` reads either message back.
"""

from __future__ import annotations

from tmgwr_agent.core.outcome import EPISODE_START, Outcome
from tmgwr_agent.map_replica import MapChange
from tmgwr_common.node import f64, i32, u8


def outcome_of(msg) -> Outcome:
    if msg.episode_start:
        return EPISODE_START
    return Outcome(action=int(msg.action), bumped=bool(msg.bumped),
                   goal_reached=bool(msg.goal_reached), episode_over=bool(msg.terminal),
                   truncated=bool(getattr(msg, "truncated", False)))


def fill_change(msg, c: MapChange) -> None:
    """Write ``c`` into a ``tmgwr_interfaces/MapChange`` message (one memcpy per array)."""
    msg.map_id, msg.base_sequence, msg.sequence = c.map_id, c.base, c.sequence
    msg.n_slots, msg.degree, msg.dim = c.n, c.degree, c.dim
    msg.slots = i32(c.slots)
    msg.alive = u8(c.alive)
    msg.terminal_nodes = u8(c.terminal)
    msg.weights = f64(c.w)
    msg.link_targets = i32(c.out)
    msg.link_reliability = f64(c.E)


def change_of(msg) -> MapChange:
    """The map change of a SensorimotorState (``map_change``) or SensorimotorSnapshot
    (``map``), with the message's map version and step."""
    fields = msg.map_change if hasattr(msg, "map_change") else msg.map
    return MapChange.of_fields(fields, msg.map_version, msg.run_id, msg.step_id)
