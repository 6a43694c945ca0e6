//! The `latent_dynamics` Python module (DESIGN §13): PyO3 bindings over latent-sim's runtime
//! and the pipeline, built by maturin as an abi3 wheel (`pip install ./crates/python`).
//!
//! * `Model`: a model file loaded (`Model.load(path)`), with what it is.
//! * `Simulator`: the model stepping (or its mesh in full space): grab, move and
//!   release handles, gravity, reset, step (without the GIL), and positions read into numpy
//!   arrays with no copy beyond the one into the array.
//! * `run_pipeline`, `run_trajectories` and `export_model`: `cargo xtask run` (with
//!   `--trajectories`) and `export`
//!   from Python, with the same stages and cache, and the report as Python objects.
//! * The errors module: the exception classes every library error arrives as.
//!
//! The compiled module is `latent_dynamics._native`; the package `python/latent_dynamics`
//! re-exports it with type stubs. Its tests are pytest's (`tests/`).

mod errors;
mod interrupt;
mod model;
mod pipeline;
mod simulator;
mod warnings;

use pyo3::prelude::*;

/// The compiled part of the latent_dynamics package (import ``latent_dynamics`` instead).
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<model::Model>()?;
    m.add_class::<simulator::Simulator>()?;
    m.add_class::<simulator::Handle>()?;
    m.add_class::<simulator::StepStats>()?;
    m.add_class::<simulator::RunStats>()?;
    m.add_class::<pipeline::Report>()?;
    m.add_class::<pipeline::MethodRow>()?;
    m.add_class::<pipeline::Stage>()?;
    m.add_function(wrap_pyfunction!(pipeline::run_pipeline, m)?)?;
    m.add_function(wrap_pyfunction!(pipeline::run_trajectories, m)?)?;
    m.add_function(wrap_pyfunction!(pipeline::export_model, m)?)?;
    for class in errors::Class::ALL {
        m.add(class.name(), class.type_object(py)?)?;
    }
    m.add("PipelineWarning", warnings::class(py)?)?;
    warnings::install();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("MODEL_FORMAT_VERSION", latent_sim::model::FORMAT_VERSION)?;
    m.add("OUTSIDE_TRAINING", latent_sim::coverage::OUTSIDE_TRAINING)?;
    Ok(())
}
