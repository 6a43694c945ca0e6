"""The Simulator: numpy shapes and dtypes, reads in place, handles, gravity, reset, stats."""

from __future__ import annotations

import numpy as np
import pytest

import latent_dynamics as ld
from conftest import tip


def test_model_describes_itself(model: ld.Model, neural_path) -> None:
    assert model.method == "neural-cubature"
    assert model.scene == "tiny"
    assert model.neural
    assert model.vertex_count == 7 * 2 * 2
    assert model.tet_count > 0 and 0 < model.elements <= model.tet_count
    # Six PCA columns and the three positions of the beam's fall under gravity they miss.
    assert model.pca_dim == 6 + 3
    assert model.latent_dim >= 2
    assert model.has_all_rows and model.rows_vertex_count == model.vertex_count
    assert model.time_step == pytest.approx(0.02)
    # 1.0 × 0.2 × 0.2 m of density 1000 kg/m³.
    assert model.mass == pytest.approx(40.0, rel=1e-12)
    assert model.pinned == [v for v in model.pinned if v < model.vertex_count]
    assert len(model.pinned) == 4
    assert model.path == neural_path
    assert any(held_out for _, held_out, _ in model.errors)
    assert "neural-cubature" in repr(model)


def test_model_saves_and_loads_the_same(model: ld.Model, tmp_path) -> None:
    copy = tmp_path / "copy.ldm"
    model.save(copy)
    again = ld.Model.load(copy)
    assert copy.read_bytes() == model.path.read_bytes()
    assert (again.latent_dim, again.elements) == (model.latent_dim, model.elements)


def test_arrays_have_the_documented_shapes_and_dtypes(sim: ld.Simulator) -> None:
    n, m = sim.vertex_count, sim.surface_vertex_count
    rest = sim.rest_positions
    assert rest.shape == (n, 3) and rest.dtype == np.float64
    positions = sim.positions()
    assert positions.shape == (n, 3) and positions.dtype == np.float64
    assert positions.flags.c_contiguous
    np.testing.assert_allclose(positions, rest, atol=1e-12)
    for dtype in (None, np.float64, "float64", np.dtype("f8")):
        s = sim.surface_positions() if dtype is None else sim.surface_positions(dtype)
        assert s.shape == (m, 3) and s.dtype == np.float64
    s32 = sim.surface_positions(np.float32)
    assert s32.shape == (m, 3) and s32.dtype == np.float32
    vertices = sim.surface_vertices
    assert vertices.shape == (m,) and vertices.dtype == np.int64
    assert np.all(np.diff(vertices) > 0)
    # The decoder's rest state is zero up to round-off.
    np.testing.assert_allclose(sim.surface_positions(), rest[vertices], rtol=0, atol=1e-12)
    triangles = sim.surface_triangles
    assert triangles.dtype == np.uint32 and triangles.ndim == 2 and triangles.shape[1] == 3
    assert triangles.max() < m
    # Every boundary face of the 6×1×1 box: 2 triangles per square.
    assert triangles.shape[0] == 2 * (6 * 4 + 2)


def test_reads_write_into_a_given_array(sim: ld.Simulator) -> None:
    h = sim.grab(tip(sim), 500.0)
    sim.move_handle(h, sim.rest_positions[tip(sim)] + [0.0, 0.05, 0.0])
    for _ in range(3):
        sim.step()
    m = sim.surface_vertex_count
    expected = sim.surface_positions()
    out = np.empty((m, 3))
    assert sim.surface_positions(out=out) is out
    np.testing.assert_array_equal(out, expected)
    out32 = np.empty((m, 3), dtype=np.float32)
    assert sim.surface_positions(out=out32) is out32
    np.testing.assert_array_equal(out32, expected.astype(np.float32))
    # Not contiguous: through one buffer, with the same values.
    wide = np.zeros((m, 6))
    strided = wide[:, ::2]
    assert sim.surface_positions(out=strided) is strided
    np.testing.assert_array_equal(wide[:, ::2], expected)
    assert not wide[:, 1::2].any()
    # Contiguous in column order (Fortran's, or a transposed array): the same values, not the
    # rows' bytes laid over its columns.
    for columns in (np.empty((m, 3), order="F"), np.empty((3, m)).T):
        assert sim.surface_positions(out=columns) is columns
        np.testing.assert_array_equal(columns, expected)
    full_f = np.empty((sim.vertex_count, 3), order="F")
    assert sim.positions(out=full_f) is full_f
    np.testing.assert_array_equal(full_f, sim.positions())
    # Every vertex's position decodes all rows with another kernel than the surface's: the
    # same to round-off.
    full = np.empty((sim.vertex_count, 3))
    assert sim.positions(out=full) is full
    np.testing.assert_allclose(full[sim.surface_vertices], expected, rtol=1e-14, atol=1e-16)


def test_a_dragged_tip_rises_and_falls_back(sim: ld.Simulator) -> None:
    v = tip(sim)
    start = sim.rest_positions[v].copy()
    h = sim.grab([v], 2000.0)
    heights = []
    for k in range(1, 26):
        sim.move_handle(h, start + [0.0, 0.1 * k / 25, 0.0])
        stats = sim.step()
        assert stats.step == k and stats.iterations > 0 and stats.seconds > 0
        heights.append(sim.positions()[v, 1] - start[1])
    # Against gravity, which alone sags the soft beam's tip by several centimetres.
    assert heights[-1] > 0.01 and heights[-1] > min(heights) + 0.04, heights
    assert sim.steps == 25 and sim.time == pytest.approx(0.5)
    sim.release(h)
    for _ in range(25):
        sim.step()
    assert sim.positions()[v, 1] - start[1] < heights[-1] - 0.01
    run = sim.stats
    assert run.steps == 50 and run.last is not None and run.last.step == 50
    assert run.steps_per_second > 0 and run.iterations_per_step > 0
    assert run.seconds == pytest.approx(run.steps / run.steps_per_second)
    sim.reset_stats()
    assert sim.stats.steps == 0 and sim.stats.last is None


def test_a_pull_far_beyond_the_training_is_said_step_by_step(model: ld.Model) -> None:
    sim = ld.Simulator(model)
    first = sim.step()
    # Sagging under gravity, as every training schedule starts: among the training poses.
    assert first.beyond_training is not None and first.beyond_training < 0.1, first
    # The tip lifted a whole beam length: no schedule went there.
    v = tip(sim)
    h = sim.grab(v, 5000.0)
    sim.move_handle(h, sim.rest_positions[v] + [0.0, 1.0, 0.0])
    far = [sim.step().beyond_training for _ in range(10)]
    assert ld.OUTSIDE_TRAINING == 0.1 and max(far) > ld.OUTSIDE_TRAINING, far
    assert "beyond_training=" in repr(sim.stats.last)
    assert sim.stats.beyond_training == pytest.approx(max(far + [first.beyond_training]))
    sim.reset_stats()
    assert sim.stats.beyond_training is None
    # Full space has no training poses to leave.
    full = ld.Simulator(model, full_space=True)
    assert full.step().beyond_training is None and full.stats.beyond_training is None


def test_gravity_off_keeps_the_body_at_rest_and_reset_returns_to_rest(pca_path) -> None:
    sim = ld.Simulator(ld.Model.load(pca_path))
    rest = sim.rest_positions[sim.surface_vertices]
    assert sim.gravity
    sim.set_gravity(False)
    assert not sim.gravity
    for _ in range(5):
        sim.step()
    np.testing.assert_allclose(sim.surface_positions(), rest, atol=1e-9)
    sim.set_gravity(True)
    for _ in range(5):
        sim.step()
    sagged = sim.surface_positions()
    assert sagged[:, 1].min() < rest[:, 1].min() - 1e-5
    sim.reset()
    assert sim.steps == 0 and sim.time == 0.0
    np.testing.assert_allclose(sim.surface_positions(), rest, atol=1e-12)
    # Gravity turned upside down: the body rises about as far as it sagged.
    g = sim.gravity_acceleration
    sim.set_gravity_acceleration([-c for c in g])
    assert sim.gravity_acceleration == tuple(-c for c in g)
    for _ in range(5):
        sim.step()
    rise, sag = (sim.surface_positions() - rest)[:, 1].max(), (sagged - rest)[:, 1].min()
    assert 0.7 < rise / -sag < 1.3, (rise, sag)
    with pytest.raises(ld.InvalidArgumentError, match="g must be 3 numbers"):
        sim.set_gravity_acceleration([0.0, 1.0])


def test_grab_near_and_several_handles(sim: ld.Simulator) -> None:
    v = tip(sim)
    p = sim.rest_positions[v]
    a = sim.grab_near(p, 1e-6, 1000.0)
    b = sim.grab_near(p, 0.3, 1000.0)
    assert a != b and a == a and len({a, b}) == 2
    sim.move_handle(a, p + [0.0, 0.0, 0.05])
    sim.move_handle(b, p + [0.0, 0.0, 0.05])
    sim.step()
    sim.release(a)
    sim.release(b)
    sim.step()


def test_prepare_grab_leaves_the_steps_as_they_were(model: ld.Model) -> None:
    # The first grab's factorisation done ahead: the same drag, the same positions.
    def drag(prepare: bool) -> np.ndarray:
        s = ld.Simulator(model)
        if prepare:
            s.prepare_grab()
        v = tip(s)
        h = s.grab(v, 1000.0)
        s.move_handle(h, s.rest_positions[v] + [0.0, 0.05, 0.0])
        for _ in range(10):
            s.step()
        return s.positions()

    np.testing.assert_array_equal(drag(True), drag(False))
    ld.Simulator(model, full_space=True).prepare_grab()


def test_full_space_simulator_offers_the_same_api(model: ld.Model) -> None:
    full = ld.Simulator(model, full_space=True)
    reduced = ld.Simulator(model)
    assert full.full_space and not reduced.full_space
    assert full.vertex_count == reduced.vertex_count
    np.testing.assert_array_equal(full.surface_triangles, reduced.surface_triangles)
    for s in (full, reduced):
        v = tip(s)
        h = s.grab(v, 1000.0)
        s.move_handle(h, s.rest_positions[v] + [0.0, 0.05, 0.0])
        for _ in range(10):
            s.step()
    # The tiny model (latent dimension 2) follows full space only roughly: the tip moves the
    # same way in both, by similar amounts.
    v = tip(full)
    moved = [s.positions()[v] - s.rest_positions[v] for s in (full, reduced)]
    cosine = moved[0] @ moved[1] / np.linalg.norm(moved[0]) / np.linalg.norm(moved[1])
    assert cosine > 0.9, moved
    assert 0.5 < np.linalg.norm(moved[1]) / np.linalg.norm(moved[0]) < 2.0, moved
    assert "full space" in repr(full)


def test_rows_in_use_model_reads_the_surface_but_not_every_vertex(pca_path) -> None:
    model = ld.Model.load(pca_path)
    assert model.method == "pca-cubature" and not model.neural and not model.has_all_rows
    sim = ld.Simulator(model)
    sim.step()
    assert sim.surface_positions().shape == (sim.surface_vertex_count, 3)
    with pytest.raises(ld.InvalidArgumentError, match=r"no basis rows.*all_rows=True"):
        sim.positions()


def test_add_force_applies_springs_and_point_loads_as_data(model: ld.Model) -> None:
    # Full space and the reduced model alike; gravity off so that only the added forces act.
    for full_space in (True, False):
        sim = ld.Simulator(model, full_space=full_space)
        sim.set_gravity(False)
        v = tip(sim)
        start = sim.rest_positions[v].copy()
        rest = sim.rest_positions
        end_face = np.flatnonzero(rest[:, 0] > rest[:, 0].max() - 1e-9)
        # A point load of 20 N down spread over the free end, ramped in over 0.1 s (down: the
        # tiny model's subspace holds the sag its gravity-loaded training made, not much else).
        load = sim.add_force("point", end_face, [(0.0, 0, 0, 0), (0.1, 0, -20.0, 0)], end=None)
        for _ in range(10):
            sim.step()
        pushed = (sim.positions() - rest)[end_face].mean(axis=0)
        assert pushed[1] < -0.01 and np.abs(pushed[[0, 2]]).max() < 0.3 * -pushed[1], pushed
        # A point load is not a spring: it has no target to move.
        with pytest.raises(ld.HandleError):
            sim.move_handle(load, start)
        sim.release(load)
        sim.reset()
        # A spring pulling the tip 5 cm up from its rest centroid, from t = 0.04 s on.
        spring = sim.add_force(
            "spring", np.array([v]), np.array([[0.0, 0.0, 0.05, 0.0]]), stiffness=2000.0,
            start=0.04,
        )
        sim.step()
        np.testing.assert_allclose(sim.positions()[v], start, atol=1e-12)  # not active yet
        for _ in range(19):
            sim.step()
        lifted = sim.positions()[v, 1] - start[1]
        assert 0.005 < lifted < 0.06, lifted
        sim.release(spring)


@pytest.mark.parametrize(
    ("kind", "keyframes", "stiffness", "span", "needle"),
    [
        ("wind", [(0, 0, 0, 1)], None, (0.0, 1.0), "kind"),
        ("spring", [(0, 0, 0, 1)], None, (0.0, 1.0), "stiffness"),
        ("point", [(0, 0, 0, 1)], 10.0, (0.0, 1.0), "stiffness"),
        ("spring", [(0, 0, 0, 1)], -1.0, (0.0, 1.0), "stiffness"),
        ("point", [], None, (0.0, 1.0), "keyframe"),
        ("point", [(1, 0, 0, 1), (0, 0, 0, 1)], None, (0.0, 1.0), "keyframe"),
        ("point", [(0, 0, 0)], None, (0.0, 1.0), "row 0 has 3 numbers"),
        ("point", [(0, 0, 0, 1)], None, (1.0, 0.5), "span"),
        ("point", [(0, 0, 0, 1)], None, (-1.0, 0.0), "would never act"),
    ],
)
def test_add_force_refuses_what_cannot_work(
    sim: ld.Simulator, kind, keyframes, stiffness, span, needle
) -> None:
    v = tip(sim)
    with pytest.raises(ld.InvalidArgumentError, match=needle):
        sim.add_force(kind, v, keyframes, stiffness=stiffness, start=span[0], end=span[1])


def test_a_copy_steps_as_the_original_and_rolls_back(sim: ld.Simulator) -> None:
    import copy

    v = tip(sim)
    h = sim.grab(v, 2000.0)
    start = sim.rest_positions[v].mean(axis=0)

    def drag(s: ld.Simulator, n: int) -> np.ndarray:
        for i in range(n):
            s.move_handle(h, start + [0.0, 0.0, 0.002 * i])
            s.step()
        return s.surface_positions()

    drag(sim, 5)
    saved = sim.copy()
    ahead = drag(sim, 10)
    for again in (saved.copy(), copy.copy(saved), copy.deepcopy(saved)):
        np.testing.assert_array_equal(drag(again, 10), ahead)
        assert again.steps == sim.steps
    late = saved.grab(v, 100.0)
    with pytest.raises(ld.HandleError, match="made on a copy"):
        sim.release(late)
    sim.release(h)


def test_targets_loads_handles_and_velocities(sim: ld.Simulator) -> None:
    v = [tip(sim)]
    before = sim.surface_positions()
    sim.step()
    h = sim.model.time_step
    velocity = sim.surface_velocities()
    assert velocity.shape == before.shape and velocity.dtype == np.float64
    np.testing.assert_allclose(velocity, (sim.surface_positions() - before) / h, atol=1e-9)
    spring = sim.grab(v, 1000.0)
    sim.move_handle(spring, (1.0, 0.2, 0.1))
    np.testing.assert_allclose(sim.handle_target(spring), (1.0, 0.2, 0.1), atol=1e-12)
    load = sim.add_force("point", v, [(0.0, 0.0, 0.0, 0.0)])
    assert sim.handles() == [spring, load]
    sim.set_load(load, (0.0, 0.0, 5.0))
    sim.step()
    with pytest.raises(ld.HandleError, match="only a point load"):
        sim.set_load(spring, (0.0, 0.0, 1.0))
    with pytest.raises(ld.HandleError, match="only a spring"):
        sim.handle_target(load)
    sim.release(spring)
    assert sim.handles() == [load]
