"""Loads a model, drags a vertex up for a second, lets go for another second, prints how fast it
stepped and plots the grabbed vertex's height over time (with matplotlib, if installed).

    cargo xtask export                                   # out/cantilever/neural-cubature.ldm
    pip install ./crates/python
    python crates/python/examples/drag.py out/cantilever/neural-cubature.ldm [--full] [--plot FILE]

The Python twin of `cargo run --release -p latent-sim --example drag`: the vertex is the surface
vertex farthest from the pins, pulled against gravity by 20 % of the mesh's size L with a spring
of 1e-3 E L, or, when that is weaker, one that carries the body's weight at that stretch,
M|g|/(0.2 L). Each frame reads the surface back as float32, as a renderer would. --full steps the
model's mesh in full space instead. The plot goes to FILE (default drag.png beside the model).
"""

from __future__ import annotations

import argparse
import pathlib
import time

import numpy as np

import latent_dynamics as ld


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", type=pathlib.Path, help="a model file (cargo xtask export)")
    parser.add_argument("--full", action="store_true", help="step in full space")
    parser.add_argument("--plot", type=pathlib.Path, help="where to save the plot")
    args = parser.parse_args()

    model = ld.Model.load(args.model)
    print(model)
    sim = ld.Simulator(model, full_space=args.full)

    rest = sim.rest_positions
    surface = sim.surface_vertices
    anchor = rest[model.pinned] if model.pinned else rest[surface]
    distance = np.linalg.norm(rest[surface] - anchor.mean(axis=0), axis=1)
    at = len(distance) - 1 - int(distance[::-1].argmax())  # the last of ties, as the Rust example
    vertex = int(surface[at])
    g = np.array(model.gravity)
    up = -g / np.linalg.norm(g) if np.linalg.norm(g) > 0 else np.array([0.0, 1.0, 0.0])
    size = float(np.linalg.norm(rest.max(axis=0) - rest.min(axis=0)))
    # A spring that holds the body's weight when stretched by the drag's 0.2 L (a soft, heavy
    # body hangs from it instead of falling away), and at least 1e-3 E L.
    weight = model.mass * np.linalg.norm(g)
    stiffness = max(1e-3 * model.youngs_modulus * size, weight / (0.2 * size))
    steps = max(1, round(1.0 / model.time_step))

    handle = sim.grab(vertex, stiffness)
    frame = np.empty((sim.surface_vertex_count, 3), dtype=np.float32)
    times, heights, step_s, read_s = [0.0], [0.0], [], []
    for k in range(2 * steps):
        if k < steps:
            sim.move_handle(handle, rest[vertex] + up * (0.2 * size * (k + 1) / steps))
        elif k == steps:
            sim.release(handle)
        t = time.perf_counter()
        sim.step()
        step_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        sim.surface_positions(out=frame)
        read_s.append(time.perf_counter() - t)
        times.append(sim.time)
        heights.append(float((frame[at] - rest[vertex]) @ up))

    stats = sim.stats
    print(
        f"dragged vertex {vertex} {0.2 * size:.3f} m against gravity over {steps} steps "
        f"(spring {stiffness:.0f} N/m), then let go for {steps} steps"
    )
    print(
        f"{stats.steps_per_second:.0f} steps/s inside the library, "
        f"{len(step_s) / sum(step_s):.0f} steps/s called from Python; "
        f"{stats.iterations_per_step:.2f} iterations per step; surface read-back "
        f"{1e6 * float(np.median(read_s)):.1f} µs/frame median ({len(frame)} vertices, float32)"
    )
    print(f"height at the release {heights[steps]:.4f} m, 1 s later {heights[-1]:.4f} m")
    beyond = stats.beyond_training
    if beyond is not None:
        where = ", where the model extrapolates" if beyond > ld.OUTSIDE_TRAINING else ""
        print(f"the pose went up to {100 * beyond:.0f} % of its size beyond the training poses{where}")

    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot")
        return
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.plot(times, heights)
    ax.axvline(times[steps], color="grey", linestyle="--", label="released")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("height of the grabbed vertex (m)")
    ax.set_title(f"{model.method} on {model.scene}" + (" (full space)" if args.full else ""))
    ax.legend()
    fig.tight_layout()
    out = args.plot or args.model.with_name("drag.png")
    fig.savefig(out, dpi=120)
    print(f"plot: {out}")


if __name__ == "__main__":
    main()
