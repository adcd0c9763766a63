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


def sprinkle_close_up(distance: float, **look_at: object) -> tuple[Camera, np.ndarray]:
    """A camera `distance` from the donut's sprinkle a (tests/data/real_cases/cases.json), looking
    at it as its az180 view does, and the sprinkle's stroke as 3D points (that view's stroke at its
    depth, 0.3). `look_at` goes to `Camera.look_at` (width, height, fov_y_deg, near)."""
    import json

    cases = json.loads((DATA / "real_cases" / "cases.json").read_text(encoding="utf-8"))["cases"]
    view = next(c for c in cases if c["name"] == "donut_sprinkle_a")["views"][0]
    far = Camera.from_dict(view["camera"])
    stroke = np.asarray(view["stroke"], np.float64)
    rays = np.column_stack([(stroke - [far.cx, far.cy]) / [far.fx, far.fy], np.ones(len(stroke))]) * 0.3
    points = rays @ far.camera_to_world[:3, :3].T + far.camera_to_world[:3, 3]
    forward = far.camera_to_world[:3, 2]
    target = far.center + 0.3 * forward
    camera = Camera.look_at(target - distance * forward, target, up=-far.camera_to_world[:3, 1], **look_at)
    return camera, points
