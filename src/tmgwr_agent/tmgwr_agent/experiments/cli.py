"""``./tmgwr experiment | demo | bench | tune`` (docs/experiments.md, docs/tuning.md).

``experiment SCENARIO --maze FILE --agents LIST --trials N --seed S --json OUT
[--plot OUT.png] [--jobs J] [--params FILE | AGENT=FILE ...]`` with ``--goals``,
``--episodes``, ``--event``, ``--goal`` for the scenarios that take them (``--params``:
parameter files such as ``./tmgwr tune`` writes, :func:`.tune.experiment_params`);
``--suite SPEC [--suite-seed K] [--suite-first I]``
instead of ``--maze`` runs env-change or goal-change on generated mazes
(:mod:`tmgwr_agent.experiments.suite_runner`); ``demo`` runs every scenario briefly and
then the ROS graph demo (:mod:`tmgwr_agent.graph.demo`); ``bench`` measures the TMGWR core
and merges the graph / bag benchmarks; ``tune AGENT`` tunes an agent with Optuna
(:mod:`tmgwr_agent.experiments.tune`). An unknown agent, scenario, goal or
event, or a missing maze file, exits with code 2 and a message naming it.

Imports stay light here (argparse only): the scenario modules load when a command runs.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _csv(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def _default_maze() -> str:
    from maze_sim.maze import maze_file
    return str(maze_file())


def register(subparsers) -> None:
    from tmgwr_agent.experiments.names import SCENARIOS
    p = subparsers.add_parser(
        "experiment", help="run one of the paper's experiments (Tables 3-6, Figs 5-7)",
        description="Run a scenario of the paper over several trials and write its JSON "
                    "(docs/experiments.md). Agents: tmgwr, tmgwr:grid, tmgwr:literal, "
                    "tmgwr:credit, q_learning, model_based, dyna_q_plus, rmax, freespace; "
                    "tmgwr options join with + and "
                    "'paper' turns our three additions off (tmgwr:credit+paper).")
    p.add_argument("scenario", choices=SCENARIOS, metavar="SCENARIO",
                   help=f"one of {', '.join(SCENARIOS)}")
    p.add_argument("--maze", default=None,
                   help="maze file, a path (default: the installed paper_13x17.txt)")
    p.add_argument("--agents", type=_csv, default=None,
                   help="comma-separated agents (default: tmgwr,q_learning,model_based,"
                        "dyna_q_plus; env-change adds tmgwr:literal,tmgwr:credit)")
    p.add_argument("--trials", type=int, default=10, help="trials per agent (default 10)")
    p.add_argument("--seed", type=int, default=0, help="seed of the trial seeds (default 0)")
    p.add_argument("--json", default=None, metavar="OUT",
                   help="write the results JSON here (default: standard output)")
    p.add_argument("--plot", default=None, metavar="OUT.png", help="also draw the figure")
    p.add_argument("--jobs", type=int, default=None,
                   help="worker processes (default: the number of cores)")
    p.add_argument("--goals", type=_csv, default=None,
                   help="goal names: goal-change sequence (default 1,2,3,4,1), "
                        "sample-complexity goals (1,2,3,4), timing FROM,TO (4,3)")
    p.add_argument("--episodes", type=int, default=None,
                   help="episodes per goal (goal-change, default 1000) or episodes of "
                        "the curve (sample-complexity, default 100)")
    p.add_argument("--event", default="a", help="maze event (env-change, timing; default a)")
    p.add_argument("--goal", default="G",
                   help="goal of the env-change / timing training (default G)")
    p.add_argument("--event-delay", default=None, metavar="K[,K...]",
                   help="env-change: every agent runs K more learning episodes after "
                        "convergence before the event (default 0: the event right at "
                        "convergence); several K (e.g. 0,4,8) run the whole scenario at "
                        "each and the JSON holds each K's figures under 'delays'; with "
                        "K > 0 'settled_steps' is the mean steps of those K episodes")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--params", action="append", default=None, metavar="FILE|AGENT=FILE",
                   help="parameter overrides from a ROS 2 parameter file such as tune "
                        "writes (config/tuned/*.yaml): tmgwr agents read '/**', a "
                        "baseline the section named after it; AGENT=FILE gives the file "
                        "to that agent (a spec of --agents, or a name for all its specs) "
                        "only; AGENT=tuned: the committed tuned file of AGENT for the "
                        "--world (config/tuned/[WORLD/]AGENT.yaml). Repeatable, later "
                        "files win; recorded in the JSON")
    p.add_argument("--sensor", default=None, metavar="SPEC",
                   help="how the agents sense the maze (default identity: the (row, col) "
                        "of the cell): comma-joined noise=SIGMA (cells), scale=SX:SY, "
                        "rotate=DEG (composed in that order), or view=K alone (the "
                        "(2K+1)^2 window of walls around the agent plus a compass to the "
                        "goal); recorded as 'sensor' in the JSON")
    p.add_argument("--world", default=None, metavar="NAME",
                   help="the world the maze is built in (default grid): grid, minigrid "
                        "(MiniGrid's turn left / turn right / forward, sensation row, col, "
                        "cos h, sin h), pointmaze (MuJoCo's PointMaze), or gym:ID, a "
                        "registered Gymnasium env (MiniGrid-*, PointMaze_*; "
                        "sample-complexity only); recorded as 'world' in the JSON")
    p.add_argument("--world-kwargs", default=None, metavar="JSON",
                   help="keyword arguments of the world as a JSON object, e.g. "
                        "'{\"start_dir\": 1}' (minigrid), '{\"layout_seed\": 3}' (gym:ID)")
    p.add_argument("--suite", default=None, metavar="SPEC",
                   help="instead of --maze: generated mazes (env-change, goal-change), "
                        "FAMILY[:N] or all[:N] or a comma list (braided:3,rooms:3); "
                        "families braided, rooms, open, blocking, shortcut, large. "
                        "env-change: --event block (default) or open; goal-change: each "
                        "maze's goals 1,2,3,4,1. Mazes go to OUT_mazes/ beside --json OUT")
    p.add_argument("--suite-seed", type=int, default=0,
                   help="seed of the generated mazes (default 0)")
    p.add_argument("--suite-first", type=int, default=0,
                   help="first maze index of each family (a held-out split; default 0)")
    p.set_defaults(func=cmd_experiment)

    d = subparsers.add_parser(
        "demo", help="quick run of all four scenarios on the default maze, then the ROS "
                     "graph demo",
        description="All four scenarios with few trials on the default maze: JSON and "
                    "PNG files under results/<timestamp>/, a short table on stdout. Then "
                    "the ROS 2 graph demo (tmgwr_agent.graph.demo) when it is installed.")
    d.add_argument("--out", default=None, help="output directory (default results/<UTC time>)")
    d.add_argument("--trials", type=int, default=3, help="trials per agent (default 3)")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--jobs", type=int, default=None)
    d.add_argument("--no-graph", action="store_true", help="skip the ROS graph demo")
    d.set_defaults(func=cmd_demo)

    b = subparsers.add_parser(
        "bench", help="step time of the TMGWR core, CPU seconds to convergence; merges "
                      "the graph and bag benchmarks",
        description="Median (and percentiles) of the TMGWR core step time (act + observe: "
                    "learn, plan, select) on the default maze and on a generated maze of "
                    "about 1300 free cells, CPU seconds to convergence per agent; then the "
                    "graph and bag benchmarks. Writes results/bench.json.")
    b.add_argument("--json", default=None,
                   help="output JSON (default results/bench.json)")
    b.add_argument("--trials", type=int, default=5,
                   help="trials of the CPU-to-convergence measure (default 5)")
    b.add_argument("--seed", type=int, default=0)
    b.add_argument("--steps", type=int, default=5000, help="timed steps per maze (default 5000)")
    b.add_argument("--jobs", type=int, default=1,
                   help="processes for the convergence trials (default 1: less noise)")
    b.add_argument("--no-graph", action="store_true",
                   help="skip the graph and bag benchmarks")
    b.set_defaults(func=cmd_bench)

    t = subparsers.add_parser(
        "tune", help="tune an agent's hyperparameters with Optuna (TPE) on a training "
                     "split of the maze suite",
        description="Optuna TPE over the parameters tune.SEARCH lists for AGENT (--list "
                    "shows them), minimising the geometric mean over the training mazes of "
                    "steps / oracle of the first episode after the block, plus a penalty "
                    "for failed runs, plus --open-weight x the share of openings whose "
                    "shortcut the greedy path does not use within 10 episodes (docs/"
                    "tuning.md). Writes the best parameters as a ROS 2 parameter file and a "
                    "JSON summary.")
    t.add_argument("agent", metavar="AGENT",
                   help="tmgwr (with options, e.g. tmgwr:credit), q_learning, model_based, "
                        "dyna_q_plus, rmax or freespace")
    t.add_argument("--trials", type=int, default=40,
                   help="trials of the study in all, every agent the same (default 40)")
    t.add_argument("--workers", type=int, default=1,
                   help="worker processes on the study (default 1)")
    t.add_argument("--study", default=None, help="study name (default: the agent)")
    t.add_argument("--storage", default=None, metavar="PATH_OR_URL",
                   help="journal file, or an RDB URL (sqlite:///f.db, postgresql://...); "
                        "share it (and --study) to add workers on other machines "
                        "(default results/tune/optuna.journal)")
    t.add_argument("--suite", default=None, metavar="SPEC",
                   help="training split (default: tune.TRAIN_SUITE, small mazes of the "
                        "families with a block)")
    t.add_argument("--open-suite", default=None, metavar="SPEC",
                   help="the openings of the training split (default: "
                        "tune.TRAIN_OPEN_SUITE, the same indices of the families with an "
                        "opening)")
    t.add_argument("--open-weight", type=float, default=1.0,
                   help="weight of the share of openings missed (default 1; 0: blocks "
                        "only)")
    t.add_argument("--suite-seed", type=int, default=0, help="seed of the mazes (default 0)")
    t.add_argument("--suite-first", type=int, default=0,
                   help="first maze index of each family (default 0)")
    t.add_argument("--seeds", type=int, default=2,
                   help="trial seeds per maze in the objective (default 2)")
    t.add_argument("--seed", type=int, default=0,
                   help="seed of the trial seeds and of the sampler (default 0)")
    t.add_argument("--space", default=None, metavar="LIST",
                   help="search these instead: NAME (the interval --list shows for it, "
                        "else its declared range), NAME=LOW:HIGH or NAME=LOW:HIGH:log, "
                        "comma-separated")
    t.add_argument("--fix", default=None, metavar="LIST",
                   help="keep these searched parameters at their defaults, "
                        "comma-separated (e.g. --fix eps_min)")
    t.add_argument("--list", action="store_true",
                   help="list the agent's parameters, searched or fixed, and exit")
    t.add_argument("--params-out", default=None, metavar="FILE",
                   help="parameter file of the best values (default "
                        "results/tune/STUDY.yaml)")
    t.add_argument("--json", default=None, metavar="OUT",
                   help="JSON summary (default results/tune/STUDY.json)")
    t.add_argument("--evaluate", action="store_true",
                   help="then run the tuned values and the defaults on a held-out split")
    t.add_argument("--eval-suite", default=None, metavar="SPEC",
                   help="held-out families (default: those of --suite)")
    t.add_argument("--eval-open-suite", default=None, metavar="SPEC",
                   help="held-out openings (default: the families of --open-suite)")
    t.add_argument("--eval-first", type=int, default=None,
                   help="first held-out index of each family (default: after the "
                        "training mazes)")
    t.add_argument("--eval-trials", type=int, default=5,
                   help="seeds per held-out maze (default 5)")
    t.add_argument("--world", default=None, metavar="NAME",
                   help="tune in this world (experiment --world; default grid): the same "
                        "budget and objective, oracles in the world's primitive steps; "
                        "the default study name gains -NAME, the default outputs go "
                        "to results/tune/NAME/")
    t.add_argument("--world-kwargs", default=None, metavar="JSON",
                   help="keyword arguments of the world, a JSON object")
    t.add_argument("--quiet", action="store_true", help="no progress lines")
    t.set_defaults(func=cmd_tune)


def _fail(msg: str) -> int:
    print(f"tmgwr: error: {msg}", file=sys.stderr)
    return 2


def cmd_experiment(args: argparse.Namespace) -> int:
    from tmgwr_agent.experiments.output import write_json
    from tmgwr_agent.experiments.scenarios import UsageError, run_scenario
    if args.suite:
        return _cmd_suite(args)
    try:
        overrides, params_files = _overrides(args)
        result = run_scenario(args.scenario, args.maze or _default_maze(), args.agents,
                              args.trials, args.seed, args.goals, args.episodes, args.event,
                              args.goal, args.jobs, progress=not args.quiet,
                              overrides=overrides, params_files=params_files,
                              sensor=args.sensor, world=args.world,
                              world_kwargs=args.world_kwargs, delays=args.event_delay)
    except UsageError as exc:
        return _fail(str(exc))
    write_json(result, args.json)
    if args.plot:
        from tmgwr_agent.experiments.plots import plot
        Path(args.plot).parent.mkdir(parents=True, exist_ok=True)
        plot(result, args.plot)
    if args.json:
        from tmgwr_agent.experiments.report import table
        print(table(result))
    return 0


def _overrides(args: argparse.Namespace) -> tuple[dict | None, tuple[str, ...]]:
    """``--params``: parameter overrides per agent spec (None without the flag) and the
    files they came from (``AGENT=tuned`` resolved), which the JSON records."""
    if not args.params:
        return None, ()
    from tmgwr_agent.experiments.scenarios import DEFAULTS, check_agents
    from tmgwr_agent.experiments.tune import experiment_params, resolve_tuned
    agents = check_agents(args.agents or DEFAULTS[args.scenario]["agents"])
    files = tuple(resolve_tuned(args.params, args.world))
    return experiment_params(agents, files), files


def _cmd_suite(args: argparse.Namespace) -> int:
    """``experiment SCENARIO --suite SPEC`` (:mod:`tmgwr_agent.experiments.suite_runner`)."""
    from tmgwr_agent.experiments.output import write_json
    from tmgwr_agent.experiments.scenarios import UsageError
    from tmgwr_agent.experiments.suite_runner import maze_dir_for, run_suite, table
    if args.maze:
        return _fail("--maze and --suite exclude each other")
    if args.goal != "G":
        return _fail("--goal does not apply with --suite (every suite maze's goal is G)")
    maze_dir = maze_dir_for(args.json) if args.json and args.json != "-" else None
    try:
        overrides, params_files = _overrides(args)
        result = run_suite(args.scenario, args.suite, args.agents, args.trials, args.seed,
                           args.suite_seed, args.suite_first, args.event, args.goals,
                           args.episodes, args.jobs, progress=not args.quiet,
                           maze_dir=maze_dir, overrides=overrides,
                           params_files=params_files, sensor=args.sensor,
                           world=args.world, world_kwargs=args.world_kwargs,
                           delays=args.event_delay)
    except UsageError as exc:
        return _fail(str(exc))
    write_json(result, args.json)
    if args.plot:
        from tmgwr_agent.experiments.plots import plot
        Path(args.plot).parent.mkdir(parents=True, exist_ok=True)
        plot(result, args.plot)
    if args.json and args.json != "-":
        print(table(result))
        print(f"mazes: {maze_dir}/")
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from tmgwr_agent.experiments.demo import run
    return run(args)


def cmd_bench(args: argparse.Namespace) -> int:
    from tmgwr_agent.experiments.bench import run
    return run(args)


def cmd_tune(args: argparse.Namespace) -> int:
    from tmgwr_agent.experiments.scenarios import UsageError
    from tmgwr_agent.experiments.tune import TRAIN_OPEN_SUITE, TRAIN_SUITE, run
    args.suite = args.suite or TRAIN_SUITE
    args.open_suite = args.open_suite or TRAIN_OPEN_SUITE
    try:
        return run(args)
    except UsageError as exc:
        return _fail(str(exc))
