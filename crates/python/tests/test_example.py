"""The example script runs start to end on a model (plotting only where matplotlib is)."""

from __future__ import annotations

import pathlib
import subprocess
import sys

EXAMPLE = pathlib.Path(__file__).resolve().parents[1] / "examples" / "drag.py"


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
