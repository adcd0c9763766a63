"""Contact (docs/contact.md): the scene's distance field from its Gaussians, rods that do not
enter it nor each other, the switch that turns it off, and gravity that keeps the captured shape."""

from __future__ import annotations

import numpy as np
import pytest

from sketchrodgs import GaussianScene, data, extract_rod, load_scene
from sketchrodgs.animate import Animation, Pull
from sketchrodgs.contact import scene_field
from sketchrodgs.errors import SimulationError
from sketchrodgs.rod import ContactSettings, Rod, World
from sketchrodgs.rod_file import Extraction

R = 0.01


def slab(top: float = 0.0, size: float = 0.6, step: float = 0.004, width: float | None = None) -> GaussianScene:
    """A table top of Gaussians: `size` by `width` (default: square) of round, opaque Gaussians of
    sigma `step`, `step` apart, in 2 layers, their top row of centres a step under `top`."""
    u = np.arange(-size / 2, size / 2, step)
    v = u if width is None else np.arange(-width / 2, width / 2, step)
    x, y, z = np.meshgrid(u, v, [top - step, top - 2 * step], indexing="ij")
    means = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    n = len(means)
    return GaussianScene.from_colors(
        means, np.full((n, 3), step), np.tile([1.0, 0, 0, 0], (n, 1)), np.full(n, 0.95), np.full((n, 3), 0.5)
    )


def test_the_field_of_a_slab_is_its_signed_distance():
    scene = slab()
    rod = np.stack([np.linspace(-0.2, 0.2, 41), np.zeros(41), np.full(41, 4 * R)], axis=1)
    field = scene_field(scene, [rod], [R])
    assert field is not None
    probe = np.array([[0.05, 0.05, 0.03], [0.05, 0.05, 0.0], [0.05, 0.05, -0.01]])
    distance = field.distance(probe)
    # the slab's Gaussians reach about a sigma past their centres (top - step): its surface is
    # within a cell or two of z = 0
    assert abs(distance[0] - 0.03) < 1.5 * field.spacing + 0.004
    assert abs(distance[1]) < 1.5 * field.spacing + 0.004
    assert distance[2] < 0
    assert field.distance(np.array([[5.0, 0, 0]]))[0] == np.inf
    # nothing solid around a rod far from everything: no field
    far = rod + (0.0, 0.0, 10.0)
    assert scene_field(scene, [far], [R]) is None


def test_a_rod_pulled_into_a_slab_of_gaussians_stays_on_it():
    scene = slab()
    rod_line = np.stack([np.linspace(-0.2, 0.2, 41), np.zeros(41), np.full(41, 4 * R)], axis=1)
    field = scene_field(scene, [rod_line], [R])
    assert field is not None
    for contact in (True, False):
        world = World()
        world.contact = ContactSettings(scene=contact)
        world.set_scene_field(field.values, field.origin, field.spacing)
        rod = Rod(rod_line, radius=R, world=world)
        rod.clamp(0)
        rod.clamp(-1)
        rod.grab(20, rod_line[20])
        lowest = np.inf
        for frame in range(1, 61):
            rod.move_grab(rod_line[20] - (0.0, 0.0, 24 * R * frame / 60))
            reports = world.step(1 / 60)
            assert reports[0].converged
            lowest = min(lowest, float(field.distance(rod.positions).min()))
        if contact:
            # within a field cell of the surface: the rod's surface (R) never goes far in
            assert lowest >= R - 0.05 * R - field.spacing, lowest / R
        else:
            assert rod.positions[20][2] < -10 * R  # through the slab


def test_a_grab_target_too_far_to_square_does_not_hang_the_contact_search():
    """A target 1e300 below the slab (a pull in the wrong units): the way to it was marched along
    a direction of zero length (its square overflowed), for ever. It now meets the slab at once,
    and the rod stays finite and on top."""
    scene = slab()
    rod_line = np.stack([np.linspace(-0.2, 0.2, 41), np.zeros(41), np.full(41, 4 * R)], axis=1)
    field = scene_field(scene, [rod_line], [R])
    assert field is not None
    world = World()
    world.set_scene_field(field.values, field.origin, field.spacing)
    rod = Rod(rod_line, radius=R, world=world)
    rod.clamp(0)
    rod.clamp(-1)
    rod.grab(20, rod_line[20] - (0.0, 0.0, 1e300))
    world.step(1 / 60, 3)
    assert np.isfinite(rod.positions).all()
    assert float(field.distance(rod.positions).min()) >= R - 0.05 * R - field.spacing


def test_a_rod_pulled_through_a_slab_stays_on_its_top_with_cells_of_a_radius():
    """Issue 20's measure: a 1 m rod of R = 1 cm, 4 R above a slab of Gaussians (sigma R / 2, R / 2
    apart; they reach alpha 0.5 between 0.06 R under and 0.07 R over z = 0), its middle pulled 20 R
    down. The field's cells are then about a radius; its surface, found along the grid lines, keeps
    the rod's surface within 0.05 R of z = 0 in every frame."""
    scene = slab(size=1.2, width=0.4, step=R / 2)
    rest = np.stack([np.linspace(-0.5, 0.5, 200), np.zeros(200), np.full(200, 4 * R)], axis=1)
    field = scene_field(scene, [rest], [R])
    assert field is not None and field.spacing > R
    world = World()
    world.set_scene_field(field.values, field.origin, field.spacing)
    rod = Rod(rest, radius=R, world=world)
    rod.clamp(0)
    rod.clamp(-1)
    lowest = np.inf
    for frame in range(1, 91):
        rod.grab(100, (0.0, 0.0, 4 * R - 24 * R * min(frame / 60, 1.0)))
        assert world.step(1 / 60)[0].converged
        x = rod.positions
        lowest = min(lowest, float(np.concatenate([x[:, 2], 0.5 * (x[1:, 2] + x[:-1, 2])]).min()) - R)
    assert lowest >= -0.05 * R, lowest / R


def _plant() -> tuple[GaussianScene, Extraction]:
    scene = load_scene(data.sample("plant"))
    return scene, extract_rod(scene, data.sample_camera("plant"), data.sample_stroke("plant"))


def test_animation_builds_the_field_of_what_the_rods_do_not_carry_and_can_turn_it_off():
    scene, rod = _plant()
    anim = Animation(scene, [rod])
    assert anim.field is not None and anim.world.has_scene_field
    # at rest the rod touches nothing: its own place is carved out of the scene
    assert anim.field.distance(anim.rods[0].positions).min() > rod.radius
    # the Gaussians it carries are not part of the field
    carried = anim.rig.bound[0].gaussian_ids
    assert (anim.field.distance(anim.rest_scene.means[carried]) > 0).mean() > 0.95
    off = Animation(scene, [rod], contact=False)
    assert off.field is None and not off.world.has_scene_field
    assert off.world.contact.rods is False


def test_a_stem_pulled_into_the_main_stem_stops_at_it():
    scene, rod = _plant()
    polyline = rod.polyline.astype(np.float64)
    anim = Animation(scene, [rod])
    middle = len(polyline) // 2
    assert anim.field is not None
    # towards the main stem, far past it
    target = np.array([0.0, polyline[middle, 1], 0.0])
    offset = 1.5 * (target - polyline[middle])
    for _ in anim.frames(Pull(middle, tuple(offset), duration=0.5, hold=0.2, release=False), fps=30):
        assert anim.field.distance(anim.rods[0].positions).min() > -0.5 * rod.radius


def test_gravity_keeps_the_captured_shape_and_refuses_what_cannot_hang():
    scene, rod = _plant()
    still = Animation(scene, [rod], up="-y")  # the plant's up is -y
    start = still.rods[0].positions.copy()
    for _ in still.frames(Pull(1, (0.0, 0.0, 0.0), duration=0.1, hold=1.0, release=True, settle=0.0), fps=30):
        pass
    assert np.abs(still.rods[0].positions - start).max() < 0.01 * rod.radius
    # a stem held only by a pin at its end cannot carry its weight
    with pytest.raises(SimulationError, match="cannot carry its weight"):
        Animation(scene, [rod], clamp="none", pins=[[0]], up="-y")
    with pytest.raises(Exception, match="up"):
        Animation(scene, [rod], up="sideways")
