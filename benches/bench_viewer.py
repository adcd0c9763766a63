"""Viewer frames: the Python side of one simulation frame (simulate with contact, skin, push to
viser) and what it sends to the browser, with ~5k Gaussians on the pulled rod, in scenes of 100k
and 1M Gaussians, for both ways of moving a rod's Gaussians ("exact": the rod's splat buffer
re-sent each frame; "segments": one pose per rod segment); and what adding a rod sends (the scene
is sent once, in chunks; a rod re-sends only the chunks it took Gaussians from) and costs, its
contact field included.

The scene is the bundled ring plus filler Gaussians behind it. A raw websocket client (a thread
of this process) stands in for the browser and counts the bytes the server sends. Frames are
paced at 60 Hz as in the viewer (viser drops a node's superseded updates, so unpaced frames would
under-count bytes). "process CPU" is the CPU time of this whole process per frame: our thread,
viser's event loop serialising and sending, the Rust skinning threads and the counting client.
"""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
import viser
from websockets.sync.client import connect

from _table import print_table
from sketchrodgs import Camera, data, extract_rod, load_scene
from sketchrodgs.scene import GaussianScene
from sketchrodgs.viewer.contact import SceneContact
from sketchrodgs.viewer.display import SceneDisplay
from sketchrodgs.viewer.rods import RodSet

FPS = 60.0
FRAMES = 120
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
# What the viser 1.1 client does on its main thread when any splat node's buffer changes
# (client/src/Splatting/GaussianSplats.tsx: mergeGaussianGroups, then the texture staging copy and
# the post to the sorting worker), replayed on synthetic buffers; GPU upload and re-sort excluded.
MERGE_REPLICA_JS = r"""
async ([n, rodN, reps]) => {
  function mergeGaussianGroups(groupBufferFromName) {
    let totalBufferLength = 0;
    for (const buffer of Object.values(groupBufferFromName)) totalBufferLength += buffer.length;
    const numGaussians = totalBufferLength / 8;
    const gaussianBuffer = new Uint32Array(totalBufferLength);
    const groupIndices = new Uint32Array(numGaussians);
    let offset = 0;
    for (const [groupIndex, groupBuffer] of Object.values(groupBufferFromName).entries()) {
      groupIndices.fill(groupIndex, offset / 8, (offset + groupBuffer.length) / 8);
      gaussianBuffer.set(groupBuffer, offset);
      for (let i = 0; i < groupBuffer.length; i += 8) gaussianBuffer[offset + i + 3] = groupIndex;
      offset += groupBuffer.length;
    }
    return { numGaussians, gaussianBuffer, numGroups: Object.keys(groupBufferFromName).length, groupIndices };
  }
  const worker = new Worker(URL.createObjectURL(new Blob(
    ["onmessage = e => postMessage(e.data.updateBuffer.length)"], { type: "text/javascript" })));
  const groups = { scene: new Uint32Array((n - rodN) * 8).fill(7), rod: new Uint32Array(rodN * 8) };
  const texture = new Uint32Array(n * 8);
  const times = [];
  for (let k = 0; k < reps; k++) {
    groups.rod = new Uint32Array(rodN * 8).fill(k);
    const t0 = performance.now();
    const merged = mergeGaussianGroups(groups);
    texture.fill(0); texture.set(merged.gaussianBuffer);
    const answered = new Promise(r => { worker.onmessage = r; });
    worker.postMessage({ updateBuffer: merged.gaussianBuffer, updateGroupIndices: merged.groupIndices, updateNumGroups: merged.numGroups });
    times.push(performance.now() - t0);
    await answered;
  }
  times.sort((a, b) => a - b);
  return times[Math.floor(times.length / 2)];
}
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def with_filler(scene: GaussianScene, total: int, seed: int = 0) -> GaussianScene:
    """`scene` plus random Gaussians behind it, `total` in all."""
    rng = np.random.default_rng(seed)
    n = total - len(scene)
    means = np.c_[rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), rng.uniform(0.5, 3, n)].astype(np.float32)
    quats = rng.normal(size=(n, 4)).astype(np.float32)
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    filler = GaussianScene.from_colors(
        means,
        rng.uniform(0.002, 0.02, (n, 3)).astype(np.float32),
        quats,
        rng.uniform(0.2, 1, n).astype(np.float32),
        rng.uniform(0, 1, (n, 3)),
    )
    return GaussianScene(
        *(
            np.concatenate([getattr(scene, k), getattr(filler, k)])
            for k in ("means", "scales", "quats", "opacities", "sh")
        )
    )


class WireCounter:
    """A websocket client of the viser server that only counts the bytes it receives."""

    def __init__(self, port: int) -> None:
        self.bytes = 0
        self.messages = 0
        self.last = time.perf_counter()
        self._ws = connect(f"ws://127.0.0.1:{port}", subprotocols=[f"viser-v{viser.__version__}"], max_size=None)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        try:
            for message in self._ws:
                self.bytes += len(message)
                self.messages += 1
                self.last = time.perf_counter()
        except Exception:  # closed at the end of the benchmark
            return

    def settle(self, quiet: float = 1.0, timeout: float = 120.0) -> None:
        """Wait until nothing arrived for `quiet` seconds (counting from now at the earliest)."""
        start = time.perf_counter()
        deadline = start + timeout
        while time.perf_counter() < deadline and time.perf_counter() - max(self.last, start) < quiet:
            time.sleep(0.05)

    def close(self) -> None:
        self._ws.close()


def ring_extraction(ring: GaussianScene):
    camera = Camera.look_at((0, 0, -1.4), (0, 0, 0), up=(0, 1, 0), width=960, height=720, fov_y_deg=60)
    theta = np.radians(np.linspace(10, 170, 30))
    uv, _ = camera.project(np.stack([0.455 * np.cos(theta), 0.136 * np.sin(theta), 0 * theta], axis=1))
    return extract_rod(ring, camera, uv)


SPLAT_BYTES = 32  # viser's buffer: 8 uint32 a Gaussian


def measure(scene: GaussianScene, extraction, update: str, tint: bool = True) -> dict[str, float]:
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    wire = WireCounter(server.get_port())
    try:
        rods = RodSet(scene, skin_each_frame=update == "exact")
        contact = SceneContact(rods)
        display = SceneDisplay(server, scene, update, lambda rod_id, vertex, event: None)
        display.dots_wanted = tint  # the bound-Gaussian tint moves with the rod (a tab shows it)
        with rods.lock:
            display.sync(rods)  # the scene, sent once
        wire.settle()
        # adding a rod as the app does: the rod set, the nodes that changed, the contact field
        # (built on its own thread: the add itself does not wait for it)
        clock, sent = time.perf_counter(), wire.bytes
        with rods.lock:
            entry = rods.add(extraction)
            display.sync(rods)
            built = contact.rebuild()
        add_seconds = time.perf_counter() - clock
        built.result()
        field_seconds = time.perf_counter() - clock
        wire.settle()
        add_bytes = wire.bytes - sent

        vertex = entry.rod.num_vertices // 2
        start = np.asarray(entry.rod.positions[vertex])
        rods.grab(entry.id, vertex, start)
        stages: dict[str, list[float]] = {"simulate": [], "skin": [], "push": []}
        sent, cpu = wire.bytes, time.process_time()
        deadline = time.perf_counter()
        for k in range(FRAMES):
            rods.move_grab(entry.id, start + [0.0, 0.15 * np.sin(np.pi * k / FRAMES), 0.0])
            with rods.lock:
                timings = rods.step(1 / FPS) or {}
                timings.update(display.push(rods))
            for stage in stages:
                stages[stage].append(timings[stage])
            deadline += 1 / FPS
            time.sleep(max(0.0, deadline - time.perf_counter()))
        server.flush()
        wire.settle(quiet=0.5)
        cpu = time.process_time() - cpu
        contact.close()
        return {
            "bound": len(entry.gaussian_ids),
            "segments": entry.rod.num_vertices - 1,
            **{k: 1e3 * float(np.mean(v)) for k, v in stages.items()},
            "cpu": 1e3 * cpu / FRAMES,
            "bytes": (wire.bytes - sent) / FRAMES,
            "add_s": add_seconds,
            "field_s": field_seconds,
            "add_bytes": add_bytes,
            "rod_bytes": SPLAT_BYTES * len(entry.gaussian_ids),
            "field": rods.has_scene_field,
        }
    finally:
        wire.close()
        server.stop()


def browser_merge_ms(totals: list[int], rod: int) -> list[float] | None:
    """Median main-thread ms per rod-buffer update in headless Chromium, or None without Chromium."""
    import os

    if not os.path.exists(CHROMIUM):
        return None
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_FLAGS)
        try:
            page = browser.new_page()
            page.set_content("<html><body></body></html>")
            return [float(page.evaluate(MERGE_REPLICA_JS, [total, rod, 15])) for total in totals]
        finally:
            browser.close()


def main() -> None:
    ring = load_scene(data.sample("ring"))
    extraction = ring_extraction(ring)
    rows, adds = [], []
    for total in (100_000, 1_000_000):
        scene = with_filler(ring, total)
        for update, tint in (("exact", True), ("segments", True), ("segments", False)):
            m = measure(scene, extraction, update, tint)
            sim_skin_push = m["simulate"] + m["skin"] + m["push"]
            rows.append(
                [
                    f"{total:,}",
                    update,
                    "on" if tint else "off",
                    f"{m['bound']:,}",
                    f"{m['simulate']:.2f}",
                    f"{m['skin']:.2f}",
                    f"{m['push']:.2f}",
                    f"{sim_skin_push:.2f}",
                    f"{m['cpu']:.2f}",
                    f"{m['bytes'] / 1e3:.1f}",
                ]
            )
            if tint:  # what an add sends does not depend on it
                adds.append(
                    [
                        f"{total:,}",
                        update,
                        f"{m['rod_bytes'] / 1e6:.2f}",
                        f"{m['add_bytes'] / 1e6:.2f}",
                        f"{m['add_bytes'] / m['rod_bytes']:.2f}",
                        f"{1e3 * m['add_s']:.0f}",
                        f"{1e3 * m['field_s']:.0f}" + ("" if m["field"] else " (none)"),
                    ]
                )
    totals = [10_000, 100_000, 1_000_000]
    merge = browser_merge_ms(totals, 5_000)
    if merge is None:
        print("\n(no Chromium at /usr/bin/chromium: browser-side merge not measured)")
    else:
        print_table(
            "browser main thread per 'exact' rod update (viser 1.1 merge/copy/post replica, headless "
            "Chromium, GPU upload and re-sort excluded)",
            ["scene Gaussians", "ms per update", "updates/s it allows"],
            [[f"{t:,}", f"{ms:.1f}", f"{1e3 / ms:.0f}"] for t, ms in zip(totals, merge)],
        )
    print_table(
        f"viewer frame, Python side ({FRAMES} frames at {FPS:.0f} Hz, one rod pulled)",
        [
            "scene Gaussians",
            "rod update",
            "bound tint",
            "rod Gaussians",
            "simulate ms",
            "skin ms",
            "push ms",
            "sim+skin+push ms",
            "process CPU ms/frame",
            "sent kB/frame",
        ],
        rows,
    )
    print_table(
        "adding a rod: bytes sent to a browser (the chunks it took Gaussians from, its own nodes, the "
        "overlays) against its own Gaussians' splat bytes (target <= 2x), and time",
        ["scene Gaussians", "rod update", "rod's splats MB", "sent MB", "sent / rod's", "add ms", "contact field ms"],
        adds,
    )


if __name__ == "__main__":
    main()
