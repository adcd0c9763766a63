"""The paper's capture size (issue 16): 2,272,960 SH-3 Gaussians (`capture_scene`), every figure a
user meets, on this machine. Load runs in a fresh process, which also reports the peak memory
through load, extract and animate. Prints tables, never asserts a time.

Targets on 2 cores: extract_rod with its render <= 100 ms; full render <= 250 ms at 960x540 and
<= 600 ms at 1920x1080, index-only clearly cheaper; animate frames <= 100 ms; load <= 1.5 s;
peak memory <= 1.5 GB; rod files <= 2 MB per 100k bound Gaussians.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _table import best_time, print_table
from capture_scene import capture_scene
from sketchrodgs import save_scene
from sketchrodgs.animate import Animation, Pull
from sketchrodgs.extract import extract_rod
from sketchrodgs.frames import FrameRenderer
from sketchrodgs.images import FRAME_PNG_LEVEL, save_png, to_uint8
from sketchrodgs.partial_render import MARGIN_PX, band_tiles
from sketchrodgs.render import COLOR_OUTPUTS, SOLID_OUTPUTS, render
from sketchrodgs.rod_file import bindings_path

REPEAT = 5
RENDER_ROUNDS = 3
FRAMES = 6

# In a fresh process: load, extract and a few frames of animate, with the high-water mark after each.
_PIPELINE = """
import json, sys, time
sys.path.insert(0, sys.argv[2])
import numpy as np
import sketchrodgs
from capture_scene import capture_scene
from sketchrodgs.animate import Animation, Pull
from sketchrodgs.frames import FrameRenderer

def peak():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024

out = {"start": peak()}
clock = time.perf_counter()
scene = sketchrodgs.load_scene(sys.argv[1])
out["load_s"] = time.perf_counter() - clock
out["load"] = peak()
camera, stroke = sketchrodgs.data.sample_camera("plant"), sketchrodgs.data.sample_stroke("plant")
rod = sketchrodgs.extract_rod(scene, camera, stroke)
out["extract"] = peak()
animation = Animation(scene, [rod])
renderer = FrameRenderer(animation.rest_scene, camera, animation.moving_rows)
frames = animation.frames(Pull(-1, (0.0, -0.05, 0.03), duration=0.1, hold=0.0, release=False, settle=0.0), fps=30)
for frame in frames:
    renderer.frame(animation.means, animation.scales, animation.quats)
out["animate"] = peak()
print(json.dumps(out))
"""


def pipeline_stats(path: Path) -> dict:
    out = subprocess.run(
        [sys.executable, "-c", _PIPELINE, str(path), str(Path(__file__).parent)],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout)


# Run a command and print the peak resident memory of its process tree (bytes; Linux reports kB).
_PEAK_OF = (
    "import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, capture_output=True); "
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024)"
)


def command_peak(*command: str) -> int:
    """Peak resident memory (bytes) of one `sketchrodgs` command run in its own process."""
    out = subprocess.run([sys.executable, "-c", _PEAK_OF, *command], capture_output=True, text=True, check=True)
    return int(out.stdout)


def cli_peaks(scene_path: Path, tmp: Path) -> dict[str, int]:
    """Peak memory of `sketchrodgs extract` and of `sketchrodgs animate` on the scene file, each in
    a fresh process, with the plant sample's camera and stroke (the scene's front plant)."""
    from sketchrodgs import data

    data.sample_camera("plant").save(tmp / "cam.json")
    (tmp / "stroke.json").write_text(json.dumps({"points": data.sample_stroke("plant").tolist()}))
    cli = [sys.executable, "-m", "sketchrodgs"]
    extract = [
        *cli,
        "extract",
        str(scene_path),
        "--camera",
        str(tmp / "cam.json"),
        "--stroke",
        str(tmp / "stroke.json"),
    ]
    animate = [*cli, "animate", str(scene_path), str(tmp / "cli_rod.json"), "--grab", "-1", "--to=0,-0.05,0.03"]
    return {
        "extract": command_peak(*extract, "-o", str(tmp / "cli_rod.json")),
        "animate": command_peak(
            *animate, "--duration", "0.2", "--hold", "0", "--video", "none", "-o", str(tmp / "cli")
        ),
    }


def main() -> None:
    scene, camera, stroke = capture_scene()
    n = len(scene.means)
    rows = []
    modes = (
        ("all", "all"),
        ("colour: rgb and alpha", COLOR_OUTPUTS),
        ("index", "index"),
        ("index and solid", SOLID_OUTPUTS),
    )
    for label, cam in (("960x540", camera), ("1920x1080", camera.resized(1920, 1080))):
        # The modes take turns, RENDER_ROUNDS rounds of 2 renders each, so that a noisy stretch of
        # this shared machine (or the first renders' page faults) does not fall on one mode only.
        best = {name: float("inf") for name, _ in modes}
        for _ in range(RENDER_ROUNDS):
            for name, outputs in modes:
                best[name] = min(best[name], best_time(lambda: render(scene, cam, outputs=outputs), repeat=2, warmup=0))
        rows += [[f"render {label} ({name})", f"{best[name] * 1e3:.0f}"] for name, _ in modes]
    tiles = band_tiles(camera, stroke, 0.01 * camera.width + MARGIN_PX)
    seconds = best_time(lambda: render(scene, camera, outputs=SOLID_OUTPUTS, tiles=tiles), repeat=REPEAT)
    rows.append(
        [f"render the sketch's band ({tiles.mean():.1%} of the tiles, index and solid)", f"{seconds * 1e3:.0f}"]
    )

    runs = []
    for _ in range(REPEAT):
        clock = time.perf_counter()
        rod = extract_rod(scene, camera, stroke)
        runs.append((time.perf_counter() - clock, rod.timings, rod.rendered_tiles))
    total, stages, share = min(runs, key=lambda r: r[0])
    rows.append(["extract_rod with its render", f"{total * 1e3:.0f}"])
    rows.append([f"  of which render ({share:.1%} of the tiles)", f"{stages['render'] * 1e3:.0f}"])
    full = render(scene, camera, outputs="index")
    given = best_time(lambda: extract_rod(scene, camera, stroke, render=full), repeat=REPEAT)
    rows.append(["extract_rod with K and Z given", f"{given * 1e3:.0f}"])

    animation = Animation(scene, [rod])
    pull = Pull(-1, (0.0, -0.05, 0.03), duration=FRAMES / 30, hold=0.0, release=False, settle=0.0)
    with tempfile.TemporaryDirectory() as tmp:
        clock = time.perf_counter()
        count = 0
        for count, _frame in enumerate(animation.frames(pull, fps=30), start=1):
            save_png(
                Path(tmp) / f"{count:04d}.png", render(animation.current_scene(), camera, outputs=COLOR_OUTPUTS).rgb
            )
        plain = (time.perf_counter() - clock) / max(count, 1)
        rows.append([f"animate frame, full render each frame ({count} frames)", f"{plain * 1e3:.0f}"])
        animation = Animation(scene, [rod])
        clock = time.perf_counter()
        renderer = FrameRenderer(animation.rest_scene, camera, animation.moving_rows, outputs=COLOR_OUTPUTS)
        setup = time.perf_counter() - clock
        clock = time.perf_counter()
        stages = {"simulate": 0.0, "skin": 0.0, "render": 0.0, "png": 0.0}
        for count, frame in enumerate(animation.frames(pull, fps=30), start=1):
            stages["simulate"] += frame.timings["simulate"]
            stages["skin"] += frame.timings["skin"]
            start = time.perf_counter()
            rgb = to_uint8(renderer.frame(animation.means, animation.scales, animation.quats).rgb)
            stages["render"] += time.perf_counter() - start
            start = time.perf_counter()
            save_png(Path(tmp) / f"{count:04d}.png", rgb, compress_level=FRAME_PNG_LEVEL)
            stages["png"] += time.perf_counter() - start
        frame_s = (time.perf_counter() - clock) / max(count, 1)
        parts = ", ".join(f"{k} {v / count * 1e3:.0f}" for k, v in stages.items())
        rows.append(
            [
                f"animate frame as `sketchrodgs animate` ({parts}; {len(animation.moving_rows):,} moving)",
                f"{frame_s * 1e3:.0f}",
            ]
        )
        rows.append(["  its one-off set-up (project and bin the static part)", f"{setup * 1e3:.0f}"])

        path = Path(tmp) / "capture.ply"
        save_scene(scene, path)
        size = os.path.getsize(path)
        stats = pipeline_stats(path)
        peaks = cli_peaks(path, Path(tmp))
        rows.append([f"load the .ply ({size / 1e6:.0f} MB)", f"{stats['load_s'] * 1e3:.0f}"])
        rod_path = Path(tmp) / "rod.json"
        rod.save(rod_path)
        rod_size = os.path.getsize(rod_path) + os.path.getsize(bindings_path(rod_path))
    print_table(f"{n:,} Gaussians, SH 3 (the plant and 19 copies), 2 cores", ["step", "ms"], rows)
    print_table(
        "peak memory (VmHWM) of load -> extract -> animate in one fresh Python process that keeps the "
        "loaded scene (the animation's scene adds the split needles' pieces and shares its SH table; target 1.5 GB)",
        ["after", "GB"],
        [[k, f"{stats[k] / 1e9:.2f}"] for k in ("start", "load", "extract", "animate")],
    )
    print_table(
        "peak memory of the command line, each command in its own process (`animate` lets the loaded "
        "scene go once its animation holds its own)",
        ["command", "GB"],
        [[f"sketchrodgs {k}", f"{v / 1e9:.2f}"] for k, v in peaks.items()],
    )
    bound = len(rod.gaussian_ids)
    print_table(
        "rod file (JSON and its .npz)",
        ["bound Gaussians", "bytes", "MB per 100k bound"],
        [[f"{bound:,}", f"{rod_size:,}", f"{rod_size / 1e6 / max(bound, 1) * 1e5:.1f}"]],
    )


if __name__ == "__main__":
    main()
