"""Round trip against the Rust runtime: the same script of interactions replayed by the
latent-sim example `replay` (a separate Rust program over the same model file) and through
this module gives the same trajectory, step by step, to 1e-12 (in fact to the bit)."""

from __future__ import annotations

import json
import pathlib
import shutil
import subprocess

import numpy as np
import pytest

import latent_dynamics as ld

ROOT = pathlib.Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def replay() -> pathlib.Path:
    """The example's executable, built (or found fresh) by cargo."""
    cargo = shutil.which("cargo")
    if cargo is None:
        pytest.skip("cargo is not on PATH: the Rust side of the round trip cannot be built")
    built = subprocess.run(
        [cargo, "build", "--release", "-p", "latent-sim", "--example", "replay",
         "--message-format=json-render-diagnostics"],
        cwd=ROOT, check=True, capture_output=True, text=True,
    )
    for line in built.stdout.splitlines():
        message = json.loads(line)
        if message.get("reason") == "compiler-artifact" and message["target"]["name"] == "replay":
            return pathlib.Path(message["executable"])
    raise AssertionError("cargo built no replay executable")


def script_for(sim: ld.Simulator, gravity_off: bool) -> str:
    """Grab the tip, drag it up and sideways, grab a second patch near the middle, let go of
    the first, reset, drag again: every action the script language has."""
    rest = sim.rest_positions
    surface = sim.surface_vertices
    tip = int(surface[rest[surface, 0].argmax()])
    p = rest[tip]
    middle = rest[surface].mean(axis=0) + [0.0, 0.0, 0.1]
    def f(x: float) -> str:
        return repr(float(x))  # the shortest form that reads back to the same double

    lines = [f"grab 1500 {tip}"]
    for k in range(1, 13):
        lines += [f"move 0 {f(p[0])} {f(p[1] + 0.01 * k)} {f(p[2] + 0.004 * k)}", "step"]
    lines.append(f"grab_near {f(middle[0])} {f(middle[1])} {f(middle[2])} 0.25 800")
    lines += [f"move 1 {f(middle[0])} {f(middle[1] - 0.03)} {f(middle[2])}", "step", "step"]
    lines += ["release 0", "step", "step"]
    if gravity_off:
        lines += ["gravity off", "step", "step", "gravity on"]
    lines += ["reset", "step", f"move 1 {f(middle[0])} {f(middle[1] + 0.05)} {f(middle[2])}"]
    lines += ["step"] * 5
    return "\n".join(lines) + "\n"


def play(sim: ld.Simulator, script: str) -> list[tuple[int, float, int, np.ndarray]]:
    """The script through this module, with the surface after each step."""
    handles: list[ld.Handle] = []
    out = []
    for line in script.splitlines():
        action, *args = line.split()
        if action == "grab":
            handles.append(sim.grab([int(v) for v in args[1:]], float(args[0])))
        elif action == "grab_near":
            x, y, z, radius, stiffness = map(float, args)
            handles.append(sim.grab_near((x, y, z), radius, stiffness))
        elif action == "move":
            sim.move_handle(handles[int(args[0])], [float(a) for a in args[1:]])
        elif action == "release":
            sim.release(handles[int(args[0])])
        elif action == "gravity":
            sim.set_gravity(args[0] == "on")
        elif action == "reset":
            sim.reset()
        elif action == "step":
            s = sim.step()
            out.append((s.step, s.time, s.iterations, sim.surface_positions()))
        else:
            raise AssertionError(action)
    return out


def rust(replay: pathlib.Path, model: pathlib.Path, script: str, tmp: pathlib.Path, full: bool):
    path = tmp / "script.txt"
    path.write_text(script)
    args = [str(replay), str(model), str(path)] + (["--full"] if full else [])
    done = subprocess.run(args, check=True, capture_output=True, text=True)
    frames = []
    for line in done.stdout.splitlines():
        words = line.split()
        xyz = np.array([float(w) for w in words[3:]]).reshape(-1, 3)
        frames.append((int(words[0]), float(words[1]), int(words[2]), xyz))
    return frames


@pytest.mark.parametrize(
    "which, full",
    [("neural", False), ("neural", True), ("pca", False), ("pca", True)],
)
def test_same_trajectory_as_the_rust_runtime(
    replay, neural_path, pca_path, tmp_path, which: str, full: bool
) -> None:
    path = neural_path if which == "neural" else pca_path
    sim = ld.Simulator(ld.Model.load(path), full_space=full)
    # Gravity off from rest is only asked of PCA (see docs/python.md).
    script = script_for(sim, gravity_off=which == "pca")
    ours = play(sim, script)
    theirs = rust(replay, path, script, tmp_path, full)
    assert len(ours) == len(theirs) == script.count("step")
    moved = max(np.abs(f - ours[0][3]).max() for *_, f in ours)
    assert moved > 0.01, "the script should move the body"
    for (s, t, i, x), (rs, rt, ri, rx) in zip(ours, theirs):
        assert (s, t, i) == (rs, rt, ri)
        assert x.shape == rx.shape
        assert np.abs(x - rx).max() <= 1e-12
