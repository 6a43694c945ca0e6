//! Small trained models of a bar, made the way the pipeline makes them (a PCA basis of
//! full-space snapshots, a cubature rule, an autoencoder with linear directions beside it) in
//! milliseconds.

use cubature::CubatureRule;
use fem_core::Vec3;
use fem_core::constraints::{Axis, Side, VertexSelection};
use fem_core::forces::{ExternalForce, ForceKind};
use fem_core::integrator::{FullSpaceModel, Simulator, TimeConfig};
use fem_core::mesh::generate::{BoxSpec, box_mesh};
use fem_core::optim::{SolverConfig, SolverMethod};
use latent_sim::ReducedModel;
use latent_sim::model::{ModelSource, Provenance, Rows, SubspaceSource};
use pca::{PcaBasis, PcaConfig};

use super::material;

/// The four reduced methods.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Pca,
    PcaCubature,
    Neural,
    NeuralCubature,
}

pub const KINDS: [Kind; 4] = [
    Kind::Pca,
    Kind::PcaCubature,
    Kind::Neural,
    Kind::NeuralCubature,
];

impl Kind {
    pub fn name(self) -> &'static str {
        match self {
            Kind::Pca => "pca",
            Kind::PcaCubature => "pca-cubature",
            Kind::Neural => "neural",
            Kind::NeuralCubature => "neural-cubature",
        }
    }

    fn neural(self) -> bool {
        matches!(self, Kind::Neural | Kind::NeuralCubature)
    }

    fn cubature(self) -> bool {
        matches!(self, Kind::PcaCubature | Kind::NeuralCubature)
    }
}

/// A 1 m bar of `cells`, clamped at x = 0, under gravity `g` (m/s², along y), no force.
pub fn bar(cells: [usize; 3], g: f64) -> FullSpaceModel {
    let mesh = box_mesh(&BoxSpec {
        size: [1.0, 0.2, 0.2],
        cells,
        ..Default::default()
    })
    .unwrap();
    let pinned = VertexSelection::plane(Axis::X, Side::Min, None)
        .select(&mesh, "pin")
        .unwrap();
    FullSpaceModel::new(mesh, &material(), pinned, Vec3::new(0.0, g, 0.0), vec![]).unwrap()
}

/// The vertices of the bar's free end.
pub fn tip(m: &FullSpaceModel) -> Vec<usize> {
    (0..m.mesh.num_vertices())
        .filter(|&v| m.mesh.vertices[v].x > 0.999)
        .collect()
}

/// A spring on the tip, its offset ramping to `offset` over 0.1 s, acting until `end`.
pub fn tip_spring(m: &FullSpaceModel, offset: [f64; 3], end: f64) -> ExternalForce {
    ExternalForce {
        kind: ForceKind::Spring,
        vertices: tip(m),
        stiffness: 500.0,
        keyframes: vec![[0.0, 0.0, 0.0, 0.0], [0.1, offset[0], offset[1], offset[2]]],
        start: 0.0,
        end,
    }
}

pub fn time(frames: usize) -> TimeConfig {
    TimeConfig {
        step: 0.01,
        frames,
        quasi_static: false,
    }
}

pub fn solver() -> SolverConfig {
    SolverConfig {
        method: SolverMethod::Lbfgs,
        tolerance: 1e-6,
        max_iterations: 200,
        ..Default::default()
    }
}

/// A k-column mass-orthonormal PCA basis of full-space snapshots of the bar pulled at its tip
/// up, down and sideways, and at its middle up and down, and let go.
pub fn snapshot_basis(m: &FullSpaceModel, k: usize) -> PcaBasis {
    let nf = m.dofs.num_free();
    let mut data = Vec::new();
    let middle: Vec<usize> = (0..m.mesh.num_vertices())
        .filter(|&v| (m.mesh.vertices[v].x - 0.5).abs() < 0.1)
        .collect();
    let pulls = [
        (tip(m), [0.0, 0.15, 0.0]),
        (tip(m), [0.0, -0.15, 0.0]),
        (tip(m), [0.0, 0.0, 0.15]),
        (middle.clone(), [0.0, 0.1, 0.0]),
        (middle, [0.0, -0.1, 0.0]),
    ];
    for (vertices, offset) in pulls {
        let mut model = m.clone();
        model.forces = vec![ExternalForce {
            vertices,
            ..tip_spring(m, offset, 0.2)
        }];
        let mut sim = Simulator::new(model, time(40), solver()).unwrap();
        let mut free = vec![0.0; nf];
        for _ in 0..40 {
            sim.step().unwrap();
            sim.model.dofs.gather(&sim.state.u, &mut free);
            data.extend_from_slice(&free);
        }
    }
    let mass: Vec<f64> = m.dofs.free.iter().map(|&d| m.mass.lumped[d / 3]).collect();
    let s = faer::MatRef::from_column_major_slice(&data, nf, data.len() / nf);
    PcaBasis::fit(s, Some(&mass), &PcaConfig::by_dimension(k), 3)
        .unwrap()
        .basis
}

/// Up to `count` elements whose vertices are all on the surface, weighted to the mesh's
/// element count: a rule that leaves the interior vertices out.
pub fn surface_rule(m: &FullSpaceModel, count: usize) -> CubatureRule {
    let surface = m.mesh.surface_vertices();
    let elements: Vec<usize> = (0..m.elements.len())
        .filter(|&e| m.elements.tets[e].iter().all(|v| surface.contains(v)))
        .take(count)
        .collect();
    CubatureRule {
        weights: vec![m.elements.len() as f64 / elements.len() as f64; elements.len()],
        elements,
        training_error: 0.1,
        tolerance_met: true,
        error_curve: Vec::new(),
    }
}

/// Every third element, weight 3.
pub fn rule(m: &FullSpaceModel) -> CubatureRule {
    let elements: Vec<usize> = (0..m.elements.len()).step_by(3).collect();
    CubatureRule {
        weights: vec![3.0; elements.len()],
        elements,
        training_error: 0.05,
        tolerance_met: true,
        error_curve: Vec::new(),
    }
}

/// A small autoencoder k → 3 with a linear skip, its rest state exact.
pub fn autoencoder(k: usize) -> nn::Autoencoder {
    let mut ae = nn::Autoencoder::with_architecture(k, 3, &[12, 10], nn::Activation::Elu, None, 5)
        .unwrap()
        .with_skip()
        .unwrap();
    ae.anchor(&vec![0.0; k]);
    ae
}

/// The model of `kind` on `m` with `basis` (two gravity-onset directions beside a neural
/// subspace), keeping `rows`.
pub fn build(kind: Kind, m: &FullSpaceModel, basis: &PcaBasis, rows: Rows) -> ReducedModel {
    let rule = kind.cubature().then(|| rule(m));
    build_with_rule(kind, m, basis, rows, rule.as_ref())
}

/// [`build`] with the cubature rule `rule`.
pub fn build_with_rule(
    kind: Kind,
    m: &FullSpaceModel,
    basis: &PcaBasis,
    rows: Rows,
    rule: Option<&CubatureRule>,
) -> ReducedModel {
    let ae = autoencoder(basis.k());
    let subspace = if kind.neural() {
        SubspaceSource::Neural {
            autoencoder: &ae,
            onset_directions: 2,
            complement: &[],
        }
    } else {
        SubspaceSource::Linear
    };
    ReducedModel::build(ModelSource {
        model: m,
        material: &material(),
        time: &time(1),
        basis,
        cubature: rule,
        subspace,
        solver: solver(),
        preconditioning: Default::default(),
        spring_compliance: true,
        full_solver: solver(),
        rows,
        provenance: Provenance {
            project_version: "test".into(),
            scene: "bar".into(),
            method: kind.name().into(),
            ..Default::default()
        },
        training: None,
    })
    .unwrap()
}
