"""Every exception class, raised with the library's message, and the state left usable."""

from __future__ import annotations

import itertools
import math
import pathlib

import numpy as np
import pytest

import latent_dynamics as ld
from conftest import TINY, tip

CLASSES = [
    ld.ModelFileError,
    ld.SceneError,
    ld.SolverError,
    ld.PipelineError,
    ld.HandleError,
    ld.InvalidArgumentError,
]


def test_hierarchy() -> None:
    assert issubclass(ld.LatentDynamicsError, Exception)
    for cls in CLASSES:
        assert issubclass(cls, ld.LatentDynamicsError), cls
        assert cls.__module__ == "latent_dynamics" and cls.__doc__
    assert issubclass(ld.SceneError, ValueError)
    assert issubclass(ld.InvalidArgumentError, ValueError)
    assert issubclass(ld.HandleError, LookupError)
    assert not issubclass(ld.SolverError, ValueError)


def test_model_file_errors(neural_path: pathlib.Path, tmp_path: pathlib.Path) -> None:
    missing = tmp_path / "missing.ldm"
    with pytest.raises(ld.ModelFileError, match="missing.ldm: cannot read"):
        ld.Model.load(missing)
    good = neural_path.read_bytes()
    cases = {
        "truncated": (good[: len(good) // 2], "truncated"),
        "corrupted": (good[:-10] + bytes([good[-10] ^ 1]) + good[-9:], "checksum"),
        "foreign": (b"name = 'a scene, not a model'\n" * 4, "not a latent-dynamics model"),
        "appended": (good + b"\0", "follow the payload"),
    }
    for name, (data, message) in cases.items():
        path = tmp_path / f"{name}.ldm"
        path.write_bytes(data)
        with pytest.raises(ld.ModelFileError, match=message):
            ld.Model.load(path)
    model = ld.Model.load(neural_path)
    not_a_folder = tmp_path / "file.txt"
    not_a_folder.write_text("a file")
    with pytest.raises(ld.ModelFileError, match="cannot write"):
        model.save(not_a_folder / "model.ldm")


def test_scene_errors(tmp_path: pathlib.Path) -> None:
    cache = tmp_path / "cache"
    with pytest.raises(ld.SceneError, match="cannot read scene file"):
        ld.run_pipeline(tmp_path / "missing.toml", cache_dir=cache, out_dir=tmp_path)
    text = TINY.read_text()
    cases = {
        "typo": (text.replace("youngs_modulus", "youngs_modulos"), "youngs_modulos"),
        "negative": (text.replace("youngs_modulus = 1.0e5", "youngs_modulus = -1.0"), "youngs_modulus"),
        "mesh": (text.replace('generate = { kind = "box", size = [1.0, 0.2, 0.2], cells = [6, 1, 1] }', 'path = "nowhere.mesh"'), "nowhere.mesh"),
    }
    for name, (scene_text, message) in cases.items():
        scene = tmp_path / f"{name}.toml"
        scene.write_text(scene_text)
        assert scene_text != text
        with pytest.raises(ld.SceneError, match=message):
            ld.run_pipeline(scene, cache_dir=cache, out_dir=tmp_path / name)
        with pytest.raises(ValueError):
            ld.export_model(scene, "pca", cache_dir=cache, path=tmp_path / "m.ldm")


def test_a_failed_step_raises_solver_error_and_keeps_the_state(sim: ld.Simulator) -> None:
    sim.step()
    before = sim.positions()
    # A spring pulled 1e200 m away: the step's energy overflows. (A stiffness of 1e300 N/m is
    # refused when grabbing since 2026-12-02; the stiff spring alone would not overflow anyway:
    # in series with the patch compliance the basis lacks, its pull is bounded by the patch's
    # own stiffness.)
    with pytest.raises(ld.InvalidArgumentError, match="give at most 1.039e11 N/m"):
        sim.grab(tip(sim), 1e300)
    h = sim.grab(tip(sim), 1e10)
    sim.move_handle(h, (1e200, 0.0, 0.0))
    with pytest.raises(ld.SolverError, match="non-finite value in energy .* at step 2"):
        sim.step()
    assert sim.steps == 1
    np.testing.assert_array_equal(sim.positions(), before)
    sim.release(h)
    sim.step()
    assert sim.steps == 2


def test_a_failed_stage_raises_pipeline_error_with_the_solver_message(tmp_path: pathlib.Path) -> None:
    scene = tmp_path / "stiff.toml"
    # Every schedule fails at its first step (one that fails later keeps its earlier frames and
    # the stage goes on); the training family's tolerance is its own, by default the looser 1e-3.
    scene.write_text(
        TINY.read_text()
        .replace("tolerance = 1.0e-8", 'method = "newton"\ntolerance = 1.0e-15\nmax_iterations = 1')
        .replace("[training]\n", "[training]\ntolerance = 1.0e-15\n")
    )
    with pytest.raises(ld.PipelineError, match="stage snapshots: every training schedule.* did not converge"):
        ld.export_model(scene, "pca", cache_dir=tmp_path / "cache", path=tmp_path / "m.ldm")


def test_pipeline_error(tmp_path: pathlib.Path, cache_dir: pathlib.Path) -> None:
    # An output folder that cannot be made: a file stands where it would go.
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    with pytest.raises(ld.PipelineError, match="a-file"):
        ld.run_pipeline(TINY, cache_dir=cache_dir, out_dir=blocker / "out", methods=["pca"])
    # So is a cache folder that cannot be made: the scene is fine, the run cannot write.
    with pytest.raises(ld.PipelineError, match="cache folder"):
        ld.run_pipeline(TINY, cache_dir=blocker / "cache", out_dir=tmp_path / "out", methods=["pca"])


def test_handle_errors(model: ld.Model) -> None:
    a, b = ld.Simulator(model), ld.Simulator(model)
    h = a.grab(tip(a), 100.0)
    with pytest.raises(ld.HandleError, match="another|not to this one"):
        b.move_handle(h, (0.0, 0.0, 0.0))
    with pytest.raises(ld.HandleError):
        b.release(h)
    a.release(h)
    with pytest.raises(ld.HandleError, match="released already"):
        a.release(h)
    with pytest.raises(ld.HandleError, match="released already"):
        a.move_handle(h, (0.0, 0.0, 0.0))
    with pytest.raises(ld.HandleError, match="no surface vertex within"):
        a.grab_near((10.0, 10.0, 10.0), 0.1, 100.0)
    with pytest.raises(LookupError):
        a.grab_near((10.0, 10.0, 10.0), 0.1, 100.0)


def test_invalid_arguments(sim: ld.Simulator) -> None:
    n, m = sim.vertex_count, sim.surface_vertex_count
    bad = [
        (lambda: sim.grab([], 1.0), "at least one vertex"),
        (lambda: sim.grab([n], 1.0), f"vertex {n} does not exist"),
        (lambda: sim.grab(-1, 1.0), "negative"),
        (lambda: sim.grab("12", 1.0), "sequence of ints"),
        (lambda: sim.grab(True, 1.0), "got bool"),
        (lambda: sim.grab(2**64, 1.0), "vertex 18446744073709551616 does not exist"),
        (lambda: sim.grab([0, 2**64], 1.0), r"vertices\[1\] = 18446744073709551616 does not exist"),
        (lambda: sim.grab([0, 1.5], 1.0), r"vertices\[1\] must be an int, got 1.5"),
        (lambda: sim.grab([True], 1.0), r"vertices\[0\] is a bool"),
        (lambda: sim.grab(np.array([True, False]), 1.0), "boolean array"),
        (lambda: sim.grab(np.array([0.0, 1.0]), 1.0), r"vertices\[0\] must be an int"),
        (lambda: sim.grab([0], 0.0), "stiffness must be positive"),
        (lambda: sim.grab([0], -5.0), "stiffness must be positive"),
        (lambda: sim.grab([0], math.nan), "stiffness must be positive"),
        (lambda: sim.grab_near((math.nan, 0.0, 0.0), 0.1, 1.0), "point must be finite"),
        (lambda: sim.grab_near((0.0, 0.0, 0.0), 0.0, 1.0), "radius must be positive"),
        (lambda: sim.grab_near((0.0, 0.1), 0.1, 1.0), r"point must be 3 numbers \(x, y, z\), got 2"),
        (lambda: sim.grab_near((10**400, 0.0, 0.0), 0.1, 1.0), r"got int as item 0, which is no float \(.*too large"),
        (lambda: sim.grab_near(itertools.count(), 0.1, 1.0), r"point must be 3 numbers \(x, y, z\), got count"),
        (lambda: sim.grab_near(range(10**12), 0.1, 1.0), r"point must be 3 numbers \(x, y, z\), got 1000000000000"),
        # Lists reserved or read whole, once until memory ran out: refused by their length first.
        (lambda: sim.grab(range(10**12), 1.0), f"16 for each of the mesh's {n} vertices"),
        (lambda: sim.grab(itertools.count(), 1.0), f"16 for each of the mesh's {n} vertices"),
        (lambda: sim.add_force("point", [0], range(10**12)), "keyframes has 1000000000000 rows"),
        (lambda: sim.add_force("point", [0], range(2**62)), "keyframes has 4611686018427387904 rows"),
        (lambda: ld.run_pipeline(TINY, methods=range(10**12)), "methods lists 1000000000000 items"),
        (lambda: sim.move_handle(sim.grab([tip(sim)], 1.0), np.zeros((3, 1))), r"got an array of shape \[3, 1\]"),
        (lambda: sim.move_handle(sim.grab([tip(sim)], 1.0), "abc"), "target must be 3 numbers"),
        (lambda: sim.move_handle(sim.grab([tip(sim)], 1.0), (0.0, math.inf, 0.0)), "target must be finite"),
        (lambda: sim.positions(out=np.empty((n, 2))), r"expected \(%d, 3\)" % n),
        (lambda: sim.positions(out=np.empty((n, 3), dtype=np.float32)), "float64"),
        (lambda: sim.positions(out=[[0.0] * 3] * n), "numpy array"),
        (lambda: sim.surface_positions(np.int32), "float32 or float64"),
        (lambda: sim.surface_positions("no such dtype"), "dtype"),
        (lambda: sim.surface_positions(">f8"), "other byte order"),
        (lambda: sim.grab(np.array([[0, 1], [2, 3]]), 1.0), "1-D array"),
        (lambda: sim.surface_positions(out=np.empty((m + 1, 3))), "expected"),
        (lambda: ld.run_pipeline(TINY, methods=["nerual"]), "unknown method"),
        (lambda: ld.run_pipeline(TINY, methods=[]), "at least one"),
        (lambda: ld.run_pipeline(TINY, methods=["pca", "pca"]), "names pca twice"),
        (lambda: ld.run_pipeline(TINY, methods=3), "a list of method names"),
        (lambda: ld.run_pipeline(TINY, methods=["pca", 3]), r"methods\[1\] must be a method name \(a str\), got int"),
        (lambda: ld.run_pipeline(TINY, trajectory=-1), "trajectory must be 0 or more"),
        (lambda: ld.run_pipeline(TINY, every=-1), "every must be 0 or more"),
        (lambda: ld.run_trajectories(TINY, 2, every=-1), "every must be 0 or more"),
        (lambda: ld.export_model(TINY, "full"), "full-space method"),
    ]
    for call, message in bad:
        with pytest.raises(ld.InvalidArgumentError, match=message):
            call()
    # Read-only arrays are refused rather than written.
    frozen = np.empty((m, 3))
    frozen.flags.writeable = False
    with pytest.raises(ld.InvalidArgumentError, match="cannot be written"):
        sim.surface_positions(out=frozen)
    # The simulator still works after every refusal.
    sim.step()
    assert sim.steps == 1


def test_a_grab_of_pinned_vertices_only_is_refused(sim: ld.Simulator) -> None:
    rest = sim.rest_positions
    clamped = [int(v) for v in sim.surface_vertices if rest[v, 0] < 1e-9]
    with pytest.raises(ld.InvalidArgumentError, match="all pinned"):
        sim.grab(clamped[:3], 100.0)
    # A point load on them is refused in its own words, not a grab's.
    with pytest.raises(ld.InvalidArgumentError, match="a spring or a load on them moves nothing"):
        sim.add_force("point", clamped[:3], [(0.0, 0.0, 0.0, 1.0)])
