"""``./tmgwr up | goal | cell | event | reset``: run the node graph and talk to it.

* ``up`` starts the five nodes (and the recorder, to ``runs/<UTC timestamp>/`` unless
  ``--no-record``) as separate processes and keeps them running until Ctrl-C, printing
  each episode (steps, outcome) as the Observation topic shows it. ``up --resume RUN``
  continues a run from its directory's checkpoints (graph.resume; docs/graph.md, Continuing a
  run).
* ``goal X Y`` calls ``/set_goal`` (x = column, y = row); ``cell R C --block|--open`` and
  ``event NAME`` change the maze; ``reset`` restarts the episode. Each waits a bounded
  time for its service and says so when no graph is running.

Exit codes: 0 done / accepted, 1 refused or a node died, 2 no graph running or bad usage.
rclpy is imported inside the commands, so ``./tmgwr --help`` stays fast.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from tmgwr_agent.graph.output import say


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "up", help="start the ROS 2 node graph and keep it running (Ctrl-C stops it)",
        description="Start maze_sim and the four agent nodes as separate processes (what "
                    "`ros2 run` starts), wait until each is ready, record the run to MCAP "
                    "and print episodes until Ctrl-C; then stop the nodes in reverse order.")
    p.add_argument("--maze", metavar="FILE", help="maze file (default: the simulator's "
                   "parameter, the installed paper_13x17.txt)")
    p.add_argument("--seed", type=int, metavar="S", help="seed of the simulator and the "
                   "exploration policy")
    p.add_argument("--goal", metavar="NAME", help="initial goal name in the maze (G, 1-9)")
    p.add_argument("--world", metavar="NAME", help="the world the simulator hosts, built "
                   "from the maze: grid (default), minigrid (native turn / forward) or "
                   "pointmaze (MuJoCo's PointMaze); the "
                   "agent nodes take its senses")
    p.add_argument("--no-record", action="store_true", help="do not start the recorder")
    p.add_argument("--record-dir", metavar="DIR", help="record here instead of "
                   "runs/<UTC timestamp>/")
    p.add_argument("--quiet", action="store_true", help="do not forward the nodes' output "
                   "(it is still shown when a node fails)")
    p.add_argument("--max-steps", type=int, metavar="N", help="stop by itself after N steps")
    p.add_argument("--composed", action="store_true", help="run the five nodes (and the "
                   "recorder) in one process on one executor (tmgwr_agent composed), same "
                   "names, topics and services")
    p.add_argument("--params-file", action="append", default=[], metavar="FILE",
                   help="ROS 2 parameter file passed to every node (overrides only: "
                        "'/**: ros__parameters: {gamma: 0.9}' or per-node sections); "
                        "repeatable, later files win")
    p.add_argument("--resume", metavar="RUN", help="continue run RUN (its directory, or "
                   "its stamp under runs/) where it stopped: map, exploration state, "
                   "counters, with the run's settings; records to RUN/resumed_<N>/")
    from tmgwr_agent.graph.respawn import RESPAWN_DELAY, RESPAWN_MAX_DEATHS, RESPAWN_WINDOW
    p.add_argument("--respawn-limit", type=int, default=RESPAWN_MAX_DEATHS, metavar="N",
                   help="a node that dies is started again (from its checkpoint); one that "
                        "dies more than N times within the window stops the graph; 0: any "
                        f"death stops it (default {RESPAWN_MAX_DEATHS})")
    p.add_argument("--respawn-window", type=float, default=RESPAWN_WINDOW, metavar="S",
                   help=f"seconds the deaths are counted over (default {RESPAWN_WINDOW:g})")
    p.add_argument("--respawn-delay", type=float, default=RESPAWN_DELAY, metavar="S",
                   help=f"seconds from a death to the restart (default {RESPAWN_DELAY:g})")
    _domain_arg(p)
    _namespace_arg(p)
    p.set_defaults(func=cmd_up)

    p = subparsers.add_parser("goal", help="change the goal of a running graph (/set_goal)",
                              description="Call /set_goal with the cell at column X, row Y "
                                          "(x = column, y = row, from the top left).")
    p.add_argument("x", type=float, metavar="X", help="column")
    p.add_argument("y", type=float, metavar="Y", help="row")
    _client_args(p)
    p.set_defaults(func=cmd_goal)

    p = subparsers.add_parser("cell", help="block or open a maze cell of a running graph")
    p.add_argument("row", type=int, metavar="R")
    p.add_argument("col", type=int, metavar="C")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--block", dest="blocked", action="store_true", help="make it a wall")
    g.add_argument("--open", dest="blocked", action="store_false", help="make it free")
    _client_args(p)
    p.set_defaults(func=cmd_cell)

    p = subparsers.add_parser("event", help="fire a maze event (a-z) in a running graph")
    p.add_argument("name", metavar="NAME", help="event letter, e.g. a")
    _client_args(p)
    p.set_defaults(func=cmd_event)

    p = subparsers.add_parser("reset", help="reset the simulator of a running graph "
                                            "(the agent goes back to the start)")
    _client_args(p)
    p.set_defaults(func=cmd_reset)


def _domain_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--domain-id", type=int, metavar="N", help="ROS_DOMAIN_ID (default: the "
                   "environment's, else 0)")


def _namespace_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--namespace", default="/", metavar="NS", help="the graph's ROS namespace "
                   "(default /; a graph started with __ns:=/a or namespace:=a is in /a)")


def _client_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--timeout", type=float, default=10.0, metavar="SEC",
                   help="how long to wait for the service (default 10 s)")
    _domain_arg(p)
    _namespace_arg(p)


def _name(args, name: str, node: str = "") -> str:
    """A service name of the graph in ``--namespace`` (fully qualified)."""
    from tmgwr_common import topics
    return topics.qualified(name, args.namespace, node)


def _apply_domain(args) -> None:
    if getattr(args, "domain_id", None) is not None:
        if not 0 <= args.domain_id <= 232:
            raise SystemExit(f"--domain-id must be in 0..232, got {args.domain_id}")
        os.environ["ROS_DOMAIN_ID"] = str(args.domain_id)


# --------------------------------------------------------------------------- clients
def _service(args, make, name: str, what: str) -> int:
    from tmgwr_agent.graph.clients import NoGraph, call_once
    _apply_domain(args)
    srv_type, request = make()
    try:
        response = call_once(srv_type, name, request, timeout=args.timeout)
    except NoGraph as exc:
        say(f"{what}: {exc}", sys.stderr)
        return 2
    except (TimeoutError, RuntimeError) as exc:
        say(f"{what}: {exc}", sys.stderr)
        return 1
    ok = bool(getattr(response, "accepted", getattr(response, "success", False)))
    say(f"{what}: {'accepted' if ok else 'refused'}: {response.message}")
    return 0 if ok else 1


def cmd_goal(args) -> int:
    from tmgwr_agent.graph.clients import set_goal_request
    from tmgwr_common import topics
    return _service(args, lambda: set_goal_request(args.x, args.y), _name(args, topics.SET_GOAL),
                    f"goal (x={args.x:g}, y={args.y:g})")


def cmd_cell(args) -> int:
    from tmgwr_agent.graph.clients import set_cell_request
    from tmgwr_common import topics
    what = f"cell (row {args.row}, col {args.col}) {'block' if args.blocked else 'open'}"
    return _service(args, lambda: set_cell_request(args.row, args.col, args.blocked),
                    _name(args, topics.SET_CELL, topics.SIMULATOR), what)


def cmd_event(args) -> int:
    from tmgwr_agent.graph.clients import fire_event_request
    from tmgwr_common import topics
    from tmgwr_common.text import shown
    return _service(args, lambda: fire_event_request(args.name),
                    _name(args, topics.FIRE_EVENT, topics.SIMULATOR),
                    f"event {shown(args.name)}")


def cmd_reset(args) -> int:
    from tmgwr_agent.graph.clients import reset_request
    from tmgwr_common import topics
    return _service(args, reset_request, _name(args, topics.RESET, topics.SIMULATOR), "reset")


# --------------------------------------------------------------------------- up
def _run_settings(args) -> tuple[dict, Path | None, Path | None]:
    """(settings, run directory, bag directory) of ``up``: a new run, or with ``--resume``
    the run's directory and settings (graph.resume) and a new bag inside it."""
    from maze_sim.maze import maze_file
    from tmgwr_agent.graph import resume
    from tmgwr_agent.graph.supervisor import default_run_dir
    maze = args.maze
    if maze is not None:
        try:
            maze = str(maze_file(maze).resolve())
        except FileNotFoundError as exc:
            raise resume.ResumeError(f"--maze: {exc}") from None
    given = {"maze": maze, "goal": args.goal, "seed": args.seed,
             "params_files": [str(Path(f).expanduser().resolve()) for f in args.params_file],
             "composed": args.composed, "world": args.world}
    if args.world is not None:
        from tmgwr_agent.world_senses import GRAPH_WORLDS
        if args.world not in GRAPH_WORLDS:
            raise resume.ResumeError(f"--world: unknown world {args.world!r}; worlds the "
                                     f"graph hosts: {', '.join(GRAPH_WORLDS)}")
    if not args.resume:
        run_dir = None if args.no_record else Path(args.record_dir or default_run_dir())
        return given, run_dir, run_dir
    run_dir = resume.find_run(args.resume)
    settings = resume.merged_settings(run_dir, given)
    resume.check_checkpoints(run_dir)
    bag = None if args.no_record else Path(args.record_dir or resume.resumed_bag_dir(run_dir))
    return settings, run_dir, bag


def cmd_up(args) -> int:
    _apply_domain(args)
    from tmgwr_agent.graph.respawn import Respawner, RespawnPolicy
    from tmgwr_agent.graph.resume import ResumeError, write_settings
    from tmgwr_agent.graph.run import GraphRun
    from tmgwr_agent.graph.supervisor import GraphError
    from tmgwr_common.params import ParamError
    try:
        policy = RespawnPolicy(args.respawn_delay, args.respawn_limit, args.respawn_window)
    except ValueError as exc:
        say(f"up: --respawn-*: {exc}", sys.stderr)
        return 2
    try:
        settings, run_dir, bag_dir = _run_settings(args)
        run = GraphRun(maze=settings["maze"], seed=settings["seed"], goal=settings["goal"],
                       world=settings.get("world"), record=bag_dir is not None,
                       record_dir=bag_dir, run_dir=run_dir,
                       echo=not args.quiet, params_files=settings["params_files"] or [],
                       namespace=args.namespace)
        if run_dir is not None and not args.resume:
            write_settings(run_dir, settings)       # what --resume starts again with
        elif args.resume:
            say(f"resuming {run_dir}" + (f", recording to {bag_dir}" if bag_dir else ""))
        if settings["composed"]:      # one process instead of five (nodes/composed.py)
            from tmgwr_agent.graph.supervisor import composed_specs
            run.specs = run.supervisor.specs = composed_specs(run.specs)
    except (ParamError, ResumeError) as exc:
        say(f"up: {exc}", sys.stderr)
        return 2
    outcomes = {"goal": "reached the goal", "previous_goal": "ended at the previous goal",
                "cut": "cut short"}

    def episode_line(rec) -> None:
        say(f"episode {rec.episode}: {rec.steps} steps, {outcomes[rec.outcome]} "
              f"(step {rec.end_step}, {run.monitor.rate():.0f} steps/s)")

    run.monitor.on_episode = episode_line
    stop = {"now": False}
    code = run.start_or_exit_code("up", on_stop_signal=lambda: stop.update(now=True))
    if code is not None:
        return code
    domain = os.environ.get("ROS_DOMAIN_ID", "0")
    say(f"graph up in ROS_DOMAIN_ID={domain}: "
          + ", ".join(f"{k} (pid {v})" for k, v in run.supervisor.pids().items()))
    if run.record_dir:
        say(f"recording to {run.record_dir}")
    say("Ctrl-C stops the graph; from another shell: ./tmgwr goal X Y | cell R C --block "
          "| event a | reset" + (f" --domain-id {domain}" if domain != "0" else "")
          + (f" --namespace {run.namespace}" if run.namespace != "/" else ""))

    code = 0
    last_note = time.monotonic()
    respawner = Respawner(run.supervisor, policy, steps=lambda: run.monitor.seen)
    try:
        while not stop["now"]:
            run.spin_once(0.2)
            try:
                for line in respawner.watch():
                    say(f"up: {line}", sys.stderr)
            except GraphError as exc:
                say(f"up: {exc}", sys.stderr)
                code = 1
                break
            if args.max_steps is not None and run.monitor.last_step_id >= args.max_steps:
                say(f"up: {args.max_steps} steps done")
                break
            if time.monotonic() - last_note > 10.0:
                last_note = time.monotonic()
                m = run.monitor
                say(f"... step {m.last_step_id}, {len(m.episodes)} episodes ended, "
                      f"{m.rate():.0f} steps/s")
    finally:
        codes = run.stop()
    say("graph stopped: " + ", ".join(f"{k} exit {v}" for k, v in codes.items()))
    if run.record_dir:
        say(f"recording: {run.record_dir}")
    if run.run_dir is not None:
        say(f"continue this run: ./tmgwr up --resume {run.run_dir}")
    return code
