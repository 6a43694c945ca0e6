"""run_pipeline and export_model: the stages and cache of `cargo xtask`, the report as Python
objects matching report.json."""

from __future__ import annotations

import json
import math
import os
import pathlib
import signal
import threading
import time

import latent_dynamics as ld
import pytest
from conftest import TINY


def test_run_reports_every_method_and_reuses_the_cache(tmp_path: pathlib.Path) -> None:
    out, cache = tmp_path / "out", tmp_path / "cache"
    methods = ["full", "pca", "pca-cubature", "neural-cubature"]
    report = ld.run_pipeline(TINY, out_dir=out, cache_dir=cache, methods=methods)
    assert report.scene == "tiny" and report.out_dir == out
    assert [r.method for r in report.rows] == methods
    assert report.stages and not any(s.cached for s in report.stages)
    assert {"snapshots", "pca"} <= {s.name for s in report.stages}
    for s in report.stages:
        assert s.path.exists() and s.summary and s.seconds >= 0
    written = json.loads((out / "report.json").read_text())
    assert written["format"] == "latent-dynamics run report" and written["version"] == 2
    assert written["scene"] == "tiny" and written["trajectory"] == 0
    assert [s["stage"] for s in written["stages"]] == [s.name for s in report.stages]
    assert [r["method"] for r in written["methods"]] == methods
    for row, raw in zip(report.rows, written["methods"]):
        assert row.dimension == raw["dim"] and row.elements == raw["cubature_elements"]
        assert row.ms_per_step == raw["ms_per_step"] and row.ms_per_step > 0
        assert row.timed_runs == raw["timed_runs"] >= 1
        assert row.mean_rel_error == raw["mean_rel_error"]
        assert row.trajectory_error == raw["trajectory_error"] >= 0.0
        assert row.frame_errors == raw["frame_errors"]
        # What full space has none of is null in report.json and None here.
        for key in ["subspace_error", "step_error", "training_distance", "training_distance_time"]:
            assert getattr(row, key) == raw[key]
            assert (raw[key] is None) == (row.method == "full"), (row.method, key)
        assert row.method == "full" or row.training_distance >= 0.0
        assert row.step_restarts == raw["step_restarts"] >= 0
        assert row.failure is None
    full = report.row("full")
    assert full.mean_rel_error == 0.0 and full.trajectory_error == 0.0 and full.speedup == 1.0
    cubature = report.row("pca-cubature")
    # Six PCA columns and the three positions of the beam's fall under gravity they miss.
    assert cubature.dimension == 6 + 3 and 0 < cubature.elements < full.elements
    assert 0 < cubature.mean_rel_error < 1 and math.isfinite(cubature.iterations)
    # The tiny beam's cheap trajectory is timed again, full space once.
    assert cubature.timed_runs > 1 and full.timed_runs == 1
    assert report.row("neural-cubature").dimension >= 2
    assert isinstance(report.warnings, list)
    assert isinstance(report.caveats, list)
    assert report.model_path == out / "neural-cubature.ldm"
    model = ld.Model.load(report.model_path)
    assert model.method == "neural-cubature"
    assert any("test trajectory" in name for name, held_out, _ in model.errors if held_out)
    # Every stage is cached now: the same run loads them all.
    again = ld.run_pipeline(TINY, out_dir=out, cache_dir=cache, methods="pca")  # one name, as ["pca"]
    assert again.stages and all(s.cached for s in again.stages)
    assert again.row("pca").mean_rel_error == report.row("pca").mean_rel_error
    # No full-space solver ran beside it, so there is no speed-up to give.
    assert again.row("pca").speedup is None and report.row("pca").speedup > 0
    # A method that did not run is named with the ones that did.
    with pytest.raises(ld.InvalidArgumentError, match='"neural" in this report; its rows are pca'):
        again.row("neural")


def test_export_writes_a_model_that_loads(tmp_path: pathlib.Path, cache_dir) -> None:
    used = ld.export_model(TINY, "pca", path=tmp_path / "a.ldm", cache_dir=cache_dir)
    assert used.path == tmp_path / "a.ldm" and used.path.exists()
    assert used.method == "pca" and used.elements == used.tet_count
    loaded = ld.Model.load(used.path)
    assert (loaded.latent_dim, loaded.vertex_count) == (used.latent_dim, used.vertex_count)


def test_on_stage_sees_each_stage_and_its_exception_is_raised(tmp_path: pathlib.Path) -> None:
    seen: list[ld.Stage] = []
    model = ld.export_model(
        TINY, "pca", path=tmp_path / "a.ldm", cache_dir=tmp_path / "cache", on_stage=seen.append
    )
    assert [s.name for s in seen] == ["snapshots", "pca", "coverage"] and not any(s.cached for s in seen)
    assert model.path.exists()

    called: list[str] = []

    def fail(stage: ld.Stage) -> None:
        called.append(stage.name)
        raise RuntimeError(f"stop at {stage.name}")

    try:
        ld.run_pipeline(TINY, out_dir=tmp_path, cache_dir=tmp_path / "cache", methods=["pca"], on_stage=fail)
    except RuntimeError as e:
        # The exception stops the run at once: no later stage, no report.
        assert len(called) == 1 and str(e) == f"stop at {called[0]}"
    else:
        raise AssertionError("the callback's exception was not raised")
    assert not (tmp_path / "report.json").exists()
    try:
        ld.run_pipeline(TINY, out_dir=tmp_path, methods=["pca"], on_stage=42)
    except ld.InvalidArgumentError as e:
        assert "callable" in str(e)
    else:
        raise AssertionError("a callback that is not callable was accepted")


def test_on_progress_hears_the_stages_computing_and_the_methods_running(tmp_path: pathlib.Path) -> None:
    """on_progress gets (what, done, total) from the stages as they compute and from each
    method's run, its first report at once; a stage loaded from the cache reports nothing."""
    heard: list[tuple[str, int, int]] = []
    cache = tmp_path / "cache"
    ld.run_pipeline(TINY, out_dir=tmp_path, cache_dir=cache, methods=["full", "pca"],
                    on_progress=lambda what, done, total: heard.append((what, done, total)))
    names = {what for what, _, _ in heard}
    # `full` is the test's reference, a stage computed (and then cached) like the others.
    assert {"snapshots", "reference", "run pca"} <= names, heard
    # Each one's first and last report: a bar fed from it finishes.
    assert ("snapshots", 4, 4) in heard and ("run pca", 12, 12) in heard, heard
    assert all(isinstance(d, int) and isinstance(t, int) and 0 <= d <= max(t, d) for _, d, t in heard)
    assert any(t == 4 for what, _, t in heard if what == "snapshots"), heard  # its 4 schedules
    heard.clear()
    ld.run_pipeline(TINY, out_dir=tmp_path, cache_dir=cache, methods=["pca"],
                    on_progress=lambda what, done, total: heard.append((what, done, total)))
    assert "snapshots" not in {what for what, _, _ in heard}, heard
    with pytest.raises(ld.InvalidArgumentError, match="on_progress must be callable"):
        ld.run_pipeline(TINY, out_dir=tmp_path, cache_dir=cache, methods=["pca"], on_progress=3)


def test_what_the_library_warns_of_arrives_as_a_python_warning(tmp_path: pathlib.Path) -> None:
    """A WARN line of cargo xtask (here: a density no solid has) is a PipelineWarning, a
    UserWarning the warnings filters see."""
    text = TINY.read_text()
    assert "density = 1000.0" in text
    scene = tmp_path / "light.toml"
    scene.write_text(text.replace("density = 1000.0", "density = 2.0"))
    assert issubclass(ld.PipelineWarning, UserWarning)
    with pytest.warns(ld.PipelineWarning, match="density") as caught:
        ld.export_model(scene, "pca", path=tmp_path / "a.ldm", cache_dir=tmp_path / "cache")
    assert any(str(scene.name) in str(w.message) for w in caught), [str(w.message) for w in caught]


def test_ctrl_c_stops_a_run_at_its_next_progress_report(tmp_path: pathlib.Path) -> None:
    """Ctrl-C while the pipeline runs without the GIL raises KeyboardInterrupt at the pipeline's
    next progress report (here the next of many short training schedules), not when the stage
    or the pipeline ends, and leaves no artifact of the stage it stopped."""
    text = TINY.read_text()
    scene = tmp_path / "many-schedules.toml"
    # Schedules of a few tens of ms each, so many that the stage would take a minute or more.
    for old, new in [("cells = [6, 1, 1]", "cells = [24, 4, 4]"),
                     ("schedules = 4\nframes_per_schedule = 8", "schedules = 4000\nframes_per_schedule = 20")]:
        assert old in text
        text = text.replace(old, new)
    scene.write_text(text)
    stages: list[ld.Stage] = []
    cache = tmp_path / "cache"
    sent: list[float] = []

    def interrupt() -> None:
        sent.append(time.monotonic())
        os.kill(os.getpid(), signal.SIGINT)

    # Python turns SIGINT into KeyboardInterrupt only where it was not ignored when the
    # interpreter started, and a shell that runs a command in the background (`cmd &`) starts it
    # ignored: there the signal vanished and the 4,000 schedules ran to their end (stop 63's
    # failed CI run). A terminal's Ctrl-C reaches the default handler, which the test installs.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.5, interrupt)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            ld.run_pipeline(scene, out_dir=tmp_path, cache_dir=cache, on_stage=stages.append)
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
    # Well within the stage (the bound is loose for a busy machine; a stop at the stage's end
    # would take the whole minute).
    assert sent and time.monotonic() - sent[0] < 20.0
    assert stages == []
    assert cache.is_dir() and list(cache.iterdir()) == []


def test_run_trajectories_reports_each_drag(tmp_path: pathlib.Path) -> None:
    out, cache = tmp_path / "out", tmp_path / "cache"
    methods = ["full", "pca"]
    single = ld.run_pipeline(TINY, out_dir=tmp_path / "one", cache_dir=cache, methods=methods)
    reports = ld.run_trajectories(TINY, 3, out_dir=out, cache_dir=cache, methods=methods)
    assert len(reports) == 3
    assert [r.out_dir for r in reports] == [out, out / "trajectory-1", out / "trajectory-2"]
    # Trajectory 0 is run_pipeline's test, from the same cache: every stage loaded.
    assert reports[0].stages and all(s.cached for s in reports[0].stages)
    assert reports[0].row("pca").frame_errors == single.row("pca").frame_errors
    # The others compute their reference and nothing else.
    for r in reports[1:]:
        assert [s.name for s in r.stages if not s.cached] == ["reference"]
    errors = [r.row("pca").mean_rel_error for r in reports]
    assert len(set(errors)) == 3
    table = json.loads((out / "trajectories.json").read_text())
    pca = next(t for t in table if t["method"] == "pca")
    assert pca["errors"] == pytest.approx(errors, rel=1e-15)
    assert pca["mean"] == pytest.approx(sum(errors) / 3, rel=1e-12)
    assert (out / "trajectories.md").read_text().startswith("| method |")
    for count in (0, -1, 65):
        with pytest.raises(ld.InvalidArgumentError, match="count"):
            ld.run_trajectories(TINY, count, out_dir=out, cache_dir=cache)
