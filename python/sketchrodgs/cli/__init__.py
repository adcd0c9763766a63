"""The `sketchrodgs` command line. Each subcommand is a module in this package.

Exit codes: 0 success, 1 a domain error (one readable line on stderr; `--debug` shows the
traceback), 2 a usage error.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from ..errors import SketchRodGSError

# Subcommand modules, in the order `--help` lists them. Each defines NAME, HELP,
# add_arguments(parser) and run(args) -> int.
SUBCOMMANDS = ("demo", "info", "convert", "render", "extract", "animate", "view")


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="sketchrodgs",
        description="Sketch over a slender object in a 3D Gaussian Splatting scene, extract it as an "
        "elastic rod, pull it and let go. Runs on the CPU.",
    )
    parser.add_argument("--version", action="version", version=f"sketchrodgs {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks and debug logging")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module_name in SUBCOMMANDS:
        module = importlib.import_module(f".{module_name}", __name__)
        sub = commands.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(sub)
        sub.set_defaults(handler=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.debug else logging.WARNING, format="%(levelname)s: %(message)s")
    try:
        return int(args.handler(args) or 0)
    except (SketchRodGSError, OSError) as exc:
        if args.debug:
            raise
        print(f"sketchrodgs {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
