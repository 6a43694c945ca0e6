"""Latent-space dynamics for reduced deformable simulation, from Python.

Load a trained model file (``cargo xtask export`` or :func:`export_model`) and step it
interactively, or run the pipeline on a scene file, over the same Rust crates as ``cargo xtask``::

    import latent_dynamics as ld

    model = ld.Model.load("out/cantilever/neural-cubature.ldm")
    sim = ld.Simulator(model)
    h = sim.grab_near((1.0, 0.1, 0.1), radius=0.05, stiffness=2000.0)
    for k in range(100):
        sim.move_handle(h, (1.0, 0.1 + 0.002 * k, 0.1))
        sim.step()                     # releases the GIL
    xyz = sim.surface_positions()      # m x 3 float64, rows of sim.surface_triangles

Every error arrives as a subclass of :class:`LatentDynamicsError` with the library's message.
"""

from ._native import (
    MODEL_FORMAT_VERSION,
    OUTSIDE_TRAINING,
    Handle,
    HandleError,
    InvalidArgumentError,
    LatentDynamicsError,
    MethodRow,
    Model,
    ModelFileError,
    PipelineError,
    PipelineWarning,
    Report,
    RunStats,
    SceneError,
    Simulator,
    SolverError,
    Stage,
    StepStats,
    __version__,
    export_model,
    run_pipeline,
    run_trajectories,
)

__all__ = [
    "MODEL_FORMAT_VERSION",
    "OUTSIDE_TRAINING",
    "Handle",
    "HandleError",
    "InvalidArgumentError",
    "LatentDynamicsError",
    "MethodRow",
    "Model",
    "ModelFileError",
    "PipelineError",
    "PipelineWarning",
    "Report",
    "RunStats",
    "SceneError",
    "Simulator",
    "SolverError",
    "Stage",
    "StepStats",
    "__version__",
    "export_model",
    "run_pipeline",
    "run_trajectories",
]
