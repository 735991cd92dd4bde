"""``./tmgwr``: the project command line (``python -m tmgwr_agent.cli``).

One sub-command family per module, each registering its own parsers, so the families stay
independent (a module that fails to import only disables its own commands):

* ``experiment``, ``demo``, ``bench``  -- :mod:`tmgwr_agent.experiments.cli`
* ``up``, ``goal``, ``cell``, ``event`` -- :mod:`tmgwr_agent.graph.cli` (the ROS 2 node graph)
* ``recover``, ``replay``, ``report``  -- :mod:`tmgwr_agent.bag.cli` (MCAP recordings)
* ``results``                       -- :mod:`tmgwr_agent.experiments.results` (results/ as data)

A module provides ``register(subparsers)`` which adds its parsers and sets
``func=callable(args) -> int`` on each.
"""

from __future__ import annotations

import argparse
import importlib
import sys

FAMILIES = (
    "tmgwr_agent.experiments.cli",
    "tmgwr_agent.graph.cli",
    "tmgwr_agent.bag.cli",
    "tmgwr_agent.experiments.results",
)


def build_parser() -> tuple[argparse.ArgumentParser, list[str]]:
    parser = argparse.ArgumentParser(
        prog="./tmgwr",
        description="TMGWR goal-directed agent (Ezenkwu & Starkey 2022): experiments, "
                    "benchmarks, the ROS 2 node graph and its recordings.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    broken = []
    for name in FAMILIES:
        try:
            module = importlib.import_module(name)
        except Exception as exc:  # noqa: BLE001 -- report, keep the other families usable
            broken.append(f"{name}: {exc}")
            continue
        module.register(sub)
    return parser, broken


def main(argv: list[str] | None = None) -> int:
    parser, broken = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        for b in broken:
            print(f"tmgwr: commands unavailable ({b})", file=sys.stderr)
        parser.print_help()
        return 2
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
