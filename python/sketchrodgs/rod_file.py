"""The rod file: what `extract_rod` finds (`Extraction`), and how it is written and read back,
JSON with its bindings in a binary .npz beside it (docs/rod_file.md).
"""

from __future__ import annotations

import json
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from . import polyline as pl
from . import segment as sg
from .atomic import atomic_open, atomic_write_text
from .camera import Camera
from .errors import SketchRodGSError
from .jsonfile import read_json
from .scene_identity import SceneIdentity


@dataclass(frozen=True, eq=False)
class Extraction:
    """What `extract_rod` found.

    Attributes:
        polyline: (M, 3) float32 rest polyline of the object's axis, resampled uniformly.
        radius: R used (given, or estimated from the image).
        edge_length: target spacing of the polyline vertices.
        pixel_path: list of (P_i, 2) int arrays, the (col, row) pixels of each path piece.
        path_gaussian_ids: (L,) int64 Gaussians along the pixel path, in order (pieces joined).
        gaussian_ids: (G,) int64 the Gaussians that follow the rod (the part and its attached
            parts; docs/deformation.md), rows of the input scene.
        binding: where each sits on the rest polyline.
        coverage: fraction of the stroke within 10 px of the path.
        radius_estimated: whether `radius` was estimated from the image (not given).
        pieces_reached_goal: whether each piece reached the stroke's end (False: lost at a gap).
        camera: the camera the stroke was drawn in.
        stroke: (S, 2) float32 stroke in pixel coordinates.
        timings: seconds per stage.
        rendered_tiles: the share of the image's 16x16 tiles the sketch rendered (None where the
            render was given).
        scene_identity: the scene the rod was extracted from (None for rod files written before
            it was recorded); `Animation` refuses another scene.
    """

    polyline: np.ndarray
    radius: float
    edge_length: float
    pixel_path: list[np.ndarray]
    path_gaussian_ids: np.ndarray
    gaussian_ids: np.ndarray
    binding: sg.Binding
    coverage: float
    pieces_reached_goal: list[bool]
    camera: Camera
    stroke: np.ndarray
    radius_estimated: bool = False
    timings: dict[str, float] = field(default_factory=dict)
    rendered_tiles: float | None = None
    scene_identity: SceneIdentity | None = None

    def to_json(self, material: dict[str, Any] | None = None) -> dict[str, Any]:
        """The rod JSON (docs/rod_file.md) (polyline, radius, edge_length, camera, stroke, gaussian_ids, ...)."""
        scene = {"scene": self.scene_identity.to_dict()} if self.scene_identity is not None else {}
        return {
            **scene,
            "polyline": self.polyline.tolist(),
            "radius": self.radius,
            "edge_length": self.edge_length,
            "camera": self.camera.to_dict(),
            "stroke": self.stroke.tolist(),
            "gaussian_ids": self.gaussian_ids.tolist(),
            "binding": {
                "segment": self.binding.segment.tolist(),
                "t": self.binding.t.tolist(),
                "offset": self.binding.offset.tolist(),
                "attached": self.binding.attached.astype(int).tolist(),
            },
            "coverage": self.coverage,
            "material": material or {},
        }

    def save(self, path: str | os.PathLike[str], material: dict[str, Any] | None = None) -> None:
        """Write the rod file: `path` (JSON) and, beside it, its bindings in binary
        (`bindings_path(path)`, docs/rod_file.md). Each is written atomically, bindings first."""
        path = Path(path)
        npz = bindings_path(path)
        with atomic_open(npz) as stream:
            np.savez_compressed(stream, **_binding_arrays(self.binding))
        data = self.to_json(material)
        for key in ("gaussian_ids", "binding"):
            del data[key]
        data["bindings"] = {"file": npz.name, "count": len(self.gaussian_ids), "format": BINDINGS_FORMAT}
        atomic_write_text(path, json.dumps(data) + "\n")

    @classmethod
    def from_json(
        cls, data: dict[str, Any], source: str = "rod", folder: str | os.PathLike[str] | None = None
    ) -> Extraction:
        """Rebuild from rod JSON (`to_json`, or a saved rod file whose binary bindings lie in
        `folder`); the pixel path is not stored and comes back empty."""
        if not isinstance(data, dict):
            raise SketchRodGSError(f"{source}: expected a JSON object")
        if "bindings" in data:
            data = {**data, **_read_bindings(data["bindings"], Path(folder or "."), source)}
        missing = [k for k in ("polyline", "radius", "camera", "gaussian_ids", "binding") if k not in data]
        if missing:
            raise SketchRodGSError(f"{source}: missing field(s) {', '.join(missing)}")
        polyline = _array(data["polyline"], np.float32, (None, 3), f"{source}: polyline")
        if len(polyline) < 2:
            raise SketchRodGSError(f"{source}: polyline: needs at least 2 vertices, got {len(polyline)}")
        radius = data["radius"]
        if not isinstance(radius, (int, float)) or not np.isfinite(radius) or radius <= 0:
            raise SketchRodGSError(f"{source}: radius: must be a number > 0, got {radius!r}")
        ids = _array(data["gaussian_ids"], np.int64, (None,), f"{source}: gaussian_ids")
        sg.check_rows(ids, None, f"{source}: gaussian_ids")
        binding = data["binding"] if isinstance(data["binding"], dict) else {}
        g = len(ids)
        segment = _array(binding.get("segment"), np.int32, (g,), f"{source}: binding.segment")
        t = _array(binding.get("t"), np.float32, (g,), f"{source}: binding.t")
        offset = _array(binding.get("offset"), np.float32, (g, 3), f"{source}: binding.offset")
        if g and (segment.min() < 0 or segment.max() >= len(polyline) - 1):
            raise SketchRodGSError(f"{source}: binding.segment: values must be in 0..{len(polyline) - 2}")
        attached = _array(binding.get("attached", np.zeros(g)), np.int64, (g,), f"{source}: binding.attached") != 0
        distance = np.linalg.norm(offset, axis=1).astype(np.float32)
        return cls(
            polyline=polyline,
            radius=float(radius),
            edge_length=float(data.get("edge_length", pl.polyline_length(polyline) / (len(polyline) - 1))),
            pixel_path=[],
            path_gaussian_ids=np.empty(0, np.int64),
            gaussian_ids=ids,
            binding=sg.Binding(ids, segment, t, offset, distance, attached),
            coverage=float(data.get("coverage", float("nan"))),
            pieces_reached_goal=[],
            camera=Camera.from_dict(data["camera"], f"{source}: camera"),
            stroke=_array(data.get("stroke", np.empty((0, 2))), np.float32, (None, 2), f"{source}: stroke"),
            scene_identity=SceneIdentity.from_dict(data["scene"], source) if "scene" in data else None,
        )


def load_rod(path: str | os.PathLike[str]) -> tuple[Extraction, dict[str, Any]]:
    """Read a rod JSON file: the extraction and its stored material (may be empty)."""
    data = read_json(path)
    extraction = Extraction.from_json(data, str(path), folder=Path(path).parent)
    material = data.get("material") or {}
    if not isinstance(material, dict):
        raise SketchRodGSError(f"{path}: material: expected an object")
    return extraction, material


BINDINGS_FORMAT = 1


def bindings_path(rod_path: str | os.PathLike[str]) -> Path:
    """Where a rod file's binary bindings go: `rod.json` -> `rod.bindings.npz`."""
    rod_path = Path(rod_path)
    return rod_path.with_name(rod_path.stem + ".bindings.npz")


def _binding_arrays(binding: sg.Binding) -> dict[str, Any]:
    """The arrays of the .npz (docs/rod_file.md): ids as deltas (sorted ids compress to almost
    nothing), the rest as stored in memory."""
    ids = binding.gaussian_ids.astype(np.int64)
    return {
        "gaussian_ids_delta": np.diff(ids, prepend=0),
        "segment": binding.segment.astype(np.int32),
        "t": binding.t.astype(np.float32),
        "offset": binding.offset.astype(np.float32),
        "attached": binding.attached.astype(np.uint8),
    }


def _read_bindings(spec: Any, folder: Path, source: str) -> dict[str, Any]:
    """The `gaussian_ids` and `binding` fields from the .npz a rod file names."""
    if not isinstance(spec, dict) or not isinstance(spec.get("file"), str) or not isinstance(spec.get("count"), int):
        raise SketchRodGSError(f'{source}: bindings: expected {{"file": NAME, "count": N}}')
    if spec.get("format", BINDINGS_FORMAT) != BINDINGS_FORMAT:
        raise SketchRodGSError(f"{source}: bindings: format {spec.get('format')!r} is not {BINDINGS_FORMAT}")
    name = spec["file"]
    if Path(name).name != name:
        raise SketchRodGSError(f"{source}: bindings.file: must be a file name beside the rod file, got {name!r}")
    path = folder / name
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in npz.files}
    except FileNotFoundError:
        raise SketchRodGSError(f"{path}: the rod file's bindings are missing (it names this file)") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise SketchRodGSError(f"{path}: not a readable .npz ({err})") from None
    wanted = ("gaussian_ids_delta", "segment", "t", "offset", "attached")
    missing = [k for k in wanted if k not in arrays]
    if missing:
        raise SketchRodGSError(f"{path}: missing array(s) {', '.join(missing)}")
    delta = arrays["gaussian_ids_delta"]
    if delta.dtype.kind not in "iu" or delta.ndim != 1 or len(delta) != spec["count"]:
        raise SketchRodGSError(
            f"{path}: gaussian_ids_delta: expected {spec['count']} integers, got {delta.dtype} {delta.shape}"
        )
    return {
        "gaussian_ids": np.cumsum(delta.astype(np.int64)),
        "binding": {
            "segment": arrays["segment"],
            "t": arrays["t"],
            "offset": arrays["offset"],
            "attached": arrays["attached"],
        },
    }


def _array(value: Any, dtype: type, shape: tuple[int | None, ...], name: str) -> np.ndarray:
    """`value` as a C-contiguous array of `shape` (None: any length) with finite entries."""
    try:
        array: np.ndarray = np.ascontiguousarray(value, dtype=dtype)
    except (TypeError, ValueError):
        raise SketchRodGSError(f"{name}: expected an array of numbers") from None
    if array.ndim != len(shape) or any(want is not None and got != want for got, want in zip(array.shape, shape)):
        raise SketchRodGSError(
            f"{name}: expected shape {tuple('N' if s is None else s for s in shape)}, got {array.shape}"
        )
    if array.dtype.kind == "f" and not np.isfinite(array).all():
        raise SketchRodGSError(f"{name}: contains NaN or infinite values")
    return array
