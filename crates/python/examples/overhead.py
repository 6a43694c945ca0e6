"""Measures what calling the library from Python costs: the time a step takes called from Python
against the same step's time inside the library, and the time to read positions into numpy.

    python crates/python/examples/overhead.py MODEL [--steps N]

Steps are timed in pairs: each call's wall time around `sim.step()` in Python and the step's
own wall time measured inside the Rust runtime (`StepStats.seconds`, what a Rust program calling
`step()` sees). Their difference is what the binding adds per call (argument handling, letting
go of the GIL and taking it back, the simulator's mutex, the StepStats object), measured on the
very same steps, so the machine's drift between runs does not enter. The model is dragged by
one vertex (up, then let go), as in examples/drag.py, so the steps are the interactive kind.
"""

from __future__ import annotations

import argparse
import pathlib
import statistics
import time

import numpy as np

import latent_dynamics as ld


def timed(f, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        t = time.perf_counter_ns()
        f()
        out.append((time.perf_counter_ns() - t) * 1e-9)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", type=pathlib.Path)
    parser.add_argument("--steps", type=int, default=2000)
    args = parser.parse_args()

    model = ld.Model.load(args.model)
    sim = ld.Simulator(model)
    print(f"{model}, surface {sim.surface_vertex_count} of {sim.vertex_count} vertices")
    rest = sim.rest_positions
    surface = sim.surface_vertices
    vertex = int(surface[np.linalg.norm(rest[surface] - rest[model.pinned].mean(axis=0), axis=1).argmax()])
    handle = sim.grab(vertex, 1e-3 * model.youngs_modulus * 0.2)
    period = max(2, round(1.0 / model.time_step))

    outside, inside = [], []
    for k in range(args.steps):
        phase = k % (2 * period)
        if phase == 0:
            sim.reset()
        if phase < period:
            sim.move_handle(handle, rest[vertex] + [0.0, 0.2 * 0.2 * phase / period, 0.0])
        t = time.perf_counter_ns()
        stats = sim.step()
        outside.append((time.perf_counter_ns() - t) * 1e-9)
        inside.append(stats.seconds)
    added = [o - i for o, i in zip(outside, inside)]
    us = 1e6
    print(
        f"step, {args.steps} calls: inside the library median {statistics.median(inside) * us:.2f} µs "
        f"(mean {statistics.fmean(inside) * us:.2f}), called from Python median "
        f"{statistics.median(outside) * us:.2f} µs (mean {statistics.fmean(outside) * us:.2f})"
    )
    print(
        f"added per call: median {statistics.median(added) * us:.2f} µs, mean "
        f"{statistics.fmean(added) * us:.2f} µs, 90th percentile "
        f"{float(np.percentile(added, 90)) * us:.2f} µs"
    )
    floor = timed(lambda: sim.steps, 20000)
    print(f"for scale, reading sim.steps (a call that takes the mutex): median {statistics.median(floor) * us:.2f} µs")

    reads = 5000
    for name, f in [
        ("surface_positions() float64, new array", lambda: sim.surface_positions()),
        ("surface_positions(np.float32), new array", lambda: sim.surface_positions(np.float32)),
    ]:
        print(f"{name}: median {statistics.median(timed(f, reads)) * us:.1f} µs")
    out64 = np.empty((sim.surface_vertex_count, 3))
    out32 = np.empty((sim.surface_vertex_count, 3), dtype=np.float32)
    for name, f in [
        ("surface_positions(out=float64 array)", lambda: sim.surface_positions(out=out64)),
        ("surface_positions(out=float32 array)", lambda: sim.surface_positions(out=out32)),
    ]:
        print(f"{name}: median {statistics.median(timed(f, reads)) * us:.1f} µs")
    if model.has_all_rows:
        everything = np.empty((sim.vertex_count, 3))
        print(
            f"positions(out=...) of all {sim.vertex_count} vertices: median "
            f"{statistics.median(timed(lambda: sim.positions(out=everything), reads // 5)) * us:.1f} µs"
        )


if __name__ == "__main__":
    main()
