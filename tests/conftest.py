"""Shared fixtures: small synthetic scenes and paths to the bundled test data."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sketchrodgs import Camera, GaussianScene, data

DATA = Path(__file__).parent / "data"
# The real plant capture ships with the package (the demo uses it); tests read it from there.
PLANT = data.sample("plant")


def random_scene(n: int, sh_degree: int = 0, seed: int = 0) -> GaussianScene:
    """A scene of `n` random Gaussians with every field exercised."""
    rng = np.random.default_rng(seed)
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    k = (sh_degree + 1) ** 2
    return GaussianScene(
        means=rng.normal(size=(n, 3)),
        scales=np.exp(rng.uniform(-6, -1, size=(n, 3))),
        quats=quats,
        opacities=rng.uniform(0.01, 0.99, size=n),
        sh=rng.normal(scale=0.5, size=(n, k, 3)),
    )


@pytest.fixture
def data_dir() -> Path:
    return DATA


def outputs_per_thread_count(code: str, counts: tuple[int, ...]) -> set[str]:
    """What `python -c code` prints with each count of worker threads (a fresh process each): one
    output means the result does not depend on the thread count."""
    outputs = set()
    for threads in counts:
        env = {**os.environ, "SKETCHRODGS_NUM_THREADS": str(threads)}
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
        assert out.returncode == 0, out.stderr
        outputs.add(out.stdout.strip())
    return outputs


def close_up(
    far: Camera, stroke: np.ndarray, depth: float, distance: float, **look_at: object
) -> tuple[Camera, np.ndarray]:
    """A camera `distance` from what `far` sees at camera depth `depth` on its axis, looking as `far`
    does, and `stroke` (drawn in `far`) as 3D points at that depth. `look_at` goes to
    `Camera.look_at` (width, height, fov_y_deg, near)."""
    forward = far.camera_to_world[:3, 2]
    target = far.center + depth * forward
    camera = Camera.look_at(target - distance * forward, target, up=-far.camera_to_world[:3, 1], **look_at)
    return camera, far.unproject(stroke, depth)


def sprinkle_close_up(distance: float, **look_at: object) -> tuple[Camera, np.ndarray]:
    """`close_up` of the donut's sprinkle a (tests/data/real_cases/cases.json) as its az180 view
    sees it, the stroke at its depth, 0.3."""
    import json

    cases = json.loads((DATA / "real_cases" / "cases.json").read_text(encoding="utf-8"))["cases"]
    view = next(c for c in cases if c["name"] == "donut_sprinkle_a")["views"][0]
    return close_up(Camera.from_dict(view["camera"]), np.asarray(view["stroke"], np.float64), 0.3, distance, **look_at)
