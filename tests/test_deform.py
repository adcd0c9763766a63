"""How cleanly pulled objects deform (docs/deformation.md): the needle, tear and left-behind
fractions measure what they say, real pulls of the guitar neck, a tree branch and a plant stem meet the targets (or
are marked where they do not yet), and our skinning matches the exact bend of a tube into an arc."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sketchrodgs import Camera, extract_rod
from sketchrodgs import deform_metrics as dm
from sketchrodgs.polyline import nearest_on_polyline
from sketchrodgs.realcases import load_cases
from sketchrodgs.realpulls import PULLS, pull_case
from sketchrodgs.scene import GaussianScene

CASES = Path(__file__).parent / "data" / "real_cases" / "cases.json"
R = 0.01
AXIS = np.stack([np.linspace(0, 1, 101), np.zeros(101), np.zeros(101)], axis=1)


def scene_of(means, scales, quats=None) -> GaussianScene:
    n = len(means)
    quats = np.tile([1.0, 0, 0, 0], (n, 1)) if quats is None else quats
    return GaussianScene.from_colors(
        np.asarray(means, float), np.asarray(scales, float), quats, np.full(n, 0.5), np.full((n, 3), 0.5)
    )


def test_a_needle_sticking_out_of_a_bend_counts_and_a_rigid_move_does_not():
    # two Gaussians on the axis, 4 R long along it; the axis bends up by 90 degrees at x = 0.5
    rest = scene_of([[0.5, 0, 0], [0.2, 0, 0]], [[4 * R, 0.1 * R, 0.1 * R]] * 2)
    bent_axis = np.concatenate([AXIS[:51], np.stack([np.full(50, 0.5), AXIS[51:, 0] - 0.5, np.zeros(50)], axis=1)])
    # the first keeps pointing along x at the corner (its tip now 4 R off the new axis), and moves a bit
    stuck = scene_of([[0.5, 0.001, 0], [0.2, 0, 0]], [[4 * R, 0.1 * R, 0.1 * R]] * 2)
    assert dm.needle_fraction(rest, stuck, [AXIS], [bent_axis], R) == 1.0  # only the moved one counts
    # everything moved rigidly with the axis: no needle
    shift = np.array([0.0, 0.3, 0.0])
    moved = scene_of(rest.means + shift, rest.scales)
    assert dm.needle_fraction(rest, moved, [AXIS], [AXIS + shift], R) == 0.0
    # rows left out are not counted
    assert dm.needle_fraction(rest, stuck, [AXIS], [bent_axis], R, rows=np.array([1])) == 0.0


def test_a_flat_disk_whose_two_long_axes_trade_places_is_no_needle():
    # a disk beside the axis, its long axes along the rod (x) and away from it (y), equal to 0.1 %
    rest = scene_of([[0.5, 1.5 * R, 0]], [[2 * R, 0.999 * 2 * R, 0.2 * R]])
    # a 0.2 % stretch makes y the longer one, and the disk moves 0.1 R along the rod: nothing sticks out
    moved = scene_of([[0.5 + 0.1 * R, 1.5 * R, 0]], [[0.999 * 2 * R, 2 * R, 0.2 * R]])
    assert dm.needle_fraction(rest, moved, [AXIS], [AXIS], R) == 0.0


def test_neighbours_moving_apart_tear():
    rest = scene_of([[0.5, 0, 0], [0.5 + 0.1 * R, 0, 0], [0.9, 0, 0]], [[0.1 * R] * 3] * 3)
    together = scene_of(rest.means + [0, 2 * R, 0], rest.scales)
    assert dm.tear_fraction(rest, together, R) == 0.0
    apart = scene_of(rest.means + [[0, 2 * R, 0], [0, 0, 0], [0, 0, 0]], rest.scales)
    assert dm.tear_fraction(rest, apart, R) == 1.0  # the one close pair, one of them moved 2 R
    assert dm.tear_fraction(rest, rest, R) == 0.0


def test_what_stays_where_the_part_moved_away_is_left_behind():
    along = np.linspace(0.1, 0.9, 9)
    rest = scene_of(np.stack([along, np.full(9, 0.5 * R), np.zeros(9)], axis=1), [[0.1 * R] * 3] * 9)
    # the middle of the axis lifted by up to 4 R, its ends where they were
    lift = 4 * R * np.sin(np.pi * AXIS[:, 0])[:, None] * [0, 0, 1]
    followed = scene_of(rest.means + 4 * R * np.sin(np.pi * along)[:, None] * [0, 0, 1], rest.scales)
    assert dm.left_behind_fraction(rest, followed, AXIS, AXIS + lift, R) == 0.0
    # the one in the middle stays: of the 7 where the axis moved over 2 R (x 0.2..0.8), one is left
    one_left = followed.means.copy()
    one_left[4] = rest.means[4]
    left = dm.left_behind_fraction(rest, scene_of(one_left, rest.scales), AXIS, AXIS + lift, R)
    assert left == pytest.approx(1 / 7)
    # nothing moved more than 2 R: nothing can be left behind
    assert dm.left_behind_fraction(rest, rest, AXIS, AXIS + lift / 4, R) == 0.0


@pytest.mark.parametrize("degrees", [90, 180])
def test_skinning_matches_the_exact_bend_of_a_tube_into_an_arc(degrees):
    result = dm.arc_bend(np.radians(degrees))
    assert result["psnr"] >= 35.0, result


@pytest.fixture(scope="module")
def loaded():
    return load_cases(CASES)


@pytest.fixture(scope="module")
def pulls(loaded):
    scenes, cases = loaded
    out = {}
    for name, view in PULLS:
        case = next(c for c in cases if c["name"] == name)
        out[name] = (
            pull_case(scenes[case["scene"]], case, view),
            pull_case(
                scenes[case["scene"]],
                case,
                view,
                extract={"attach": False},
                subdivide=False,
                end_ramp=0.0,
                separate=False,
            ),
        )
    return out


@pytest.mark.parametrize("name", [name for name, _ in PULLS])
def test_pulls_leave_no_needles(pulls, name):
    now, before = pulls[name]
    assert now.needles <= 0.005, now.needles
    assert now.needles <= before.needles


@pytest.mark.parametrize("name", [name for name, _ in PULLS])
def test_pulls_do_not_tear(pulls, name):
    now, _ = pulls[name]
    assert now.tears <= 0.003, now.tears


@pytest.mark.parametrize("name", [name for name, _ in PULLS])
def test_pulls_tear_less_than_one_binding_per_gaussian_did(pulls, name):
    now, before = pulls[name]
    assert now.tears <= before.tears + 1e-4, (now.tears, before.tears)


def test_the_guitar_neck_takes_its_headstock_and_leaves_the_body(pulls, loaded):
    now, _ = pulls["guitar_neck"]
    attached = now.extraction.binding.attached
    assert attached.sum() > 3000  # headstock and tuning pegs
    scenes, cases = loaded
    # the input scene: in the rig's, a split Gaussian's row holds its first piece, at one end
    scene = scenes[next(c for c in cases if c["name"] == "guitar_neck")["scene"]]
    ids = now.extraction.binding.gaussian_ids
    # the body is below the neck's lower (clamped) end in this view: what lies below the end cap
    # (R, 19 px, past the end) stays
    uv, _ = now.camera.project(scene.means[ids].astype(np.float64))
    end_uv, _ = now.camera.project(now.rest_axis[[0, -1]].astype(np.float64))
    below = uv[:, 1] > max(end_uv[:, 1]) + 20
    assert below.sum() < 0.002 * len(ids), below.sum()


def test_a_branch_clamped_where_it_meets_its_limb_does_not_tear_from_it():
    """The tall tree branch's rod ends where it leaves the limb it joins, and is clamped there: the
    separation cut leaves what it shares with the limb by that end, where the rod does not move
    (docs/deformation.md, "Separation"). Cut anywhere before it, the branch tore (0.15 %)."""
    scenes, cases = load_cases(CASES)
    case = next(c for c in cases if c["name"] == "tree_branch_tall")
    now = pull_case(scenes[case["scene"]], case, "az000")
    uncut = pull_case(scenes[case["scene"]], case, "az000", separate=False)
    assert now.tears <= uncut.tears and now.tears < 0.0005, (now.tears, uncut.tears)


@pytest.mark.parametrize("name", [name for name, _ in PULLS])
def test_pulls_leave_nothing_behind(pulls, name):
    now, _ = pulls[name]
    assert now.left_behind <= 0.005, now.left_behind


def test_a_stand_leg_pulled_off_the_guitar_body_leaves_no_streaks_where_it_lay():
    """The stand's right leg in az135 lies against the guitar body; its far face is joined to the
    rest of the leg by 3 close pairs and touches the body by 18. The separation cut, counting pairs
    alone, left that face (269 Gaussians) where the leg had been: dark streaks over the body, 4.8 %
    of what lay within 2 R of it (docs/deformation.md, "Separation")."""
    scenes, cases = load_cases(CASES)
    case = next(c for c in cases if c["name"] == "guitar_stand_leg_right")
    now = pull_case(scenes[case["scene"]], case, "az135")
    assert now.left_behind < 0.005, now.left_behind
    assert now.tears < 0.003, now.tears


@pytest.mark.parametrize("view", ["az000", "az045", "az090"])
def test_the_stands_front_foot_leaves_the_leg_standing_on_it(view):
    """The left leg stands on the front foot, and its Gaussians thin out a few radii above it: the
    foot's rod carried that lower piece as an attached part (381-415 of the leg's Gaussians past
    3 R of the foot's axis), and pulled, the piece swung off the rest of the leg. A piece of another
    part now stays with it (docs/deformation.md, "Segmentation", A piece of another part)."""
    scenes, cases = load_cases(CASES)
    scene = scenes["guitar"]

    def rod(name: str, view_name: str):
        case = next(c for c in cases if c["name"] == name)
        stroke = next(v for v in case["views"] if v["name"] == view_name)
        camera = Camera.from_dict(stroke["camera"], view_name)
        return case, extract_rod(scene, camera, np.asarray(stroke["stroke"], np.float64), radius=case["radius"])

    leg_case, leg = rod("guitar_stand_leg_left", "az045")
    off_leg, _ = nearest_on_polyline(scene.means.astype(np.float64), leg.polyline.astype(np.float64))
    on_leg = off_leg <= leg_case["radius"]
    foot_case, foot = rod("guitar_stand_foot_front", view)
    ids = foot.gaussian_ids
    off_foot, _ = nearest_on_polyline(scene.means[ids].astype(np.float64), foot.polyline.astype(np.float64))
    carried = on_leg[ids] & (off_foot > 3 * foot_case["radius"])
    assert on_leg.sum() > 1000 and carried.sum() == 0, carried.sum()
    assert foot.binding.attached.sum() > 100  # what else hangs on the foot still rides with it


def test_a_static_needle_lying_mostly_in_the_part_goes_with_it_in_pieces():
    """The held-out back foot of the guitar stand in az090: needles a little longer than an edge
    whose centres lie off the part run along it for most of their length. They are split from one
    edge (docs/deformation.md, "Subdivision"), and their pieces in the part follow it; left whole,
    being no longer than a piece may be, they stayed where the foot had been (0.17 %)."""
    scenes, cases = load_cases(CASES.parent / "heldout_cases.json")
    case = next(c for c in cases if c["name"] == "guitar_stand_foot_back")
    now = pull_case(scenes[case["scene"]], case, "az090")
    assert now.left_behind < 0.0005, now.left_behind


def test_a_speck_inside_the_parts_tube_goes_with_it():
    """Two opaque Gaussians at one place 1.1 R from the axis of a tree tip seen from the back
    (second held-out cases, az135) are linked to nothing: the segmentation's graph did not reach
    them, and pulled, the tip left them hanging in the air, a speck where it had been. A small
    cluster inside the part's tube now goes with it (docs/deformation.md, "Segmentation")."""
    scenes, cases = load_cases(CASES.parent / "heldout2_cases.json")
    case = next(c for c in cases if c["name"] == "tree_tip_back_centre")
    now = pull_case(scenes[case["scene"]], case, "az135")
    assert now.left_behind == 0.0, now.left_behind
    bound = set(now.extraction.gaussian_ids.tolist())
    assert {10884, 99310} <= bound


def test_the_plant_stem_takes_its_leaves(pulls):
    now, _ = pulls["plant_side_stem_left"]
    binding = now.extraction.binding
    assert binding.attached.sum() > (~binding.attached).sum()  # its leaves outweigh the stem


def test_a_free_tip_carries_the_stem_and_leaves_past_the_stroke_and_a_clamped_one_holds_them():
    """The bundled plant's stroke stops short of its stem's tip: past the rod's end the stem runs
    on with three leaves (docs/deformation.md, "Continuations"). Held at its base only, the stem's
    tip carries them along; held at both ends, they stay still."""
    from sketchrodgs import data, extract_rod, load_scene
    from sketchrodgs.animate import Animation, Pull

    scene, camera = load_scene(data.sample("plant")), data.sample_camera("plant")
    extraction = extract_rod(scene, camera, data.sample_stroke("plant"))
    b = extraction.binding
    tip = b.gaussian_ids[b.attached & (b.segment == len(extraction.polyline) - 2) & (b.t == 1)]
    assert len(tip) > 1000  # the stem's tip and its leaves
    middle = len(extraction.polyline) // 2
    drag = tuple(camera.screen_offset(extraction.polyline[middle], (-40, 0)))
    for clamp in ("start", "both"):
        animation = Animation(scene, [extraction], clamp=clamp)
        rest_end = np.array(animation.rods[0].positions[-1])
        for _ in animation.frames(Pull(vertex=middle, offset=drag, duration=0.3, hold=0.1, release=False), fps=30):
            pass  # held out
        end_moved = np.linalg.norm(np.array(animation.rods[0].positions[-1]) - rest_end)
        tip_moved = np.linalg.norm(animation.means[tip] - scene.means[tip], axis=1)
        if clamp == "start":
            assert end_moved > 10 * extraction.radius
            assert np.median(tip_moved) > 0.5 * end_moved  # they go with the end, turning with it
        else:
            assert end_moved < 1e-6 and tip_moved.max() < 1e-6
