"""One entry point for the four scenarios: checks the request, runs it, returns the JSON.

:func:`run_scenario` validates every name before any work starts (agents, goals, event,
maze file) and raises :class:`UsageError` with a message naming what is wrong; the CLI
turns it into exit code 2. The JSON starts with the contract header (docs/experiments.md)
(``scenario, maze, trials, seed``, and ``sensor``: the normalised ``--sensor`` spec,
``"identity"`` without one), then the scenario's own top-level fields, the step
caps used (:class:`.runner.Caps`), with parameter overrides (``--params``) the ``params``
they came from (:func:`params_record`), and ``agents``.
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from maze_sim.maze import Maze, MazeError, maze_file
from maze_sim.sensors import SensorSpec, SensorSpecError, parse_sensor
from maze_sim.worlds import WorldError, WorldSpec, parse_world
from tmgwr_agent.experiments import env_change, goal_change, sample_complexity, timing
from tmgwr_agent.experiments.agent_factory import AGENT_NAMES, make_agent, parse_spec
from tmgwr_agent.experiments.names import SCENARIOS
from tmgwr_agent.experiments.runner import Caps, declared_probe_tolerance
from tmgwr_agent.experiments.sensing import check_sensor, check_world

DEFAULT_MAZE = maze_file()
DEFAULT_AGENTS = AGENT_NAMES

#: Per scenario: default goals (None = the scenario takes a single --goal), episodes, agents.
DEFAULTS = {
    "goal-change": {"goals": goal_change.DEFAULT_GOALS,
                    "episodes": goal_change.DEFAULT_EPISODES, "agents": DEFAULT_AGENTS},
    "env-change": {"goals": None, "episodes": None, "agents": env_change.DEFAULT_AGENTS},
    "sample-complexity": {"goals": sample_complexity.DEFAULT_GOALS,
                          "episodes": sample_complexity.DEFAULT_EPISODES,
                          "agents": DEFAULT_AGENTS},
    "timing": {"goals": timing.DEFAULT_GOALS, "episodes": None, "agents": DEFAULT_AGENTS},
}


class UsageError(ValueError):
    """A request that names something that does not exist (exit code 2)."""


def load_maze(path: str | Path) -> Maze:
    """A maze given as a path or by the name of a maze maze_sim installs."""
    try:
        path = maze_file(path)
    except FileNotFoundError as exc:
        raise UsageError(f"maze {exc}") from None   # maze file '...' not found (looked in: ...)
    try:
        return Maze.from_file(path)
    except MazeError as exc:
        raise UsageError(str(exc)) from exc


def check_agents(agents: Sequence[str]) -> list[str]:
    agents = [a.strip() for a in agents if a.strip()]
    if not agents:
        raise UsageError("no agents given")
    for a in agents:
        try:
            parse_spec(a)
        except ValueError as exc:
            raise UsageError(str(exc)) from exc
    if len(set(agents)) != len(agents):
        raise UsageError(f"agent listed twice in {','.join(agents)}")
    return agents


def check_overrides(agents: Sequence[str], overrides: Mapping[str, Mapping[str, Any]],
                    maze: Maze) -> dict[str, dict[str, Any]]:
    """Parameter overrides per agent spec, checked before any work: every spec is one of
    ``agents`` and its agent is built once with them (an unknown name, a value out of
    range or an invalid combination is refused, naming it)."""
    out = {a: dict(overrides.get(a) or {}) for a in agents}
    for spec in overrides:
        if spec not in out:
            raise UsageError(f"parameter overrides for {spec!r}, which is not among the "
                             f"agents run ({', '.join(agents)})")
    for spec, values in out.items():
        if values:
            try:
                make_agent(spec, maze, np.random.default_rng(0), values)
            except ValueError as exc:          # ParamError: a name, range, combination
                raise UsageError(f"parameters of {spec}: {exc}") from None
    return out


def params_record(overrides: Mapping[str, Mapping[str, Any]],
                  files: Sequence[str] = ()) -> dict:
    """The JSON's ``params``: the ``--params`` arguments as given and the overrides every
    agent ran with (``{}``: its declared defaults)."""
    return {"files": [str(f) for f in files],
            "agents": {a: dict(v) for a, v in overrides.items()}}


def parse_sensor_spec(sensor: str | None) -> SensorSpec:
    """``--sensor`` parsed (its agents not checked yet), a :class:`UsageError` naming the
    part that does not parse."""
    try:
        return parse_sensor(sensor)
    except SensorSpecError as exc:
        raise UsageError(f"--sensor: {exc}") from None


def check_sensor_spec(sensor: str | None, agents: Sequence[str]) -> SensorSpec:
    """``--sensor``: the checked spec, refused (naming the part, or the agent that cannot
    run under it) as a :class:`UsageError`."""
    try:
        spec = parse_sensor(sensor)
    except SensorSpecError as exc:
        raise UsageError(f"--sensor: {exc}") from None
    why = check_sensor(agents, spec)
    if why:
        raise UsageError(f"--sensor: {why}")
    return spec


#: The scenarios a registered env (``--world gym:ID``: no events, no named goals) runs.
GYM_SCENARIOS = ("sample-complexity",)


def check_world_spec(world: str | None, world_kwargs: str | None,
                     agents: Sequence[str] | None, default_agents: Sequence[str],
                     scenario: str, sensor: SensorSpec) -> tuple[WorldSpec, list[str]]:
    """``--world`` / ``--world-kwargs``: the checked spec and the agents to run (without
    ``--agents``, those of ``default_agents`` that can run there), refused (naming the
    world, the env id, the kwargs, or the scenario or agent that cannot run there) as a
    :class:`UsageError`."""
    try:
        spec = parse_world(world, world_kwargs)
    except WorldError as exc:
        raise UsageError(f"--world: {exc}") from None
    if not spec.from_maze and scenario not in GYM_SCENARIOS:
        raise UsageError(f"--world {spec.text}: a registered env has no events or named "
                         f"goals; it runs {', '.join(GYM_SCENARIOS)} only (not {scenario})")
    if spec.name != "grid" and not sensor.identity:
        raise UsageError(f"--sensor {sensor.text} applies to the grid world only; "
                         f"--world {spec.text} senses through its own wrapper")
    if not agents:
        agents = [a for a in default_agents if check_world([a], spec) is None]
    agents = check_agents(agents)
    why = check_world(agents, spec)
    if why:
        raise UsageError(f"--world: {why}")
    return spec, agents


def gym_maze(spec: WorldSpec, directory: str | Path) -> Path:
    """The layout of a ``gym:ID`` world as a maze file (``#`` wall, ``S`` start, ``G``
    goal) in ``directory``: the caps and goal checks of the scenarios read it."""
    from maze_sim.worlds import make_world
    try:
        w = make_world(spec, None)
    except WorldError as exc:
        raise UsageError(f"--world: {exc}") from None
    except (TypeError, ValueError) as exc:
        raise UsageError(f"--world {spec.text} --world-kwargs: {exc}") from None
    rows = []
    for r in range(w.walls.shape[0]):
        rows.append("".join("S" if (r, c) == w.start_pose[:2] else
                            "G" if (r, c) == w.goal else
                            "#" if w.walls[r, c] else "." for c in range(w.walls.shape[1])))
    path = Path(directory) / (spec.env_id.replace("/", "_") + ".txt")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def check_goals(maze: Maze, goals: Sequence[str]) -> tuple[str, ...]:
    for g in goals:
        if g not in maze.goals:
            raise UsageError(f"no goal named {g!r} in {maze.source} "
                             f"(goals: {', '.join(sorted(maze.goals))})")
    return tuple(goals)


def check_event(maze: Maze, event: str, goal: str = "G") -> str:
    if event not in maze.events:
        known = ", ".join(sorted(maze.events)) or "none"
        raise UsageError(f"no event named {event!r} in {maze.source} (events: {known})")
    if maze.shortest_path_length(maze.start, maze.goal_cell(goal),
                                 walls=maze.walls_after([event])) < 0:
        raise UsageError(f"event {event!r} cuts the goal off from the start in {maze.source}")
    return event


def run_scenario(scenario: str, maze_path: str | Path = DEFAULT_MAZE,
                 agents: Sequence[str] | None = None, trials: int = 10, seed: int = 0,
                 goals: Sequence[str] | None = None, episodes: int | None = None,
                 event: str = "a", goal: str = "G", jobs: int | None = None,
                 progress: bool = True,
                 overrides: Mapping[str, Mapping[str, Any]] | None = None,
                 params_files: Sequence[str] = (), sensor: str | None = None,
                 world: str | None = None, world_kwargs: str | None = None,
                 delays: str | Sequence[int] | None = None) -> dict:
    """``overrides``: parameter overrides per agent spec (``--params``; None: every agent
    with its declared defaults, and no ``params`` in the JSON); ``params_files``: where
    they came from, recorded beside them; ``sensor``: the ``--sensor`` spec (None:
    identity), recorded normalised as ``sensor``; ``world``, ``world_kwargs``: the
    ``--world`` and its ``--world-kwargs`` JSON (None: the grid), recorded as ``world``
    (and ``world_kwargs`` when given); ``delays``: env-change's ``--event-delay``
    (:func:`check_delays`). A ``gym:ID`` world runs on its own layout (written
    as a maze file to a temporary folder: ``maze_path`` is not read)."""
    if scenario not in SCENARIOS:
        raise UsageError(f"unknown scenario {scenario!r}; scenarios: {', '.join(SCENARIOS)}")
    delays = check_delays(delays, scenario)
    d = DEFAULTS[scenario]
    wspec, agents = check_world_spec(world, world_kwargs, agents, d["agents"], scenario,
                                     parse_sensor_spec(sensor))
    if not wspec.from_maze:
        import tempfile
        with tempfile.TemporaryDirectory(prefix="tmgwr_gym_") as tmp:
            out = _run_scenario(scenario, gym_maze(wspec, tmp), agents, trials, seed,
                                goals or ("G",), episodes, event, goal, jobs, progress,
                                overrides, params_files, sensor, wspec, delays)
        out["maze"] = f"{wspec.text} (layout seed {wspec.kwargs.get('layout_seed', 0)})"
        return out
    return _run_scenario(scenario, maze_path, agents, trials, seed, goals, episodes, event,
                         goal, jobs, progress, overrides, params_files, sensor, wspec, delays)


def check_delays(delays: str | Sequence[int] | None, scenario: str) -> tuple[int, ...]:
    """``--event-delay``: the delays (:func:`.env_change.parse_delays`; None: ``(0,)``),
    refused as a :class:`UsageError` naming the part, or the scenario when it is not
    env-change."""
    try:
        out = env_change.parse_delays(delays)
    except env_change.DelayError as exc:
        raise UsageError(f"--event-delay: {exc}") from None
    if out != (0,) and scenario != "env-change":
        raise UsageError(f"--event-delay applies to env-change only, not {scenario}")
    return out


def _run_scenario(scenario, maze_path, agents, trials, seed, goals, episodes, event, goal,
                  jobs, progress, overrides, params_files, sensor, wspec: WorldSpec,
                  delays: tuple[int, ...] = (0,)) -> dict:
    d = DEFAULTS[scenario]
    maze = load_maze(maze_path)
    maze_path = maze.source          # the file found (a name resolves to the installed maze)
    agents = check_agents(agents if agents else d["agents"])
    if trials < 1:
        raise UsageError(f"--trials must be >= 1, got {trials}")
    goals = check_goals(maze, goals if goals else (d["goals"] or ()))
    check_goals(maze, [goal])
    episodes = episodes if episodes is not None else d["episodes"]
    if episodes is not None and episodes < 1:
        raise UsageError(f"--episodes must be >= 1, got {episodes}")
    if overrides is not None:
        overrides = check_overrides(agents, overrides, maze)
    spec = check_sensor_spec(sensor, agents)
    maze_s = str(maze_path)
    common = dict(jobs=jobs, progress=progress, overrides=overrides, sensor=spec.text,
                  world=wspec)
    if scenario == "goal-change":
        if len(goals) < 2:
            raise UsageError("goal-change needs at least two goals (--goals 1,2,...)")
        body = goal_change.run(maze_s, agents, trials, seed, goals, episodes, **common)
    elif scenario == "env-change":
        body = env_change.run(maze_s, agents, trials, seed, check_event(maze, event, goal),
                              goal, delays=delays, **common)
    elif scenario == "sample-complexity":
        body = sample_complexity.run(maze_s, agents, trials, seed, goals, episodes, **common)
    else:
        if len(goals) != 2:
            raise UsageError(f"timing takes two goals FROM,TO (got {','.join(goals)})")
        body = timing.run(maze_s, agents, trials, seed, goals, check_event(maze, event, goal),
                          goal, **common)
    out = {"scenario": scenario, "maze": maze_s, "trials": trials, "seed": seed,
           "sensor": spec.text, "world": wspec.text}
    if wspec.kwargs:
        out["world_kwargs"] = dict(wspec.kwargs)
    if declared_probe_tolerance(wspec):
        out["probe_tolerance"] = declared_probe_tolerance(wspec)
    out.update({k: v for k, v in body.items() if k not in ("agents", "delays")})
    out["caps"] = asdict(Caps.for_maze(maze))
    if overrides is not None:
        out["params"] = params_record(overrides, params_files)
    if "delays" in body:                     # several --event-delay values
        out["delays"] = body["delays"]
    else:
        out["agents"] = body["agents"]
    return out
