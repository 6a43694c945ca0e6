//! `Model`: a trained model file, loaded ([`ReducedModel`]), with what a program asks of it
//! before stepping it.

use std::path::PathBuf;
use std::sync::Arc;

use latent_sim::ReducedModel;
use latent_sim::model::SubspaceParts;
use pyo3::prelude::*;

use crate::errors;

/// A trained model loaded from a model file (``cargo xtask export``, or ``export_model``).
///
/// Load one with ``Model.load(path)``; step it with ``Simulator(model)``. The model is
/// immutable and may be shared by several simulators.
#[pyclass(module = "latent_dynamics", frozen)]
#[derive(Debug)]
pub struct Model {
    pub(crate) inner: Arc<ReducedModel>,
    path: Option<PathBuf>,
}

impl Model {
    pub(crate) fn new(model: ReducedModel, path: Option<PathBuf>) -> Self {
        Self {
            inner: Arc::new(model),
            path,
        }
    }
}

#[pymethods]
impl Model {
    /// Loads a model file.
    ///
    /// Raises ``ModelFileError`` when the file cannot be read or is not a valid model
    /// (truncated, corrupted, foreign, another format version, inconsistent), with the
    /// library's message naming the file.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        // Reading and checking a large model takes a while: other threads may run meanwhile.
        let model = py
            .detach(|| ReducedModel::load(&path))
            .map_err(errors::model_file)?;
        Ok(Self::new(model, Some(path)))
    }

    /// Writes the model to ``path`` (atomically: a reader never sees a half-written file),
    /// creating the folders it needs.
    ///
    /// Raises ``ModelFileError`` when it cannot be written.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| self.inner.save(&path))
            .map_err(errors::model_file)
    }

    /// The file the model was loaded from (None for a model made in this process).
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.path.clone()
    }

    /// The pipeline's name of the method (``"neural-cubature"``, ``"pca"``, ...).
    #[getter]
    fn method(&self) -> String {
        self.inner.provenance.method.clone()
    }

    /// The name of the scene the model was trained on.
    #[getter]
    fn scene(&self) -> String {
        self.inner.provenance.scene.clone()
    }

    /// The version of the project that wrote the model.
    #[getter]
    fn project_version(&self) -> String {
        self.inner.provenance.project_version.clone()
    }

    /// Dimension of the latent space the simulator steps (for the neural methods the
    /// autoencoder's latent coordinates plus the linear directions beside them).
    #[getter]
    fn latent_dim(&self) -> usize {
        self.inner.latent_dim()
    }

    /// Columns of the PCA basis (k).
    #[getter]
    fn pca_dim(&self) -> usize {
        self.inner.space.k
    }

    /// Whether the latent space is an autoencoder's (the neural methods) rather than PCA's.
    #[getter]
    fn neural(&self) -> bool {
        matches!(self.inner.subspace, SubspaceParts::Neural { .. })
    }

    /// Vertices of the mesh.
    #[getter]
    fn vertex_count(&self) -> usize {
        self.inner.mesh.num_vertices()
    }

    /// Tetrahedra of the mesh.
    #[getter]
    fn tet_count(&self) -> usize {
        self.inner.mesh.num_tets()
    }

    /// Vertices whose basis rows the model keeps (the surface's and the evaluated elements' by
    /// default; every vertex's when exported with all rows, which ``Simulator.positions`` needs).
    #[getter]
    fn rows_vertex_count(&self) -> usize {
        self.inner.space.vertices.len()
    }

    /// Whether the model keeps every vertex's basis rows (so the whole mesh can be read back).
    #[getter]
    fn has_all_rows(&self) -> bool {
        self.inner.space.vertices.len() == self.inner.mesh.num_vertices()
    }

    /// Elements the elastic energy is evaluated on (the cubature rule's, or every tetrahedron).
    #[getter]
    fn elements(&self) -> usize {
        self.inner
            .cubature
            .as_ref()
            .map_or(self.inner.mesh.num_tets(), |c| c.len())
    }

    /// Time step h (s).
    #[getter]
    fn time_step(&self) -> f64 {
        self.inner.time_step
    }

    /// Gravitational acceleration (m/s²).
    #[getter]
    fn gravity(&self) -> (f64, f64, f64) {
        let [x, y, z] = self.inner.gravity;
        (x, y, z)
    }

    /// Pinned vertices (mesh indices, increasing).
    #[getter]
    fn pinned(&self) -> Vec<usize> {
        self.inner.pinned.clone()
    }

    /// Young's modulus of the material (Pa).
    #[getter]
    fn youngs_modulus(&self) -> f64 {
        self.inner.material.youngs_modulus
    }

    /// The body's mass (kg): the density times the rest volume of the mesh's tets.
    #[getter]
    fn mass(&self) -> f64 {
        self.inner.mass()
    }

    /// The errors the pipeline measured while making the model: a list of
    /// ``(name, held_out, value)``, ``held_out`` telling a held-out test trajectory's from the
    /// training data's.
    #[getter]
    fn errors(&self) -> Vec<(String, bool, f64)> {
        self.inner
            .provenance
            .errors
            .iter()
            .map(|e| (e.name.clone(), e.held_out, e.value))
            .collect()
    }

    fn __repr__(&self) -> String {
        format!(
            "Model(method={:?}, scene={:?}, vertices={}, latent_dim={}, elements={})",
            self.method(),
            self.scene(),
            self.vertex_count(),
            self.latent_dim(),
            self.elements()
        )
    }
}
