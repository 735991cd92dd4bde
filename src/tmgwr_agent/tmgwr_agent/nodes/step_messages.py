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


def outcome_of(msg) -> Outcome:
    if msg.episode_start:
        return EPISODE_START
    return Outcome(action=int(msg.action), bumped=bool(msg.bumped),
                   goal_reached=bool(msg.goal_reached), episode_over=bool(msg.terminal),
                   truncated=bool(getattr(msg, "truncated", False)))


def fill_change(msg, c: MapChange) -> None:
    """Write ``c`` into the fields of a ``tmgwr_interfaces/MapChange`` (an object of
    :mod:`tmgwr_common.cdr`, which takes numpy arrays and converts them to the wire's types
    when it writes: slot ids and targets int32, flags uint8, rows flattened)."""
    msg.map_id, msg.base_sequence, msg.sequence = c.map_id, c.base, c.sequence
    msg.n_slots, msg.degree, msg.dim = c.n, c.degree, c.dim
    msg.slots = c.slots
    msg.alive = c.alive
    msg.terminal_nodes = c.terminal
    msg.weights = c.w.ravel()
    msg.link_targets = c.out.ravel()
    msg.link_reliability = c.E.ravel()
    msg.merges = c.merges.ravel()


def change_of(msg) -> MapChange:
    """The map change of a SensorimotorState (``map_change``) or SensorimotorSnapshot
    (``map``), with the message's map version and step."""
    fields = msg.map_change if hasattr(msg, "map_change") else msg.map
    return MapChange.of_fields(fields, msg.map_version, msg.run_id, msg.step_id)
