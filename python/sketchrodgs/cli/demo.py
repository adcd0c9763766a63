"""`sketchrodgs demo [-o DIR] [--view]`: the whole pipeline on the bundled plant capture."""

from __future__ import annotations

import argparse
from pathlib import Path

SAMPLE = "plant"

NAME = "demo"
HELP = "render the bundled plant, extract a stem from a stored stroke, pull and release it; write images, rod.json and a video"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "-o", "--output", default="sketchrodgs-demo", metavar="DIR", help="where to write (default ./sketchrodgs-demo)"
    )
    parser.add_argument(
        "--view", action="store_true", help="then open the browser viewer on the plant with the rod ready to pull"
    )
    parser.add_argument("--port", type=int, default=8080, help="port for --view (default 8080)")
    parser.add_argument(
        "--contact",
        action="store_true",
        help="also drag a side stem past the main stem with contact on and off: contact.png, contact.mp4",
    )


def run(args: argparse.Namespace) -> int:
    from .. import data
    from ..demo import run_demo
    from ._outputs import check_folder

    out = Path(args.output)
    check_folder(out, "-o")
    summary = run_demo(out, sample=SAMPLE, progress=lambda line: print(f"  {line}", flush=True))
    print(
        f"wrote {out}/: view.png, overlay.png, pulled.png, rod.json (+ rod.bindings.npz), frames/ ({summary['frames']} PNGs), "
        f"pull.mp4, summary.txt in {summary['total_s']:.1f} s"
    )
    if args.contact:
        from ..demo import push_past_the_main_stem

        pushed = push_past_the_main_stem(out, progress=lambda line: print(f"  {line}", flush=True))
        print(f"wrote {out}/: contact.png, contact.mp4 ({pushed['frames']} frames) in {pushed['total_s']:.1f} s")
    if args.view:
        from . import main  # the same `view` command a user would type

        return main(
            ["view", str(data.sample(SAMPLE)), "--rod", str(out / "rod.json"), "-o", str(out), "--port", str(args.port)]
        )
    return 0
