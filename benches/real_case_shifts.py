"""How steady the real cases' rods are when the stroke moves by a pixel: each view's stroke shifted
by each of the 8 offsets of up to 1 px in x and y, extracted with R given and with R estimated, and
compared with the stroke as drawn. A user never draws the same stroke twice to the pixel, and the
issue's jitter (3-8 px of noise, R given) does not show what a pixel does to the radius estimate, nor
a rod that comes out shorter (the distances count only where the rods overlap). Both cores, about
a minute (docs/real_captures.md, "A pixel's shift").

    python benches/real_case_shifts.py [--only SUBSTRING] [--all] [--save F] [--against F]
        [--sideways K | --overshoot PX | --zoom F | --diameters K | --part SHARE]

Per set: the views whose shifted rods lie over 1.5 R from the rod as drawn, come out under 0.75 of
its length, or whose R estimates spread over 1.3 x; `--all` lists every view. `--save F` writes
every view's figures to F (JSON); `--against F` lists the views whose figures moved since F.
`--sideways K` moves each stroke sideways instead, by K times R on screen to either side (along its
normal at each point, R at the rod's median depth): a stroke drawn along the part's edge
(docs/real_captures.md, "Drawn along an edge"). `--overshoot PX` carries each stroke's first point,
then its last, PX pixels further along its end's direction: a stroke drawn on past the part's end.
`--zoom F` draws each stroke in its camera zoomed in by F and out by F about the stroke's centre: the
part at F times and 1/F times its pixels, at the same image size (docs/extraction.md, "Resolution");
a stroke zoomed in past the image's edge is left out. `--diameters K` draws a stroke K diameters
long along the rod as drawn, where it is seen, nearest its middle (`realcases.short_stroke`): the
issue's short stroke (docs/extraction.md, "Radius"). `--part SHARE` draws the first, middle and
last SHARE of the stroke's stretch over the rod as drawn (`realcases.part_strokes`): a stroke over
part of the part (docs/real_captures.md, "Part of a part"); its rods' lengths count against SHARE of
the rod as drawn.
"""

from __future__ import annotations

import argparse
import json
import time
from multiprocessing import Pool
from pathlib import Path
from typing import NamedTuple

import numpy as np

from _table import print_table
from sketchrodgs import Camera, realcases, render
from sketchrodgs import consistency as cs
from sketchrodgs.errors import PathNotFoundError
from sketchrodgs.extract import extract_rod
from sketchrodgs.polyline import polyline_length

DATA = Path(__file__).resolve().parent.parent / "tests" / "data" / "real_cases"
SETS = [
    ("cases.json", "14 cases"),
    ("heldout_cases.json", "10 held-out parts"),
    ("sprinkle_cases.json", "18 sprinkles"),
]
SHIFTS = [(dx, dy) for dx in (-1.0, 0.0, 1.0) for dy in (-1.0, 0.0, 1.0) if (dx, dy) != (0.0, 0.0)]
FAR_R = realcases.TARGETS["cross_max"]  # a shifted rod this far from the rod as drawn (in R) is listed
SHORT = 0.75  # and one shorter than this share of it
SPREAD = 1.3  # and R estimates spreading over this ratio


def shifted(scene, camera, stroke, moved, radius, images, true_radius, share=1.0) -> dict[str, float]:
    """The rod of `stroke` (R `radius`, None to estimate it) against the rods of the `moved` strokes,
    each (camera, stroke, render or None): the largest distance (in `true_radius`), the least length
    ratio (to `share` of the rod as drawn), the estimates' range (x `true_radius`) and how many moved
    strokes failed."""
    drawn = extract_rod(scene, camera, stroke, radius=radius, render=images)
    length = share * polyline_length(drawn.polyline)
    far, short, radii, failed = 0.0, 1.0, [drawn.radius], 0
    for other_camera, other, other_images in moved:
        try:
            rod = extract_rod(scene, other_camera, other, radius=radius, render=other_images)
        except PathNotFoundError:
            failed += 1
            continue
        far = max(far, cs.polyline_agreement(drawn.polyline, rod.polyline, true_radius)["max"])
        short = min(short, polyline_length(rod.polyline) / length)
        radii.append(rod.radius)
    return {
        "far": far,
        "short": short,
        "low": min(radii) / true_radius,
        "high": max(radii) / true_radius,
        "failed": failed,
    }


class Job(NamedTuple):
    """One case's views to score: shifted by a pixel, or moved as the one non-zero measure says."""

    file: str
    index: int  # of the case in the file
    sideways: float  # R to either side
    overshoot: float  # px each end is carried on
    zoom: float  # factor zoomed in and out
    diameters: float  # the stroke's length
    part: float  # the share of the stretch over the rod drawn


def score(job: Job) -> list[dict]:
    """The views of one case, shifted by a pixel or moved as `job` says."""
    scenes, cases = realcases.load_cases(DATA / job.file)
    case = cases[job.index]
    scene, radius = scenes[case["scene"]], float(case["radius"])
    rows = []
    for view in case["views"]:
        camera = Camera.from_dict(view["camera"], f"{case['name']}/{view['name']}")
        stroke = np.asarray(view["stroke"], np.float64)
        images = render(scene, camera, outputs=realcases.SOLID_OUTPUTS)
        if job.sideways or job.diameters or job.part:
            rod = extract_rod(scene, camera, stroke, radius=radius, render=images).polyline
        if job.diameters:
            short = realcases.short_stroke(camera, rod, radius, job.diameters, images)
            moved = [] if short is None else [(camera, short, images)]
        elif job.part:
            moved = [(camera, s, images) for s in realcases.part_strokes(stroke, camera, rod, job.part)]
        elif job.sideways:
            moved = [(camera, s, images) for s in realcases.sideways(stroke, camera, rod, radius, job.sideways)]
        elif job.overshoot:
            moved = [(camera, s, images) for s in realcases.overshooting(stroke, job.overshoot)]
        elif job.zoom:
            zoomed = [realcases.zoomed(camera, stroke, f) for f in (job.zoom, 1 / job.zoom)]
            # (a stroke zoomed in past the image's edge would give a shorter rod for that alone)
            moved = [(c, s, None) for c, s in zoomed if (s >= 0).all() and (s < [c.width, c.height]).all()]
        else:
            moved = [(camera, stroke + offset, images) for offset in SHIFTS]
        share = job.part or 1.0
        given = shifted(scene, camera, stroke, moved, radius, images, radius, share)
        estimated = shifted(scene, camera, stroke, moved, None, images, radius, share)
        rows.append({"view": f"{case['name']}/{view['name']}", "given": given, "estimated": estimated})
    return rows


def missed(row: dict) -> dict[str, bool]:
    """Which of the bounds a view's shifted rods miss."""
    g, e = row["given"], row["estimated"]
    return {
        "far": max(g["far"], e["far"]) > FAR_R,
        "short": min(g["short"], e["short"]) < SHORT,
        "spread": e["high"] / e["low"] > SPREAD,
        "failed": g["failed"] + e["failed"] > 0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="", help="cases whose name holds this")
    parser.add_argument("--all", action="store_true", help="list every view, not only those missing a bound")
    parser.add_argument("--save", help="write every view's figures to this JSON file")
    parser.add_argument("--against", help="list the views whose figures moved since this file")
    parser.add_argument("--sideways", type=float, default=0.0, help="move each stroke this many R to either side")
    parser.add_argument("--overshoot", type=float, default=0.0, help="carry each stroke's ends this many px on")
    parser.add_argument("--zoom", type=float, default=0.0, help="zoom each view in and out by this factor (> 1)")
    parser.add_argument("--diameters", type=float, default=0.0, help="a stroke this many diameters long instead")
    parser.add_argument("--part", type=float, default=0.0, help="strokes over this share of the rod drawn (0-1)")
    args = parser.parse_args()
    measures = [
        (args.sideways, f"moved {args.sideways:g} R to either side"),
        (args.overshoot, f"with an end carried {args.overshoot:g} px on"),
        (args.zoom, f"zoomed {args.zoom:g} x in and out"),
        (args.diameters, f"drawn {args.diameters:g} diameters long"),
        (args.part, f"drawn over its first, middle and last {args.part:g}"),
    ]
    if sum(value != 0 for value, _ in measures) > 1:
        parser.error("--sideways, --overshoot, --zoom, --diameters and --part measure one at a time")
    if args.part and not 0 < args.part < 1:
        parser.error(f"--part: a share between 0 and 1, got {args.part:g}")
    if args.zoom and not args.zoom > 1:
        parser.error(f"--zoom: a factor over 1, got {args.zoom:g}")
    how = next((text for value, text in measures if value), "shifted by a pixel")
    every = []
    with Pool(2) as pool:
        for file, what in SETS:
            start = time.perf_counter()
            _, cases = realcases.load_cases(DATA / file)
            jobs = [
                Job(file, k, args.sideways, args.overshoot, args.zoom, args.diameters, args.part)
                for k, case in enumerate(cases)
                if args.only in case["name"]
            ]
            rows = [row for rows in pool.map(score, jobs, chunksize=1) for row in rows]
            every += rows
            count = {bound: sum(missed(r)[bound] for r in rows) for bound in ("far", "short", "spread")}
            count["failed"] = sum(r["given"]["failed"] + r["estimated"]["failed"] for r in rows)
            print_table(
                f"{what}, {len(rows)} views {how}: {count['far']} with a rod over {FAR_R} R away, "
                f"{count['short']} under {SHORT:.0%} of the length, {count['spread']} with R over {SPREAD} x apart, "
                f"{count['failed']} failed ({time.perf_counter() - start:.0f} s)",
                ["view", "R given: max (R)", "least length", "R estimated: R / R", "max (R)", "least length", "failed"],
                [
                    [
                        r["view"],
                        f"{r['given']['far']:.2f}",
                        f"{r['given']['short']:.2f}",
                        f"{r['estimated']['low']:.2f}-{r['estimated']['high']:.2f}",
                        f"{r['estimated']['far']:.2f}",
                        f"{r['estimated']['short']:.2f}",
                        str(r["given"]["failed"] + r["estimated"]["failed"]),
                    ]
                    for r in rows
                    if args.all or any(missed(r).values())
                ],
            )
    if args.against:
        print_moved(every, json.loads(Path(args.against).read_text(encoding="utf-8")), args.against)
    if args.save:
        Path(args.save).write_text(json.dumps(every, indent=0), encoding="utf-8")


def print_moved(rows: list[dict], before: list[dict], name: str) -> None:
    """The views whose largest distance moved by over 0.1 R, least length by over 0.05 or estimates'
    range by over 0.05 x R since `before` (with R given / R estimated)."""
    old = {r["view"]: r for r in before}

    def moved(a: dict, b: dict) -> bool:
        return any(
            abs(a[kind][key] - b[kind][key]) > limit
            for kind in ("given", "estimated")
            for key, limit in (("far", 0.1), ("short", 0.05), ("low", 0.05), ("high", 0.05))
        )

    def figures(r: dict) -> str:
        g, e = r["given"], r["estimated"]
        return f"{g['far']:.2f} / {g['short']:.2f} / {e['low']:.2f}-{e['high']:.2f} / {e['far']:.2f} / {e['short']:.2f}"

    changed = [
        [r["view"], figures(old[r["view"]]), figures(r)] for r in rows if r["view"] in old and moved(old[r["view"]], r)
    ]
    print_table(
        f"views that moved since {name}: {len(changed)} (R given: max, least length / R estimated: R / R, max, least length)",
        ["view", "before", "now"],
        changed,
    )


if __name__ == "__main__":
    main()
