"""The extension's worker pool: its size is configurable, results do not depend on it, and a
forked child can still run parallel work (rayon deadlocks there unless the pool is rebuilt)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import outputs_per_thread_count
from sketchrodgs import _core

SCRIPT = """
import numpy as np, sys
from sketchrodgs import _core
rng = np.random.default_rng(0)
line = np.cumsum(rng.normal(size=(300, 3)), axis=0).astype(np.float32)
points = (line[rng.integers(0, 300, 20000)] + rng.normal(size=(20000, 3))).astype(np.float32)
segment, t, distance = _core.nearest_on_polyline(line, points, 1.5)
print(_core.num_threads(), segment.sum(), float(t.sum()), float(distance[np.isfinite(distance)].sum()))
"""


def run_with_threads(threads: str) -> list[str]:
    env = dict(os.environ, SKETCHRODGS_NUM_THREADS=threads)
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=120, check=True
    )
    return out.stdout.split()


def test_results_do_not_depend_on_the_thread_count():
    one, two = run_with_threads("1"), run_with_threads("2")
    assert one[0] == "1" and two[0] == "2"
    assert one[1:] == two[1:]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork on this platform")
def test_a_forked_child_runs_parallel_work():
    line = np.array([[0, 0, 0], [1, 0, 0]], np.float32)
    points = np.random.default_rng(1).normal(size=(50000, 3)).astype(np.float32)
    _core.nearest_on_polyline(line, points, 0.5)  # the parent's pool is running
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: must not hang on the parent's (missing) worker threads
        segment, _, _ = _core.nearest_on_polyline(line, points, 0.5)
        os.write(write, str(int((segment >= 0).sum())).encode())
        os._exit(0)
    os.close(write)
    _, status = os.waitpid(pid, 0)
    child = os.read(read, 64).decode()
    expected = int((_core.nearest_on_polyline(line, points, 0.5)[0] >= 0).sum())
    assert status == 0 and child == str(expected)


EXTRACT = """
import hashlib, json, numpy as np
from sketchrodgs import Camera, extract_rod, load_scene
from sketchrodgs.data import sample
case = json.load(open("tests/data/real_cases/cases.json"))["cases"][1]  # a plant side stem
view = case["views"][0]
ex = extract_rod(load_scene(sample("plant")), Camera.from_dict(view["camera"]), np.asarray(view["stroke"]))
digest = hashlib.sha256()
for array in (ex.polyline, ex.gaussian_ids, ex.binding.offset, *ex.pixel_path):
    digest.update(np.ascontiguousarray(array).tobytes())
print(ex.radius, digest.hexdigest())
"""


def test_extraction_does_not_depend_on_the_thread_count():
    """The path search measures widths and surfaces in parallel: the rod is the same bit for bit."""
    assert len(outputs_per_thread_count(EXTRACT, (1, 2, 3))) == 1
