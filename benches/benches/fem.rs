//! Full-space FEM throughput: elastic assembly (energy + gradient, projected Hessian) per element,
//! the sparse Cholesky's factorisation and solves (f64, and the f32 factor L-BFGS's preconditioner
//! uses where it passes its check), and the cost of one implicit Euler step with Newton and with
//! L-BFGS; and per material, the element kernels ψ and P, and the projected tangent, on
//! deformation gradients like a moving body's.
//!
//! Two meshes: `catapult` (shared/meshes/catapult_low.mesh, skipped with a printed reason when the
//! shared folder is absent) and `beam10k`, a generated 1 × 0.1 × 0.1 m beam of 10,000 vertices.
//! Both use stable Neo-Hookean (ν = 0.45) and are pinned on their x-min plane. Every measurement
//! runs inside an explicit rayon pool, so the thread count is the one in the benchmark's name.
//!
//! ```sh
//! cargo bench -p benches --bench fem
//! ```

use std::hint::black_box;
use std::time::Duration;

use benches::{beam_10k, det_f_range, read_shared_mesh, smooth_displacement};
use criterion::{BatchSize, Criterion, SamplingMode, Throughput};
use fem_core::assembly::{self, AssemblyBuffers, ElementSet};
use fem_core::constraints::{Axis, DofMap, Side, VertexSelection};
use fem_core::element::Elements;
use fem_core::integrator::{FullSpaceModel, Simulator, TimeConfig};
use fem_core::material::{Material, MaterialConfig, MaterialModel};
use fem_core::mesh::generate::box_mesh;
use fem_core::optim::{SolverConfig, SolverMethod};
use fem_core::sparse::HessianPattern;
use fem_core::sparse_cholesky::SparseCholesky;
use fem_core::{Mat3, TetMesh, Vec3, rng::SplitMix64, with_material};
use rayon::{ThreadPool, ThreadPoolBuilder};

/// Thread counts of the assembly benchmarks.
const THREADS: [usize; 2] = [1, 2];
/// Steps taken from rest before the measured step, so that it starts from a moving state.
const WARM_STEPS: usize = 5;
/// Time step h in seconds.
const TIME_STEP: f64 = 0.01;

/// A mesh to benchmark on, with how to pin it and how stiff to make it for time stepping.
struct Case {
    name: &'static str,
    mesh: TetMesh,
    /// Tolerance of the x-min pin plane (mesh units); `None` is the selector's default.
    pin_tolerance: Option<f64>,
    /// Young's modulus of the time-stepping benchmarks.
    step_youngs_modulus: f64,
}

impl Case {
    fn pinned(&self) -> Vec<usize> {
        VertexSelection::plane(Axis::X, Side::Min, self.pin_tolerance)
            .select(&self.mesh, "pin[0]")
            .expect("the x-min plane selects vertices")
    }

    /// The pinned case under gravity with `material`, no other load.
    fn model(&self, material: &MaterialConfig) -> FullSpaceModel {
        FullSpaceModel::new(
            self.mesh.clone(),
            material,
            self.pinned(),
            Vec3::new(0.0, -9.81, 0.0),
            Vec::new(),
        )
        .expect("the benchmark model is valid")
    }
}

fn cases() -> Vec<Case> {
    let mut cases = Vec::new();
    if let Some(mesh) = read_shared_mesh("catapult_low.mesh") {
        // Only one vertex lies exactly on the catapult's x-min plane; a slab of 10 % of its
        // x-extent pins its flat side (about 135 vertices) instead of hanging it from a point.
        let (lo, hi) = mesh.bounding_box();
        cases.push(Case {
            name: "catapult",
            pin_tolerance: Some(0.1 * (hi.x - lo.x)),
            step_youngs_modulus: 1.0e5,
            mesh,
        });
    } else {
        eprintln!("skipping: the catapult benchmarks (no shared/meshes/catapult_low.mesh)");
    }
    // At E = 1e5 the beam's static sag under its own weight would be ~15 m; 1e6 keeps it bending.
    cases.push(Case {
        name: "beam10k",
        mesh: box_mesh(&beam_10k()).expect("the beam spec is valid"),
        pin_tolerance: None,
        step_youngs_modulus: 1.0e6,
    });
    for c in &cases {
        eprintln!(
            "mesh {}: {} vertices, {} tets, {} pinned",
            c.name,
            c.mesh.num_vertices(),
            c.mesh.num_tets(),
            c.pinned().len()
        );
    }
    cases
}

fn pool(threads: usize) -> ThreadPool {
    ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("can start a rayon thread pool")
}

/// Energy + gradient and projected-Hessian assembly over all elements at a fixed deformed state.
fn bench_assembly(c: &mut Criterion, cases: &[Case]) {
    let material = MaterialConfig::default().build();
    let pools: Vec<(usize, ThreadPool)> = THREADS.iter().map(|&t| (t, pool(t))).collect();
    let mut group = c.benchmark_group("assembly");
    group
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));
    for case in cases {
        let elements = Elements::new(&case.mesh);
        let u = smooth_displacement(&case.mesh);
        let (det_lo, det_hi) = det_f_range(&elements, &u);
        assert!(
            det_lo > 0.0,
            "{}: the benchmark state inverts an element (min det F = {det_lo})",
            case.name
        );
        eprintln!("mesh {}: det F in [{det_lo:.4}, {det_hi:.4}]", case.name);
        let dofs = DofMap::new(&case.mesh, &case.pinned());
        let pattern = HessianPattern::new(&elements.tets, &dofs);
        let mut values = vec![0.0; pattern.nnz()];
        let mut grad = vec![0.0; u.len()];
        let mut buf = AssemblyBuffers::default();
        group.throughput(Throughput::Elements(elements.len() as u64));
        for (threads, pool) in &pools {
            group.bench_function(format!("energy_gradient/{}/{threads}t", case.name), |b| {
                pool.install(|| {
                    b.iter(|| {
                        with_material!(&material, |m| assembly::energy_gradient(
                            m,
                            &elements,
                            ElementSet::All,
                            black_box(&u),
                            &mut grad,
                            &mut buf
                        ))
                    })
                })
            });
            group.bench_function(format!("hessian/{}/{threads}t", case.name), |b| {
                pool.install(|| {
                    b.iter(|| {
                        with_material!(&material, |m| assembly::hessian(
                            m,
                            &elements,
                            ElementSet::All,
                            black_box(&u),
                            true,
                            &pattern,
                            &mut values,
                            &mut buf
                        ));
                        black_box(values[0])
                    })
                })
            });
        }
    }
    group.finish();
}

/// The projected Hessian at the benchmark state plus M/h², factorised and solved on one thread.
fn bench_sparse(c: &mut Criterion, cases: &[Case]) {
    let pool = pool(1);
    let mut group = c.benchmark_group("sparse");
    group
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));
    for case in cases {
        let model = case.model(&MaterialConfig::default());
        let u = smooth_displacement(&case.mesh);
        let pattern = HessianPattern::new(&model.elements.tets, &model.dofs);
        let mut values = vec![0.0; pattern.nnz()];
        with_material!(&model.material, |m| assembly::hessian(
            m,
            &model.elements,
            ElementSet::All,
            &u,
            true,
            &pattern,
            &mut values,
            &mut AssemblyBuffers::default()
        ));
        // The time-stepping matrix: plus M/h².
        for (j, &d) in model.dofs.free.iter().enumerate() {
            values[pattern.diag[j]] += model.mass.lumped[d / 3] / (TIME_STEP * TIME_STEP);
        }
        let mut chol = SparseCholesky::analyse(&pattern).expect("the pattern analyses");
        pool.install(|| chol.factor(pattern.matrix(&values)))
            .expect("the pinned projected Hessian is positive definite");
        eprintln!(
            "sparse/{}: {} DOFs, nnz(A) = {}, nnz(L) = {}, supernodal: {}",
            case.name,
            pattern.dim(),
            pattern.nnz(),
            chol.factor_nnz(),
            chol.is_supernodal()
        );
        let b: Vec<f64> = (0..pattern.dim()).map(|i| (i % 7) as f64 - 3.0).collect();
        let mut x = b.clone();
        group.bench_function(format!("factor/{}", case.name), |bench| {
            pool.install(|| bench.iter(|| chol.factor(pattern.matrix(black_box(&values)))))
        });
        group.bench_function(format!("solve/{}", case.name), |bench| {
            pool.install(|| {
                bench.iter(|| {
                    x.copy_from_slice(&b);
                    chol.solve_in_place(&mut x);
                    black_box(x[0])
                })
            })
        });
        let single = chol
            .factor_for_preconditioning(pattern.matrix(&values))
            .expect("the pinned projected Hessian is positive definite");
        eprintln!(
            "sparse/{}: preconditioner factor stored in {single:?} precision",
            case.name
        );
        group.bench_function(format!("factor_preconditioner/{}", case.name), |bench| {
            pool.install(|| {
                bench.iter(|| chol.factor_for_preconditioning(pattern.matrix(black_box(&values))))
            })
        });
        group.bench_function(format!("solve_preconditioner/{}", case.name), |bench| {
            pool.install(|| {
                bench.iter(|| {
                    x.copy_from_slice(&b);
                    chol.solve_preconditioner_in_place(&mut x);
                    black_box(x[0])
                })
            })
        });
    }
    group.finish();
}

/// One implicit Euler step from the same moving state, Newton and L-BFGS, on two threads.
fn bench_step(c: &mut Criterion, cases: &[Case]) {
    let pool = pool(2);
    let time = TimeConfig {
        step: TIME_STEP,
        frames: WARM_STEPS + 1,
        quasi_static: false,
    };
    let mut group = c.benchmark_group("step");
    // A step takes milliseconds to a second: equal-length samples, few of them.
    group
        .sampling_mode(SamplingMode::Flat)
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(4));
    for case in cases {
        let material = MaterialConfig {
            youngs_modulus: case.step_youngs_modulus,
            ..Default::default()
        };
        let model = case.model(&material);
        let start = pool.install(|| {
            let mut warm = Simulator::new(model.clone(), time.clone(), SolverConfig::default())
                .expect("the benchmark simulator is valid");
            for _ in 0..WARM_STEPS {
                warm.step().expect("the warm-up steps converge");
            }
            warm.state.clone()
        });
        for (label, method) in [
            ("newton", SolverMethod::Newton),
            ("lbfgs", SolverMethod::Lbfgs),
        ] {
            let solver = SolverConfig {
                method,
                ..Default::default()
            };
            let mut sim = Simulator::new(model.clone(), time.clone(), solver)
                .expect("the benchmark simulator is valid");
            // The first step also builds the pattern and factorisations; keep that out of the
            // measurement and report the iteration count of the (deterministic) measured step.
            sim.state = start.clone();
            let report = pool
                .install(|| sim.step())
                .expect("the measured step converges");
            eprintln!(
                "step/{label}/{}: {} iterations, relative gradient {:.2e}, first call {:.1} ms",
                case.name,
                report.iterations,
                report.relative_gradient,
                1e3 * report.wall_seconds
            );
            group.bench_function(format!("{label}/{}", case.name), |b| {
                pool.install(|| {
                    b.iter_batched(
                        || start.clone(),
                        |state| {
                            // Hand the previous state back so that it is freed outside the timing.
                            let old = std::mem::replace(&mut sim.state, state);
                            (sim.step().expect("the measured step converges"), old)
                        },
                        BatchSize::PerIteration,
                    )
                })
            });
        }
    }
    group.finish();
}

/// Deformation gradients F = R(I + G) with R a random rotation and G's entries uniform in
/// ±0.05 (strains up to about 10 %, nearly all of them compressed in some direction).
fn deformation_gradients(count: usize) -> Vec<Mat3> {
    let mut rng = SplitMix64::new(20_261_127);
    (0..count)
        .map(|_| {
            let axis = Vec3::from(rng.unit_vector());
            let rotation = nalgebra::Rotation3::from_scaled_axis(axis * rng.range(0.0, 3.0));
            let g = Mat3::from_fn(|_, _| rng.range(-0.05, 0.05));
            rotation.matrix() * (Mat3::identity() + g)
        })
        .collect()
}

/// Each material's ψ with P (what an energy-and-gradient pass evaluates per element), its
/// tangent (the reduced preconditioners' per-element Hessian) and the projected tangent
/// (Newton's), per F.
fn bench_materials(c: &mut Criterion) {
    const COUNT: usize = 4096;
    let fs = deformation_gradients(COUNT);
    let mut group = c.benchmark_group("material");
    group
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(2))
        .throughput(Throughput::Elements(COUNT as u64));
    for model in MaterialModel::ALL {
        let material = MaterialConfig {
            model,
            ..MaterialConfig::default()
        }
        .build();
        let name = material.name();
        with_material!(&material, |m| {
            // Each whole result goes through black_box, so no part of it can be skipped.
            group.bench_function(format!("psi_pk1/{name}"), |b| {
                b.iter(|| {
                    fs.iter()
                        .for_each(|f| _ = black_box(m.psi_pk1(black_box(f))))
                })
            });
            group.bench_function(format!("dpdf/{name}"), |b| {
                b.iter(|| fs.iter().for_each(|f| _ = black_box(m.dpdf(black_box(f)))))
            });
            group.bench_function(format!("dpdf_projected/{name}"), |b| {
                b.iter(|| {
                    fs.iter()
                        .for_each(|f| _ = black_box(m.dpdf_projected(black_box(f))))
                })
            });
        });
    }
    group.finish();
}

fn main() {
    let cases = cases();
    let mut c = Criterion::default().configure_from_args();
    bench_assembly(&mut c, &cases);
    bench_sparse(&mut c, &cases);
    bench_step(&mut c, &cases);
    bench_materials(&mut c);
    c.final_summary();
}
