"""`sketchrodgs info SCENE`: what is in a scene file, and which way is up."""

from __future__ import annotations

import argparse
from typing import Any

from ._args import scene_help, scene_path

NAME = "info"
HELP = "print the Gaussian count, SH degree, bounding box, opacity/scale statistics and up axis of a scene"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", type=scene_path, help=scene_help())
    parser.add_argument(
        "--camera",
        metavar="CAMERAS.json",
        help="the scene's training cameras, whose up is reported (default: a training output folder's cameras.json)",
    )
    parser.add_argument("--json", action="store_true", help="print the statistics as JSON")


def scene_summary(path: str, cameras_path: str | None = None) -> dict[str, Any]:
    """The statistics `info` prints, as a JSON-ready dict."""
    import os

    import numpy as np

    from ..camera import load_cameras
    from ..framing import scene_up
    from ..io import FORMAT_NAMES, detect_format, format_up, load_scene, scene_file

    scene = load_scene(path)
    fmt = detect_format(path)
    largest_scale = scene.scales.max(axis=1)
    up = scene_up(scene, load_cameras(cameras_path) if cameras_path else [], file_up=format_up(path))

    def stats(values: np.ndarray) -> dict[str, float]:
        q = np.percentile(values, [0, 50, 100])
        return {"min": float(q[0]), "median": float(q[1]), "max": float(q[2]), "mean": float(values.mean())}

    return {
        "file": os.fspath(scene_file(path)),
        "format": fmt,
        "format_name": FORMAT_NAMES[fmt],
        "bytes": os.path.getsize(scene_file(path)),
        "count": len(scene),
        "sh_degree": scene.sh_degree,
        "bbox_min": scene.means.min(axis=0).tolist(),
        "bbox_max": scene.means.max(axis=0).tolist(),
        "opacity": stats(scene.opacities),
        "largest_scale": stats(largest_scale),
        "up": {"axis": up.axis, "vector": up.vector.tolist(), "source": up.source, "reason": up.reason},
    }


def run(args: argparse.Namespace) -> int:
    import json

    from ._framing import camera_file

    summary = scene_summary(args.scene, camera_file(args))
    if args.json:
        print(json.dumps(summary, indent=1))
        return 0
    lo, hi = summary["bbox_min"], summary["bbox_max"]
    op, sc, up = summary["opacity"], summary["largest_scale"], summary["up"]
    print(f"file       {summary['file']}  ({summary['format_name']}, {summary['bytes'] / 1e6:.2f} MB)")
    print(f"gaussians  {summary['count']:,}")
    print(f"sh degree  {summary['sh_degree']}")
    print(f"bbox min   {lo[0]: .4f} {lo[1]: .4f} {lo[2]: .4f}")
    print(f"bbox max   {hi[0]: .4f} {hi[1]: .4f} {hi[2]: .4f}")
    print(f"extent     {max(h - l for l, h in zip(lo, hi)):.4f}")
    print(f"opacity    min {op['min']:.3f}  median {op['median']:.3f}  mean {op['mean']:.3f}  max {op['max']:.3f}")
    print(f"scale(max) min {sc['min']:.3g}  median {sc['median']:.3g}  mean {sc['mean']:.3g}  max {sc['max']:.3g}")
    vector = ", ".join(f"{v:.3f}" for v in up["vector"])
    print(
        f"up         {up['axis']}  ({up['reason']}{': ' + vector if up['source'] == 'cameras' else ''}; --up overrides)"
    )
    return 0
