//! Peer benchmark: fem-core's elastic assembly against fenris 0.0.33 (+ fenris-solid), a Rust FEM
//! library, on the same meshes, displacement and Lamé parameters, measured in one run.
//!
//! ```sh
//! cargo bench -p benches --features peers --bench peers
//! # one mesh or one stage: criterion filters by name
//! cargo bench -p benches --features peers --bench peers -- 'peer_hessian/beam10k'
//! ```
//!
//! The feature keeps fenris (and its nalgebra 0.32) out of every normal build and test.
//!
//! Meshes: `catapult` (shared/meshes/catapult_low.mesh, skipped with a printed reason when the
//! shared folder is absent) and `beam10k` (the generated 10,000-vertex beam of the `fem` bench),
//! both at [`benches::smooth_displacement`]. Material E = 1e5 Pa, ν = 0.45, converted once to
//! Lamé parameters and handed to both codes. Nothing is pinned: fenris assembles every DOF, so
//! ours does too and both fill the same sparsity pattern.
//!
//! What is compared with what:
//!
//! * `fenris-nh`: fenris-solid's `NeoHookeanMaterial`, μ/2 (I_C − 3) − μ ln J + λ/2 (ln J)²,
//!   one-point quadrature on Tet4. Single thread uses fenris's serial assemblers; two threads
//!   its parallel ones (energy by a rayon reduction, gradient and Hessian scattered colour by
//!   colour). fenris computes energy and gradient in two passes; it has no fused pass.
//! * `ours-nh`: fem-core's classic Neo-Hookean, the same energy: equal work. Before measuring,
//!   the benchmark prints the relative difference of energy, gradient and Hessian between the
//!   two (round-off, ~1e-15); `cargo test -p benches --features peers` asserts it.
//! * `ours-snh`: fem-core's default stable Neo-Hookean (a different, inversion-safe energy with
//!   the same small-strain behaviour): what the simulator actually runs.
//! * Hessians: fenris unprojected; ours unprojected and `-projected` (per-element PSD
//!   projection, what Newton uses; analytic for stable Neo-Hookean, eigen-decomposition
//!   fallback for classic Neo-Hookean).
//!
//! Throughput is elements per second. Every measurement runs inside an explicit rayon pool of
//! the thread count in its name.

use std::hint::black_box;
use std::time::Duration;

use benches::peers::FenrisNeoHookean;
use benches::{beam_10k, det_f_range, read_shared_mesh, smooth_displacement};
use criterion::{BenchmarkGroup, Criterion, Throughput, measurement::WallTime};
use fem_core::TetMesh;
use fem_core::assembly::{self, AssemblyBuffers, ElementSet};
use fem_core::constraints::DofMap;
use fem_core::element::Elements;
use fem_core::material::{Lame, Material, MaterialConfig, NeoHookean, StableNeoHookean};
use fem_core::mesh::generate::box_mesh;
use fem_core::sparse::HessianPattern;
use fenris::nalgebra::DVector;
use rayon::{ThreadPool, ThreadPoolBuilder};

/// Thread counts measured.
const THREADS: [usize; 2] = [1, 2];

struct Case {
    name: &'static str,
    mesh: TetMesh,
}

fn cases() -> Vec<Case> {
    let mut cases = Vec::new();
    if let Some(mesh) = read_shared_mesh("catapult_low.mesh") {
        cases.push(Case {
            name: "catapult",
            mesh,
        });
    } else {
        eprintln!("skipping: the catapult benchmarks (no shared/meshes/catapult_low.mesh)");
    }
    cases.push(Case {
        name: "beam10k",
        mesh: box_mesh(&beam_10k()).expect("the beam spec is valid"),
    });
    cases
}

fn pool(threads: usize) -> ThreadPool {
    ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("can start a rayon thread pool")
}

fn max_abs(v: impl Iterator<Item = f64>) -> f64 {
    v.fold(0.0, |m, x| m.max(x.abs()))
}

/// Everything one mesh needs, set up outside the measurements.
struct Setup {
    name: &'static str,
    elements: Elements,
    u: Vec<f64>,
    pattern: HessianPattern,
    peer: FenrisNeoHookean,
    nh: NeoHookean,
    snh: StableNeoHookean,
}

impl Setup {
    fn new(case: &Case, lame: Lame) -> Self {
        let elements = Elements::new(&case.mesh);
        let u = smooth_displacement(&case.mesh);
        let (det_lo, det_hi) = det_f_range(&elements, &u);
        assert!(det_lo > 0.0, "{}: the state inverts an element", case.name);
        let pattern = HessianPattern::new(&elements.tets, &DofMap::new(&case.mesh, &[]));
        let peer = FenrisNeoHookean::new(&case.mesh, lame);
        eprintln!(
            "mesh {}: {} vertices, {} tets, det F in [{det_lo:.4}, {det_hi:.4}], {} Hessian \
             entries, fenris colours {}",
            case.name,
            case.mesh.num_vertices(),
            elements.len(),
            pattern.nnz(),
            peer.num_colors()
        );
        Self {
            name: case.name,
            elements,
            u,
            pattern,
            peer,
            nh: NeoHookean::new(lame),
            snh: StableNeoHookean::new(lame),
        }
    }

    /// Prints how far fenris's energy, gradient and Hessian are from ours (classic NH), and
    /// panics if they are not the same computation.
    fn check_equal_work(&self) {
        let mut buf = AssemblyBuffers::default();
        let (els, u) = (&self.elements, &self.u);
        let mut g = vec![0.0; u.len()];
        let e = assembly::energy_gradient(&self.nh, els, ElementSet::All, u, &mut g, &mut buf);
        let mut gf = DVector::zeros(u.len());
        let ef = self.peer.energy_gradient(u, &mut gf);
        let e_snh = assembly::energy(&self.snh, els, ElementSet::All, u, &mut buf);
        let g_diff = max_abs(g.iter().zip(gf.iter()).map(|(a, b)| a - b));
        let g_scale = max_abs(g.iter().copied());

        let mut values = vec![0.0; self.pattern.nnz()];
        assembly::hessian(
            &self.nh,
            els,
            ElementSet::All,
            u,
            false,
            &self.pattern,
            &mut values,
            &mut buf,
        );
        let mut h = self.peer.hessian_matrix(u);
        assert_eq!(self.pattern.symbolic.col_ptr(), h.row_offsets());
        assert_eq!(self.pattern.symbolic.row_idx(), h.col_indices());
        self.peer.hessian(u, &mut h);
        let h_diff = max_abs(values.iter().zip(h.values()).map(|(a, b)| a - b));
        let h_scale = max_abs(values.iter().copied());

        eprintln!(
            "mesh {}: energy ours-nh {e:.15e}, fenris-nh {ef:.15e} (relative difference \
             {:.1e}); ours-snh {e_snh:.6e}",
            self.name,
            (e - ef).abs() / e
        );
        eprintln!(
            "mesh {}: max |gradient difference| / max |gradient| {:.1e}, max |Hessian \
             difference| / max |Hessian entry| {:.1e}",
            self.name,
            g_diff / g_scale,
            h_diff / h_scale
        );
        assert!((e - ef).abs() <= 1e-12 * e && g_diff <= 1e-12 * g_scale);
        assert!(h_diff <= 1e-12 * h_scale);
    }
}

fn bench_ours_energy_gradient<M: Material>(
    group: &mut BenchmarkGroup<'_, WallTime>,
    id: String,
    pool: &ThreadPool,
    s: &Setup,
    material: &M,
) {
    let mut grad = vec![0.0; s.u.len()];
    let mut buf = AssemblyBuffers::default();
    group.bench_function(id, |b| {
        pool.install(|| {
            b.iter(|| {
                assembly::energy_gradient(
                    material,
                    &s.elements,
                    ElementSet::All,
                    black_box(&s.u),
                    &mut grad,
                    &mut buf,
                )
            })
        })
    });
}

fn bench_ours_hessian<M: Material>(
    group: &mut BenchmarkGroup<'_, WallTime>,
    id: String,
    pool: &ThreadPool,
    s: &Setup,
    material: &M,
    projected: bool,
) {
    let mut values = vec![0.0; s.pattern.nnz()];
    let mut buf = AssemblyBuffers::default();
    group.bench_function(id, |b| {
        pool.install(|| {
            b.iter(|| {
                assembly::hessian(
                    material,
                    &s.elements,
                    ElementSet::All,
                    black_box(&s.u),
                    projected,
                    &s.pattern,
                    &mut values,
                    &mut buf,
                );
                black_box(values[0])
            })
        })
    });
}

fn bench_energy_gradient(c: &mut Criterion, setups: &[Setup], pools: &[(usize, ThreadPool)]) {
    let mut group = c.benchmark_group("peer_energy_gradient");
    group
        .sample_size(20)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));
    for s in setups {
        group.throughput(Throughput::Elements(s.elements.len() as u64));
        for (threads, pool) in pools {
            let mut grad = DVector::zeros(s.u.len());
            group.bench_function(format!("{}/fenris-nh/{threads}t", s.name), |b| {
                pool.install(|| {
                    b.iter(|| {
                        if *threads == 1 {
                            s.peer.energy_gradient(black_box(&s.u), &mut grad)
                        } else {
                            s.peer.par_energy_gradient(black_box(&s.u), &mut grad)
                        }
                    })
                })
            });
            let id = |m: &str| format!("{}/{m}/{threads}t", s.name);
            bench_ours_energy_gradient(&mut group, id("ours-nh"), pool, s, &s.nh);
            bench_ours_energy_gradient(&mut group, id("ours-snh"), pool, s, &s.snh);
        }
    }
    group.finish();
}

fn bench_hessian(c: &mut Criterion, setups: &[Setup], pools: &[(usize, ThreadPool)]) {
    let mut group = c.benchmark_group("peer_hessian");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3));
    for s in setups {
        group.throughput(Throughput::Elements(s.elements.len() as u64));
        let mut h = s.peer.hessian_matrix(&s.u);
        for (threads, pool) in pools {
            group.bench_function(format!("{}/fenris-nh/{threads}t", s.name), |b| {
                pool.install(|| {
                    b.iter(|| {
                        if *threads == 1 {
                            s.peer.hessian(black_box(&s.u), &mut h);
                        } else {
                            s.peer.par_hessian(black_box(&s.u), &mut h);
                        }
                        black_box(h.values()[0])
                    })
                })
            });
            let id = |m: &str| format!("{}/{m}/{threads}t", s.name);
            bench_ours_hessian(&mut group, id("ours-nh"), pool, s, &s.nh, false);
            bench_ours_hessian(&mut group, id("ours-nh-projected"), pool, s, &s.nh, true);
            bench_ours_hessian(&mut group, id("ours-snh"), pool, s, &s.snh, false);
            bench_ours_hessian(&mut group, id("ours-snh-projected"), pool, s, &s.snh, true);
        }
    }
    group.finish();
}

fn main() {
    let lame = MaterialConfig::default().lame();
    eprintln!(
        "Lamé parameters: mu = {}, lambda = {}",
        lame.mu, lame.lambda
    );
    let setups: Vec<Setup> = cases().iter().map(|c| Setup::new(c, lame)).collect();
    for s in &setups {
        s.check_equal_work();
    }
    let pools: Vec<(usize, ThreadPool)> = THREADS.iter().map(|&t| (t, pool(t))).collect();
    let mut c = Criterion::default().configure_from_args();
    bench_energy_gradient(&mut c, &setups, &pools);
    bench_hessian(&mut c, &setups, &pools);
    c.final_summary();
}
