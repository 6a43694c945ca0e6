//! `Simulator`: a model stepping, reduced ([`ReducedRuntime`]) or in full space
//! ([`FullRuntime`]), behind latent-sim's [`Interactive`] API, with positions read into numpy
//! arrays.
//!
//! Threads: the runtime sits behind a mutex, and every call that waits for it or works long
//! (a step, a read-back) releases the GIL first. So a thread can step while another draws, a read
//! never sees half a step (it waits for the step to finish), and the two locks are never held in
//! opposite orders: the mutex is only ever waited for without the GIL.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard, TryLockError};

use fem_core::Vec3;
use fem_core::forces::{ExternalForce, ForceKind};
use latent_sim::{FullRuntime, Interactive, Real, ReducedRuntime, RuntimeError};
use numpy::ndarray::Array2;
use numpy::{Element, PyArray2, PyArrayDescrMethods, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;

use crate::errors::{self, Class};
use crate::model::Model;

/// Either runtime.
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)] // one per simulator
enum Runtime {
    Reduced(ReducedRuntime),
    Full(FullRuntime),
}

/// `$body` with `$s` bound to the runtime inside a [`Runtime`].
macro_rules! each {
    ($rt:expr, $s:ident => $body:expr) => {
        match $rt {
            Runtime::Reduced($s) => $body,
            Runtime::Full($s) => $body,
        }
    };
}

/// What the mutex guards: the runtime and the figures of the steps taken.
#[derive(Debug, Clone)]
struct State {
    runtime: Runtime,
    timed_steps: usize,
    seconds: f64,
    iterations: usize,
    last: Option<latent_sim::StepStats>,
    /// The largest `beyond_training` of the steps counted (None in full space).
    beyond_training: Option<f64>,
}

/// Tells the simulators of a process apart, so that a handle of one is refused by another.
static NEXT_ID: AtomicU64 = AtomicU64::new(0);

/// The outcome of one step.
#[pyclass(module = "latent_dynamics", frozen, get_all)]
#[derive(Debug, Clone, Copy)]
pub struct StepStats {
    /// The step just taken (1 for the first after a reset).
    step: usize,
    /// The simulated time it reached (s).
    time: f64,
    /// Solver iterations the step took.
    iterations: usize,
    /// The solve's gradient against the step's forces when it stopped.
    relative_gradient: f64,
    /// Wall time of the step inside the library (s), without the Python call around it.
    seconds: f64,
    /// L-BFGS's preconditioner was rebuilt during the step (a step several times a plain one's
    /// cost; in a reduced model one step in two to five while the body moves, rarely at rest).
    preconditioner_rebuilt: bool,
    /// L-BFGS crawled and the step was solved on with Newton (in full space, with the other
    /// solver than the scene's): a slow step, in a reduced model usually a pull far beyond the
    /// training.
    newton_fallback: bool,
    /// How far the pose the step reached lies beyond the training poses' ranges, relative to
    /// its size (``cargo xtask run`` reports the largest over a test as "from training"): 0
    /// among them; above ``OUTSIDE_TRAINING`` (0.1) the model extrapolates and its motion is
    /// not to be trusted as the body's. None in full space.
    beyond_training: Option<f64>,
}

impl From<latent_sim::StepStats> for StepStats {
    fn from(s: latent_sim::StepStats) -> Self {
        Self {
            step: s.step,
            time: s.time,
            iterations: s.iterations,
            relative_gradient: s.relative_gradient,
            seconds: s.seconds,
            preconditioner_rebuilt: s.preconditioner_rebuilt,
            newton_fallback: s.newton_fallback,
            beyond_training: s.beyond_training,
        }
    }
}

#[pymethods]
impl StepStats {
    fn __repr__(&self) -> String {
        format!(
            "StepStats(step={}, time={}, iterations={}, seconds={:.3e}{})",
            self.step,
            self.time,
            self.iterations,
            self.seconds,
            self.beyond_training
                .map_or(String::new(), |b| format!(", beyond_training={b:.3}"))
        )
    }
}

/// Figures of the steps taken since the simulator was made or ``reset_stats`` was called.
#[pyclass(module = "latent_dynamics", frozen, get_all)]
#[derive(Debug, Clone)]
pub struct RunStats {
    /// Steps taken.
    steps: usize,
    /// Their wall time inside the library (s).
    seconds: f64,
    /// Steps per second of wall time (0 before the first step).
    steps_per_second: f64,
    /// Mean solver iterations per step (0 before the first step).
    iterations_per_step: f64,
    /// The last step's figures (None before the first step).
    last: Option<StepStats>,
    /// The largest ``beyond_training`` of those steps: above 0.1 the model left its training
    /// poses at least once (None in full space and before the first step).
    beyond_training: Option<f64>,
}

#[pymethods]
impl RunStats {
    fn __repr__(&self) -> String {
        format!(
            "RunStats(steps={}, seconds={:.4}, steps_per_second={:.1}, iterations_per_step={:.2})",
            self.steps, self.seconds, self.steps_per_second, self.iterations_per_step
        )
    }
}

/// A grabbed set of vertices, to move or release; valid only in the simulator that made it.
#[pyclass(module = "latent_dynamics", frozen, eq, hash)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Handle {
    handle: latent_sim::Handle,
    owner: u64,
}

#[pymethods]
impl Handle {
    fn __repr__(&self) -> String {
        format!("Handle({} of simulator {})", self.handle, self.owner)
    }
}

/// A model stepping: the interaction API of latent-sim's runtime.
///
/// ``Simulator(model)`` steps the trained model in its latent space with the solver settings
/// ``cargo xtask run`` measures; ``Simulator(model, full_space=True)`` steps the same mesh,
/// material, pins and gravity in full space (the reference). Both start at rest, gravity on.
///
/// Grab vertices with a spring (``grab``, ``grab_near``), move the spring's target
/// (``move_handle``), let go (``release``); several handles at once. ``step`` releases the GIL:
/// another thread may read positions meanwhile (the read waits for the step to finish, so it
/// never sees half a step).
#[pyclass(module = "latent_dynamics", frozen)]
#[derive(Debug)]
pub struct Simulator {
    state: Mutex<State>,
    /// Calls waiting for `state`: a step, once done, lets them have it before its thread can
    /// take it again (the mutex is not fair, and a stepping loop starved a reader).
    waiting: AtomicUsize,
    id: u64,
    model: Py<Model>,
    full_space: bool,
    /// What never changes, kept outside the mutex so that reading it never waits for a step.
    rest: Vec<Vec3>,
    surface_vertices: Vec<usize>,
    surface_triangles: Vec<[u32; 3]>,
}

impl Simulator {
    /// Runs `f` on the state: at once when the mutex is free, else waiting for it without the
    /// GIL (a step in another thread holds it and needs no GIL to finish).
    fn with<R, F>(&self, py: Python<'_>, f: F) -> PyResult<R>
    where
        F: FnOnce(&mut State) -> R + Send,
        R: Send,
    {
        let run = |mut guard: MutexGuard<'_, State>| f(&mut guard);
        match self.state.try_lock() {
            Ok(guard) => Ok(run(guard)),
            Err(TryLockError::WouldBlock) => {
                self.waiting.fetch_add(1, Ordering::SeqCst);
                py.detach(|| {
                    let guard = self.state.lock();
                    self.waiting.fetch_sub(1, Ordering::SeqCst);
                    guard.map(run).map_err(|_| ())
                })
                .map_err(|()| poisoned())
            }
            Err(TryLockError::Poisoned(_)) => Err(poisoned()),
        }
    }

    /// Fills an n×3 array of `T` with `read`: `out` itself when given (C-contiguous: written in
    /// place; otherwise through one buffer), else a new array. The read runs without the GIL.
    fn read_into<'py, T, F>(
        &self,
        py: Python<'py>,
        rows: usize,
        out: Option<&Bound<'py, PyAny>>,
        read: F,
    ) -> PyResult<Bound<'py, PyArray2<T>>>
    where
        T: Element + Real + Send,
        F: Fn(&mut Runtime, &mut [T]) -> Result<(), RuntimeError> + Send + Sync,
    {
        let array = match out {
            None => PyArray2::<T>::zeros(py, [rows, 3], false),
            Some(out) => {
                let array = out.cast::<PyArray2<T>>().map_err(|_| {
                    Class::InvalidArgument.err(format!(
                        "out must be a 2-d numpy array of {}, got {}",
                        numpy::dtype::<T>(py),
                        describe(out)
                    ))
                })?;
                if array.shape() != [rows, 3] {
                    return Err(Class::InvalidArgument.err(format!(
                        "out has shape {:?}, expected ({rows}, 3)",
                        array.shape()
                    )));
                }
                array.clone()
            }
        };
        let mut view = array
            .try_readwrite()
            .map_err(|e| Class::InvalidArgument.err(format!("out cannot be written: {e}")))?;
        // In place only in row order: `as_slice_mut` also takes a Fortran-order array, whose
        // memory holds the columns one after another.
        let in_place = if array.is_c_contiguous() {
            view.as_slice_mut().ok()
        } else {
            None
        };
        match in_place {
            Some(slice) => self
                .with(py, |s| read(&mut s.runtime, slice))?
                .map_err(errors::runtime)?,
            None => {
                let mut buffer = vec![T::from_f64(0.0); 3 * rows];
                self.with(py, |s| read(&mut s.runtime, &mut buffer))?
                    .map_err(errors::runtime)?;
                let mut strided = view.as_array_mut();
                for (i, mut row) in strided.rows_mut().into_iter().enumerate() {
                    for c in 0..3 {
                        row[c] = buffer[3 * i + c];
                    }
                }
            }
        }
        drop(view);
        Ok(array)
    }

    fn own(&self, handle: &Handle) -> PyResult<latent_sim::Handle> {
        if handle.owner == self.id {
            Ok(handle.handle)
        } else {
            Err(Class::Handle.err(format!(
                "handle {} belongs to simulator {}, not to this one ({})",
                handle.handle, handle.owner, self.id
            )))
        }
    }

    fn wrap(&self, handle: latent_sim::Handle) -> Handle {
        Handle {
            handle,
            owner: self.id,
        }
    }
}

fn poisoned() -> PyErr {
    Class::Base.err(
        "an earlier call panicked inside this simulator and its state is lost; make a new \
         Simulator",
    )
}

/// A Python object's type and, for an array, its dtype and dimensions, for messages.
pub(crate) fn describe(obj: &Bound<'_, PyAny>) -> String {
    if let Ok(a) = obj.cast::<numpy::PyUntypedArray>() {
        format!("an array of {} with {} dimension(s)", a.dtype(), a.ndim())
    } else {
        obj.get_type()
            .name()
            .map_or_else(|_| "an object".into(), |n| n.to_string())
    }
}

/// A numpy dtype that is float32 (true) or float64 (false), from anything `numpy.dtype` takes.
fn is_float32(py: Python<'_>, dtype: &Bound<'_, PyAny>) -> PyResult<bool> {
    let descr = py
        .import("numpy")?
        .getattr("dtype")?
        .call1((dtype,))
        .map_err(|e| Class::InvalidArgument.err(format!("dtype: {e}")))?;
    let descr = descr.cast_into::<numpy::PyArrayDescr>()?;
    if descr.is_equiv_to(&numpy::dtype::<f32>(py)) {
        Ok(true)
    } else if descr.is_equiv_to(&numpy::dtype::<f64>(py)) {
        Ok(false)
    } else if descr.kind() == b'f' && matches!(descr.itemsize(), 4 | 8) {
        // A float32 or float64 that is not the machine's own: the other byte order (`>f8`).
        Err(Class::InvalidArgument.err(format!(
            "dtype {descr} is in the other byte order: give float32 or float64 in the machine's \
             own (e.g. numpy.float64)"
        )))
    } else {
        Err(Class::InvalidArgument.err(format!("dtype must be float32 or float64, got {descr}")))
    }
}

/// Vertex indices from an int or a sequence (or integer array) of them, none negative and no
/// more of them than the mesh's `count` vertices (a `range(10**12)` or an endless generator is
/// refused before it is read, not read until memory runs out); the error names the element that
/// is not one (a bool, a float, an int past 64 bits).
fn vertex_list(vertices: &Bound<'_, PyAny>, count: usize) -> PyResult<Vec<usize>> {
    use pyo3::types::{PyBool, PyInt, PyString};
    fn bad<T>(message: String) -> PyResult<T> {
        Err(Class::InvalidArgument.err(message))
    }
    // The index `item` holds; `place` is its place in a list, `None` for a lone index.
    let index = |item: &Bound<'_, PyAny>, place: Option<usize>| -> PyResult<i64> {
        // `True` is an int to Python, and would be vertex 1.
        if item.is_instance_of::<PyBool>() {
            return bad(match place {
                Some(i) => format!("vertices[{i}] is a bool, not a vertex index"),
                None => "vertices must be an int or a sequence of ints, got bool".to_string(),
            });
        }
        match item.extract::<i64>() {
            Ok(v) => Ok(v),
            Err(_) if item.is_instance_of::<PyInt>() => bad(match place {
                Some(i) => format!(
                    "vertices[{i}] = {item} does not exist (beyond any mesh's vertex count)"
                ),
                None => {
                    format!("vertex {item} does not exist (beyond any mesh's vertex count)")
                }
            }),
            Err(_) => bad(format!(
                "vertices[{}] must be an int, got {item} ({})",
                place.unwrap_or(0),
                describe(item)
            )),
        }
    };
    // One index: a Python int or anything with __index__ (a numpy integer).
    let values: Vec<i64> = if vertices.is_instance_of::<PyBool>()
        || vertices.is_instance_of::<PyInt>()
        || vertices.extract::<i64>().is_ok()
    {
        vec![index(vertices, None)?]
    } else {
        if let Ok(a) = vertices.cast::<numpy::PyUntypedArray>()
            && a.dtype().kind() == b'b'
        {
            return bad(
                "vertices is a boolean array (a mask): give the indices it selects, e.g. \
                 numpy.flatnonzero(mask)"
                    .to_string(),
            );
        }
        if let Ok(a) = vertices.cast::<numpy::PyUntypedArray>()
            && a.ndim() != 1
        {
            let shape: Vec<String> = a.shape().iter().map(usize::to_string).collect();
            return bad(format!(
                "vertices must be a 1-D array of indices, got shape ({}) (flatten it, e.g. \
                 array.ravel())",
                shape.join(", ")
            ));
        }
        // A string iterates over its characters, which are no list of vertices.
        let items = vertices
            .try_iter()
            .ok()
            .filter(|_| !vertices.is_instance_of::<PyString>());
        let Some(items) = items else {
            return bad(format!(
                "vertices must be an int or a sequence of ints, got {}",
                describe(vertices)
            ));
        };
        // Repeats are taken once; more than 16 items a vertex are no list of the mesh's.
        let most = count.saturating_mul(16);
        let too_many = || {
            bad(format!(
                "vertices lists more than {most} items, 16 for each of the mesh's {count} \
                 vertices: give each vertex once"
            ))
        };
        if vertices.len().is_ok_and(|n| n > most) {
            return too_many();
        }
        let mut values = Vec::new();
        for (i, item) in items.enumerate() {
            if i == most {
                return too_many();
            }
            values.push(index(&item?, Some(i))?);
        }
        values
    };
    values
        .into_iter()
        .map(|v| {
            usize::try_from(v).map_err(|_| {
                Class::InvalidArgument.err(format!("vertex {v} does not exist (negative)"))
            })
        })
        .collect()
}

/// Three finite-or-not numbers (x, y, z) from any sequence of three (a tuple, a list, a
/// 1-D array), or the `InvalidArgumentError` naming `what` and what was given: a (3, 1) array
/// or a string said "only 0-dimensional arrays can be converted" or "must be real number".
fn point3(what: &str, value: &Bound<'_, PyAny>) -> PyResult<[f64; 3]> {
    // An array other than 1-D is refused whatever numpy would convert (older numpy turned a
    // (3, 1) array's size-1 rows into floats).
    let array = value.cast::<numpy::PyUntypedArray>().ok();
    let flat = array.is_none_or(|a| a.ndim() == 1);
    // Only a sized object of three is read: a generator may never end, and a range of 10**12
    // was reserved whole before its length was looked at.
    let len = value.len().ok();
    let text = value.is_instance_of::<pyo3::types::PyString>();
    let values: Option<Vec<f64>> = (flat && len == Some(3))
        .then(|| value.extract().ok())
        .flatten();
    if let Some(&[x, y, z]) = values.as_deref() {
        return Ok([x, y, z]);
    }
    // Three items of which one is no float (an integer too large for one): that item is
    // named, not the sequence ("got tuple" for (10**400, 0, 0)).
    let items: Option<Vec<Bound<'_, PyAny>>> = (array.is_none() && len == Some(3) && !text)
        .then(|| value.try_iter().ok()?.take(3).collect::<PyResult<_>>().ok())
        .flatten();
    let bad = items
        .iter()
        .flatten()
        .enumerate()
        .find_map(|(i, item)| item.extract::<f64>().err().map(|e| (i, item, e)));
    let given = match (bad, array, len) {
        (Some((i, item, e)), _, _) => {
            format!("{} as item {i}, which is no float ({e})", describe(item))
        }
        (None, Some(a), _) => format!("an array of shape {:?}", a.shape()),
        (None, None, Some(n)) if n != 3 && !text => n.to_string(),
        (None, None, _) => describe(value),
    };
    Err(Class::InvalidArgument.err(format!("{what} must be 3 numbers (x, y, z), got {given}")))
}

fn array_n3<'py, T: Element>(py: Python<'py>, rows: Vec<[T; 3]>) -> Bound<'py, PyArray2<T>> {
    let n = rows.len();
    let flat: Vec<T> = rows.into_iter().flatten().collect();
    let array = Array2::from_shape_vec((n, 3), flat).expect("3 values per row");
    numpy::IntoPyArray::into_pyarray(array, py)
}

#[pymethods]
impl Simulator {
    /// A simulator of ``model`` at rest, gravity on, no handle: reduced (the model's latent
    /// space, its solver settings), or in full space on the model's mesh when ``full_space``.
    ///
    /// Raises ``SolverError`` when a reduced matrix cannot be factorised and
    /// ``LatentDynamicsError`` when the model is inconsistent.
    #[new]
    #[pyo3(signature = (model, full_space = false))]
    fn new(py: Python<'_>, model: Py<Model>, full_space: bool) -> PyResult<Self> {
        let reduced = model.get().inner.clone();
        let runtime = py
            .detach(|| -> Result<Runtime, RuntimeError> {
                Ok(if full_space {
                    Runtime::Full(FullRuntime::from_model(&reduced)?)
                } else {
                    Runtime::Reduced(ReducedRuntime::new(&reduced)?)
                })
            })
            .map_err(errors::runtime)?;
        let (rest, surface) =
            each!(&runtime, s => (s.rest_positions().to_vec(), s.surface().clone()));
        Ok(Self {
            waiting: AtomicUsize::new(0),
            state: Mutex::new(State {
                runtime,
                timed_steps: 0,
                seconds: 0.0,
                iterations: 0,
                last: None,
                beyond_training: None,
            }),
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
            model,
            full_space,
            rest,
            surface_vertices: surface.vertices().to_vec(),
            surface_triangles: surface.triangles().to_vec(),
        })
    }

    /// A copy that steps exactly as this simulator would from here (its solver's history and
    /// handles included): keep one to roll back to (``sim = saved.copy()``) or to try a move
    /// ahead. The handles made before the copy act on both; one made on either after it is
    /// unknown to the other. ``copy.copy`` and ``copy.deepcopy`` make the same.
    fn copy(&self, py: Python<'_>) -> PyResult<Self> {
        let state = self.with(py, |s| s.clone())?;
        Ok(Self {
            state: Mutex::new(state),
            waiting: AtomicUsize::new(0),
            id: self.id,
            model: self.model.clone_ref(py),
            full_space: self.full_space,
            rest: self.rest.clone(),
            surface_vertices: self.surface_vertices.clone(),
            surface_triangles: self.surface_triangles.clone(),
        })
    }

    fn __copy__(&self, py: Python<'_>) -> PyResult<Self> {
        self.copy(py)
    }

    fn __deepcopy__(&self, py: Python<'_>, _memo: &Bound<'_, PyAny>) -> PyResult<Self> {
        self.copy(py)
    }

    /// Advances one time step, without the GIL.
    ///
    /// Raises ``SolverError`` when the solve fails (diverges, does not converge, meets an
    /// inverted element); the state is then the one before the step.
    fn step(&self, py: Python<'_>) -> PyResult<StepStats> {
        let result = py
            .detach(|| {
                let stats = {
                    let mut state = self.state.lock().map_err(|_| None)?;
                    let stats = each!(&mut state.runtime, s => s.step()).map_err(Some)?;
                    state.timed_steps += 1;
                    state.seconds += stats.seconds;
                    state.iterations += stats.iterations;
                    state.last = Some(stats);
                    state.beyond_training = stats
                        .beyond_training
                        .map(|b| state.beyond_training.map_or(b, |m| m.max(b)));
                    stats
                };
                // Calls that waited for this step go first (for at most a millisecond).
                let deadline = std::time::Instant::now() + std::time::Duration::from_millis(1);
                while self.waiting.load(Ordering::SeqCst) > 0
                    && std::time::Instant::now() < deadline
                {
                    std::thread::yield_now();
                }
                Ok(stats)
            })
            .map_err(|e: Option<RuntimeError>| e.map_or_else(poisoned, errors::step))?;
        Ok(result.into())
    }

    /// Grabs ``vertices`` (mesh indices: an int, a sequence or an integer array) with a spring
    /// of total stiffness ``stiffness`` (N/m), its target at their current centroid.
    ///
    /// Raises ``InvalidArgumentError`` for no vertex, a vertex past the mesh, a stiffness that
    /// is not positive or more than 1e6 times the body's own at its size (E times its
    /// bounding-box diagonal), vertices that are all pinned, or (reduced) a vertex whose basis
    /// rows the model does not keep.
    fn grab(
        &self,
        py: Python<'_>,
        vertices: &Bound<'_, PyAny>,
        stiffness: f64,
    ) -> PyResult<Handle> {
        let vertices = vertex_list(vertices, self.vertex_count())?;
        let handle = self
            .with(
                py,
                |s| each!(&mut s.runtime, r => r.grab(&vertices, stiffness)),
            )?
            .map_err(errors::runtime)?;
        Ok(self.wrap(handle))
    }

    /// Grabs the surface vertices within ``radius`` of ``point`` (where they are now) with a
    /// spring of total stiffness ``stiffness`` (N/m), its target at ``point``: it holds them
    /// where they are until ``move_handle`` moves the target, which pulls each vertex by the
    /// target's offset from ``point`` (a point far from the body is no pull toward it).
    ///
    /// Raises ``HandleError`` when no surface vertex is in reach and ``InvalidArgumentError``
    /// for a point that is not finite, a radius or stiffness that is not positive, a stiffness
    /// ``grab`` refuses, or only pinned vertices in reach.
    fn grab_near(
        &self,
        py: Python<'_>,
        point: &Bound<'_, PyAny>,
        radius: f64,
        stiffness: f64,
    ) -> PyResult<Handle> {
        let point = point3("point", point)?;
        let handle = self
            .with(
                py,
                |s| each!(&mut s.runtime, r => r.grab_near(point, radius, stiffness)),
            )?
            .map_err(errors::runtime)?;
        Ok(self.wrap(handle))
    }

    /// Adds a force given as data, as a scene's ``[[force]]`` is: ``kind`` ``"spring"`` pulls
    /// ``vertices`` toward their rest centroid moved by the keyframed offset, with total
    /// stiffness ``stiffness`` (N/m); ``"point"`` spreads the keyframed total force (N) over
    /// them. ``keyframes`` are ``(t, x, y, z)`` rows (t in seconds of simulation time, not
    /// decreasing), linear in between and held after the last; the force acts from ``start``
    /// to ``end`` (``None``, the default: for ever). Returns a handle: ``release`` removes the force, ``move_handle`` moves a
    /// spring's target.
    ///
    /// Raises ``InvalidArgumentError`` for an unknown kind, a spring without a positive
    /// stiffness or with one ``grab`` refuses, a stiffness given to a point load, vertices that
    /// are all pinned, keyframes that are empty, not finite or
    /// out of order, ``end`` before ``start``, or a vertex as ``grab`` refuses it.
    #[pyo3(signature = (kind, vertices, keyframes, stiffness=None, start=0.0, end=None))]
    fn add_force(
        &self,
        py: Python<'_>,
        kind: &str,
        vertices: &Bound<'_, PyAny>,
        keyframes: &Bound<'_, PyAny>,
        stiffness: Option<f64>,
        start: f64,
        end: Option<f64>,
    ) -> PyResult<Handle> {
        let end = end.unwrap_or(f64::INFINITY);
        let (kind, stiffness) = match (kind, stiffness) {
            ("spring", Some(k)) => (ForceKind::Spring, k),
            ("spring", None) => {
                return Err(Class::InvalidArgument.err("a spring needs a stiffness (N/m)"));
            }
            ("point", None) => (ForceKind::Point, 0.0),
            ("point", Some(_)) => {
                return Err(Class::InvalidArgument
                    .err("a point load has no stiffness: its keyframes are the total force (N)"));
            }
            (other, _) => {
                return Err(Class::InvalidArgument.err(format!(
                    "kind must be \"spring\" or \"point\", got {other:?}"
                )));
            }
        };
        // A sequence is reserved whole before it is read: its length is checked first.
        if let Ok(n) = keyframes.len()
            && n > fem_core::integrator::MAX_FRAMES
        {
            return Err(Class::InvalidArgument.err(format!(
                "keyframes has {n} rows, more than {}",
                fem_core::integrator::MAX_FRAMES
            )));
        }
        let keyframes: Vec<[f64; 4]> = keyframes.extract().map_err(|_| {
            // Rows of numbers of another length are said by the first such row.
            let rows: Option<Vec<Vec<f64>>> = keyframes.extract().ok();
            let got = match rows
                .as_deref()
                .and_then(|r| r.iter().position(|row| row.len() != 4).map(|i| (i, &r[i])))
            {
                Some((i, row)) => format!("row {i} has {} numbers", row.len()),
                None => describe(keyframes),
            };
            Class::InvalidArgument.err(format!(
                "keyframes must be rows of 4 numbers (t, x, y, z), got {got}"
            ))
        })?;
        let force = ExternalForce {
            kind,
            vertices: vertex_list(vertices, self.vertex_count())?,
            stiffness,
            keyframes,
            start,
            end,
        };
        let handle = self
            .with(
                py,
                |s| each!(&mut s.runtime, r => r.add_force(force.clone())),
            )?
            .map_err(errors::runtime)?;
        Ok(self.wrap(handle))
    }

    /// Moves a handle's target to ``target``: its vertices are pulled toward where they were
    /// grabbed, moved by ``target`` minus the grab point.
    ///
    /// Raises ``HandleError`` for a handle released already or of another simulator, and
    /// ``InvalidArgumentError`` for a target that is not 3 numbers or not finite.
    fn move_handle(
        &self,
        py: Python<'_>,
        handle: &Handle,
        target: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let target = point3("target", target)?;
        let handle = self.own(handle)?;
        self.with(
            py,
            |s| each!(&mut s.runtime, r => r.move_handle(handle, target)),
        )?
        .map_err(errors::runtime)
    }

    /// A spring handle's target now (3 floats): where ``move_handle`` put it, or where a spring
    /// added with ``add_force`` pulls at this time.
    ///
    /// Raises ``HandleError`` for a handle released already, of another simulator, or a point
    /// load.
    fn handle_target(&self, py: Python<'_>, handle: &Handle) -> PyResult<(f64, f64, f64)> {
        let handle = self.own(handle)?;
        let [x, y, z] = self
            .with(py, |s| each!(&mut s.runtime, r => r.handle_target(handle)))?
            .map_err(errors::runtime)?;
        Ok((x, y, z))
    }

    /// Sets a point load's total force (N, 3 numbers) from now on: a force that changes every
    /// frame, at the cost of moving a handle.
    ///
    /// Raises ``HandleError`` for a handle released already, of another simulator, or a spring,
    /// and ``InvalidArgumentError`` for a force that is not 3 finite numbers.
    fn set_load(&self, py: Python<'_>, handle: &Handle, force: &Bound<'_, PyAny>) -> PyResult<()> {
        let force = point3("force", force)?;
        let handle = self.own(handle)?;
        self.with(
            py,
            |s| each!(&mut s.runtime, r => r.set_load(handle, force)),
        )?
        .map_err(errors::runtime)
    }

    /// The handles held now (grabs and forces added as data), in the order they were made.
    fn handles(&self, py: Python<'_>) -> PyResult<Vec<Handle>> {
        let held = self.with(py, |s| each!(&mut s.runtime, r => r.handles()))?;
        Ok(held.into_iter().map(|h| self.wrap(h)).collect())
    }

    /// Velocities (m/s) of the surface vertices, an m×3 float64 array (into ``out`` when
    /// given): (x_n − x_{n−1})/h; a reduced model's are its subspace's, without the dents its
    /// springs make outside it.
    #[pyo3(signature = (out = None))]
    fn surface_velocities<'py>(
        &self,
        py: Python<'py>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.read_into(
            py,
            self.surface_vertices.len(),
            out,
            |rt, buf| each!(rt, r => r.surface_velocities_into(buf)),
        )
    }

    /// Lets go of a handle.
    ///
    /// Raises ``HandleError`` for a handle released already or of another simulator.
    fn release(&self, py: Python<'_>, handle: &Handle) -> PyResult<()> {
        let handle = self.own(handle)?;
        self.with(py, |s| each!(&mut s.runtime, r => r.release(handle)))?
            .map_err(errors::runtime)
    }

    /// Sets gravity's acceleration (m/s², 3 numbers), e.g. to tilt the world; it acts while
    /// gravity is on. A direction the model's training did not fall along moves the body where
    /// its subspace may not reach.
    ///
    /// Raises ``InvalidArgumentError`` for a value that is not 3 finite numbers.
    fn set_gravity_acceleration(&self, py: Python<'_>, g: &Bound<'_, PyAny>) -> PyResult<()> {
        let g = point3("g", g)?;
        self.with(
            py,
            |s| each!(&mut s.runtime, r => r.set_gravity_acceleration(g)),
        )?
        .map_err(errors::runtime)
    }

    /// Gravity's acceleration (m/s²), whether or not gravity is on.
    #[getter]
    fn gravity_acceleration(&self, py: Python<'_>) -> PyResult<(f64, f64, f64)> {
        let [x, y, z] = self.with(py, |s| each!(&s.runtime, r => r.gravity_acceleration()))?;
        Ok((x, y, z))
    }

    /// Turns gravity on (its acceleration, the model's unless ``set_gravity_acceleration``
    /// changed it) or off.
    fn set_gravity(&self, py: Python<'_>, enabled: bool) -> PyResult<()> {
        self.with(py, |s| each!(&mut s.runtime, r => r.set_gravity(enabled)))
    }

    /// Whether gravity is on.
    #[getter]
    fn gravity(&self, py: Python<'_>) -> PyResult<bool> {
        self.with(py, |s| each!(&s.runtime, r => r.gravity()))
    }

    /// Back to rest at time 0; handles and the gravity setting stay.
    fn reset(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, |s| each!(&mut s.runtime, r => r.reset()))
    }

    /// Does now the work the first grab would do in the grab call (a reduced model factorises
    /// the full step's operator at rest once: about 0.1 s on the default bar), so that a
    /// loop's first grab does not stall a frame. Nothing in full space, or when done already.
    fn prepare_grab(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, |s| each!(&mut s.runtime, r => r.prepare_grab()))
    }

    /// Simulated time (s).
    #[getter]
    fn time(&self, py: Python<'_>) -> PyResult<f64> {
        self.with(py, |s| each!(&s.runtime, r => r.time()))
    }

    /// Steps taken since rest.
    #[getter]
    fn steps(&self, py: Python<'_>) -> PyResult<usize> {
        self.with(py, |s| each!(&s.runtime, r => r.steps()))
    }

    /// Figures of the steps taken since the simulator was made or ``reset_stats`` was called:
    /// steps per second and solver iterations per step.
    #[getter]
    fn stats(&self, py: Python<'_>) -> PyResult<RunStats> {
        self.with(py, |s| {
            let per = |x: f64, n: usize| if n > 0 { x / n as f64 } else { 0.0 };
            RunStats {
                steps: s.timed_steps,
                seconds: s.seconds,
                steps_per_second: if s.seconds > 0.0 {
                    s.timed_steps as f64 / s.seconds
                } else {
                    0.0
                },
                iterations_per_step: per(s.iterations as f64, s.timed_steps),
                last: s.last.map(StepStats::from),
                beyond_training: s.beyond_training,
            }
        })
    }

    /// Starts the figures of ``stats`` afresh.
    fn reset_stats(&self, py: Python<'_>) -> PyResult<()> {
        self.with(py, |s| {
            s.timed_steps = 0;
            s.seconds = 0.0;
            s.iterations = 0;
            s.last = None;
            s.beyond_training = None;
        })
    }

    /// Positions of every vertex, an n×3 float64 array, written into ``out`` when given (an
    /// n×3 float64 array; in place when C-contiguous, else through one buffer).
    ///
    /// A reduced model keeps only the basis rows in use by default (the surface's and the
    /// evaluated elements'): reading every vertex then raises ``InvalidArgumentError``; read
    /// ``surface_positions``, or export the model with all rows.
    #[pyo3(signature = (out = None))]
    fn positions<'py>(
        &self,
        py: Python<'py>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.read_into(
            py,
            self.rest.len(),
            out,
            |rt, buf| each!(rt, r => r.positions_into(buf)),
        )
    }

    /// Positions of the surface vertices (in ``surface_vertices``' order), an m×3 array of
    /// ``dtype`` (float64 by default, or float32 as a renderer wants), written into ``out``
    /// when given (whose dtype then decides; a ``dtype`` given beside it must be the same).
    /// A reduced model decodes only the surface's rows.
    #[pyo3(signature = (dtype = None, out = None))]
    fn surface_positions<'py>(
        &self,
        py: Python<'py>,
        dtype: Option<&Bound<'py, PyAny>>,
        out: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let rows = self.surface_vertices.len();
        let single = match (out, dtype) {
            (Some(o), None) => {
                let array = o.cast::<numpy::PyUntypedArray>().map_err(|_| {
                    Class::InvalidArgument
                        .err(format!("out must be a numpy array, got {}", describe(o)))
                })?;
                is_float32(py, array.dtype().as_any())?
            }
            (_, Some(d)) => is_float32(py, d)?,
            (None, None) => false,
        };
        if single {
            Ok(self
                .read_into::<f32, _>(
                    py,
                    rows,
                    out,
                    |rt, buf| each!(rt, r => r.surface_positions_into(buf)),
                )?
                .into_any())
        } else {
            Ok(self
                .read_into::<f64, _>(
                    py,
                    rows,
                    out,
                    |rt, buf| each!(rt, r => r.surface_positions_into(buf)),
                )?
                .into_any())
        }
    }

    /// Rest positions of every vertex, an n×3 float64 array (a new one each call).
    #[getter]
    fn rest_positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        array_n3(py, self.rest.iter().map(|v| [v.x, v.y, v.z]).collect())
    }

    /// Mesh indices of the surface vertices (increasing), int64: row i of
    /// ``surface_positions`` is vertex ``surface_vertices[i]``.
    #[getter]
    fn surface_vertices<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<i64>> {
        numpy::PyArray1::from_iter(py, self.surface_vertices.iter().map(|&v| v as i64))
    }

    /// The surface triangles, an m×3 uint32 array of rows of ``surface_positions``, outward.
    #[getter]
    fn surface_triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        array_n3(py, self.surface_triangles.clone())
    }

    /// Vertices of the mesh.
    #[getter]
    fn vertex_count(&self) -> usize {
        self.rest.len()
    }

    /// Vertices of the surface (rows of ``surface_positions``).
    #[getter]
    fn surface_vertex_count(&self) -> usize {
        self.surface_vertices.len()
    }

    /// Whether this simulator steps in full space rather than the model's latent space.
    #[getter]
    fn full_space(&self) -> bool {
        self.full_space
    }

    /// The model this simulator steps.
    #[getter]
    fn model(&self, py: Python<'_>) -> Py<Model> {
        self.model.clone_ref(py)
    }

    fn __repr__(&self) -> String {
        format!(
            "Simulator({}, {} vertices, {} on the surface)",
            if self.full_space {
                "full space"
            } else {
                "reduced"
            },
            self.rest.len(),
            self.surface_vertices.len()
        )
    }
}
