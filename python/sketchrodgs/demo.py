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
from .render import COLOR_OUTPUTS, render
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
    renderer = FrameRenderer(
        animation.rest_scene, camera, animation.moving_rows, background=BACKGROUND, outputs=COLOR_OUTPUTS
    )
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


def push_past_the_main_stem(out_dir: str | Path, progress: Callable[[str], Any] = print) -> dict[str, Any]:
    """Contact on the bundled plant (docs/contact.md): its left side stem, held at its far end, its
    near end dragged up past the main stem, once with contact and once without (the prepared push
    of `data/plant_contact.json`). Writes `contact.png` (at rest, contact on, contact off, at the
    end of the hold, seen from another side) and `contact.mp4` (the push with contact, released)."""
    from PIL import Image, ImageDraw

    from .camera import Camera

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    push = data.contact_push()
    scene = load_scene(data.sample("plant"))
    camera = Camera.from_dict(push["camera"], "plant_contact.json camera")
    shown = Camera.from_dict(push["show_camera"], "plant_contact.json show_camera")
    extraction = extract_rod(scene, camera, np.asarray(push["stroke"]["points"], np.float64), radius=push["radius"])
    polyline = extraction.polyline.astype(np.float64)
    grab = int(push["grab"])
    offset = camera.screen_offset(polyline[grab], push["drag"])
    pull = Pull(grab, tuple(offset), duration=0.5, hold=0.3, release=True, settle=1.0)
    held = round((pull.duration + pull.hold) * FPS) - 1  # the last frame before the release
    panels = [to_uint8(render(scene, shown, background=BACKGROUND, outputs=COLOR_OUTPUTS).rgb_image)]
    frames: list[np.ndarray] = []
    field = None
    closest: dict[bool, float] = {}
    for contact in (True, False):
        animation = Animation(scene, [extraction], clamp=push["clamp"], contact=contact)
        field = animation.field if contact else field
        renderer = FrameRenderer(
            animation.rest_scene, shown, animation.moving_rows, background=BACKGROUND, outputs=COLOR_OUTPUTS
        )
        for frame in animation.frames(pull, FPS):
            if contact or frame.index == held:
                rgb = to_uint8(renderer.frame(animation.means, animation.scales, animation.quats).rgb_image)
                frames += [rgb] if contact else []
                panels += [rgb] if frame.index == held else []
            if frame.index <= held and field is not None:
                # how close the stem's axis came to the scene's solid parts, in radii
                now = float(field.distance(animation.rods[0].positions).min()) / extraction.radius
                closest[contact] = min(closest.get(contact, np.inf), now)
            if frame.index == held and not contact:
                break
        progress(f"pushed with contact {'on' if contact else 'off'}")
    # around the stem and where it was pulled to
    uv, _ = shown.project(np.concatenate([polyline, polyline + offset]))
    low = np.maximum(uv.min(axis=0) - 80, 0).astype(int)
    high = np.minimum(uv.max(axis=0) + 80, [shown.width, shown.height]).astype(int)
    width, height = high - low
    picture = Image.new("RGB", (3 * width + 20, height + 24), "white")
    captions = ["at rest", "pulled, contact on: it stops at the main stem", "contact off: it passes through"]
    for k, (rgb, caption) in enumerate(zip(panels, captions)):
        picture.paste(Image.fromarray(rgb[low[1] : high[1], low[0] : high[0]]), (k * (width + 10), 24))
        ImageDraw.Draw(picture).text((k * (width + 10) + 4, 6), caption, fill=(0, 0, 0))
    save_png(out / "contact.png", np.asarray(picture))
    write_video(out / "contact.mp4", frames, FPS)
    return {
        "frames": len(frames),
        "closest_on_radii": closest.get(True),
        "closest_off_radii": closest.get(False),
        "total_s": round(time.perf_counter() - start, 2),
    }


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
