"""Fixtures: models of the tiny scene (tests/data/tiny.toml) made by the pipeline once per
session, in a temporary folder, through the module's own export_model."""

from __future__ import annotations

import pathlib

import pytest

import latent_dynamics as ld

DATA = pathlib.Path(__file__).parent / "data"
TINY = DATA / "tiny.toml"


def pytest_configure(config: pytest.Config) -> None:
    # The tiny scene is one element thick on purpose (it is fast), and every pipeline call on it
    # says so; the tests that look for warnings catch them with pytest.warns all the same.
    config.addinivalue_line(
        "filterwarnings", "ignore:.*about one element thick:latent_dynamics.PipelineWarning"
    )


@pytest.fixture(scope="session")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    return tmp_path_factory.mktemp("latent-dynamics")


@pytest.fixture(scope="session")
def cache_dir(workdir: pathlib.Path) -> pathlib.Path:
    return workdir / "cache"


@pytest.fixture(scope="session")
def neural_path(workdir: pathlib.Path, cache_dir: pathlib.Path) -> pathlib.Path:
    """The tiny scene's neural-cubature model, keeping every vertex's basis rows."""
    path = workdir / "neural-cubature.ldm"
    ld.export_model(TINY, "neural-cubature", path=path, cache_dir=cache_dir, all_rows=True)
    return path


@pytest.fixture(scope="session")
def pca_path(workdir: pathlib.Path, cache_dir: pathlib.Path) -> pathlib.Path:
    """A pca-cubature model with the rows in use only (the default export), of the tiny scene
    8×3×3 cells, so that some vertices inside the mesh belong to no evaluated element."""
    scene = workdir / "tiny-thick.toml"
    text = TINY.read_text().replace("cells = [6, 1, 1]", "cells = [8, 3, 3]")
    assert text != TINY.read_text()
    scene.write_text(text.replace('name = "tiny"', 'name = "tiny-thick"'))
    path = workdir / "pca-cubature.ldm"
    ld.export_model(scene, "pca-cubature", path=path, cache_dir=cache_dir)
    return path


@pytest.fixture()
def model(neural_path: pathlib.Path) -> ld.Model:
    return ld.Model.load(neural_path)


@pytest.fixture()
def sim(model: ld.Model) -> ld.Simulator:
    return ld.Simulator(model)


def tip(sim: ld.Simulator) -> int:
    """The surface vertex farthest along x (the free end of the beam pinned at x = 0)."""
    rest = sim.rest_positions
    surface = sim.surface_vertices
    return int(surface[rest[surface, 0].argmax()])
