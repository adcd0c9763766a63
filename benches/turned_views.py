"""Writes tests/data/real_cases/turned_views.json: each real case's rod (its first two views, R
given) seen from cameras turned about it (`realcases.TURNS`), with a stroke drawn along its
projection (`realcases.stroke_along`). Views nobody chose by hand: how extraction does where a
user's own view would be, leaves in front included. Run it again only when the cases change: the
strokes are seeded, but the rods it turns come from the extraction of the day, so a rerun after
an extraction change moves every view (and the tests' lists of misses with them).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sketchrodgs import Camera, realcases
from sketchrodgs.atomic import atomic_write_text
from sketchrodgs.render import SOLID_OUTPUTS, render

CASES = Path(__file__).parent.parent / "tests" / "data" / "real_cases"
SOURCE_VIEWS = 2
SEED = 7
SHORTEST_PX = 30.0  # a turned view where the rod projects shorter than this is left out


def main() -> None:
    scenes, cases = realcases.load_cases(CASES / "cases.json")
    rng = np.random.default_rng(SEED)
    views = []
    for case in cases:
        scene, radius = scenes[case["scene"]], float(case["radius"])
        for view in case["views"][:SOURCE_VIEWS]:
            camera = Camera.from_dict(view["camera"])
            polyline = realcases.view_rod(scene, case, view).polyline.astype(np.float64)
            for turn, axis, degrees in realcases.TURNS:
                name = realcases.turned_view_name({"case": case["name"], "source": view["name"], "turn": turn})
                turned = realcases.turned_camera(camera, polyline.mean(axis=0), axis, degrees, name)
                uv, _ = turned.project(polyline)
                if np.sum(np.linalg.norm(np.diff(uv, axis=0), axis=1)) < SHORTEST_PX:
                    continue
                drawn = realcases.stroke_along(turned, polyline, rng)
                seen = realcases.visible_share(render(scene, turned, outputs=SOLID_OUTPUTS), turned, polyline, radius)
                views.append(
                    {
                        "case": case["name"],
                        "source": view["name"],
                        "turn": turn,
                        "visible": round(seen, 3),
                        "camera": turned.to_dict(),
                        "stroke": np.round(drawn, 2).tolist(),
                    }
                )
    about = (
        "Each case's rod (first two views, R given) seen from cameras turned about it, with a stroke "
        "along its projection; written by benches/turned_views.py (README.md here)."
    )
    lines = ",\n  ".join(json.dumps(v) for v in views)  # a view a line
    atomic_write_text(CASES / "turned_views.json", f'{{"about": {json.dumps(about)},\n "views": [\n  {lines}\n ]\n}}\n')
    print(f"{len(views)} turned views -> {CASES / 'turned_views.json'}")


if __name__ == "__main__":
    main()
