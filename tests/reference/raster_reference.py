"""A slow, obvious NumPy implementation of the reference 3DGS rasteriser (docs/rendering.md), in float64.

It is the test oracle of the Rust rasteriser on small scenes and the "simple reference" of
benches/bench_render.py. Every step is written as docs/rendering.md states it, with no shortcut: the
projection is vectorised over Gaussians, then each 16x16 tile blends its depth-sorted list one
Gaussian at a time, vectorised over the tile's pixels.
"""

from __future__ import annotations

import numpy as np

TILE = 16
NEAR = 0.2
LOW_PASS = 0.3
ALPHA_MAX = 0.99
ALPHA_MIN = 1.0 / 255.0
T_MIN = 1e-4

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = [1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396]
C3 = [
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
]


def quat_to_rotation(quats: np.ndarray) -> np.ndarray:
    """(N, 4) wxyz -> (N, 3, 3), normalised by max(|q|, 1e-12)."""
    q = quats / np.maximum(np.linalg.norm(quats, axis=1, keepdims=True), 1e-12)
    w, x, y, z = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=1,
    )


def eval_sh(sh: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """`computeColorFromSH`: sh (N, K, 3), unit dirs (N, 3) -> colour (N, 3), clamped at 0 only."""
    k = sh.shape[1]
    x, y, z = (dirs[:, i : i + 1] for i in range(3))
    r = C0 * sh[:, 0]
    if k >= 4:
        r = r - C1 * y * sh[:, 1] + C1 * z * sh[:, 2] - C1 * x * sh[:, 3]
    if k >= 9:
        xx, yy, zz = x * x, y * y, z * z
        r = (
            r
            + C2[0] * x * y * sh[:, 4]
            + C2[1] * y * z * sh[:, 5]
            + C2[2] * (2 * zz - xx - yy) * sh[:, 6]
            + C2[3] * x * z * sh[:, 7]
            + C2[4] * (xx - yy) * sh[:, 8]
        )
        if k >= 16:
            r = (
                r
                + C3[0] * y * (3 * xx - yy) * sh[:, 9]
                + C3[1] * x * y * z * sh[:, 10]
                + C3[2] * y * (4 * zz - xx - yy) * sh[:, 11]
                + C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh[:, 12]
                + C3[4] * x * (4 * zz - xx - yy) * sh[:, 13]
                + C3[5] * z * (xx - yy) * sh[:, 14]
                + C3[6] * x * (xx - 3 * yy) * sh[:, 15]
            )
    return np.maximum(r + 0.5, 0.0)


def project_reference(scene, camera) -> dict[str, np.ndarray]:
    """Per-Gaussian screen-space quantities (docs/rendering.md steps 1-7), all float64.

    Returns a dict with `visible` (N,) bool, `z`, `mean2d` (N, 2) = (u - 0.5, v - 0.5),
    `conic` (N, 3), `radius`, `rect` (N, 4) = tile x0, y0, x1, y1 (half-open), `color` (N, 3).
    """
    means = scene.means.astype(np.float64)
    scales = scene.scales.astype(np.float64)
    w2c = np.asarray(camera.world_to_camera, dtype=np.float64)
    rot_w, t_w = w2c[:3, :3], w2c[:3, 3]
    p = means @ rot_w.T + t_w
    x, y, z = p.T
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        rot = quat_to_rotation(scene.quats.astype(np.float64))
        m = rot * scales[:, None, :]  # R S
        cov3d = m @ m.transpose(0, 2, 1)
        width, height, fx, fy, cx, cy = camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy
        tan_fovx, tan_fovy = width / (2 * fx), height / (2 * fy)
        lim_x_pos, lim_x_neg = (width - cx) / fx + 0.3 * tan_fovx, cx / fx + 0.3 * tan_fovx
        lim_y_pos, lim_y_neg = (height - cy) / fy + 0.3 * tan_fovy, cy / fy + 0.3 * tan_fovy
        tx = z * np.clip(x / z, -lim_x_neg, lim_x_pos)
        ty = z * np.clip(y / z, -lim_y_neg, lim_y_pos)
        zeros = np.zeros_like(z)
        jac = np.stack(
            [np.stack([fx / z, zeros, -fx * tx / z**2], -1), np.stack([zeros, fy / z, -fy * ty / z**2], -1)], axis=1
        )
        tmat = jac @ rot_w
        cov2d = tmat @ cov3d @ tmat.transpose(0, 2, 1)
        a = cov2d[:, 0, 0] + LOW_PASS
        b = cov2d[:, 0, 1]
        c = cov2d[:, 1, 1] + LOW_PASS
        det = a * c - b * b
        conic = np.stack([c / det, -b / det, a / det], -1)
        mid = 0.5 * (a + c)
        lambda1 = mid + np.sqrt(np.maximum(0.1, mid * mid - det))
        radius = np.ceil(3.0 * np.sqrt(lambda1))
        u = fx * x / z + cx
        v = fy * y / z + cy
        mean2d = np.stack([u - 0.5, v - 0.5], -1)
        grid_x, grid_y = -(-width // TILE), -(-height // TILE)

        def trunc_clamp(values: np.ndarray, hi: int) -> np.ndarray:
            return np.clip(np.nan_to_num(np.trunc(values), nan=0.0, posinf=hi, neginf=0.0), 0, hi).astype(np.int64)

        rect = np.stack(
            [
                trunc_clamp((mean2d[:, 0] - radius) / TILE, grid_x),
                trunc_clamp((mean2d[:, 1] - radius) / TILE, grid_y),
                trunc_clamp((mean2d[:, 0] + radius + TILE - 1) / TILE, grid_x),
                trunc_clamp((mean2d[:, 1] + radius + TILE - 1) / TILE, grid_y),
            ],
            -1,
        )
        centre = camera.center
        dirs = means - centre
        dirs = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        color = eval_sh(scene.sh.astype(np.float64), dirs)
    visible = (z > NEAR) & (det != 0) & np.isfinite(det) & (rect[:, 0] < rect[:, 2]) & (rect[:, 1] < rect[:, 3])
    return {
        "visible": visible,
        "z": z,
        "mean2d": mean2d,
        "conic": conic,
        "radius": radius,
        "rect": rect,
        "color": color,
    }


def render_reference(scene, camera, background=(0.0, 0.0, 0.0)) -> dict[str, np.ndarray]:
    """Render like docs/rendering.md, float64. Returns rgb (H, W, 3), alpha, depth, index (int32),
    index_depth, max_weight and n_contrib, each (H, W)."""
    proj = project_reference(scene, camera)
    width, height = camera.width, camera.height
    bg = np.asarray(background, dtype=np.float64)
    rgb = np.zeros((height, width, 3))
    alpha = np.zeros((height, width))
    depth = np.zeros((height, width))
    index = np.full((height, width), -1, dtype=np.int32)
    index_depth = np.zeros((height, width))
    max_weight = np.zeros((height, width))
    n_contrib = np.zeros((height, width), dtype=np.int32)
    visible = np.flatnonzero(proj["visible"])
    # Depth order with ties by ascending index, comparing z as float32 like the reference keys.
    order = visible[np.lexsort((visible, proj["z"][visible].astype(np.float32)))]
    rect = proj["rect"]
    for ty in range(-(-height // TILE)):
        for tx in range(-(-width // TILE)):
            r = rect[order]
            in_tile = (r[:, 0] <= tx) & (tx < r[:, 2]) & (r[:, 1] <= ty) & (ty < r[:, 3])
            tile_list = order[in_tile]
            ys = np.arange(ty * TILE, min((ty + 1) * TILE, height))
            xs = np.arange(tx * TILE, min((tx + 1) * TILE, width))
            py, px = np.meshgrid(ys, xs, indexing="ij")
            t = np.ones(py.shape)
            color = np.zeros((*py.shape, 3))
            depth_acc = np.zeros(py.shape)
            best_w = np.zeros(py.shape)
            best = np.full(py.shape, -1)
            last = np.zeros(py.shape, dtype=np.int32)
            done = np.zeros(py.shape, dtype=bool)
            for position, g in enumerate(tile_list, start=1):
                if done.all():
                    break
                dx = proj["mean2d"][g, 0] - px
                dy = proj["mean2d"][g, 1] - py
                ca, cb, cc = proj["conic"][g]
                power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy
                a = np.minimum(ALPHA_MAX, scene.opacities[g] * np.exp(power))
                take = ~done & (power <= 0) & (a >= ALPHA_MIN)
                test_t = t * (1 - a)
                stop = take & (test_t < T_MIN)
                done |= stop
                take &= ~stop
                w = np.where(take, a * t, 0.0)
                color += w[..., None] * proj["color"][g]
                depth_acc += w * proj["z"][g]
                better = take & (w > best_w)
                best_w = np.where(better, w, best_w)
                best = np.where(better, g, best)
                last = np.where(take, position, last)
                t = np.where(take, test_t, t)
            sl = (slice(ys[0], ys[-1] + 1), slice(xs[0], xs[-1] + 1))
            rgb[sl] = color + t[..., None] * bg
            alpha[sl] = 1 - t
            with np.errstate(divide="ignore", invalid="ignore"):
                depth[sl] = np.where(1 - t > 0, depth_acc / (1 - t), 0.0)
            index[sl] = best
            index_depth[sl] = np.where(best >= 0, proj["z"][np.maximum(best, 0)], 0.0)
            max_weight[sl] = best_w
            n_contrib[sl] = last
    return {
        "rgb": rgb,
        "alpha": alpha,
        "depth": depth,
        "index": index,
        "index_depth": index_depth,
        "max_weight": max_weight,
        "n_contrib": n_contrib,
    }
