"""A scene of the paper's capture size (issue 16): the bundled plant in front, 19 shifted copies of it
behind filling the view, SH degree 3 with random higher coefficients: 2,272,960 Gaussians, seen by
the plant's own camera and stroked with its own stroke.
"""

from __future__ import annotations

import numpy as np

from sketchrodgs import Camera, GaussianScene, data, load_scene

COPIES = 19


def capture_scene(seed: int = 0) -> tuple[GaussianScene, Camera, np.ndarray]:
    """The scene, the plant's camera and the plant's stroke."""
    base = load_scene(data.sample("plant"))
    camera, stroke = data.sample_camera("plant"), data.sample_stroke("plant")
    to_world = np.asarray(camera.camera_to_world, np.float64)
    # copies on two layers behind the plant (camera z 2.1 and 3.1, the plant sits at 1.0), spread
    # across the view at their depth: 4 x 2 and 6 x 2 less one, so the whole image is covered
    shifts = []
    for depth, columns in ((2.1, 4), (3.1, 6)):
        half_w = 0.5 * depth * camera.width / camera.fx
        half_h = 0.5 * depth * camera.height / camera.fy
        for row in (-0.5, 0.5):
            for col in np.linspace(-1, 1, columns) * (1 - 1 / columns):
                shifts.append((col * half_w, row * half_h, depth - 1.0))
    shifts = shifts[:COPIES]
    moves = np.asarray(shifts) @ to_world[:3, :3].T  # camera-space shift in world axes
    n = len(base)
    total = n * (1 + len(moves))
    means = np.concatenate([base.means] + [base.means + m.astype(np.float32) for m in moves])
    rows = np.tile(np.arange(n), 1 + len(moves))
    rng = np.random.default_rng(seed)
    sh = np.empty((total, 16, 3), np.float32)
    sh[:, 0] = base.sh[rows, 0]
    sh[:, 1:] = rng.normal(scale=0.05, size=(total, 15, 3)).astype(np.float32)
    scene = GaussianScene(means, base.scales[rows], base.quats[rows], base.opacities[rows], sh)
    return scene, camera, stroke
