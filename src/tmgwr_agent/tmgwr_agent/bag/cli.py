"""Bag commands of ``./tmgwr``: ``recover``, ``replay``, ``report`` (MCAP recordings).

Recordings are made by the ``tmgwr_agent recorder`` node (``./tmgwr up`` starts it, writing
to ``runs/<UTC timestamp>/``). Imports stay inside the command functions so that
``./tmgwr --help`` does not load rclpy, mcap or matplotlib.
"""

from __future__ import annotations

import argparse
import json
import sys


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "recover", help="salvage a recording whose writer died (kill -9) into a valid file",
        description="Read a broken MCAP file (or every file of a bag directory) as a stream "
                    "and rewrite everything readable into a finished, indexed file.")
    p.add_argument("bag", metavar="BAG", help=".mcap file or bag directory")
    p.add_argument("-o", "--output", metavar="OUT",
                   help="output file (default BAG.recovered.mcap) or directory "
                        "(default BAG.recovered/)")
    p.add_argument("--compression", default="zstd", choices=("zstd", "lz4", "none"))
    p.set_defaults(func=_recover)

    p = subparsers.add_parser(
        "replay", help="republish a recording on live topics with its timing and QoS",
        description="Publish the recorded CDR bytes unchanged, each topic with the QoS its "
                    "publisher offered, at the recorded pace (scaled by --rate).")
    p.add_argument("bag", metavar="BAG", help=".mcap file or bag directory")
    p.add_argument("--rate", type=float, default=1.0, metavar="R",
                   help="playback speed factor (default 1.0)")
    p.add_argument("--topics", nargs="+", metavar="TOPIC", help="only these topics")
    p.add_argument("--loop", action="store_true", help="play again and again until Ctrl-C")
    p.add_argument("--delay", type=float, default=1.0, metavar="S",
                   help="seconds to wait for discovery before the first message (default 1)")
    p.add_argument("--wait-subscribers", type=int, default=0, metavar="N",
                   help="before playing, wait until every topic has N subscribers")
    p.add_argument("--message-order", choices=("received", "sent"), default="received",
                   help="play in the order the recorder received the messages (default) "
                        "or the order their publishers sent them (the ring's causal order "
                        "on one host: what a node of the ring fed by a replay needs)")
    p.set_defaults(func=_replay)

    p = subparsers.add_parser(
        "report", help="JSON summary and figures of a recorded run (from the bag alone)",
        description="Read a recording with rosbags and compute the run's episodes, goal "
                    "changes, events and map growth; write report.json and PNG figures.")
    p.add_argument("bag", metavar="BAG", help=".mcap file or bag directory")
    p.add_argument("-o", "--output", metavar="DIR",
                   help="output directory (default BAG/report or BAG_report/)")
    p.add_argument("--maze", metavar="FILE",
                   help="the run's maze file: name the goal cells (G, 1-9) in the report")
    p.set_defaults(func=_report)


def _recover(args: argparse.Namespace) -> int:
    from tmgwr_agent.bag.recover import recover
    try:
        results = recover(args.bag, args.output, args.compression)
    except (OSError, ValueError) as exc:
        print(f"recover: {exc}", file=sys.stderr)
        return 1
    for r in results:
        print(r.describe())
    total = sum(r.messages for r in results)
    where = results[0].output if len(results) == 1 else results[0].output.parent
    print(f"recover: {total} messages saved into {where}")
    return 0


def _replay(args: argparse.Namespace) -> int:
    from tmgwr_agent.bag.replay import replay
    try:
        res = replay(args.bag, rate=args.rate, topics=args.topics, loop=args.loop,
                     delay=args.delay, wait_subscribers=args.wait_subscribers,
                     order=args.message_order)
    except (OSError, ValueError, TimeoutError) as exc:
        print(f"replay: {exc}", file=sys.stderr)
        return 1
    print("REPLAY " + json.dumps(res))
    return 0


def _pct(v) -> str:
    return "n/a" if v is None else f"{v:.0f}%"


def _report(args: argparse.Namespace) -> int:
    from tmgwr_agent.bag.report import report
    try:
        res = report(args.bag, args.output, maze=args.maze)
    except (OSError, ValueError) as exc:
        print(f"report: {exc}", file=sys.stderr)
        return 1
    eps = res["episodes"]
    print(f'report: {res["steps"]["count"]} steps, {eps["count"]} episodes '
          f'({", ".join(f"{k} {v}" for k, v in sorted(eps["outcomes"].items()))}); '
          f'steps per episode: {" ".join(map(str, eps["steps_per_episode"]))}')
    for t in res["goal_changes"]:
        print(f'  goal change at step {t["step"]} {t["from"]} -> {t["to"]}: {t["episodes"]} '
              f'episodes, {_pct(t["previous_pct"])} ended at the previous goal '
              f'({_pct(t.get("previous_visit_pct"))} passed its cell), '
              f'{_pct(t["current_pct"])} at the current one; goal first reached '
              f'{t["first_goal_steps_after"]} steps later (shortest path {t["optimal_steps"]})')
    for e in res["events"]:
        print(f'  {e["what"]} at step {e["step"]}: goal first reached '
              f'{e["first_goal_steps_after"]} steps later (shortest path {e["optimal_steps"]})')
    print(f'report: {res["output"]["json"]} and {len(res["output"]["figures"])} figures in '
          f'{res["output"]["dir"]}')
    return 0
