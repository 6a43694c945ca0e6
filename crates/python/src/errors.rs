//! The module's exception classes and the mapping of the library's typed errors onto them: every
//! error reaches Python as one of these classes with the library's own message.
//!
//! ```text
//! LatentDynamicsError(Exception)
//! ├── ModelFileError            a model file that cannot be read, written or decoded
//! ├── SceneError(ValueError)    a scene file that cannot be read, a bad field, a bad mesh
//! ├── SolverError               a step whose solve failed
//! ├── PipelineError             a pipeline run or export that failed (a stage's solve included)
//! ├── HandleError(LookupError)  a handle released already, of another simulator, nothing in reach
//! └── InvalidArgumentError(ValueError)   a vertex, stiffness, point, array or name that is wrong
//! ```
//!
//! The classes are made with `type(name, bases, namespace)` rather than PyO3's
//! `create_exception!`, which allows one base only: `SceneError` is also a `ValueError`, so
//! `except ValueError` catches it as a user expects.

use latent_sim::{ModelFileError, ReducedError, RuntimeError};
use pyo3::exceptions::{PyException, PyLookupError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};

/// The exception classes of the module.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    Base,
    ModelFile,
    Scene,
    Solver,
    Pipeline,
    Handle,
    InvalidArgument,
}

impl Class {
    pub const ALL: [Class; 7] = [
        Class::Base,
        Class::ModelFile,
        Class::Scene,
        Class::Solver,
        Class::Pipeline,
        Class::Handle,
        Class::InvalidArgument,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Class::Base => "LatentDynamicsError",
            Class::ModelFile => "ModelFileError",
            Class::Scene => "SceneError",
            Class::Solver => "SolverError",
            Class::Pipeline => "PipelineError",
            Class::Handle => "HandleError",
            Class::InvalidArgument => "InvalidArgumentError",
        }
    }

    fn doc(self) -> &'static str {
        match self {
            Class::Base => "Base class of every error the latent_dynamics module raises.",
            Class::ModelFile => {
                "A model file that cannot be read or written, or whose bytes are not a valid \
                 model (truncated, corrupted, foreign, another format version, inconsistent)."
            }
            Class::Scene => {
                "A scene that cannot be used: its file cannot be read, a field is unknown or \
                 invalid, or its mesh cannot be loaded."
            }
            Class::Solver => {
                "A step whose solve failed: it diverged, did not converge or met an inverted \
                 element (the simulator keeps the state before the step); or a reduced matrix \
                 that is not positive definite or not finite."
            }
            Class::Pipeline => {
                "A pipeline run or export that failed: a stage whose solve failed (with the \
                 solver's message), an output that cannot be written."
            }
            Class::Handle => {
                "A handle this simulator does not have (released already, or another \
                 simulator's), a point load moved like a spring, or no surface vertex within \
                 a grab's radius."
            }
            Class::InvalidArgument => {
                "An argument the library refuses: a vertex past the mesh, a stiffness or radius \
                 that is not positive, a point that is not finite, an array of the wrong shape \
                 or dtype, an unknown method name, a vertex without basis rows."
            }
        }
    }

    fn cell(self) -> &'static PyOnceLock<Py<PyType>> {
        static CELLS: [PyOnceLock<Py<PyType>>; 7] = [
            PyOnceLock::new(),
            PyOnceLock::new(),
            PyOnceLock::new(),
            PyOnceLock::new(),
            PyOnceLock::new(),
            PyOnceLock::new(),
            PyOnceLock::new(),
        ];
        &CELLS[self as usize]
    }

    /// The class, made on first use.
    pub fn type_object(self, py: Python<'_>) -> PyResult<Bound<'_, PyType>> {
        let ty = self
            .cell()
            .get_or_try_init(py, || -> PyResult<Py<PyType>> {
                let mut bases = vec![];
                if self != Class::Base {
                    bases.push(Class::Base.type_object(py)?.into_any());
                }
                match self {
                    Class::Base => bases.push(py.get_type::<PyException>().into_any()),
                    Class::Scene | Class::InvalidArgument => {
                        bases.push(py.get_type::<PyValueError>().into_any())
                    }
                    Class::Handle => bases.push(py.get_type::<PyLookupError>().into_any()),
                    _ => {}
                }
                let namespace = PyDict::new(py);
                namespace.set_item("__module__", "latent_dynamics")?;
                namespace.set_item("__doc__", self.doc())?;
                let made = py.get_type::<PyType>().call1((
                    self.name(),
                    PyTuple::new(py, bases)?,
                    namespace,
                ))?;
                Ok(made.cast_into::<PyType>()?.unbind())
            })?;
        Ok(ty.bind(py).clone())
    }

    /// An exception of this class with `message`.
    pub fn err(self, message: impl Into<String>) -> PyErr {
        let message = message.into();
        Python::attach(|py| match self.type_object(py) {
            Ok(ty) => PyErr::from_type(ty, message),
            Err(e) => e,
        })
    }
}

/// The class of an error of the interactive runtime outside a step: bad arguments and unknown
/// handles. (A step's error is always a [`Class::Solver`].)
pub fn runtime_class(e: &RuntimeError) -> Class {
    match e {
        RuntimeError::UnknownHandle(_)
        | RuntimeError::ForeignHandle(_)
        | RuntimeError::NotASpring(_)
        | RuntimeError::NotAPointLoad(_)
        | RuntimeError::NothingInReach { .. } => Class::Handle,
        RuntimeError::NoSuchVertex { .. }
        | RuntimeError::NoVertices
        | RuntimeError::NotInBody { .. }
        | RuntimeError::ActiveSpan { .. }
        | RuntimeError::SpanOver { .. }
        | RuntimeError::NotPositive { .. }
        | RuntimeError::TooStiff { .. }
        | RuntimeError::TooLarge { .. }
        | RuntimeError::AllPinned { .. }
        | RuntimeError::PointStiffness(_)
        | RuntimeError::NotFinite { .. }
        | RuntimeError::BufferLength { .. }
        | RuntimeError::Reduced(ReducedError::NoBasisRows { .. })
        | RuntimeError::Reduced(ReducedError::Keyframes)
        | RuntimeError::Reduced(ReducedError::NoSuchForce { .. }) => Class::InvalidArgument,
        RuntimeError::Reduced(
            ReducedError::NotPositiveDefinite { .. } | ReducedError::NotFinite { .. },
        ) => Class::Solver,
        RuntimeError::Reduced(_) | RuntimeError::Fem(_) => Class::Base,
    }
}

/// An error of the interactive runtime outside a step.
pub fn runtime(e: RuntimeError) -> PyErr {
    runtime_class(&e).err(e.to_string())
}

/// A step's error: the solve failed.
pub fn step(e: RuntimeError) -> PyErr {
    Class::Solver.err(e.to_string())
}

pub fn model_file(e: ModelFileError) -> PyErr {
    Class::ModelFile.err(e.to_string())
}

/// A pipeline error (anyhow, with its context chain): a model file's own error keeps its class;
/// anything else is `fallback`. (The stages put their errors' messages, not the errors, in the
/// chain, so a stage whose solve failed is a [`Class::Pipeline`] with the solver's message.)
pub fn pipeline(e: anyhow::Error, fallback: Class) -> PyErr {
    let class = if e.downcast_ref::<ModelFileError>().is_some() {
        Class::ModelFile
    } else {
        fallback
    };
    class.err(format!("{e:#}"))
}
