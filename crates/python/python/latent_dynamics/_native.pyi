"""Type stubs of the compiled module (crates/python/src); import ``latent_dynamics`` instead."""

from __future__ import annotations

import os
import pathlib
from typing import Callable, Optional, Sequence, Tuple, Union, final, overload

import numpy as np
import numpy.typing as npt

_Path = Union[str, "os.PathLike[str]"]
_Point = Union[Sequence[float], npt.NDArray[np.floating]]
_Vertices = Union[int, Sequence[int], npt.NDArray[np.integer]]

__all__ = [
    "Model",
    "Simulator",
    "Handle",
    "StepStats",
    "RunStats",
    "Report",
    "MethodRow",
    "Stage",
    "run_pipeline",
    "run_trajectories",
    "export_model",
    "LatentDynamicsError",
    "ModelFileError",
    "SceneError",
    "SolverError",
    "PipelineError",
    "HandleError",
    "InvalidArgumentError",
    "PipelineWarning",
    "__version__",
    "MODEL_FORMAT_VERSION",
    "OUTSIDE_TRAINING",
]

__version__: str
MODEL_FORMAT_VERSION: int
#: A step's ``beyond_training`` above this (0.1): the model extrapolates there.
OUTSIDE_TRAINING: float

class LatentDynamicsError(Exception):
    """Base class of every error the latent_dynamics module raises."""

class ModelFileError(LatentDynamicsError):
    """A model file that cannot be read or written, or whose bytes are not a valid model."""

class SceneError(LatentDynamicsError, ValueError):
    """A scene file that cannot be read, an unknown or invalid field, a mesh that cannot be
    loaded."""

class SolverError(LatentDynamicsError):
    """A step whose solve failed (the simulator keeps the state before the step)."""

class PipelineError(LatentDynamicsError):
    """A pipeline run or export that failed (a stage's solve included)."""

class PipelineWarning(UserWarning):
    """What the library warns of while it works (cargo xtask's WARN lines), via warnings.warn."""

class HandleError(LatentDynamicsError, LookupError):
    """A handle released already or of another simulator; no surface vertex within reach."""

class InvalidArgumentError(LatentDynamicsError, ValueError):
    """A vertex, stiffness, radius, point, array, dtype or method name the library refuses."""

@final
class Model:
    """A trained model loaded from a model file; immutable, shareable by simulators."""

    @staticmethod
    def load(path: _Path) -> Model:
        """Loads a model file; raises ModelFileError when it is missing or damaged."""
    def save(self, path: _Path) -> None:
        """Writes the model atomically, creating the folders it needs; raises ModelFileError
        when it cannot."""
    @property
    def path(self) -> Optional[pathlib.Path]:
        """The file the model was loaded from or exported to."""
    @property
    def method(self) -> str:
        """The pipeline's name of the method: "neural-cubature", "pca", ..."""
    @property
    def scene(self) -> str:
        """The name of the scene it was trained on."""
    @property
    def project_version(self) -> str: ...
    @property
    def latent_dim(self) -> int:
        """Dimension of the space the simulator steps (latent coordinates and directions)."""
    @property
    def pca_dim(self) -> int:
        """Columns k of the PCA basis."""
    @property
    def neural(self) -> bool:
        """Whether the latent space is an autoencoder's."""
    @property
    def vertex_count(self) -> int: ...
    @property
    def tet_count(self) -> int: ...
    @property
    def rows_vertex_count(self) -> int:
        """Vertices whose basis rows the model keeps."""
    @property
    def has_all_rows(self) -> bool:
        """Whether Simulator.positions can read every vertex."""
    @property
    def elements(self) -> int:
        """Elements the elastic energy is evaluated on."""
    @property
    def time_step(self) -> float: ...
    @property
    def gravity(self) -> Tuple[float, float, float]: ...
    @property
    def pinned(self) -> list[int]: ...
    @property
    def youngs_modulus(self) -> float: ...
    @property
    def mass(self) -> float:
        """The body's mass (kg): density times the mesh's rest volume."""
    @property
    def errors(self) -> list[Tuple[str, bool, float]]:
        """(name, held_out, value) of each error the pipeline measured."""

@final
class StepStats:
    """The outcome of one step."""

    @property
    def step(self) -> int: ...
    @property
    def time(self) -> float: ...
    @property
    def iterations(self) -> int: ...
    @property
    def seconds(self) -> float:
        """Wall time of the step inside the library."""
    @property
    def relative_gradient(self) -> float:
        """The solve's gradient against the step's forces when it stopped."""
    @property
    def preconditioner_rebuilt(self) -> bool:
        """L-BFGS's preconditioner was rebuilt during the step (a costly step)."""
    @property
    def newton_fallback(self) -> bool:
        """L-BFGS crawled and the step was solved on with Newton (in full space, with the
        other solver than the scene's)."""
    @property
    def beyond_training(self) -> Optional[float]:
        """How far the pose the step reached lies beyond the training poses' ranges,
        relative to its size: 0 among them; above 0.1 the model extrapolates. None in full
        space."""

@final
class RunStats:
    """Figures of the steps since the simulator was made or reset_stats was called."""

    @property
    def steps(self) -> int: ...
    @property
    def seconds(self) -> float: ...
    @property
    def steps_per_second(self) -> float: ...
    @property
    def iterations_per_step(self) -> float: ...
    @property
    def last(self) -> Optional[StepStats]: ...
    @property
    def beyond_training(self) -> Optional[float]:
        """The largest beyond_training of those steps (None in full space or before a step)."""

@final
class Handle:
    """A grabbed set of vertices; valid only in the simulator that made it. Hashable."""

@final
class Simulator:
    """A model stepping, reduced or (full_space=True) in full space on its mesh."""

    def __new__(cls, model: Model, full_space: bool = False) -> Simulator:
        """A simulator of model at rest, gravity on, no handle: reduced (the model's latent
        space, its solver settings), or in full space on the model's mesh when full_space.
        Raises SolverError when a reduced matrix cannot be factorised and LatentDynamicsError
        when the model is inconsistent."""
    def step(self) -> StepStats:
        """One time step, without the GIL; raises SolverError (state kept) when it fails."""
    def grab(self, vertices: _Vertices, stiffness: float) -> Handle:
        """A spring of total stiffness (N/m) on mesh vertices, its target at their centroid."""
    def grab_near(self, point: _Point, radius: float, stiffness: float) -> Handle:
        """A spring on the surface vertices within radius of point, its target at point: it
        holds them where they are until move_handle moves the target, which pulls each vertex
        by the target's offset from point (a point far from the body is no pull toward it)."""
    def add_force(
        self,
        kind: str,
        vertices: _Vertices,
        keyframes: Union[Sequence[Sequence[float]], npt.NDArray[np.floating]],
        stiffness: Optional[float] = None,
        start: float = 0.0,
        end: Optional[float] = None,
    ) -> Handle:
        """A spring ("spring", toward the rest centroid plus the keyframed offset) or a point
        load ("point", the keyframed total force) on mesh vertices, as a scene's [[force]].
        Keyframe times, start and end are on the simulation's clock (`time`), not counted
        from the call."""
    def move_handle(self, handle: Handle, target: _Point) -> None:
        """Moves a handle's target to target: its vertices are pulled toward where they were
        grabbed, moved by target minus the grab point."""
    def release(self, handle: Handle) -> None:
        """Lets go of a handle."""
    def handle_target(self, handle: Handle) -> Tuple[float, float, float]:
        """A spring handle's target now."""
    def set_load(self, handle: Handle, force: _Point) -> None:
        """Sets a point load's total force (N) from now on."""
    def handles(self) -> list[Handle]:
        """The handles held now, in the order they were made."""
    def surface_velocities(
        self, out: Optional[npt.NDArray[np.float64]] = None
    ) -> npt.NDArray[np.float64]:
        """Velocities (m/s) of the surface vertices, m×3 float64."""
    def copy(self) -> Simulator:
        """A copy that steps exactly as this one would from here, handles included: keep one
        to roll back to. A handle made on either after the copy is unknown to the other."""
    def __copy__(self) -> Simulator: ...
    def __deepcopy__(self, memo: object) -> Simulator: ...
    def set_gravity(self, enabled: bool) -> None:
        """Turns gravity on (its acceleration, the model's unless set_gravity_acceleration
        changed it) or off."""
    @property
    def gravity(self) -> bool: ...
    def set_gravity_acceleration(self, g: _Point) -> None:
        """Sets gravity's acceleration (m/s²), e.g. to tilt the world; it acts while gravity
        is on."""
    @property
    def gravity_acceleration(self) -> Tuple[float, float, float]: ...
    def reset(self) -> None:
        """Back to rest at time 0; handles and gravity stay."""
    def prepare_grab(self) -> None:
        """Does now the work the first grab would do in the grab call (a reduced model
        factorises the full step's operator at rest once, about 0.1 s on the default bar), so
        that a loop's first grab does not stall a frame."""
    @property
    def time(self) -> float: ...
    @property
    def steps(self) -> int: ...
    @property
    def stats(self) -> RunStats: ...
    def reset_stats(self) -> None:
        """Starts the figures of stats afresh."""
    def positions(
        self, out: Optional[npt.NDArray[np.float64]] = None
    ) -> npt.NDArray[np.float64]:
        """Every vertex, n x 3 float64 (into out when given)."""
    @overload
    def surface_positions(
        self, dtype: None = None, out: None = None
    ) -> npt.NDArray[np.float64]: ...
    @overload
    def surface_positions(
        self, dtype: npt.DTypeLike, out: None = None
    ) -> npt.NDArray[np.floating]: ...
    @overload
    def surface_positions(
        self, dtype: None = None, *, out: npt.NDArray[np.floating]
    ) -> npt.NDArray[np.floating]: ...
    @property
    def rest_positions(self) -> npt.NDArray[np.float64]:
        """n x 3 float64."""
    @property
    def surface_vertices(self) -> npt.NDArray[np.int64]:
        """Mesh index of each row of surface_positions."""
    @property
    def surface_triangles(self) -> npt.NDArray[np.uint32]:
        """m x 3 rows of surface_positions, outward."""
    @property
    def vertex_count(self) -> int: ...
    @property
    def surface_vertex_count(self) -> int: ...
    @property
    def full_space(self) -> bool: ...
    @property
    def model(self) -> Model: ...

@final
class Stage:
    """One pipeline stage, computed or loaded from the cache."""

    @property
    def name(self) -> str: ...
    @property
    def cached(self) -> bool: ...
    @property
    def seconds(self) -> float: ...
    @property
    def path(self) -> pathlib.Path: ...
    @property
    def summary(self) -> str: ...

@final
class MethodRow:
    """One method's row of a run's report (report.json's fields)."""

    @property
    def method(self) -> str: ...
    @property
    def dimension(self) -> int: ...
    @property
    def elements(self) -> int: ...
    @property
    def ms_per_step(self) -> float: ...
    @property
    def ms_min(self) -> float: ...
    @property
    def ms_max(self) -> float: ...
    @property
    def ms_median(self) -> float: ...
    @property
    def timed_runs(self) -> int: ...
    @property
    def hz(self) -> float: ...
    @property
    def speedup(self) -> Optional[float]: ...
    @property
    def mean_rel_error(self) -> float: ...
    @property
    def max_rel_error(self) -> float: ...
    @property
    def trajectory_error(self) -> float: ...
    @property
    def max_vertex_error(self) -> float: ...
    @property
    def iterations(self) -> float: ...
    @property
    def subspace_error(self) -> Optional[float]: ...
    @property
    def step_error(self) -> Optional[float]: ...
    @property
    def training_distance(self) -> Optional[float]: ...
    @property
    def training_distance_time(self) -> Optional[float]: ...
    @property
    def step_restarts(self) -> int: ...
    @property
    def frame_errors(self) -> list[float]: ...
    @property
    def failure(self) -> Optional[str]: ...

@final
class Report:
    """What cargo xtask run prints and writes."""

    @property
    def scene(self) -> str: ...
    @property
    def rows(self) -> list[MethodRow]: ...
    @property
    def stages(self) -> list[Stage]: ...
    @property
    def warnings(self) -> list[str]: ...
    @property
    def caveats(self) -> list[str]: ...
    @property
    def out_dir(self) -> pathlib.Path: ...
    @property
    def model_path(self) -> Optional[pathlib.Path]: ...
    def row(self, method: str) -> MethodRow:
        """The row of method; raises InvalidArgumentError when it did not run."""

def run_pipeline(
    scene: Optional[_Path] = None,
    *,
    out_dir: Optional[_Path] = None,
    cache_dir: Optional[_Path] = None,
    methods: Optional[Union[str, Sequence[str]]] = None,
    trajectory: int = 0,
    every: int = 0,
    on_stage: Optional[Callable[[Stage], object]] = None,
    on_progress: Optional[Callable[[str, int, int], object]] = None,
) -> Report:
    """cargo xtask run: the cached stages, then each method on a held-out test trajectory."""

def run_trajectories(
    scene: Optional[_Path] = None,
    count: int = 4,
    *,
    out_dir: Optional[_Path] = None,
    cache_dir: Optional[_Path] = None,
    methods: Optional[Union[str, Sequence[str]]] = None,
    every: int = 0,
    on_stage: Optional[Callable[[Stage], object]] = None,
    on_progress: Optional[Callable[[str, int, int], object]] = None,
) -> list[Report]:
    """cargo xtask run --trajectories count: one Report per held-out test trajectory 0..count."""

def export_model(
    scene: Optional[_Path] = None,
    method: str = "neural-cubature",
    *,
    path: Optional[_Path] = None,
    cache_dir: Optional[_Path] = None,
    all_rows: bool = False,
    on_stage: Optional[Callable[[Stage], object]] = None,
    on_progress: Optional[Callable[[str, int, int], object]] = None,
) -> Model:
    """cargo xtask export: a reduced method's model as one file, returned loaded."""
