"""The example scripts run start to end on a model (plotting only where matplotlib is)."""

from __future__ import annotations

import pathlib
import subprocess
import sys

import pytest

EXAMPLE = pathlib.Path(__file__).resolve().parents[1] / "examples" / "drag.py"
GAME_LOOP = EXAMPLE.with_name("game_loop.py")


def test_drag_example_runs(neural_path: pathlib.Path, tmp_path: pathlib.Path) -> None:
    plot = tmp_path / "drag.png"
    done = subprocess.run(
        [sys.executable, str(EXAMPLE), str(neural_path), "--plot", str(plot)],
        check=True, capture_output=True, text=True,
    )
    assert "steps/s inside the library" in done.stdout
    assert "iterations per step" in done.stdout
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        assert "no plot" in done.stdout and not plot.exists()
    else:
        assert plot.stat().st_size > 0


@pytest.mark.parametrize("full", [False, True])
def test_game_loop_example_runs_every_phase(neural_path: pathlib.Path, full: bool) -> None:
    done = subprocess.run(
        [sys.executable, str(GAME_LOOP), str(neural_path)] + (["--full"] if full else []),
        check=True, capture_output=True, text=True,
    )
    lines = done.stdout.splitlines()
    assert lines[0].endswith(", stepped in full space") == full, lines[0]
    summary = next(line for line in lines if " steps: mean " in line)
    assert "Newton fallbacks" in summary and "0 failed steps" in summary, done.stdout
    table = lines[lines.index(next(line for line in lines if line.startswith("phase"))) + 1:]
    phases = [line[:18].strip() for line in table]
    assert phases == [
        "settle", "drag 1", "drag 1, held", "drag 1, let go", "drag 2", "drag 2, held",
        "drag 2, let go", "whip", "whip, let go", "punch", "punch, after", "wind",
        "gravity sideways", "gravity up", "gravity back",
    ], done.stdout
    # Every phase's steps at the model's time step add up to the summary's count.
    counts = [int(line[18:24]) for line in table]
    assert int(summary.split()[0]) == sum(counts) and all(c > 0 for c in counts)
    # How far beyond the training poses: said for the reduced model, not in full space.
    beyond = [line.split()[-1] for line in table]
    assert any("beyond the training poses" in line for line in lines) != full, done.stdout
    assert all((b == "–") == full for b in beyond), done.stdout
