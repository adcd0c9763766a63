"""The `sketchrodgs` command line. Each subcommand is a module in this package.

Exit codes: 0 success, 1 a domain error (one readable line on stderr; `--debug` shows the
traceback), 2 a usage error.

Start-up is kept short: a subcommand module imports only argparse helpers at the top, builds its
arguments only when it is the command given, and imports the library inside `run`.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from ._args import UsageError, attach_negative_lists

# Subcommand modules, in the order `--help` lists them. Each defines NAME, HELP,
# add_arguments(parser) and run(args) -> int.
SUBCOMMANDS = ("demo", "info", "camera", "convert", "render", "extract", "animate", "view")


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser; with `command`, only that subcommand's arguments are built ("": none; None: all)."""
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="sketchrodgs",
        description="Sketch over a slender object in a 3D Gaussian Splatting scene, extract it as an "
        "elastic rod, pull it and let go. Runs on the CPU.",
        epilog="A SCENE is a scene file, a 3DGS training output folder, or sample:NAME. "
        "`sketchrodgs COMMAND --help` describes each command; docs/cli.md has examples.",
    )
    parser.add_argument("--version", action="version", version=f"sketchrodgs {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks and debug logging")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module_name in SUBCOMMANDS:
        module = importlib.import_module(f".{module_name}", __name__)
        sub = commands.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        if command is None or command == module.NAME:
            module.add_arguments(sub)
        sub.set_defaults(handler=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code."""
    words = attach_negative_lists(list(sys.argv[1:] if argv is None else argv))
    command = next((w for w in words if not w.startswith("-")), None)
    parser = build_parser(command or "")
    args = parser.parse_args(words)
    logging.basicConfig(level=logging.DEBUG if args.debug else logging.WARNING, format="%(levelname)s: %(message)s")
    from ..errors import SketchRodGSError

    try:
        return int(args.handler(args) or 0)
    except UsageError as exc:
        if args.debug:
            raise
        print(f"sketchrodgs {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except (SketchRodGSError, OSError) as exc:
        if args.debug:
            raise
        print(f"sketchrodgs {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
