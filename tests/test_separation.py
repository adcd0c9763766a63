"""Separation (docs/deformation.md, "Separation"): the part's shell is trimmed by the cut that
splits the fewest close pairs between what moves and what stays, a shell Gaussian left behind
counting a fifth of a pair, so a part leaves behind the piece of a crossing bar it touches, keeps
its own skin and a face joined to it by few pairs, a tie keeps a Gaussian with the part, and
nothing is cut where the rod does not move."""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

from sketchrodgs import synthetic
from sketchrodgs.scene import GaussianScene
from sketchrodgs.segment import Binding, segment_and_bind
from sketchrodgs.separation import PAIR_RADII, STRAND_SHARE, trim_shell

R = 0.01
AXIS = np.stack([np.linspace(-0.45, 0.45, 91), np.full(91, 0.05), np.zeros(91)], axis=1)


def split_pairs(means: np.ndarray, moving_rows: np.ndarray, radius: float) -> int:
    """Pairs closer than PAIR_RADII R with one Gaussian moving and the other not."""
    moves = np.zeros(len(means), bool)
    moves[moving_rows] = True
    pairs = cKDTree(means).query_pairs(PAIR_RADII * radius, output_type="ndarray")
    return int((moves[pairs[:, 0]] != moves[pairs[:, 1]]).sum())


def tube_with_crossing_bar(colour: tuple[float, float, float] | None = None) -> tuple[GaussianScene, np.ndarray]:
    """The synthetic straight tube (axis AXIS, R = 0.01) and a bar of radius R running across it
    along z, its surface touching the tube's, of the tube's colour (as a crossing branch is) or
    `colour`; the rows of the bar."""
    tube = synthetic.tube_scene([synthetic.straight], radius=R, clutter=0, seed=2).scene
    # the bar: a dense disk of centres per slice, its axis 2.1 R below the tube's
    ring = np.array([(u, v) for u in np.arange(-R, R + 1e-9, 0.2 * R) for v in np.arange(-R, R + 1e-9, 0.2 * R)])
    ring = ring[np.hypot(ring[:, 0], ring[:, 1]) <= R]
    z = np.arange(-0.3, 0.3 + 1e-9, 0.2 * R)  # longer than an attached part: it stays
    bar = np.array([(u, 0.05 - 2.1 * R + v, w) for w in z for u, v in ring])
    n = len(bar)
    scene = GaussianScene.from_colors(
        np.concatenate([tube.means, bar]),
        np.concatenate([tube.scales, np.full((n, 3), 0.002)]),
        np.concatenate([tube.quats, np.tile([1.0, 0, 0, 0], (n, 1))]),
        np.concatenate([tube.opacities, np.full(n, 0.8)]),
        np.concatenate([tube.colors, np.tile(np.median(tube.colors, axis=0) if colour is None else colour, (n, 1))]),
    )
    return scene, np.arange(len(tube), len(scene))


def test_the_part_leaves_the_piece_of_a_crossing_bar_and_keeps_its_own_skin():
    scene, bar = tube_with_crossing_bar()
    binding = segment_and_bind(AXIS, scene, R)
    took = np.intersect1d(binding.gaussian_ids, bar)
    assert len(took) > 50  # the shell reaches into the bar where it touches the tube
    trimmed = trim_shell(scene.means, binding, R)
    kept_bar = np.intersect1d(trimmed.gaussian_ids, bar)
    assert len(kept_bar) < 0.1 * len(took), (len(kept_bar), len(took))
    own = np.setdiff1d(binding.gaussian_ids, bar)
    assert np.isin(own, trimmed.gaussian_ids).mean() > 0.99  # the tube's own skin goes with it
    before = split_pairs(scene.means, binding.gaussian_ids, R)
    after = split_pairs(scene.means, trimmed.gaussian_ids, R)
    assert after < 0.5 * before, (after, before)
    # the rows kept keep their binding entries
    entry = {row: k for k, row in enumerate(binding.gaussian_ids.tolist())}
    rows = np.array([entry[row] for row in trimmed.gaussian_ids.tolist()])
    assert np.array_equal(binding.offset[rows], trimmed.offset)
    assert np.array_equal(binding.segment[rows], trimmed.segment)


def test_where_the_rod_does_not_move_nothing_is_cut_for_it():
    """A pair split where the rod's motion is eased to nothing (a clamped end inside what the part
    meets) cannot tear, so the cut leaves it: the bar's piece stays with the part there."""
    scene, bar = tube_with_crossing_bar()
    binding = segment_and_bind(AXIS, scene, R)
    took = np.intersect1d(binding.gaussian_ids, bar)
    moving = trim_shell(scene.means, binding, R, np.ones(len(binding.gaussian_ids)))
    assert np.array_equal(moving.gaussian_ids, trim_shell(scene.means, binding, R).gaussian_ids)
    # held still within 1.5 R of where the bar crosses (x = 0), moving fully beyond
    still = np.where(np.abs(scene.means[binding.gaussian_ids, 0]) < 1.5 * R, 0.0, 1.0)
    held = trim_shell(scene.means, binding, R, still)
    assert np.isin(took, held.gaussian_ids).all()
    assert np.intersect1d(moving.gaussian_ids, bar).size < 0.1 * took.size


def test_a_crossing_bar_of_another_colour_is_left_out_before_any_cut():
    """A grey bar across the orange tube is a surface the part lies on (another colour, and flat
    beside the axis): the segmentation leaves it out (docs/deformation.md, "Segmentation")."""
    scene, bar = tube_with_crossing_bar(colour=(0.5, 0.5, 0.5))
    binding = segment_and_bind(AXIS, scene, R)
    assert len(np.intersect1d(binding.gaussian_ids, bar)) == 0
    tube = np.setdiff1d(np.arange(len(scene)), bar)
    assert np.isin(tube, binding.gaussian_ids).mean() > 0.99


def test_a_face_joined_to_the_part_by_few_pairs_goes_with_it_though_it_touches_what_stays():
    """A flat bar's far face, joined to the near one by a thin bridge and lying against a wall (the
    guitar stand's leg against the body): cutting at the bridge splits fewer pairs than at the wall,
    but leaves the whole face behind, a ghost of the part."""
    grid = np.arange(-4 * R, 4 * R + 1e-9, 0.2 * R)
    across = np.arange(-0.4 * R, 0.4 * R + 1e-9, 0.2 * R)
    core = np.array([(x, 0.8 * R, z) for x in grid for z in across])
    bridge = np.array([(0.0, 1.0 * R, 0.0), (0.0, 1.2 * R, 0.0)])
    face = np.array([(x, y, z) for x in grid for y in (1.4 * R, 1.6 * R) for z in across])
    wall = np.array([(x, 1.8 * R, z) for x in np.arange(-0.4 * R, 0.4 * R + 1e-9, 0.2 * R) for z in across])
    means = np.concatenate([core, bridge, face, wall]).astype(np.float32)
    bound = np.arange(len(core) + len(bridge) + len(face))
    offset = means[bound] * np.array([0, 1, 1], np.float32)  # the axis is the x axis
    binding = Binding(
        bound,
        np.zeros(len(bound), np.int32),
        np.zeros(len(bound), np.float32),
        offset,
        np.linalg.norm(offset, axis=1).astype(np.float32),
        np.zeros(len(bound), bool),
    )
    face_rows = np.arange(len(core) + len(bridge), len(bound))
    without_face = np.arange(len(core) + len(bridge))
    # the bridge is the fewest pairs: cut there, the whole face would stay
    assert split_pairs(means, without_face, R) < split_pairs(means, bound, R)
    trimmed = trim_shell(means, binding, R)
    assert np.isin(face_rows, trimmed.gaussian_ids).all()


def split_cost(means: np.ndarray, moving_rows: np.ndarray, shell_rows: np.ndarray, radius: float) -> int:
    """What the cut weighs, in fifths of a pair: split pairs, and shell Gaussians left behind."""
    left = len(np.setdiff1d(shell_rows, moving_rows))
    return STRAND_SHARE * split_pairs(means, moving_rows, radius) + left


def test_the_cut_costs_the_least_and_keeps_all_it_can():
    """Against every choice of which shell Gaussians move, on small random clouds."""
    rng = np.random.default_rng(4)
    for _ in range(6):
        core = rng.uniform([-0.3 * R, -0.7 * R, -0.7 * R], [0.3 * R, 0.7 * R, 0.7 * R], (6, 3))
        shell = rng.uniform([-0.3 * R, 1.05 * R, -0.3 * R], [0.3 * R, 1.6 * R, 0.3 * R], (10, 3))
        static = rng.uniform([-0.3 * R, 1.4 * R, -0.3 * R], [0.3 * R, 2.0 * R, 0.3 * R], (8, 3))
        means = np.concatenate([core, shell, static]).astype(np.float32)
        bound = np.arange(16)
        # the axis is the x axis: each centre's offset is its (0, y, z)
        offset = means[bound] * np.array([0, 1, 1], np.float32)
        binding = Binding(
            bound,
            np.zeros(16, np.int32),
            np.zeros(16, np.float32),
            offset,
            np.linalg.norm(offset, axis=1).astype(np.float32),
            np.zeros(16, bool),
        )
        trimmed = trim_shell(means, binding, R)
        shell_rows = np.arange(6, 16)
        got = split_cost(means, trimmed.gaussian_ids, shell_rows, R)
        choices = []
        for mask in itertools.product([False, True], repeat=10):
            moving = np.concatenate([np.arange(6), 6 + np.flatnonzero(mask)])
            choices.append((split_cost(means, moving, shell_rows, R), set(moving.tolist())))
        best = min(count for count, _ in choices)
        assert got == best
        # of the choices that split the fewest, the kept set holds every one's moving Gaussians
        kept = set(trimmed.gaussian_ids.tolist())
        assert all(moving <= kept for count, moving in choices if count == best)


def test_nothing_touching_trims_nothing():
    scene = synthetic.tube_scene([synthetic.straight], radius=R, clutter=0, seed=2).scene
    binding = segment_and_bind(AXIS, scene, R)
    trimmed = trim_shell(scene.means, binding, R)
    assert np.array_equal(trimmed.gaussian_ids, binding.gaussian_ids)
