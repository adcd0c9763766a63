"""Write tests/data/real_cases/sprinkle_cases.json: 18 more sprinkles of the donut capture, each in
the 2-3 views of the donut cases' cameras where it shows whole, with strokes made from what the
image shows, not from any extraction (docs/real_captures.md, "Sprinkles from their colour").

Each sprinkle is a blue blob of the rendered image (blue minus red over 0.2): one not touching the
image's edge, at least 200 pixels, elongated (length over width at least 3) and convex (it fills at
least 0.75 of its length times width, so that two crossing sprinkles are left out). Its stroke runs
along the blob's principal axis from 2-6 px before one end to 2-6 px past the other, 10 points with
1.5 px of hand noise, drawn in either direction. The same sprinkle is found in the other views by
the Gaussians the index image shows over the blob. R is half the blob's width (sqrt(12) times the
spread across its axis) at its depth, the median over its views. The four hand-made donut cases'
sprinkles are left out.

    python benches/sprinkle_cases.py
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy import ndimage

from sketchrodgs import realcases
from sketchrodgs.camera import Camera
from sketchrodgs.render import render

DATA = Path(__file__).resolve().parent.parent / "tests" / "data" / "real_cases"
OUT = DATA / "sprinkle_cases.json"
BLUE = 0.2  # blue minus red over this is a sprinkle's pixel
SMALLEST_PX = 200
ELONGATION = 3.0
FILL = 0.75
SHARED = 0.3  # two views' blobs are one sprinkle where they share this share of their Gaussians


def blobs(scene, camera: Camera) -> list[dict]:
    """The sprinkle blobs of one view."""
    images = render(scene, camera)
    rgb = np.asarray(images.rgb)
    labels, count = ndimage.label(rgb[..., 2] - rgb[..., 0] > BLUE)
    found = []
    for k in range(1, count + 1):
        rows, cols = np.nonzero(labels == k)
        inside = (
            cols.min() >= 5 and rows.min() >= 5 and cols.max() < camera.width - 6 and rows.max() < camera.height - 6
        )
        if len(cols) < SMALLEST_PX or not inside:
            continue
        points = np.column_stack([cols, rows]).astype(float) + 0.5
        centre = points.mean(axis=0)
        spread, axes = np.linalg.eigh(np.cov((points - centre).T))
        along = (points - centre) @ axes[:, 1]
        length, width = float(np.ptp(along)), float(np.sqrt(12 * spread[0]))
        if length / width < ELONGATION or len(cols) / (length * width) < FILL:
            continue
        ids = images.index[rows, cols]
        found.append(
            {
                "centre": centre,
                "axis": axes[:, 1],
                "ends": (float(along.min()), float(along.max())),
                "width": width,
                "length": length,
                "depth": float(np.median(images.index_depth[rows, cols])),
                "ids": set(ids[ids >= 0].tolist()),
            }
        )
    return found


def stroke(blob: dict, rng: np.random.Generator) -> list[list[float]]:
    """A stroke along the blob's axis, overshooting both ends a little, in either direction."""
    before, after = rng.uniform(2, 6, 2)
    at = np.linspace(blob["ends"][0] - before, blob["ends"][1] + after, 10)
    points = blob["centre"] + at[:, None] * blob["axis"] + rng.normal(0, 1.5, (10, 2))
    if rng.random() < 0.5:
        points = points[::-1]
    return np.round(points).tolist()


def main() -> None:
    rng = np.random.default_rng(7)
    scenes, cases = realcases.load_cases(DATA / "cases.json")
    _, held_out = realcases.load_cases(DATA / "heldout_cases.json")
    scene = scenes["donut"]
    made: list[dict] = []
    taken: list[set] = []
    for source in [c for c in cases + held_out if c["scene"] == "donut"]:
        views = source["views"]
        cameras = [Camera.from_dict(v["camera"], v["name"]) for v in views]
        per_view = [blobs(scene, camera) for camera in cameras]
        drawn = np.mean(np.asarray(views[0]["stroke"], float), axis=0)
        for blob in per_view[0]:
            if np.linalg.norm(blob["centre"] - drawn) < 40:  # the hand-made case's own sprinkle
                continue
            if any(len(blob["ids"] & t) > SHARED * len(blob["ids"]) for t in taken):
                continue
            matched = [(views[0], blob)]
            for view, others in zip(views[1:], per_view[1:]):
                best = max(others, key=lambda o: len(o["ids"] & blob["ids"]), default=None)
                if best and len(best["ids"] & blob["ids"]) >= SHARED * min(len(best["ids"]), len(blob["ids"])):
                    matched.append((view, best))
            if len(matched) < 2:
                continue
            taken.append(blob["ids"])
            radius = float(np.median([b["width"] / 2 * b["depth"] / cameras[0].fx for _, b in matched]))
            made.append(
                {
                    "name": f"sprinkle_{len(made):02d}",
                    "scene": "donut",
                    "radius": round(radius, 6),
                    "description": f"A sprinkle in the cameras of {source['name']}: seen "
                    + ", ".join(f"{b['length']:.0f} x {b['width']:.0f} px" for _, b in matched)
                    + " (length x width).",
                    "views": [{"name": v["name"], "camera": v["camera"], "stroke": stroke(b, rng)} for v, b in matched],
                }
            )
            print(made[-1]["name"], made[-1]["radius"], made[-1]["description"])
    data = {"scenes": {"donut": "tests/data/donut.ply"}, "cases": made}
    OUT.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    print(f"{len(made)} sprinkles -> {OUT}")


if __name__ == "__main__":
    main()
