"""The whole system on a bundled real capture, in one call: render, extract a rod from a stored
stroke, pull it, let go, and write pictures, the rod and a video (`sketchrodgs demo`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from . import data
from .animate import Animation, Pull
from .extract import extract_rod
from .frames import FrameRenderer
from .images import FRAME_PNG_LEVEL, draw_overlay, save_png, to_uint8
from .io import load_scene
from .render import render
from .video import write_video

FPS = 30
BACKGROUND = (1.0, 1.0, 1.0)  # the capture was taken against white


def demo_pull(extraction, camera) -> Pull:
    """Grab the rod's middle vertex and pull it sideways across the screen by a quarter of the
    rod's length (both ends stay clamped), hold, let go."""
    polyline = extraction.polyline.astype(np.float64)
    middle = len(polyline) // 2
    tangent = polyline[min(middle + 1, len(polyline) - 1)] - polyline[max(middle - 1, 0)]
    view = polyline[middle] - camera.center
    side = np.cross(tangent, view)
    side /= np.linalg.norm(side)
    length = np.linalg.norm(np.diff(polyline, axis=0), axis=1).sum()
    return Pull(middle, tuple(0.25 * length * side), duration=0.6, hold=0.4, release=True, settle=1.0)


def run_demo(out_dir: str | Path, sample: str = "plant", progress: Callable[[str], Any] = print) -> dict[str, Any]:
    """Run the demo into `out_dir`; returns the summary that `summary.txt` holds."""
    out = Path(out_dir)
    (out / "frames").mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}
    start = clock = time.perf_counter()

    def lap(stage: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[stage] = timings.get(stage, 0.0) + now - clock
        clock = now

    scene = load_scene(data.sample(sample))
    camera, stroke = data.sample_camera(sample), data.sample_stroke(sample)
    lap("load")
    progress(f"loaded {data.SAMPLES[sample].file}: {len(scene):,} Gaussians")
    view = render(scene, camera, background=BACKGROUND)
    lap("render view")
    save_png(out / "view.png", view.rgb_image)
    lap("write images")
    extraction = extract_rod(scene, camera, stroke, render=view)
    lap("extract rod")
    extraction.save(out / "rod.json")
    save_png(
        out / "overlay.png",
        draw_overlay(
            view.rgb_image,
            camera,
            extraction.stroke,
            extraction.pixel_path,
            extraction.polyline,
            scene.means[extraction.gaussian_ids],
        ),
    )
    lap("write images")
    progress(
        f"rod: {len(extraction.polyline)} vertices, radius {extraction.radius:.4g}, "
        f"{len(extraction.gaussian_ids):,} Gaussians bound"
    )

    animation = Animation(scene, [extraction])
    pull = demo_pull(extraction, camera)
    lap("build rod")
    renderer = FrameRenderer(animation.rest_scene, camera, animation.moving_rows, background=BACKGROUND)
    lap("render frames")
    frames, furthest, pulled = [], -1.0, None
    count = int(round(pull.total * FPS))
    for frame in animation.frames(pull, FPS):
        timings["simulate"] = timings.get("simulate", 0.0) + frame.timings["simulate"]
        timings["skin"] = timings.get("skin", 0.0) + frame.timings["skin"]
        clock = time.perf_counter()
        rgb = to_uint8(renderer.frame(animation.means, animation.scales, animation.quats).rgb_image)
        lap("render frames")
        save_png(out / "frames" / f"frame_{frame.index:04d}.png", rgb, compress_level=FRAME_PNG_LEVEL)
        lap("write images")
        frames.append(rgb)
        shift = float(np.abs(animation.rods[0].positions - animation.rods[0].rest_positions).max())
        if shift > furthest:
            furthest, pulled = shift, rgb
        if frame.index % 15 == 0 or frame.index == count:
            progress(f"frame {frame.index}/{count} ({frame.phase})")
    save_png(out / "pulled.png", pulled if pulled is not None else frames[-1])
    write_video(out / "pull.mp4", frames, FPS)
    lap("write video")
    back = float(np.abs(animation.rods[0].positions - animation.rods[0].rest_positions).max())
    summary = {
        "scene": data.SAMPLES[sample].file,
        "gaussians": len(scene),
        "rod_vertices": len(extraction.polyline),
        "radius": extraction.radius,
        "bound_gaussians": int(len(extraction.gaussian_ids)),
        "stroke_coverage": extraction.coverage,
        "frames": count,
        "largest_pull": furthest,
        "distance_from_rest_at_end": back,
        "extraction_stages_ms": {k: round(v * 1e3, 2) for k, v in extraction.timings.items()},
        "stages_s": {k: round(v, 3) for k, v in timings.items()},
        "total_s": round(time.perf_counter() - start, 2),
    }
    _write_summary(out / "summary.txt", summary)
    return summary


def _write_summary(path: Path, summary: dict[str, Any]) -> None:
    from .atomic import atomic_write_text

    lines = ["sketchrodgs demo", ""]
    for key, value in summary.items():
        if isinstance(value, dict):
            lines.append(f"{key}:")
            lines += [f"  {k:<16} {v}" for k, v in value.items()]
        else:
            lines.append(f"{key:<26} {value:.4g}" if isinstance(value, float) else f"{key:<26} {value}")
    atomic_write_text(path, "\n".join(lines) + "\n")
