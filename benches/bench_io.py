"""Scene file I/O: load and save of 100k and 1M-Gaussian .ply (SH 3) and .splat; and writing a
rendered 960x540 frame as PNG (what `animate` does per frame).

Peak memory of a load is measured in a fresh subprocess (max RSS after the load minus before it).
The reference is the straightforward plyfile reader that copies one property at a time; for PNG,
Pillow's zlib encoder at the same level.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import plyfile
from PIL import Image

from _table import best_time, print_table
from sketchrodgs import GaussianScene, data, load_scene, render, save_scene
from sketchrodgs.images import FRAME_PNG_LEVEL, save_png, to_uint8

SIZES = (100_000, 1_000_000)

_PEAK_SCRIPT = """
import json, sys
import sketchrodgs

def high_water_mark():  # VmHWM is per process image; ru_maxrss would inherit the parent's peak
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024

before = high_water_mark()
scene = sketchrodgs.load_scene(sys.argv[1])
print(json.dumps({"peak_bytes": high_water_mark() - before}))
"""


def synthetic_scene(n: int, sh_degree: int, seed: int = 0) -> GaussianScene:
    rng = np.random.default_rng(seed)
    quats = rng.normal(size=(n, 4)).astype(np.float32)
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    return GaussianScene(
        rng.normal(size=(n, 3)).astype(np.float32),
        np.exp(rng.uniform(-6, -2, size=(n, 3))).astype(np.float32),
        quats,
        rng.uniform(0.05, 0.95, size=n).astype(np.float32),
        rng.normal(scale=0.3, size=(n, (sh_degree + 1) ** 2, 3)).astype(np.float32),
    )


def reference_ply_load(path: Path) -> np.ndarray:
    """The simple way: read with plyfile and copy each property on its own."""
    vertex = plyfile.PlyData.read(str(path))["vertex"]
    return np.stack([np.asarray(vertex[p.name], np.float32) for p in vertex.properties], axis=1)


def peak_load_bytes(path: Path) -> int:
    out = subprocess.run([sys.executable, "-c", _PEAK_SCRIPT, str(path)], capture_output=True, text=True, check=True)
    return int(json.loads(out.stdout)["peak_bytes"])


def main() -> None:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in SIZES:
            for fmt, degree in (("ply", 3), ("splat", 0)):
                scene = synthetic_scene(n, degree)
                path = Path(tmp) / f"scene_{n}.{fmt}"
                save_s = best_time(lambda: save_scene(scene, path), repeat=3)
                load_s = best_time(lambda: load_scene(path), repeat=3)
                size = os.path.getsize(path)
                ref = ""
                if fmt == "ply":
                    ref_s = best_time(lambda: reference_ply_load(path), repeat=3)
                    ref = f"{ref_s / load_s:.1f}x"
                peak = peak_load_bytes(path)
                rows.append(
                    [
                        f"{n:,}",
                        f".{fmt} SH{degree}",
                        f"{size / 1e6:.0f} MB",
                        f"{load_s * 1e3:.0f}",
                        f"{n / load_s / 1e6:.1f}",
                        f"{save_s * 1e3:.0f}",
                        f"{peak / 1e6:.0f} MB ({peak / size:.2f}x)",
                        ref,
                    ]
                )
                path.unlink()
    print_table(
        "scene I/O (best of 3)",
        [
            "gaussians",
            "format",
            "file",
            "load ms",
            "M splat/s",
            "save ms",
            "load peak RSS (x file)",
            "vs plyfile per-field",
        ],
        rows,
    )

    png_table()


def png_table() -> None:
    """A real 960x540 frame (the bundled plant) written as PNG at zlib-like levels, against Pillow."""
    frame = to_uint8(render(load_scene(data.sample("plant")), data.sample_camera("plant"), background=(1, 1, 1)).rgb)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "frame.png"
        for level in sorted({0, FRAME_PNG_LEVEL, 6, 9}):
            ours = best_time(lambda: save_png(path, frame, compress_level=level), repeat=7)
            size = os.path.getsize(path)

            def pillow(level: int = level) -> int:
                buffer = io.BytesIO()
                Image.fromarray(frame).save(buffer, format="PNG", compress_level=level)
                return buffer.tell()

            theirs = best_time(pillow, repeat=7)
            rows.append([level, f"{ours * 1e3:.1f}", f"{size / 1e3:.0f}", f"{theirs * 1e3:.1f}", f"{pillow() / 1e3:.0f}",
                         f"{theirs / ours:.1f}x"])  # fmt: skip
    print_table(
        "a 960x540 frame as PNG (best of 7; ours written to disk, Pillow to memory)",
        ["level", "ms", "KB", "Pillow ms", "Pillow KB", "ratio"],
        rows,
    )


if __name__ == "__main__":
    main()
