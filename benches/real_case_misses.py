"""The real cases' misses at a glance, for comparing a change to extraction: per case the targets it
misses and its log-excess (`realcases.CaseScore.log_excess`), and the totals, for the 14 cases,
the 10 held-out parts, the 6 second and 6 third held-out parts and the 18 sprinkles made from
colour (tests/data/real_cases). Both cores,
about 25 s; `benches/bench_extract.py` prints every figure.

    python benches/real_case_misses.py [--held-out-only] [--only SUBSTRING] [--turned [--save F] [--against F]]
                                       [--draws N] [--strokes]

`--turned` also extracts the cases' 139 turned views (about 15 s more) and prints their totals:
estimates outside the radius target, rods folding back, and the views seen over 80 % whose rod
(R given) lies over 1.5 R from its source view's rod, with the log of that excess. `--save F`
writes each view's figures to F (JSON); `--against F` lists the views that moved since F was saved,
so that a change is judged on them as on the cases (docs/real_captures.md, "Turned views"). `--draws N`
also scores N draws of jittered strokes per case (the first is the one above) and prints how many
meet the jitter targets (docs/real_captures.md, "A pixel's shift"). `--strokes` lists every jittered
stroke whose rod lies over the jitter max from the rod as drawn, or that fails, and where its max
lies: at a rod's end or inside it.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from multiprocessing import Pool
from pathlib import Path

from _table import print_table
from sketchrodgs import consistency as cs
from sketchrodgs import realcases

DATA = Path(__file__).resolve().parent.parent / "tests" / "data" / "real_cases"
SEEN = 0.8  # a turned view counts as seen where this share of its rod is visible
END_R = 2.0  # a jitter max within this many radii of a rod's end lies at its end (`jitter_misses`)


def score(job: tuple[str, int, int]) -> tuple[str, list[str], float, list[tuple[float, float]], list[list[str]]]:
    """One case of the file `job[0]`, by index `job[1]`: its name, misses and log-excess, the jitter
    mean and max of each of `job[2]` draws of jittered strokes (the first is the one scored), and a
    row per jittered stroke over the jitter max or failed (`jitter_misses`)."""
    scenes, cases = realcases.load_cases(DATA / job[0])
    case = cases[job[1]]
    runs = [realcases.run_case(scenes[case["scene"]], case, jitter=10, draw=draw) for draw in range(job[2])]
    scores = [realcases.score_case(case, views) for views in runs]
    rows = [row for draw, views in enumerate(runs) for row in jitter_misses(case, views, draw)]
    return (
        case["name"],
        scores[0].misses(),
        scores[0].log_excess(),
        [(s.jitter_mean, s.jitter_max) for s in scores],
        rows,
    )


def jitter_misses(case: dict, views: list[realcases.ViewResult], draw: int) -> list[list[str]]:
    """Per jittered stroke of one draw whose rod lies over the jitter max from the rod as drawn, or
    that failed (the mean target is the cases' mean over all strokes, so no one stroke misses it):
    the case, view, draw, the stroke's number in `jittered_strokes`' list, its mean and max, and
    where the max lies (`consistency.farthest_shared_point`): at a rod's end, a hook or a run onto
    what the part meets, or inside it, the rod on something else there."""
    t, radius, rows = realcases.TARGETS, float(case["radius"]), []
    for view in views:
        if view.given is None:
            continue
        count = len(view.jittered) + view.jitter_failures
        numbers = [k for k in range(count) if k not in view.failed_strokes]
        for number, rod in zip(numbers, view.jittered):
            agreement = cs.polyline_agreement(view.given.polyline, rod.polyline, radius)
            if agreement["max"] <= t["jitter_max"]:
                continue
            where = cs.farthest_shared_point(view.given.polyline, rod.polyline, radius)
            said = "no shared arc"
            if where is not None:
                which, along, _ = where
                said = f"{('drawn', 'jittered')[which]} rod, " + (
                    f"at its end ({along:.1f} R)" if along < END_R else f"{along:.1f} R in"
                )
            rows.append(
                [
                    case["name"],
                    view.name,
                    str(draw),
                    str(number),
                    f"{agreement['mean']:.2f}",
                    f"{agreement['max']:.2f}",
                    said,
                ]
            )
        rows += [[case["name"], view.name, str(draw), str(k), "", "", "failed"] for k in view.failed_strokes]
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--held-out-only", action="store_true")
    parser.add_argument("--only", default="", help="cases whose name holds this")
    parser.add_argument("--turned", action="store_true", help="the turned views' totals too")
    parser.add_argument("--save", help="with --turned: write each turned view's figures to this JSON file")
    parser.add_argument("--against", help="with --turned: list the turned views that moved since this file")
    parser.add_argument(
        "--draws", type=int, default=1, help="draws of jittered strokes per case (the first is scored; about 25 s each)"
    )
    parser.add_argument("--strokes", action="store_true", help="list each jittered stroke over the jitter max")
    args = parser.parse_args()
    files = [
        ("heldout_cases.json", "10 held-out parts"),
        ("heldout2_cases.json", "6 second held-out parts"),
        ("heldout3_cases.json", "6 third held-out parts"),
    ]
    if not args.held_out_only:
        files = [("cases.json", "14 cases"), *files, ("sprinkle_cases.json", "18 sprinkles (strokes from colour)")]
    with Pool(2) as pool:
        for file, what in files:
            start = time.perf_counter()
            _, cases = realcases.load_cases(DATA / file)
            jobs = [(file, k, args.draws) for k, case in enumerate(cases) if args.only in case["name"]]
            results = pool.map(score, jobs, chunksize=1)
            met = sum(not misses for _, misses, *_ in results)
            total = sum(len(misses) for _, misses, *_ in results)
            excess = sum(e for _, _, e, *_ in results if e < float("inf"))
            unmeasured = sum(e == float("inf") for _, _, e, *_ in results)
            print_table(
                f"{what}: {met} of {len(results)} meet every target, {total} misses, log-excess {excess:.2f}"
                + (f" and {unmeasured} not measurable" if unmeasured else "")
                + f" ({time.perf_counter() - start:.0f} s)",
                ["case", "log-excess", "misses"],
                [[name, f"{e:.2f}", "; ".join(misses) or "none"] for name, misses, e, *_ in results],
            )
            if args.draws > 1:
                print_draws(results, args.draws)
            if args.strokes:
                print_strokes([row for *_, rows in results for row in rows])
        if args.turned:
            print_turned(pool, args.only, args.save, args.against)


def print_draws(
    results: list[tuple[str, list[str], float, list[tuple[float, float]], list[list[str]]]], draws: int
) -> None:
    """Per case, the jitter max of each draw of jittered strokes and how many draws meet both jitter
    targets: one draw is a sample, and a change that helps it may only have been lucky with it."""
    t = realcases.TARGETS
    met = [
        sum(mean <= t["jitter_mean"] and top <= t["jitter_max"] for mean, top in jitter)
        for _, _, _, jitter, _ in results
    ]
    print_table(
        f"jitter over {draws} draws: {sum(met)} of {draws * len(results)} case draws meet both jitter targets",
        ["case", "jitter max per draw (R)", "worst mean (R)", "draws met"],
        [
            [name, " ".join(f"{top:.2f}" for _, top in jitter), f"{max(m for m, _ in jitter):.2f}", f"{k} of {draws}"]
            for (name, _, _, jitter, _), k in zip(results, met)
        ],
    )


def print_strokes(rows: list[list[str]]) -> None:
    """The jittered strokes over the jitter max or failed, and how many of them have their max at a
    rod's end, inside a rod, or failed (docs/real_captures.md, "Where the jitter misses lie")."""
    ends = sum("at its end" in row[-1] for row in rows)
    apart = sum(row[-1] == "no shared arc" for row in rows)
    failed = sum(row[-1] == "failed" for row in rows)
    print_table(
        f"jittered strokes over the {realcases.TARGETS['jitter_max']} R max or failed: {len(rows)}; the max at a "
        f"rod's end (within {END_R:g} R) {ends}, inside a rod {len(rows) - ends - apart - failed}, no shared arc "
        f"{apart}, failed {failed}",
        ["case", "view", "draw", "stroke", "mean (R)", "max (R)", "where the max lies"],
        rows,
    )


def turned_views(case_name: str) -> list[dict]:
    """The figures of one case's turned views (R estimated for the radius, R given for the rest)."""
    scenes, cases = realcases.load_cases(DATA / "cases.json")
    case = next(c for c in cases if c["name"] == case_name)
    turned = realcases.load_turned_views(DATA / "turned_views.json")
    return [
        {"name": r.name, "failed": bool(r.failed), "ratio": r.radius_ratio, "fold_back": r.fold_back}
        | {"mean": r.mean, "max": r.max, "visible": r.visible}
        for r in realcases.run_turned_views(scenes[case["scene"]], case, turned)
    ]


def print_turned(pool, only: str, save: str | None, against: str | None) -> None:
    """The totals of the turned views of the cases whose name holds `only`; with `save`, each view's
    figures written; with `against`, the views that moved since that file."""
    start = time.perf_counter()
    _, cases = realcases.load_cases(DATA / "cases.json")
    names = [c["name"] for c in cases if only in c["name"]]
    views = [v for vs in pool.map(turned_views, names, chunksize=1) for v in vs]
    t = realcases.TARGETS
    done = [v for v in views if not v["failed"]]
    seen_far = [v for v in done if v["visible"] >= SEEN and v["max"] > t["cross_max"]]
    row = [
        str(len(views)),
        str(len(views) - len(done)),
        str(sum(not t["radius_low"] <= v["ratio"] <= t["radius_high"] for v in done)),
        str(sum(v["fold_back"] > t["fold_back"] for v in done)),
        str(len(seen_far)),
        f"{sum(math.log(v['max'] / t['cross_max']) for v in seen_far):.2f}",
    ]
    print_table(
        f"turned views ({time.perf_counter() - start:.0f} s)",
        [
            "views",
            "failed",
            "R outside",
            "fold back",
            f"seen >= {SEEN:.0%}, over {t['cross_max']} R",
            "their log-excess",
        ],
        [row],
    )
    if against:
        before = {v["name"]: v for v in json.loads(Path(against).read_text(encoding="utf-8"))}
        moved = [
            [
                v["name"],
                f"{b['ratio']:.2f} -> {v['ratio']:.2f}",
                f"{b['max']:.2f} -> {v['max']:.2f}",
                f"{v['visible']:.2f}",
            ]
            for v in views
            if (b := before.get(v["name"]))
            and (abs(b["ratio"] - v["ratio"]) > 0.005 or abs(b["max"] - v["max"]) > 0.05 or b["failed"] != v["failed"])
        ]
        print_table(
            f"turned views that moved since {against}: {len(moved)}", ["view", "R est. / R", "max (R)", "seen"], moved
        )
    if save:
        Path(save).write_text(json.dumps(views, indent=0), encoding="utf-8")


if __name__ == "__main__":
    main()
