"""Segmentation (docs/deformation.md, "Segmentation"): the part's whole cross-section, not what lies
across a gap; small attached parts ride with the rod, large bodies stay; the rod file keeps it."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from sketchrodgs import Camera, SketchRodGSError, extract_rod, synthetic
from sketchrodgs.polyline import polyline_length
from sketchrodgs.rod import Rod
from sketchrodgs.rod_file import Extraction
from sketchrodgs.scene import GaussianScene
from sketchrodgs.segment import (
    DEFAULT_GROW,
    default_attach_size,
    default_attach_size_fewer,
    part_and_attached,
    segment_and_bind,
)
from sketchrodgs.skin import BoundRod, skin

R = 0.01
AXIS = np.stack([np.linspace(-0.45, 0.45, 91), np.full(91, 0.05), np.zeros(91)], axis=1)


def blobs(centres: np.ndarray, size: float = 0.002) -> dict[str, np.ndarray]:
    n = len(centres)
    return {
        "means": centres,
        "scales": np.full((n, 3), size),
        "quats": np.tile([1.0, 0, 0, 0], (n, 1)),
        "opacities": np.full(n, 0.8),
        "colors": np.full((n, 3), 0.5),
    }


def grid(low, high, step: float) -> np.ndarray:
    axes = [np.arange(lo, hi + 1e-9, step) for lo, hi in zip(low, high)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def with_extras(**extras: np.ndarray) -> tuple[GaussianScene, dict[str, slice]]:
    """The synthetic straight tube (R = 0.01, axis AXIS) plus the given extra point sets."""
    tube = synthetic.tube_scene([synthetic.straight], radius=R, clutter=0, seed=2).scene
    parts = [
        {
            "means": tube.means,
            "scales": tube.scales,
            "quats": tube.quats,
            "opacities": tube.opacities,
            "colors": tube.colors,
        }
    ]
    rows, start = {}, len(tube)
    for name, points in extras.items():
        parts.append(blobs(points))
        rows[name] = slice(start, start + len(points))
        start += len(points)
    merged = {k: np.concatenate([np.asarray(p[k], np.float64) for p in parts]) for k in parts[0]}
    scene = GaussianScene.from_colors(
        merged["means"], merged["scales"], merged["quats"], merged["opacities"], merged["colors"]
    )
    return scene, rows


def test_a_fin_on_the_part_goes_with_it_but_a_neighbour_across_a_gap_stays():
    # a fin along the tube from its surface out to 2.2 R (the part's cross-section is not round),
    # and a rail 2 R from the axis on the other side, separated from the surface by a 0.8 R gap
    fin = grid((-0.3, 0.05 + R, -0.001), (0.3, 0.05 + 2.2 * R, 0.001), 0.002)
    rail = grid((-0.3, 0.05 - 2.0 * R, -0.001), (0.3, 0.05 - 1.9 * R, 0.001), 0.002)
    scene, rows = with_extras(fin=fin, rail=rail)
    binding = segment_and_bind(AXIS, scene, R)
    bound = np.zeros(len(scene), bool)
    bound[binding.gaussian_ids] = True
    assert bound[rows["fin"]].mean() > 0.99
    assert not bound[rows["rail"]].any()
    assert bound[: rows["fin"].start].mean() > 0.95  # the tube itself
    assert not binding.attached[np.isin(binding.gaussian_ids, np.arange(len(scene))[rows["fin"]])].any()


def leaf_on_a_petiole(at_x: float) -> np.ndarray:
    """A petiole from the tube's surface up to 5 R, then a leaf blade 6 R across."""
    petiole = grid((at_x - 0.001, 0.05 + 0.8 * R, -0.001), (at_x + 0.001, 0.05 + 5 * R, 0.001), 0.0015)
    blade = grid((at_x - 3 * R, 0.05 + 5 * R, -0.001), (at_x + 3 * R, 0.05 + 8 * R, 0.001), 0.002)
    return np.concatenate([petiole, blade])


def test_a_small_attached_part_rides_rigidly_and_a_large_body_stays():
    leaf = leaf_on_a_petiole(0.1)
    # a body as long as the rod, joined to the tube's underside all along
    body = grid((-0.45, 0.05 - 12 * R, -0.001), (0.45, 0.05 - 0.9 * R, 0.001), 0.003)
    scene, rows = with_extras(leaf=leaf, body=body)
    binding = segment_and_bind(AXIS, scene, R)
    ids = np.arange(len(scene))
    is_leaf = np.isin(binding.gaussian_ids, ids[rows["leaf"]])
    assert is_leaf.sum() == len(leaf)  # all of it follows: the petiole's foot in the part, the rest attached
    beyond = binding.distance[is_leaf] > 2.6 * R
    assert binding.attached[is_leaf][beyond].all() and beyond.mean() > 0.9
    assert np.isin(ids[rows["body"]], binding.gaussian_ids).mean() < 0.2  # only its strip along the tube
    # the leaf keeps its shape (one rigid motion) when the rod bends
    rod = Rod(AXIS, radius=R)
    rest = rod.positions.copy()
    bend = np.stack([rest[:, 0], rest[:, 1] + 2.0 * rest[:, 0] ** 2, rest[:, 2]], axis=1)
    moved = skin(scene, BoundRod.from_binding(scene, binding, rod), _teleported(rod, bend))
    rigid = binding.gaussian_ids[is_leaf & binding.attached]
    leaf_rest, leaf_now = scene.means[rigid].astype(np.float64), moved.means[rigid].astype(np.float64)
    pairs = np.random.default_rng(0).integers(0, len(rigid), (500, 2))
    before = np.linalg.norm(leaf_rest[pairs[:, 0]] - leaf_rest[pairs[:, 1]], axis=1)
    after = np.linalg.norm(leaf_now[pairs[:, 0]] - leaf_now[pairs[:, 1]], axis=1)
    assert np.abs(after - before).max() < 1e-5
    assert np.linalg.norm(leaf_now - leaf_rest, axis=1).min() > 0.01  # and it did move


def _teleported(rod: Rod, positions: np.ndarray) -> Rod:
    rod.set_positions(positions)
    return rod


def leaf_of_height(at_x: float, height: float, side: float = 1.0, spacing: float = 0.002) -> np.ndarray:
    """A petiole from the tube's surface, then a blade 6 R across whose far edge lies `height` R
    from the axis, on the tube's `side` (+1 above, -1 below), its centres `spacing` apart."""
    y = lambda r: 0.05 + side * r * R  # noqa: E731
    stalk, top = sorted((y(0.8), y(height - 4))), sorted((y(height - 4), y(height)))
    petiole = grid((at_x - 0.001, stalk[0], -0.001), (at_x + 0.001, stalk[1], 0.001), 0.0015)
    blade = grid((at_x - 3 * R, top[0], -0.001), (at_x + 3 * R, top[1], 0.001), spacing)
    return np.concatenate([petiole, blade])


def test_a_short_strokes_leaves_ride_with_it_up_to_twelve_radii():
    # a stroke over 16 R of the tube: half its length is 8 R, but its leaves are as large as a
    # long stroke's (the bundled demo's stem of 20 R has a leaf reaching 10.3 R from its joint)
    short = AXIS[np.abs(AXIS[:, 0]) <= 0.08 + 1e-9]
    assert polyline_length(short) == pytest.approx(16 * R)
    assert default_attach_size(polyline_length(short), R) == pytest.approx(12 * R)
    # one leaf reaching 10.4 R from where it joins, one (below) 14.3 R
    scene, rows = with_extras(leaf=leaf_of_height(0.0, 10.0), large=leaf_of_height(0.0, 14.0, side=-1.0))
    binding = segment_and_bind(short, scene, R)
    ids = np.arange(len(scene))
    assert np.isin(ids[rows["leaf"]], binding.gaussian_ids).all()
    assert np.isin(ids[rows["large"]], binding.gaussian_ids).mean() < 0.2  # only its petiole's foot


def test_a_leaf_past_twenty_radii_rides_along_unless_it_holds_more_than_the_part():
    # a long stem's leaves reach 20-23 R from where they join; a pot under a main stem's base
    # reaches as far, but holds more Gaussians than the stem (docs/deformation.md, "Segmentation")
    length = polyline_length(AXIS)
    assert (default_attach_size(length, R), default_attach_size_fewer(length, R)) == pytest.approx((20 * R, 25 * R))
    leaf, dense = leaf_of_height(0.1, 22.0), leaf_of_height(-0.2, 23.0, side=-1.0, spacing=0.0005)
    scene, rows = with_extras(leaf=leaf, dense=dense)
    ids = np.arange(len(scene))
    binding = segment_and_bind(AXIS, scene, R)
    assert len(leaf) < (~binding.attached).sum() < len(dense)
    assert np.isin(ids[rows["leaf"]], binding.gaussian_ids).all()
    assert np.isin(ids[rows["leaf"]], binding.gaussian_ids[binding.attached]).mean() > 0.9
    assert np.isin(ids[rows["dense"]], binding.gaussian_ids).mean() < 0.05  # only its petiole's foot
    # a size given holds for every part
    given = segment_and_bind(AXIS, scene, R, attach_size=20 * R)
    assert np.isin(ids[rows["leaf"]], given.gaussian_ids).mean() < 0.2


def test_a_leafs_faint_haze_rides_with_it_but_an_opaque_sheet_as_close_stays():
    # a capture blurs a leaf with large faint Gaussians 1-2 R off its surface, linked to each other
    # and not to the leaf; left behind, they hung where the leaf had been, a faint copy of it. An
    # opaque sheet of small Gaussians as close on the other side is something the leaf touches.
    blade = lambda z: grid((0.1 - 3 * R, 0.05 + 5 * R, z), (0.1 + 3 * R, 0.05 + 8 * R, z), 0.0025)  # noqa: E731
    scene, rows = with_extras(leaf=leaf_on_a_petiole(0.1), haze=blade(0.009), sheet=blade(-0.009))
    opacities, scales = scene.opacities.copy(), scene.scales.copy()
    opacities[rows["haze"]], scales[rows["haze"]] = 0.2, 1.3 * R
    scene = replace(scene, opacities=opacities, scales=scales)
    binding = segment_and_bind(AXIS, scene, R)
    ids = np.arange(len(scene))
    attached = binding.gaussian_ids[binding.attached]
    assert np.isin(ids[rows["leaf"]], binding.gaussian_ids).all()
    assert np.isin(ids[rows["haze"]], attached).all()
    assert not np.isin(ids[rows["sheet"]], binding.gaussian_ids).any()
    # each haze Gaussian rides with the leaf: at the (segment, t) where the leaf joins
    haze = np.isin(binding.gaussian_ids, ids[rows["haze"]])
    leaf = np.isin(binding.gaussian_ids, ids[rows["leaf"]]) & binding.attached
    assert set(zip(binding.segment[haze], binding.t[haze])) <= set(zip(binding.segment[leaf], binding.t[leaf]))
    # faint but small (a speckle of the leaf's own size): not haze
    small = replace(scene, scales=np.where(np.isin(ids, ids[rows["haze"]])[:, None], 0.2 * R, scales))
    assert not np.isin(ids[rows["haze"]], segment_and_bind(AXIS, small, R).gaussian_ids).any()


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_the_haze_search_keeps_every_centre_within_reach_of_the_attached_ones():
    from scipy.spatial import cKDTree

    from sketchrodgs.segment import _in_cells_around

    rng = np.random.default_rng(5)
    attached = (rng.uniform(0, 1, (2000, 3)) * [1, 0.2, 0.2]).astype(np.float32)
    centres = rng.uniform(-0.2, 1.2, (20000, 3)).astype(np.float32)
    for reach in (0.01, 0.05, 0.3):
        kept = _in_cells_around(centres, attached, reach)
        within = cKDTree(attached).query(centres)[0] <= reach
        assert kept[within].all() and kept.sum() < 2 * within.sum() + 200
    # attached centres spread over 10^10 reaches: cells grow rather than keys overflow
    far = np.array([[0, 0, 0], [1e7, 1e7, 1e7]], np.float32)
    near_each = np.array([[5e-4, 0, 0], [5e6, 5e6, 5e6], [1e7, 1e7, 1e7 + 5e-4]], np.float32)
    assert _in_cells_around(near_each, far, 1e-3).tolist() == [True, False, True]


def test_attaching_can_be_turned_off_and_the_size_limit_holds():
    scene, rows = with_extras(leaf=leaf_on_a_petiole(0.1))
    leaf_rows = np.arange(len(scene))[rows["leaf"]]
    off = segment_and_bind(AXIS, scene, R, attach=False)
    assert not off.attached.any()
    assert np.isin(leaf_rows, off.gaussian_ids).mean() < 0.2  # only the petiole's foot, in the part
    small = segment_and_bind(AXIS, scene, R, attach_size=4 * R)  # the leaf reaches 8.5 R from its joint
    assert not np.isin(leaf_rows, small.gaussian_ids[small.attached]).any()


def test_a_piece_of_another_part_stays_with_it_but_a_whole_twig_and_a_leaf_ride_along():
    # Below the tube, a leg (1 R square, 30 R long) stands on it, its Gaussians thinning out 6 R
    # from the axis: a gap of 0.7 R, over the part's link (0.47 R here) but under two. Above, a
    # twig 8 R long that ends free, and a leaf whose far edge comes within 0.7 R of a large sheet.
    # (The stand's front foot carried the lower 40 px of the leg standing on it, which swung off
    # the rest when pulled: docs/deformation.md, "Segmentation", A piece of another part.)
    def column(x: float, y0: float, y1: float) -> np.ndarray:
        return grid((x - 0.005, 0.05 + y0 * R, -0.005), (x + 0.005, 0.05 + y1 * R, 0.005), 0.002)

    near_leg, far_leg = column(0.1, -6.0, -0.9), column(0.1, -30.0, -6.7)
    twig = column(-0.2, 0.9, 8.0)
    sheet = grid((0.25 - 3 * R, 0.05 + 10.7 * R, -0.001), (0.25 + 3 * R, 0.05 + 35 * R, 0.001), 0.002)
    scene, rows = with_extras(
        near_leg=near_leg, far_leg=far_leg, twig=twig, leaf=leaf_of_height(0.25, 10.0), sheet=sheet
    )
    ids = np.arange(len(scene))
    beyond_part = ids[rows["near_leg"]][near_leg[:, 1] < 0.05 - 3 * R]
    # the component the Rust step finds at the part's link: the leg's near piece is one
    length = polyline_length(AXIS)
    sizes = {"attach_size": default_attach_size(length, R), "attach_size_fewer": default_attach_size_fewer(length, R)}
    rust = part_and_attached(AXIS, scene, R, grow=DEFAULT_GROW, **sizes)
    assert np.isin(beyond_part, rust.gaussian_ids[rust.attached]).all()
    binding = segment_and_bind(AXIS, scene, R)
    assert not np.isin(beyond_part, binding.gaussian_ids).any()
    assert not np.isin(ids[rows["far_leg"]], binding.gaussian_ids).any()
    assert np.isin(ids[rows["twig"]], binding.gaussian_ids).all()
    assert np.isin(ids[rows["leaf"]], binding.gaussian_ids).all()
    assert not np.isin(ids[rows["sheet"]], binding.gaussian_ids).any()


def test_a_small_cluster_of_floaters_past_an_end_rides_along_but_not_a_long_rail_or_a_touching_body():
    # above the tube 1.9 R from the axis: a 0.9 R gap from its surface, more than a link
    def blob(x: float) -> np.ndarray:
        return grid((x - 0.3 * R, 0.05 + 1.9 * R, -0.3 * R), (x + 0.3 * R, 0.05 + 2.1 * R, 0.3 * R), 0.001)

    rail = grid((-0.44, 0.05 - 2.0 * R, -0.001), (-0.2, 0.05 - 1.9 * R, 0.001), 0.002)  # 24 R long
    # a blob near the other end resting on a body that reaches far above
    tower = grid((-0.3 * R + 0.43, 0.05 + 2.1 * R, -0.001), (0.3 * R + 0.43, 0.05 + 30 * R, 0.001), 0.002)
    scene, rows = with_extras(
        end=blob(0.445), middle=blob(0.0), rail=rail, touching=blob(0.43 - 0.6 * R) + [0, 0, 0.0], tower=tower
    )
    binding = segment_and_bind(AXIS, scene, R)
    ids = np.arange(len(scene))
    follows = {name: np.isin(ids[part], binding.gaussian_ids) for name, part in rows.items()}
    assert follows["end"].all()  # past the end: the strays ride along, attached
    assert binding.attached[np.isin(binding.gaussian_ids, ids[rows["end"]])].all()
    assert not follows["middle"].any()  # along the rod only the linked halo goes (the part's reach)
    assert not follows["rail"].any() and not follows["tower"].any()
    assert not follows["touching"].any()
    off = segment_and_bind(AXIS, scene, R, attach=False)
    assert not np.isin(ids[rows["end"]], off.gaussian_ids).any()


def test_a_part_touching_the_rod_near_its_end_from_the_side_is_not_attached():
    # a leaf joined at the rod's last 2 R, lying beside the rod: it belongs to what the end joins
    scene, rows = with_extras(leaf=leaf_on_a_petiole(0.44))
    binding = segment_and_bind(AXIS, scene, R)
    assert not np.isin(np.arange(len(scene))[rows["leaf"]], binding.gaussian_ids[binding.attached]).any()


def test_the_rod_file_keeps_which_gaussians_are_attached(tmp_path):
    scene, _ = with_extras(leaf=leaf_on_a_petiole(0.1))
    camera = Camera.look_at((0, 0, -1.5), (0, 0, 0), up=(0, -1, 0), width=960, height=540, fov_y_deg=40)
    uv, _ = camera.project(AXIS)
    extraction = extract_rod(scene, camera, uv, radius=R)
    assert extraction.binding.attached.sum() > 100
    extraction.save(tmp_path / "rod.json")
    again = Extraction.from_json(json.loads((tmp_path / "rod.json").read_text()), "rod.json", folder=tmp_path)
    np.testing.assert_array_equal(again.binding.attached, extraction.binding.attached)
    # a rod file from before attached parts (inline JSON bindings) reads as "nothing attached"
    data = extraction.to_json()
    del data["binding"]["attached"]
    assert not Extraction.from_json(data, "old.json").binding.attached.any()
    data["binding"]["attached"] = [1]
    with pytest.raises(Exception, match="binding.attached"):
        Extraction.from_json(data, "bad.json")


# The Rust segmentation decides as the NumPy implementation it replaced, to the bit.


def _same_binding(a, b) -> None:
    for field in ("gaussian_ids", "segment", "t", "offset", "distance", "attached"):
        x, y = getattr(a, field), getattr(b, field)
        assert x.dtype == y.dtype and x.shape == y.shape, field
        assert x.tobytes() == y.tobytes(), field


def _clutter_rope() -> tuple[np.ndarray, GaussianScene]:
    """A thin rope winding in depth, a pole across it and clutter around (the bench's, smaller)."""
    tubes = synthetic.tube_scene([synthetic.loop, synthetic.pole], radius=R, clutter=800, seed=3)
    return tubes.axes[0][::4], tubes.scene


@pytest.mark.parametrize(
    "case, options",
    [
        ("fin and rail", {}),
        ("leaf and body", {}),
        ("leaf and body", {"attach": False}),
        ("leaf and body", {"attach_size": 4 * R}),
        ("leaf and body", {"attach_size": 4 * R, "attach_size_fewer": 9 * R}),
        ("dense leaf", {"attach_size": 4 * R, "attach_size_fewer": 9 * R}),
        ("leaf near the end", {}),
        ("clutter rope", {}),
        ("clutter rope", {"grow": 1.5}),
    ],
)
def test_segmentation_matches_the_numpy_reference(case, options):
    from reference.segment_reference import segment_and_bind as reference

    if case == "fin and rail":
        fin = grid((-0.3, 0.05 + R, -0.001), (0.3, 0.05 + 2.2 * R, 0.001), 0.002)
        rail = grid((-0.3, 0.05 - 2.0 * R, -0.001), (0.3, 0.05 - 1.9 * R, 0.001), 0.002)
        (scene, _), axis = with_extras(fin=fin, rail=rail), AXIS
    elif case == "leaf and body":
        body = grid((-0.45, 0.05 - 12 * R, -0.001), (0.45, 0.05 - 0.9 * R, 0.001), 0.003)
        (scene, _), axis = with_extras(leaf=leaf_on_a_petiole(0.1), body=body), AXIS
    elif case == "dense leaf":  # more centres than the part
        dense = leaf_of_height(0.1, 8.0, spacing=0.0005)
        (scene, _), axis = with_extras(dense=dense, leaf=leaf_of_height(-0.1, 8.0, side=-1.0)), AXIS
    elif case == "leaf near the end":
        (scene, _), axis = with_extras(leaf=leaf_on_a_petiole(0.44)), AXIS
    else:
        axis, scene = _clutter_rope()
    # the Rust step the reference describes: the part and attached parts (strays come after it)
    size = options.get("attach_size", default_attach_size(polyline_length(axis), R))
    binding = part_and_attached(
        axis,
        scene,
        R,
        grow=options.get("grow", DEFAULT_GROW),
        attach_size=size if options.get("attach", True) else None,
        attach_size_fewer=options.get("attach_size_fewer"),
    )
    assert len(binding.gaussian_ids) > 100
    _same_binding(binding, reference(axis, scene.means, R, **options))


def test_segmentation_does_not_depend_on_the_thread_count():
    from conftest import outputs_per_thread_count

    code = (
        "import hashlib, numpy as np; from sketchrodgs import synthetic; "
        "from sketchrodgs.segment import segment_and_bind; "
        "t = synthetic.tube_scene([synthetic.loop, synthetic.pole], radius=0.01, clutter=800, seed=3); "
        "b = segment_and_bind(t.axes[0][::4], t.scene, 0.01); "
        "print(hashlib.sha256(b''.join(np.ascontiguousarray(getattr(b, f)).tobytes() for f in "
        "('gaussian_ids', 'segment', 't', 'offset', 'distance', 'attached'))).hexdigest())"
    )
    assert len(outputs_per_thread_count(code, (1, 2, 3))) == 1


def test_the_link_spacing_is_what_a_kd_tree_gives():
    # the continuations' and the strays' link came from scipy's k-d tree; the Rust scan that
    # replaced it gives the same spacing to the bit, so no binding moved
    from scipy.spatial import cKDTree

    from sketchrodgs import _core

    rng = np.random.default_rng(2)
    s = rng.uniform(0, 1, 3000)
    helix = np.c_[np.cos(6 * s), np.sin(6 * s), 3 * s] + rng.normal(scale=0.01, size=(3000, 3))
    for points in (rng.normal(size=(1234, 3)), helix, np.round(rng.normal(size=(800, 3)) * 3), rng.normal(size=(5, 3))):
        points = points.astype(np.float32)
        tree = cKDTree(points.astype(np.float64))
        expected = float(np.median(tree.query(tree.data[:: max(1, tree.n // 500)], k=5)[0][:, 4]))
        assert _core.median_neighbour_distance(points, 4, 500) == expected
    assert _core.median_neighbour_distance(np.zeros((4, 3), np.float32), 4, 500) is None
    with pytest.raises(ValueError, match="row 2 is not finite"):
        _core.median_neighbour_distance(
            np.where(np.arange(6)[:, None] == 2, np.nan, np.ones((6, 3), np.float32)), 4, 500
        )


def test_the_strays_clusters_are_what_scipys_components_give():
    # the strays' clusters came from scipy (every pair within the link, connected components, each
    # component's box); the Rust search that replaced it stops at a large body and gives the same
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    from sketchrodgs import _core

    rng = np.random.default_rng(5)
    # specks, small clumps and a dense slab, as around a pulled part's end
    points = np.concatenate(
        [
            rng.uniform(0, 1, (600, 3)),
            (rng.uniform(0, 1, (40, 1, 3)) + rng.normal(scale=0.01, size=(40, 8, 3))).reshape(-1, 3),
            rng.uniform([0, 0, 1.0], [1, 1, 1.05], (3000, 3)),
        ]
    ).astype(np.float32)
    link, size = 0.04, 0.1
    seeds = np.flatnonzero(rng.random(len(points)) < 0.3)
    pairs = cKDTree(points.astype(np.float64)).query_pairs(link, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(points),) * 2)
    clusters, label = connected_components(graph, directed=False)
    seeded = np.zeros(clusters, bool)
    seeded[label[seeds]] = True
    low, high = np.full((clusters, 3), np.inf), np.full((clusters, 3), -np.inf)
    np.minimum.at(low, label, points.astype(np.float64))
    np.maximum.at(high, label, points.astype(np.float64))
    expected = (seeded & (np.linalg.norm(high - low, axis=1) <= size))[label]
    small = _core.small_clusters(points, link, seeds.astype(np.int64), size)
    assert expected.any() and not expected.all()
    np.testing.assert_array_equal(small, expected)
    with pytest.raises(SketchRodGSError, match="seed 3920 is not one of the 3920 points"):
        _core.small_clusters(points, link, np.array([len(points)], np.int64), size)


def test_bad_input_is_a_clear_error():
    scene, _ = with_extras()
    for polyline, radius, match in (
        (AXIS[:1], R, "at least 2 vertices"),
        (np.where(np.arange(91)[:, None] == 5, np.nan, AXIS), R, "vertex 5 is not finite"),
        (AXIS, 0.0, "radius must be finite and > 0"),
        (AXIS, float("nan"), "radius must be finite"),
    ):
        with pytest.raises(ValueError, match=match):
            segment_and_bind(polyline, scene, radius)
    with pytest.raises(ValueError, match="grow must be finite"):
        segment_and_bind(AXIS, scene, R, grow=-1.0)
    with pytest.raises(ValueError, match="attach_size must be finite"):
        segment_and_bind(AXIS, scene, R, attach_size=float("inf"))


def test_what_continues_the_part_past_an_end_goes_with_it_unless_it_runs_on():
    # the stroke stopped short of both ends of the tube (it runs on to |x| = 0.5 with its caps): a
    # rod from x = -0.2 to 0.32 (L 0.52, so continuations up to 20 R); past its end the tube runs
    # on 18 R with a leaf at its tip, past its start 30 R (the rest of the plant)
    rod = AXIS[(AXIS[:, 0] >= -0.2 - 1e-9) & (AXIS[:, 0] <= 0.32 + 1e-9)]
    leaf = grid((0.45, 0.05 - 0.3 * R, -0.5 * R), (0.45 + 3 * R, 0.05 + 0.3 * R, 0.5 * R), 0.002)
    scene, rows = with_extras(leaf=leaf)
    binding = segment_and_bind(rod, scene, R)
    means = scene.means.astype(np.float64)
    attached = binding.gaussian_ids[binding.attached]
    tube_past_end = np.flatnonzero(means[: rows["leaf"].start, 0] > 0.32 + 3 * R)
    tube_past_start = np.flatnonzero(means[: rows["leaf"].start, 0] < -0.2 - 3 * R)
    leaf_rows = np.arange(len(scene))[rows["leaf"]]
    assert np.isin(tube_past_end, attached).all() and np.isin(leaf_rows, attached).all()
    assert not np.isin(tube_past_start, binding.gaussian_ids).any()
    # bound at the end itself: a clamped end holds them still, a free one carries them
    at_end = np.isin(binding.gaussian_ids, leaf_rows)
    assert (binding.segment[at_end] == len(rod) - 2).all() and (binding.t[at_end] == 1).all()
    # a size given bounds them too, and without attached parts nothing continues
    small = segment_and_bind(rod, scene, R, attach_size=4 * R)
    assert not np.isin(leaf_rows, small.gaussian_ids).any()
    assert not np.isin(leaf_rows, segment_and_bind(rod, scene, R, attach=False).gaussian_ids).any()
