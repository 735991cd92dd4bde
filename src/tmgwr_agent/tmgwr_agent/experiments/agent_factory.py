"""Agent names of the experiments CLI (docs/experiments.md) and their factory.

``make_agent("tmgwr:credit", maze, rng)``: a name, optionally followed by ``:options``
joined by ``+``. TMGWR options: ``literal`` / ``credit`` choose the sensorimotor-link rule
(plain ``tmgwr`` uses the default of ``MapConfig.link_rule``); ``grid`` measures the value
of the unknown on the sensor's axes (``unknown`` grid: it is told the sensation is a grid
cell's coordinates; plain ``tmgwr`` learns its frame, core/frame.py); ``none`` gives what
the map does not know no value (Eq. 5 as printed, our other additions kept: the learnt
frame assumes primitives that displace the sensation alike everywhere, which MiniGrid's
turn / forward do not); ``settle`` learns how often the world changes and re-tests its
walls in proportion (``retest_rate`` learnt: fewer steps an episode in a world that
stays, openings found later); ``paper`` turns our
additions off (``absorbing_terminals``; ``unknown`` none and ``try_untried``, the options
of Eq. 5' and Eq. 6; ``goal_search``; ``walk_while_novel``; ``merge``, one node a
place: the agent of Eq. 1-7 as
printed), e.g.
``tmgwr:literal+paper``. The baselines (:data:`BASELINES`) take no option. Options are
parameter overrides, checked like any other (an unknown name is refused).
"""

from __future__ import annotations

from importlib import import_module
from typing import Any, Mapping

import numpy as np

from maze_sim.maze import Maze
from tmgwr_agent.core.protocol import Agent
from tmgwr_agent.core.senses import Senses
from tmgwr_agent.world_senses import maze_senses

AGENT_NAMES = ("tmgwr", "q_learning", "model_based", "dyna_q_plus", "rmax", "freespace")

#: The baseline agents: name -> (module, class); each class has ``Config``, its parameters.
BASELINES = {
    "q_learning": ("tmgwr_agent.baselines.q_learning", "QLearningAgent"),
    "model_based": ("tmgwr_agent.baselines.model_based", "ModelBasedAgent"),
    "dyna_q_plus": ("tmgwr_agent.baselines.dyna_q_plus", "DynaQPlusAgent"),
    "rmax": ("tmgwr_agent.baselines.rmax", "RMaxAgent"),
    "freespace": ("tmgwr_agent.baselines.freespace", "FreeSpaceAgent"),
}


TMGWR_OPTIONS = {
    "literal": {"link_rule": "literal"},
    "credit": {"link_rule": "credit"},
    "grid": {"unknown": "grid"},
    "none": {"unknown": "none"},
    "settle": {"retest_rate": "learnt"},
    "paper": {"absorbing_terminals": False, "unknown": "none", "goal_search": False,
              "try_untried": False, "walk_while_novel": False, "eps_min": 0.1,
              "merge": False},
}


def parse_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """(agent name, parameter overrides of its options)."""
    name, _, options = spec.partition(":")
    if name not in AGENT_NAMES:
        raise ValueError(f"unknown agent {name!r} in {spec!r}; agents: {', '.join(AGENT_NAMES)}")
    if options and name != "tmgwr":
        raise ValueError(f"agent {name!r} takes no option (got {spec!r})")
    overrides: dict[str, Any] = {}
    for option in options.split("+") if options else ():
        if option not in TMGWR_OPTIONS:
            raise ValueError(f"unknown tmgwr option {option!r} in {spec!r}; "
                             f"options: {', '.join(TMGWR_OPTIONS)}")
        overrides.update(TMGWR_OPTIONS[option])
    return name, overrides


def baseline_class(name: str) -> type:
    """The agent class of a baseline name (imported on first use)."""
    module, cls = BASELINES[name]
    return getattr(import_module(module), cls)


def make_agent(spec: str, maze: Maze, rng: np.random.Generator,
               overrides: Mapping[str, Any] | None = None, senses: Senses | None = None,
               sensed: bool = False) -> Agent:
    """``senses``: what the TMGWR agent senses and acts with (default: the grid world's,
    :func:`~tmgwr_agent.world_senses.maze_senses`); ``sensed``: the world is seen through
    a sensor transform (:mod:`.sensing`): a tabular agent then keys on sensed states, not
    cells."""
    name, options = parse_spec(spec)
    if name == "tmgwr":
        from tmgwr_agent.core.agent import TMGWRAgent
        return TMGWRAgent(senses or maze_senses(), rng, {**(overrides or {}), **options})
    from tmgwr_agent.experiments.sensing import SENSED_TABLE_AGENTS
    if name in SENSED_TABLE_AGENTS:
        n_actions = senses.n_actions if senses is not None else maze_senses().n_actions
        return baseline_class(name)(maze, rng, overrides, sensed_states=sensed,
                                    n_actions=n_actions)
    return baseline_class(name)(maze, rng, overrides)   # sensing.check_sensor refuses it
