"""The ``remarl-fc`` command line: argument parsing only, one module per command group.

===========================  ====================================================
module                       commands
===========================  ====================================================
`remarl_fc.cli.scenario`     ``scenarios``, ``field``, ``rollout``
`remarl_fc.cli.learn`        ``train``, ``eval``, ``export``, ``compare``
`remarl_fc.cli.suite`        ``suite list|show|label``, ``eval --suite``
`remarl_fc.cli.bench`        ``bench pso``, ``bench sim`` (and wires the others)
`remarl_fc.cli.sitl`         ``sitl``, ``bench sitl``
`remarl_fc.cli.fly`          ``fly``, ``demo``, ``plot-flight``, ``bench fly``, ``bench bus``
`remarl_fc.cli.common`       exit statuses, ``--json`` output, shared options
===========================  ====================================================

Each handler parses its arguments, calls the library and prints; heavy imports (torch,
`policies`) happen inside handlers, never when the parser is built.
Commands that report figures take ``--json`` and then print exactly one JSON object on stdout.
Errors of the project (`remarl_fc.errors.RemarlError`) print one line on stderr and exit 2.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence

from remarl_fc._version import __version__
from remarl_fc.cli import bench, fly, learn, scenario, sitl, suite
from remarl_fc.cli.common import EXIT_BROKEN_PIPE, EXIT_USAGE, Handler
from remarl_fc.errors import RemarlError
from sim.heap import keep_freed_memory

__all__ = ["EXIT_USAGE", "build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every command."""
    parser = argparse.ArgumentParser(
        prog="remarl-fc",
        description="Train, evaluate and fly collision-avoidance policies for UAV swarms.",
    )
    parser.add_argument("--version", action="version", version=f"remarl-fc {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    # in the order `remarl-fc --help` lists them
    scenario.add_scenarios(sub)
    scenario.add_field(sub)
    learn.add_train(sub)
    learn.add_eval(sub)
    suite.add_suite(sub)
    learn.add_export(sub)
    scenario.add_rollout(sub)
    bench.add_bench(sub)
    learn.add_compare(sub)
    sitl.add_sitl_parser(sub)
    fly.add_parsers(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    handler: Handler = args.handler
    keep_freed_memory()  # the simulator's steps reuse their temporaries (sim.heap)
    try:
        return handler(args)
    except RemarlError as exc:
        print(f"remarl-fc: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # the reader went away (`remarl-fc ... | head`): not our error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
