"""Before/after pictures made with the command line alone (docs/cli.md, README "Gallery"): for the
guitar neck, a tree branch and the ring, `sketchrodgs extract` on a stored view and stroke, then
`sketchrodgs animate` with a screen-space drag, held; the rest frame and the held frame side by
side, cropped around the rod, with the commands' pull options in the caption.

    python benches/cli_gallery.py OUT_DIR

Writes OUT_DIR/cli_<name>.png (the README uses docs/gallery/).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from sketchrodgs import Camera
from sketchrodgs.rod_file import load_rod

ROOT = Path(__file__).parent.parent
CASES = json.loads((ROOT / "tests" / "data" / "real_cases" / "cases.json").read_text())
RING_VIEW = Camera.look_at((0, 0, -1.4), (0, 0, 0), up=(0, 1, 0), width=960, height=540, fov_y_deg=40)
MARGIN_PX = 60
HEIGHT = 300  # of each panel


def case_view(name: str, view: str) -> tuple[str, dict, list]:
    case = next(c for c in CASES["cases"] if c["name"] == name)
    entry = next(v for v in case["views"] if v["name"] == view)
    scene = CASES["scenes"][case["scene"]]
    return (scene if scene.startswith("sample:") else str(ROOT / scene)), entry["camera"], entry["stroke"]


def ring_view() -> tuple[str, dict, list]:
    theta = np.radians(np.linspace(20, 160, 25))  # the upper arc (the gap is in the lower one)
    uv, _ = RING_VIEW.project(np.stack([0.455 * np.cos(theta), 0.136 * np.sin(theta), 0 * theta], axis=1))
    return "sample:ring", RING_VIEW.to_dict(), uv.tolist()


# name -> (scene, camera, stroke), and the pull: which end is held, where it is grabbed, the drag in pixels
PULLS = {
    "guitar_neck": (case_view("guitar_neck", "az270"), "both", "0.5", (60, 0)),
    "tree_branch": (case_view("tree_branch_centre", "az000"), "lower", "upper", (70, 10)),
    "ring": (ring_view(), "both", "0.5", (0, 60)),
}


def sketchrodgs(*args: str) -> None:
    result = subprocess.run([sys.executable, "-m", "sketchrodgs", *args], capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"sketchrodgs {' '.join(args)}:\n{result.stderr}")


def pull_options(rod: Path, held: str, grab: str, drag: tuple[int, int], camera: Camera) -> list[str]:
    """The animate options: hold the lower end (the root; lower in the image) or both, grab the other."""
    polyline = load_rod(rod)[0].polyline
    if held == "both":
        return ["--clamp", "both", "--grab", grab, "--drag", f"{drag[0]},{drag[1]}"]
    uv, _ = camera.project(polyline[[0, -1]])
    start_is_lower = uv[0, 1] > uv[1, 1]
    return [
        "--clamp",
        "start" if start_is_lower else "end",
        "--grab",
        "1.0" if start_is_lower else "0.0",
        "--drag",
        f"{drag[0]},{drag[1]}",
    ]


def pair(rest: Image.Image, pulled: Image.Image, box: tuple[int, int, int, int], caption: str) -> Image.Image:
    panels = [im.crop(box) for im in (rest, pulled)]
    panels = [p.resize((max(1, round(p.width * HEIGHT / p.height)), HEIGHT), Image.LANCZOS) for p in panels]
    text_width = int(ImageDraw.Draw(Image.new("RGB", (1, 1))).textlength(caption)) + 8
    out = Image.new("RGB", (max(sum(p.width for p in panels) + 8, text_width), HEIGHT + 24), "white")
    for k, panel in enumerate(panels):
        out.paste(panel, (k * (panels[0].width + 8), 24))
    ImageDraw.Draw(out).text((4, 6), caption, fill=(0, 0, 0))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name, ((scene, camera_json, stroke), held, grab, drag) in PULLS.items():
        with tempfile.TemporaryDirectory() as work_dir:
            work = Path(work_dir)
            (work / "cam.json").write_text(json.dumps(camera_json))
            (work / "stroke.json").write_text(json.dumps({"points": stroke}))
            rod = work / "rod.json"
            sketchrodgs(
                "extract",
                scene,
                "--camera",
                str(work / "cam.json"),
                "--stroke",
                str(work / "stroke.json"),
                "-o",
                str(rod),
            )
            camera = Camera.from_dict(camera_json)
            options = pull_options(rod, held, grab, drag, camera)
            timing = ["--duration", "0.5", "--hold", "0.5", "--fps", "10", "--video", "none"]
            sketchrodgs("animate", scene, str(rod), *options, *timing, "-o", str(work / "anim"))
            frames = sorted((work / "anim" / "frames").glob("frame_*.png"))
            pulled = Image.open(frames[-1]).convert("RGB")
            sketchrodgs("render", scene, "--camera", str(work / "cam.json"), "-o", str(work / "rest.png"))
            rest = Image.open(work / "rest.png").convert("RGB")
            changed = np.abs(np.asarray(pulled, np.int16) - np.asarray(rest, np.int16)).max(axis=2) > 30
            uv, _ = camera.project(load_rod(rod)[0].polyline)
            rows, cols = np.nonzero(changed)
            low = np.minimum(np.nanmin(uv, axis=0), [cols.min(), rows.min()]) - MARGIN_PX
            high = np.maximum(np.nanmax(uv, axis=0), [cols.max(), rows.max()]) + MARGIN_PX
            box = (
                max(0, int(low[0])),
                max(0, int(low[1])),
                min(camera.width, int(high[0])),
                min(camera.height, int(high[1])),
            )
            caption = f"{name}: at rest | sketchrodgs animate ... {' '.join(options)} (held)"
            pair(rest, pulled, box, caption).save(args.out / f"cli_{name}.png")
            print(f"{name}: {' '.join(options)} -> {args.out / f'cli_{name}.png'}")


if __name__ == "__main__":
    main()
