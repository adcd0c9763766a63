"""`sketchrodgs info SCENE`: what is in a scene file."""

from __future__ import annotations

import argparse
import json
import os
from typing import Any

import numpy as np

from ..io import FORMAT_NAMES, detect_format, load_scene
from ._args import scene_path

NAME = "info"
HELP = "print the Gaussian count, SH degree, bounding box and opacity/scale statistics of a scene file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "scene", type=scene_path, help="scene file (.ply, compressed .ply, .splat, .spz), or sample:NAME"
    )
    parser.add_argument("--json", action="store_true", help="print the statistics as JSON")


def scene_summary(path: str) -> dict[str, Any]:
    """The statistics `info` prints, as a JSON-ready dict."""
    scene = load_scene(path)
    fmt = detect_format(path)
    largest_scale = scene.scales.max(axis=1)

    def stats(values: np.ndarray) -> dict[str, float]:
        q = np.percentile(values, [0, 50, 100])
        return {"min": float(q[0]), "median": float(q[1]), "max": float(q[2]), "mean": float(values.mean())}

    return {
        "file": os.fspath(path),
        "format": fmt,
        "format_name": FORMAT_NAMES[fmt],
        "bytes": os.path.getsize(path),
        "count": len(scene),
        "sh_degree": scene.sh_degree,
        "bbox_min": scene.means.min(axis=0).tolist(),
        "bbox_max": scene.means.max(axis=0).tolist(),
        "opacity": stats(scene.opacities),
        "largest_scale": stats(largest_scale),
    }


def run(args: argparse.Namespace) -> int:
    summary = scene_summary(args.scene)
    if args.json:
        print(json.dumps(summary, indent=1))
        return 0
    lo, hi = np.array(summary["bbox_min"]), np.array(summary["bbox_max"])
    op, sc = summary["opacity"], summary["largest_scale"]
    print(f"file       {summary['file']}  ({summary['format_name']}, {summary['bytes'] / 1e6:.2f} MB)")
    print(f"gaussians  {summary['count']:,}")
    print(f"sh degree  {summary['sh_degree']}")
    print(f"bbox min   {lo[0]: .4f} {lo[1]: .4f} {lo[2]: .4f}")
    print(f"bbox max   {hi[0]: .4f} {hi[1]: .4f} {hi[2]: .4f}")
    print(f"extent     {(hi - lo).max():.4f}")
    print(f"opacity    min {op['min']:.3f}  median {op['median']:.3f}  mean {op['mean']:.3f}  max {op['max']:.3f}")
    print(f"scale(max) min {sc['min']:.3g}  median {sc['median']:.3g}  mean {sc['mean']:.3g}  max {sc['max']:.3g}")
    return 0
