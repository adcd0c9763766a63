"""The discrete elastic rod (issue 5): mechanics against closed forms, the app's pull and
release, extreme input, several rods, and the Python API's contract."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sketchrodgs.errors import SimulationError, SketchRodGSError
from sketchrodgs.rod import Rod, RodParams, SolverSettings, StepReport, World, merge_coincident

DT = 1.0 / 60.0


def straight(n: int, length: float = 1.0) -> np.ndarray:
    p = np.zeros((n, 3))
    p[:, 0] = np.linspace(0.0, length, n)
    return p


def helix(n: int) -> np.ndarray:
    s = np.linspace(0.0, 4.0, n)
    return np.c_[0.3 * np.cos(s), 0.3 * np.sin(s), 0.1 * s]


def rot(axis, angle: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


STEEL = dict(radius=0.01, youngs_modulus=1e10, density=1000.0, gravity=(0.0, 0.0, -9.81))


def cantilever(n: int) -> Rod:
    rod = Rod(straight(n), **STEEL)
    rod.clamp(0)
    return rod


# ----- mechanics -----


def test_cantilever_tip_deflection_matches_euler_bernoulli():
    p = RodParams(**STEEL)
    area, inertia = np.pi * p.radius**2, np.pi * p.radius**4 / 4
    expected = p.density * area * 9.81 / (8 * p.youngs_modulus * inertia)  # w L^4 / (8 E I)
    assert expected == pytest.approx(4.905e-3, rel=1e-3)
    errors = {}
    print(f"\nEuler-Bernoulli tip deflection {expected:.6e} m")
    for n in (10, 25, 50, 100, 200):
        rod = cantilever(n)
        report = rod.solve_static()
        assert report.converged and report.iterations < 50  # tens of Newton iterations at most
        tip = -rod.positions[-1, 2]
        errors[n] = tip / expected - 1
        print(f"n={n:4d} tip={tip:.6e} error={100 * errors[n]:+.4f}% newton={report.iterations}")
    assert abs(errors[200]) < 0.01
    assert abs(errors[200]) < abs(errors[50]) < abs(errors[10])


def test_rods_of_the_same_material_sag_alike_whatever_their_vertex_count():
    tips = {}
    for n in (50, 200):
        rod = cantilever(n)
        rod.solve_static()
        tips[n] = -rod.positions[-1, 2]
    assert tips[50] == pytest.approx(tips[200], rel=1e-3)


def test_twisted_clamped_rod_settles_to_uniform_twist_with_torque_gj_theta_over_l():
    n, theta = 100, 1.0
    rod = Rod(straight(n), radius=0.01, youngs_modulus=1e7, poisson_ratio=0.5)
    rod.clamp(0)
    rod.clamp(-1)
    rod.move_clamp(-1, rot([1, 0, 0], theta))
    assert rod.solve_static().converged
    gj = 1e7 / 3.0 * np.pi * 0.01**4 / 2
    expected = gj * theta / 1.0
    assert abs(rod.clamp_torque(-1)) == pytest.approx(expected, rel=0.01)
    assert abs(rod.clamp_torque(0)) == pytest.approx(expected, rel=0.01)
    moment = rod.twisting_moment()[1:-1]
    np.testing.assert_allclose(moment, expected, rtol=1e-6)
    np.testing.assert_allclose(rod.positions, rod.rest_positions, atol=1e-9)


def test_shear_modulus_overrides_poisson_ratio():
    def torque(**kw):
        rod = Rod(straight(20), radius=0.01, youngs_modulus=1e7, **kw)
        rod.clamp(0)
        rod.clamp(-1)
        rod.move_clamp(-1, rot([1, 0, 0], 0.5))
        rod.solve_static()
        return abs(rod.clamp_torque(-1))

    g = 2e6
    assert torque(shear_modulus=g) == pytest.approx(g * np.pi * 0.01**4 / 2 * 0.5, rel=1e-6)
    assert torque(poisson_ratio=0.25) == pytest.approx(1e7 / 2.5 * np.pi * 0.01**4 / 2 * 0.5, rel=1e-6)


def test_curved_rest_shape_is_an_equilibrium_and_rigid_motion_leaves_it_so():
    rod = Rod(helix(40))
    f, t = rod.forces()
    assert np.abs(f).max() < 1e-9 and np.abs(t).max() < 1e-9
    assert rod.energy().elastic < 1e-18
    rod.step(DT, n=50)
    np.testing.assert_allclose(rod.positions, rod.rest_positions, atol=1e-12)

    r, t0 = rot([0.3, -0.5, 0.8], 2.1), np.array([1.0, -2.0, 0.5])
    frames_before = rod.edge_frames
    rod.transform(r, t0)
    np.testing.assert_allclose(rod.positions, rod.rest_positions @ r.T + t0, atol=1e-12)
    np.testing.assert_allclose(rod.edge_frames, r @ frames_before, atol=1e-12)
    f, t = rod.forces()
    assert np.abs(f).max() < 1e-9 and np.abs(t).max() < 1e-9
    moved = rod.positions
    rod.clamp(0)
    rod.step(DT, n=50)
    np.testing.assert_allclose(rod.positions, moved, atol=1e-12)


# ----- the app's interaction -----


@pytest.mark.parametrize("n", [51, 201])
def test_pull_and_release_like_the_app(n):
    rod = Rod(straight(n))  # both ends clamped, as the authors' app does
    rod.clamp(0)
    rod.clamp(-1)
    mid = n // 2
    energies, deviation = [], []
    for frame in range(1, 601):
        t = frame * DT
        if t <= 0.5 + 1e-9:
            rod.grab(mid, (0.5, 0.3 * t / 0.5, 0.0))
        elif t > 1.0:
            rod.release()
        report = rod.step(DT)
        assert report.converged
        x = rod.positions
        assert np.isfinite(x).all()
        if frame == 60:  # held at 0.3 L
            strain = rod.strain
            # The geometry forces 2 sqrt(0.5^2 + 0.3^2) - 1 = 16.6 % between the clamps,
            # spread along the rod, not piled up at the grab.
            assert strain.mean() == pytest.approx(0.166, abs=0.01)
            assert strain.max() < 2 * strain.mean()
        if t > 1.0:
            energies.append(rod.energy().total)
            deviation.append(np.abs(x - rod.rest_positions).max())
    energies = np.array(energies)
    assert (np.diff(energies) <= 1e-12 * energies[:-1]).all(), "energy grew after release"
    away = np.nonzero(np.array(deviation) >= 1e-3)[0]
    back = (away[-1] + 1 if len(away) else 0) * DT  # from then on within 1e-3 L of rest
    assert back < 5.0, "back to rest within 1e-3 L in bounded time"
    print(f"\nn={n}: back within 1e-3 L of rest {back:.2f} s after release, and stays")


def test_a_grabbed_vertex_follows_its_target_and_keeps_its_velocity_on_release():
    rod = Rod(straight(21))
    rod.clamp(0)
    rod.grab(-1, (1.0, 0.0, 0.0))
    for k in range(1, 11):
        rod.move_grab((1.0, 0.01 * k, 0.0))
        rod.step(DT)
        np.testing.assert_allclose(rod.positions[-1], (1.0, 0.01 * k, 0.0), atol=1e-12)
    assert rod.grabbed is not None and rod.grabbed[0] == 20
    v = rod.velocities[-1]
    assert v[1] == pytest.approx(0.01 / DT, rel=1e-9)
    rod.release()
    assert rod.grabbed is None
    with pytest.raises(SimulationError, match="no vertex is grabbed"):
        rod.move_grab((0.0, 0.0, 0.0))


# ----- extreme input -----


def test_extreme_pulls_steps_and_tiny_rods_never_nan():
    rod = Rod(straight(1000))
    rod.clamp(0)
    rod.clamp(-1)
    rod.grab(500, (0.5, 3.0, 0.0))  # 3 L away in one 0.1 s step
    rod.step(0.1)
    assert rod.positions[500] == pytest.approx([0.5, 3.0, 0.0])
    rod.release()
    for _ in range(100):
        rod.step(0.1)
        assert np.isfinite(rod.positions).all()
    assert np.abs(rod.positions - rod.rest_positions).max() < 1e-3

    for n in (2, 3):
        for clamped in (False, True):
            r = Rod(straight(n))
            if clamped:
                r.clamp(0)
            r.grab(-1, (0.0, 3.0, 3.0))
            r.step(0.1, n=20)
            r.release()
            r.step(0.1, n=20)
            assert np.isfinite(r.positions).all()
            r.solve_static()
            assert np.isfinite(r.positions).all()


def test_degenerate_polylines_are_rejected_with_their_position_or_merged():
    p = straight(6)
    p[3] = p[2]
    with pytest.raises(SimulationError, match="edge 2"):
        Rod(p)
    merged, index = merge_coincident(p)
    assert len(merged) == 5 and index.tolist() == [0, 1, 2, 2, 3, 4]
    assert len(Rod(merged)) == 5
    with pytest.raises(SimulationError, match="folds"):
        Rod([[0, 0, 0], [1, 0, 0], [0, 0, 0]])
    with pytest.raises(SimulationError, match="non-finite"):
        Rod([[0, 0, np.nan], [1, 0, 0]])
    with pytest.raises(SimulationError, match="at least 2"):
        Rod([[0, 0, 0]])
    with pytest.raises(SketchRodGSError, match=r"polyline: expected shape \(N, 3\)"):
        Rod(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="radius"):
        Rod(straight(4), radius=-1.0)
    with pytest.raises(SimulationError, match="out of range"):
        Rod(straight(4)).clamp(4)
    with pytest.raises(SimulationError, match="edge 0 has an infinite length: the coordinates are too large"):
        Rod([[-1e308, 0, 0], [1e308, 0, 0]])
    with pytest.raises(SimulationError, match="polyline: 100,001 vertices, more than a rod may have"):
        Rod(straight(100_001))
    rod = Rod(straight(4))
    with pytest.raises(SimulationError, match=r"rotation: not a rotation matrix .* det 8\.0"):
        rod.transform(2 * np.eye(3))


def test_a_held_vertex_is_not_grabbed_and_a_world_is_not_shared_across_threads():
    import threading

    rod = Rod(straight(400))
    rod.clamp(0)
    rod.pin(-1)
    for vertex, held in ((0, "clamped"), (-1, "pinned")):
        with pytest.raises(SimulationError, match=f"vertex {vertex % 400} is {held}: set it free before grabbing it"):
            rod.grab(vertex, (0.0, 0.1, 0.0))
    rod.free(-1)
    rod.grab(-1, (1.0, 0.1, 0.0))
    errors: list[str] = []
    stepping = threading.Thread(target=lambda: [rod.step(DT) for _ in range(40)])
    stepping.start()
    while stepping.is_alive():
        try:
            _ = rod.positions
        except SimulationError as err:
            errors.append(str(err))
    stepping.join()
    assert errors and "not shared across threads" in errors[0]


def test_coincident_non_adjacent_vertices_are_fine():
    a = np.linspace(0, 2 * np.pi, 21)
    loop = np.c_[np.cos(a), np.sin(a), np.zeros_like(a)]  # first and last vertex coincide
    rod = Rod(loop)
    rod.clamp(0)
    rod.grab(10, (0.0, 0.0, 2.0))
    rod.step(DT, n=30)
    assert np.isfinite(rod.positions).all()


def test_an_infeasible_step_is_reported_not_nan(caplog):
    rod = Rod(straight(10))
    rod.clamp(0)
    rod.pin(1)
    rod.grab(2, rod.positions[1])  # onto the pinned neighbour: a zero-length edge
    with caplog.at_level(logging.WARNING, logger="sketchrodgs"):
        report = rod.step(DT)
    assert isinstance(report, StepReport)
    assert not report.converged and report.rejected > 0
    assert "did not converge" in caplog.text
    assert np.isfinite(rod.positions).all()
    with pytest.raises(SimulationError, match="time step"):
        rod.step(float("nan"))


def test_a_hard_step_is_retried_in_substeps():
    # Four Newton iterations cannot resolve a 1 m jerk in one 0.1 s step; two halves can.
    world = World(SolverSettings(max_iterations=4))
    rod = Rod(straight(30), world=world)
    rod.clamp(0)
    rod.clamp(-1)
    rod.grab(15, (0.5, 1.0, 0.0))
    report = rod.step(0.1)
    assert report.converged and report.rejected >= 1 and report.substeps >= 2
    assert rod.positions[15] == pytest.approx([0.5, 1.0, 0.0])


@settings(max_examples=25, deadline=None)
@given(
    st.lists(st.tuples(*[st.floats(-1, 1)] * 3), min_size=2, max_size=12),
    st.floats(0.05, 2.0),
)
def test_random_polylines_rest_in_place_and_survive_a_pull(steps, pull):
    p = np.cumsum(np.asarray(steps) + [[1e-3, 0, 0]], axis=0)
    lengths = np.linalg.norm(np.diff(p, axis=0), axis=1)
    t = np.diff(p, axis=0) / np.maximum(lengths, 1e-300)[:, None]
    if len(p) < 2 or lengths.min() < 1e-3 * lengths.sum() or (np.sum(t[:-1] * t[1:], 1) < -0.999).any():
        return  # degenerate input is covered by the rejection test
    rod = Rod(p)
    f, _ = rod.forces()
    assert np.abs(f).max() < 1e-6 * 1e7 * np.pi * 1e-4
    rod.clamp(0)
    rod.grab(-1, p[-1] + pull)
    rod.step(0.05, n=5)
    rod.release()
    rod.step(0.05, n=5)
    assert np.isfinite(rod.positions).all()


# ----- several rods, API contract -----


def test_rods_in_one_world_that_do_not_touch_step_together_as_if_alone():
    alone = Rod(helix(30))
    alone.clamp(0)
    alone.grab(-1, (0.0, 0.0, 1.0))
    world = World()
    a = world.add(helix(30))
    b = world.add(straight(20, 0.5) - (0.0, 0.0, 2.0), radius=0.02, youngs_modulus=1e6)  # 2 m below
    a.clamp(0)
    a.grab(-1, (0.0, 0.0, 1.0))
    b.pin(0)
    b.grab(-1, (0.0, 0.5, -2.0))
    for _ in range(20):
        reports = world.step(DT)
        assert len(reports) == 2 and all(r.converged for r in reports)
        alone.step(DT)
    np.testing.assert_array_equal(a.positions, alone.positions)
    np.testing.assert_allclose(b.positions[-1], (0.0, 0.5, -2.0), atol=1e-12)
    assert [r.index for r in world.rods] == [0, 1]
    world.remove(a)
    assert b.index == 0 and len(world) == 1
    with pytest.raises(SimulationError, match="removed"):
        _ = a.positions


def test_a_rod_is_the_worlds_own_handle_taking_lists_and_naming_bad_input():
    from sketchrodgs import _core

    world = World()
    first, rod, last = (world.add(straight(n)) for n in (5, 7, 9))
    assert isinstance(rod, _core.Rod) and rod.world is world and [r.index for r in world.rods] == [0, 1, 2]
    world.remove(first)
    assert (rod.index, last.index, len(world)) == (0, 1, 2)
    # array-likes in, vertices counted from either end
    rod.clamp(-7)
    rod.grab(-1, [0.5, 0.1, 0.0])
    assert rod.grabbed is not None and rod.grabbed[0] == 6
    np.testing.assert_array_equal(rod.grabbed[1], [0.5, 0.1, 0.0])
    rod.transform([[1, 0, 0], [0, 1, 0], [0, 0, 1]], (0, 0, 1))
    assert rod.boundaries[0] == "clamped" and rod.rest_positions.shape == (7, 3)
    rod.set_velocities(np.zeros((7, 3), np.float32).tolist())
    for call, message in (
        (lambda: rod.grab(7, (0, 0, 0)), "vertex 7 is out of range for a rod of 7 vertices"),
        (lambda: rod.clamp(2**70), "vertex 1180591620717411303424 is out of range"),
        (lambda: rod.clamp(1.5), "vertex: expected an integer index, got 1.5"),
        (lambda: rod.move_grab((0, 0)), r"target: expected 3 values, got shape \(2,\)"),
        (lambda: rod.transform(np.eye(4)), r"rotation: expected a \(3, 3\) rotation matrix, got shape \(4, 4\)"),
        (lambda: rod.set_positions(np.zeros((7, 2))), r"positions: expected shape \(N, 3\), got \(7, 2\)"),
        (lambda: rod.pin(1, "here"), "position: expected an array of numbers"),
        (lambda: Rod([[0, 0, 0], [1, 0]]), "polyline: expected"),
        # each finite and positive, but the cross-section's area overflows (a radius in the wrong units)
        (lambda: Rod(straight(5), radius=1e300), r"`radius` = 1e300 is invalid: makes the cross-section's stiffness"),
    ):
        with pytest.raises(SimulationError, match=message):
            call()
    other = World()
    stranger = other.add(straight(5))  # id 0 there, as `first` was here
    with pytest.raises(SimulationError, match="belongs to another world"):
        world.remove(stranger)
    assert len(other) == 1 and len(world) == 2
    world.remove(rod)
    assert "detached" in repr(rod)
    for call in (lambda: rod.positions, lambda: rod.index, lambda: rod.clamp(0), lambda: world.remove(rod)):
        with pytest.raises(SimulationError, match="removed from its world"):
            call()
    assert last.index == 0 and len(world) == 1 and last.positions.shape == (9, 3)


def test_frames_are_rotations_with_the_tangent_third_and_vertex_frames_average_them():
    rod = Rod(helix(25))
    rod.clamp(0)
    rod.grab(-1, (0.0, 0.5, 0.8))
    rod.step(DT, n=20)
    e, v = rod.frames()
    assert e.shape == (24, 3, 3) and v.shape == (25, 3, 3)
    eye = np.broadcast_to(np.eye(3), e.shape)
    np.testing.assert_allclose(e @ e.transpose(0, 2, 1), eye, atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(e), 1.0, atol=1e-12)
    t = np.diff(rod.positions, axis=0)
    np.testing.assert_allclose(e[:, :, 2], t / np.linalg.norm(t, axis=1, keepdims=True), atol=1e-12)
    # Vertex frames: ends take their edge's frame, interior ones sit halfway in rotation.
    np.testing.assert_allclose(v[0], e[0], atol=1e-12)
    np.testing.assert_allclose(v[-1], e[-1], atol=1e-12)
    half_a = np.arccos(np.clip((np.trace(e[4].T @ v[5]) - 1) / 2, -1, 1))
    half_b = np.arccos(np.clip((np.trace(v[5].T @ e[5]) - 1) / 2, -1, 1))
    assert half_a == pytest.approx(half_b, abs=1e-9)
    # Quaternions (w, x, y, z) describe the same rotations.
    q = rod.edge_quats
    w, x, y, z = q.T
    r00 = 1 - 2 * (y * y + z * z)
    r10 = 2 * (x * y + w * z)
    np.testing.assert_allclose(np.c_[r00, r10], e[:, :2, 0], atol=1e-12)
    assert (q[:, 0] >= 0).all() and rod.vertex_quats.shape == (25, 4)


def test_arrays_out_are_float64_c_contiguous_and_fresh():
    rod = Rod(straight(5))
    x = rod.positions
    assert x.dtype == np.float64 and x.flags.c_contiguous and x.shape == (5, 3)
    x[:] = 7.0  # a copy of the state: writing to it does not move the rod
    assert rod.positions[0, 0] == 0.0
    for arr, shape in [
        (rod.velocities, (5, 3)),
        (rod.strain, (4,)),
        (rod.twist, (4,)),
        (rod.masses, (5,)),
        (rod.edge_frames, (4, 3, 3)),
        (rod.vertex_quats, (5, 4)),
    ]:
        assert arr.shape == shape and arr.dtype == np.float64 and arr.flags.c_contiguous
    assert rod.masses.sum() == pytest.approx(1000 * np.pi * 0.01**2 * 1.0)


def test_the_defaults_are_the_rod_crates():
    from sketchrodgs import _core

    # one source: RodParams and SolverSettings show the crate's defaults, and a rod made without
    # a material has them on the Rust side too
    assert RodParams().to_dict() == {**_core.default_rod_params(), "gravity": [0.0, 0.0, 0.0]}
    assert SolverSettings().to_dict() == _core.default_solver_settings()
    rod = Rod(straight(5))
    assert rod.params == RodParams()
    on_the_rust_side = rod._material()
    assert (
        on_the_rust_side["youngs_modulus"] == RodParams().youngs_modulus
        and on_the_rust_side["radius"] == RodParams().radius
    )
    assert Rod(straight(5), youngs_modulus=3e6).params.youngs_modulus == 3e6
    with pytest.raises(SimulationError, match="unknown material field"):
        Rod(straight(5), young=3e6)
    with pytest.raises(SimulationError, match="not both"):
        Rod(straight(5), params=RodParams(), radius=0.1)


def test_params_and_settings_round_trip_through_json():
    p = RodParams(radius=0.02, youngs_modulus=5e6, shear_modulus=1e6, damping=0.5, gravity=(0, -9.81, 0))
    assert RodParams.from_dict(json.loads(json.dumps(p.to_dict()))) == p
    with pytest.raises(SimulationError, match="unknown keys"):
        RodParams.from_dict({"radius": 0.1, "stiffness": 3})
    s = SolverSettings(tolerance=1e-6, max_iterations=10)
    assert SolverSettings.from_dict(json.loads(json.dumps(s.to_dict()))) == s
    world = World(s)
    assert world.solver == s
    rod = Rod(straight(4), params=p, world=world)
    assert rod.params == p
    assert rod.boundaries == ["free"] * 4
    rod.clamp(-1)
    rod.pin(0, (0.0, 0.1, 0.0))
    assert rod.boundaries == ["pinned", "free", "free", "clamped"]
