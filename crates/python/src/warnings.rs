//! The library's warnings as Python warnings: what `cargo xtask` prints on stderr as `WARN`
//! lines (a scene whose mesh is not in metres, a body that gives way under its own weight while
//! its snapshots are computed, …) reaches a Python program as a `latent_dynamics.PipelineWarning`
//! through `warnings.warn`, so that it shows in a notebook or a script's output and the
//! `warnings` module's filters apply to it. Without this the messages went nowhere: no
//! `tracing` subscriber listens in a Python process.

use std::ffi::CString;
use std::fmt::Write as _;

use pyo3::exceptions::PyUserWarning;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};
use tracing::field::{Field, Visit};
use tracing_subscriber::Layer;
use tracing_subscriber::filter::LevelFilter;
use tracing_subscriber::layer::{Context, SubscriberExt};

/// `latent_dynamics.PipelineWarning(UserWarning)`, made on first use.
pub fn class(py: Python<'_>) -> PyResult<Bound<'_, PyType>> {
    static CELL: PyOnceLock<Py<PyType>> = PyOnceLock::new();
    let ty = CELL.get_or_try_init(py, || -> PyResult<Py<PyType>> {
        let namespace = PyDict::new(py);
        namespace.set_item("__module__", "latent_dynamics")?;
        namespace.set_item(
            "__doc__",
            "What the library warns of while it works: a scene whose mesh may not be in \
             metres, a body that gives way under its own weight, pins that hold too much of it, \
             … (the `WARN` lines `cargo xtask` prints).",
        )?;
        let bases = PyTuple::new(py, [py.get_type::<PyUserWarning>()])?;
        let made = py
            .get_type::<PyType>()
            .call1(("PipelineWarning", bases, namespace))?;
        Ok(made.cast_into::<PyType>()?.unbind())
    })?;
    Ok(ty.bind(py).clone())
}

/// Sends every `tracing` event at `WARN` or above to Python's `warnings.warn`, from whatever
/// thread emits it (the pipeline's worker takes the GIL for it, as for its callbacks). Does
/// nothing when the process already has a global subscriber (a Rust program embedding Python).
pub fn install() {
    let subscriber = tracing_subscriber::registry().with(ToPython.with_filter(LevelFilter::WARN));
    let _ = tracing::subscriber::set_global_default(subscriber);
}

/// The layer that turns events into Python warnings.
struct ToPython;

impl<S: tracing::Subscriber> Layer<S> for ToPython {
    fn on_event(&self, event: &tracing::Event<'_>, _: Context<'_, S>) {
        let mut text = Text::default();
        event.record(&mut text);
        let message = text.finish();
        // A message with a NUL byte cannot be a C string; it is cut there.
        let message = CString::new(message).unwrap_or_else(|e| {
            let end = e.nul_position();
            CString::new(&e.into_vec()[..end]).unwrap_or_default()
        });
        Python::attach(|py| {
            // On the pipeline's threads (its worker, the snapshots' pool) there is no Python
            // frame to name ("sys:1" otherwise): the warning names the module instead. Where
            // there is one (a step called from Python), it names the caller's line.
            let framed = py
                .import("sys")
                .and_then(|sys| sys.getattr("_getframe"))
                .and_then(|f| f.call1((0,)))
                .is_ok();
            let warned = class(py).and_then(|c| {
                if !framed {
                    PyErr::warn_explicit(
                        py,
                        c.as_any(),
                        &message,
                        c"latent_dynamics",
                        0,
                        Some(c"latent_dynamics"),
                        None,
                    )
                } else {
                    PyErr::warn(py, c.as_any(), &message, 1)
                }
            });
            // A filter that turns warnings into errors raises here, on a thread that cannot
            // raise into the caller: Python's own report of an exception it cannot raise.
            if let Err(e) = warned {
                e.write_unraisable(py, None);
            }
        });
    }
}

/// An event's message, then its other fields as `name=value`, as `cargo xtask`'s log shows
/// them.
#[derive(Default)]
struct Text {
    message: String,
    fields: String,
}

impl Text {
    fn finish(self) -> String {
        self.message + &self.fields
    }
}

impl Visit for Text {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.message.push_str(value);
        } else {
            let _ = write!(self.fields, " {}={value}", field.name());
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.message, "{value:?}");
        } else {
            let _ = write!(self.fields, " {}={value:?}", field.name());
        }
    }
}
