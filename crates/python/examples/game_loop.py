"""Steps a model the way a game does, one fixed step per frame, through what a player does to it,
and prints what each part cost: step times, solver iterations, preconditioner rebuilds and
steps that fell back to Newton; and how far each part took the model beyond its training poses
(`StepStats.beyond_training`: above 10 % it extrapolates, and what it shows may not be the
body's motion).

    cargo xtask export                                   # out/cantilever/neural-cubature.ldm
    pip install ./crates/python
    python crates/python/examples/game_loop.py out/cantilever/neural-cubature.ldm [--full] [--punch 2]

The phases, at the model's own time step: 0.5 s settling under gravity; the surface vertex
farthest from the pins dragged 40 % of the body's size sideways in 0.2 s, held 0.3 s and let go;
a second point pulled 50 % outward in 0.15 s; a third swung in a circle of 30 % of the size twice
a second for 1 s; a punch (a point load of `--punch` body weights for 0.1 s) near the first
point; a wind there that changes every frame; gravity turned sideways for 1 s, upward for 0.5 s,
and back. Grabs are springs of 20 W/L (W the body's weight, L its largest extent) on the free
surface vertices within 4 % of the bounding-box diagonal of the point. Every frame reads the
surface back as float32, as a renderer would. A step that fails (a punch far beyond what the
model can solve) lets go of everything, as a game would, and is counted. Times are measured
inside the library (`StepStats.seconds`).
"""

from __future__ import annotations

import argparse
import math
import pathlib

import numpy as np

import latent_dynamics as ld

# A step's phase, wall seconds, iterations, rebuilt, Newton fallback, failed, the surface's
# largest move (m) and how far beyond the training poses (nan in full space or when failed).
Row = tuple[str, float, int, bool, bool, bool, float, float]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", type=pathlib.Path, help="a model file (cargo xtask export)")
    parser.add_argument("--full", action="store_true", help="step in full space")
    parser.add_argument("--punch", type=float, default=2.0, help="the punch, in body weights")
    args = parser.parse_args()

    model = ld.Model.load(args.model)
    print(f"{model}, stepped in full space" if args.full else model)
    sim = ld.Simulator(model, full_space=args.full)
    sim.prepare_grab()
    h = model.time_step

    rest = sim.rest_positions
    pinned = set(model.pinned)
    free = np.array([v for v in sim.surface_vertices if int(v) not in pinned])
    extent = rest.max(axis=0) - rest.min(axis=0)
    size = float(extent.max())
    radius = 0.04 * float(np.linalg.norm(extent))
    g = np.array(model.gravity, dtype=float)
    g_norm = float(np.linalg.norm(g))
    down = g / g_norm if g_norm > 0 else np.array([0.0, -1.0, 0.0])
    weight = model.mass * max(g_norm, 9.81)
    stiffness = 20.0 * weight / size

    # Three points far apart: the free surface vertex farthest from the pins, the one farthest
    # from it, and the one farthest from both.
    anchor = rest[model.pinned].mean(axis=0) if model.pinned else rest.mean(axis=0)
    a = int(free[np.linalg.norm(rest[free] - anchor, axis=1).argmax()])
    b = int(free[np.linalg.norm(rest[free] - rest[a], axis=1).argmax()])
    spread = np.minimum(
        np.linalg.norm(rest[free] - rest[a], axis=1), np.linalg.norm(rest[free] - rest[b], axis=1)
    )
    c = int(free[spread.argmax()])
    sideways = horizontal(down)

    frame = np.empty((sim.surface_vertex_count, 3), dtype=np.float32)
    surface_rest = rest[sim.surface_vertices].astype(np.float32)
    rows: list[Row] = []

    def step(phase: str) -> None:
        try:
            s = sim.step()
        except ld.SolverError as e:
            print(f"  {phase}: step at t = {sim.time:.3f} s failed: {e}")
            for handle in sim.handles():
                sim.release(handle)
            rows.append((phase, math.nan, 0, False, False, True, math.nan, math.nan))
            return
        sim.surface_positions(out=frame)
        moved = float(np.linalg.norm(frame - surface_rest, axis=1).max())
        beyond = math.nan if s.beyond_training is None else s.beyond_training
        rows.append(
            (phase, s.seconds, s.iterations, s.preconditioner_rebuilt, s.newton_fallback, False, moved,
             beyond)
        )

    def wait(seconds: float, phase: str) -> None:
        for _ in range(frames(seconds, h)):
            step(phase)

    def drag(vertex: int, direction: np.ndarray, fraction: float, move: float, phase: str) -> None:
        handle = sim.grab(near(rest, free, vertex, radius), stiffness)
        start = np.array(sim.handle_target(handle))
        n = frames(move, h)
        for k in range(n):
            sim.move_handle(handle, start + direction * fraction * size * (k + 1) / n)
            step(phase)
        wait(0.3 if phase == "drag 1" else 0.2, phase + ", held")
        release(sim, handle)
        wait(0.5, phase + ", let go")

    wait(0.5, "settle")
    drag(a, sideways, 0.4, 0.2, "drag 1")
    outward = rest[b] - rest.mean(axis=0)
    drag(b, outward / max(float(np.linalg.norm(outward)), 1e-12), 0.5, 0.15, "drag 2")

    handle = sim.grab(near(rest, free, c, radius), stiffness)
    centre = np.array(sim.handle_target(handle))
    up = -down
    for k in range(frames(1.0, h)):
        angle = 2 * math.pi * 2 * k * h
        offset = 0.3 * size * (math.sin(angle) * sideways + (1 - math.cos(angle)) * up)
        sim.move_handle(handle, centre + offset)
        step("whip")
    release(sim, handle)
    wait(0.5, "whip, let go")

    patch = near(rest, free, a, radius)
    t = sim.time
    punch = sim.add_force(
        "point", patch, [(t, 0, 0, 0), (t + h, *(args.punch * weight * sideways))], start=t, end=t + 0.1
    )
    wait(0.1, "punch")
    wait(0.5, "punch, after")
    release(sim, punch)

    wind = sim.add_force("point", patch, [(sim.time, 0, 0, 0)], start=sim.time)
    n = frames(0.5, h)
    for k in range(n):
        sim.set_load(wind, tuple(3 * weight * math.sin(2 * math.pi * k / n) * sideways))
        step("wind")
    release(sim, wind)

    for direction, seconds, phase in [
        (sideways, 1.0, "gravity sideways"),
        (up, 0.5, "gravity up"),
        (down, 1.0, "gravity back"),
    ]:
        sim.set_gravity_acceleration(tuple(max(g_norm, 9.81) * direction))
        wait(seconds, phase)

    report(rows, size)


def frames(seconds: float, h: float) -> int:
    return max(1, round(seconds / h))


def horizontal(down: np.ndarray) -> np.ndarray:
    """A unit vector across gravity: x, or z where gravity runs along x."""
    axis = np.array([1.0, 0.0, 0.0]) if abs(down[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    across = axis - (axis @ down) * down
    return across / np.linalg.norm(across)


def near(rest: np.ndarray, free: np.ndarray, vertex: int, radius: float) -> list[int]:
    """The free surface vertices within `radius` of `vertex` at rest (the vertex itself at least)."""
    close = free[np.linalg.norm(rest[free] - rest[vertex], axis=1) <= radius]
    return [int(v) for v in close] or [vertex]


def release(sim: ld.Simulator, handle: ld.Handle) -> None:
    """Lets go of a handle unless a failed step let go of everything already."""
    if handle in sim.handles():
        sim.release(handle)


def report(rows: list[Row], size: float) -> None:
    ms = np.array([1e3 * r[1] for r in rows if not r[5]])
    print(
        f"{len(rows)} steps: mean {ms.mean():.2f} ms, median {np.median(ms):.2f}, "
        f"99th percentile {np.percentile(ms, 99):.2f}, max {ms.max():.2f}; "
        f"{sum(r[2] for r in rows) / len(rows):.1f} iterations per step; "
        f"{sum(r[3] for r in rows)} rebuilds, {sum(r[4] for r in rows)} Newton fallbacks, "
        f"{sum(r[5] for r in rows)} failed steps; the surface moved up to "
        f"{np.nanmax([r[6] for r in rows]) / size:.2f} times the body's size"
    )
    beyond = [r[7] for r in rows if not math.isnan(r[7])]
    if beyond:
        outside = sum(b > ld.OUTSIDE_TRAINING for b in beyond)
        print(
            f"the pose went up to {100 * max(beyond):.0f} % beyond the training poses; "
            f"{outside} steps more than {100 * ld.OUTSIDE_TRAINING:.0f} % beyond, where the model "
            "extrapolates"
        )
    print(
        f"{'phase':18s} {'steps':>5s} {'mean ms':>8s} {'max ms':>8s} {'iterations':>10s} "
        f"{'rebuilds':>8s} {'Newton':>6s} {'failed':>6s} {'beyond %':>8s}"
    )
    phases: dict[str, list[Row]] = {}
    for r in rows:
        phases.setdefault(r[0], []).append(r)
    for phase, rs in phases.items():
        done = [1e3 * r[1] for r in rs if not r[5]] or [math.nan]
        beyond = [r[7] for r in rs if not math.isnan(r[7])]
        print(
            f"{phase:18s} {len(rs):5d} {np.mean(done):8.2f} {np.max(done):8.2f} "
            f"{np.mean([r[2] for r in rs]):10.1f} {sum(r[3] for r in rs):8d} "
            f"{sum(r[4] for r in rs):6d} {sum(r[5] for r in rs):6d} "
            + (f"{100 * max(beyond):8.0f}" if beyond else f"{'–':>8s}")
        )


if __name__ == "__main__":
    main()
