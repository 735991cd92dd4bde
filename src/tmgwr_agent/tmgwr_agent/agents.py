"""Agent names of the experiments CLI (DESIGN.md section 5) and their factory.

``make_agent("tmgwr:credit", maze, rng)``: a name, optionally followed by ``:option``.
Options: ``tmgwr:literal`` / ``tmgwr:credit`` choose the sensorimotor-link rule (plain
``tmgwr`` uses the configured default); the baselines take no option.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from maze_sim.maze import Maze

from .agent_api import Agent

AGENT_NAMES = ("tmgwr", "q_learning", "model_based", "dyna_q_plus")


def parse_spec(spec: str) -> tuple[str, str | None]:
    name, _, option = spec.partition(":")
    if name not in AGENT_NAMES:
        raise ValueError(f"unknown agent {name!r} in {spec!r}; agents: {', '.join(AGENT_NAMES)}")
    if option and name != "tmgwr":
        raise ValueError(f"agent {name!r} takes no option (got {spec!r})")
    if option and option not in ("literal", "credit"):
        raise ValueError(f"unknown tmgwr option {option!r} in {spec!r}; "
                         "options: literal, credit")
    return name, option or None


def make_agent(spec: str, maze: Maze, rng: np.random.Generator,
               overrides: Mapping[str, Any] | None = None) -> Agent:
    name, option = parse_spec(spec)
    if name == "tmgwr":
        from .agent import TMGWRAgent
        params = dict(overrides or {})
        if option:
            params["link_rule"] = option
        return TMGWRAgent(maze, rng, params)
    if name == "q_learning":
        from .baselines.q_learning import QLearningAgent
        return QLearningAgent(maze, rng, overrides)
    if name == "model_based":
        from .baselines.model_based import ModelBasedAgent
        return ModelBasedAgent(maze, rng, overrides)
    from .baselines.dyna_q_plus import DynaQPlusAgent
    return DynaQPlusAgent(maze, rng, overrides)
