"""`sketchrodgs demo [-o DIR]`: the whole pipeline on the bundled plant capture."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..demo import run_demo

NAME = "demo"
HELP = "render the bundled plant, extract a stem from a stored stroke, pull and release it; write images, rod.json and a video"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-o", "--output", default="sketchrodgs-demo", metavar="DIR", help="where to write (default ./sketchrodgs-demo)")


def run(args: argparse.Namespace) -> int:
    out = Path(args.output)
    summary = run_demo(out, progress=lambda line: print(f"  {line}", flush=True))
    print(f"wrote {out}/: view.png, overlay.png, pulled.png, rod.json, frames/ ({summary['frames']} PNGs), "
          f"pull.mp4, summary.txt in {summary['total_s']:.1f} s")
    return 0
