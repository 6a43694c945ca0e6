//! Hyperelastic materials: P and ∂P/∂F against central finite differences, symmetry and PSD of
//! the tangents, rest state, rotation invariance, small-strain limits, extreme deformations,
//! and validation against `shared/validation/materials/neohookean_table.json`.

use fem_core::Mat3;
use fem_core::material::{
    Corotated, Lame, LinearElastic, Mat9, Material, NeoHookean, StVenantKirchhoff,
    StableNeoHookean, project_psd,
};
use nalgebra::{UnitQuaternion, Vector3};

// ---------------------------------------------------------------------------------------------
// Helpers.

/// SplitMix64: a tiny deterministic generator (no `rand` dependency).
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi).
    fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        let unit = (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * unit
    }

    fn rotation(&mut self) -> Mat3 {
        let q = nalgebra::Quaternion::new(
            self.uniform(-1.0, 1.0),
            self.uniform(-1.0, 1.0),
            self.uniform(-1.0, 1.0),
            self.uniform(-1.0, 1.0),
        );
        *UnitQuaternion::from_quaternion(q)
            .to_rotation_matrix()
            .matrix()
    }

    /// R₁ diag(σ) R₂ᵀ with random rotations: full control of the (signed) singular values.
    fn with_singular_values(&mut self, s: [f64; 3]) -> Mat3 {
        let (r1, r2) = (self.rotation(), self.rotation());
        r1 * Mat3::from_diagonal(&Vector3::from(s)) * r2.transpose()
    }

    /// A well-conditioned F with det F > 0: singular values in [0.6, 1.6].
    fn well_conditioned(&mut self) -> Mat3 {
        let s = [
            self.uniform(0.6, 1.6),
            self.uniform(0.6, 1.6),
            self.uniform(0.6, 1.6),
        ];
        self.with_singular_values(s)
    }

    /// An inverted F (det F < 0) away from the corotated singular set σ₁ + σ₂ = 0: singular
    /// values (a, b, −c) with a ≥ b ≥ c + 0.2.
    fn inverted(&mut self) -> Mat3 {
        let c = self.uniform(0.1, 0.8);
        let b = self.uniform(c + 0.2, 1.4);
        let a = self.uniform(b, 1.8);
        self.with_singular_values([a, b, -c])
    }
}

/// Material parameter sets: unit scale with ν = 0.3, and a stiff nearly incompressible one
/// (E = 1e6, ν = 0.45).
fn lame_sets() -> [Lame; 2] {
    [
        Lame::from_young_poisson(2.6, 0.3),
        Lame::from_young_poisson(1.0e6, 0.45),
    ]
}

const FD_SAMPLES: usize = 8;

/// Central-difference step for F: 1e-6 relative to the size of F's entries.
fn fd_step(f: &Mat3) -> f64 {
    1e-6 * f.amax().max(1.0)
}

fn fd_pk1<M: Material>(m: &M, f: &Mat3) -> Mat3 {
    let h = fd_step(f);
    let mut p = Mat3::zeros();
    for i in 0..9 {
        let (mut fp, mut fm) = (*f, *f);
        fp[i] += h;
        fm[i] -= h;
        p[i] = (m.psi(&fp) - m.psi(&fm)) / (2.0 * h);
    }
    p
}

fn fd_dpdf<M: Material>(m: &M, f: &Mat3) -> Mat9 {
    let h = fd_step(f);
    let mut a = Mat9::zeros();
    for b in 0..9 {
        let (mut fp, mut fm) = (*f, *f);
        fp[b] += h;
        fm[b] -= h;
        let d = (m.pk1(&fp) - m.pk1(&fm)) / (2.0 * h);
        a.column_mut(b).copy_from_slice(d.as_slice());
    }
    a
}

/// ‖x − y‖_F / max(‖y‖_F, floor).
fn rel<const R: usize, const C: usize>(
    x: &nalgebra::SMatrix<f64, R, C>,
    y: &nalgebra::SMatrix<f64, R, C>,
    floor: f64,
) -> f64 {
    (x - y).norm() / y.norm().max(floor)
}

fn min_eigenvalue(a: &Mat9) -> f64 {
    a.symmetric_eigenvalues().min()
}

fn assert_symmetric_psd(a: &Mat9, what: &str) {
    let n = a.norm();
    assert!(a.iter().all(|x| x.is_finite()), "{what}: not finite");
    assert!(
        (a - a.transpose()).norm() <= 1e-12 * n,
        "{what}: not symmetric"
    );
    let lo = min_eigenvalue(a);
    assert!(lo >= -1e-8 * n, "{what}: min eigenvalue {lo:e}, norm {n:e}");
}

/// Stamps out the generic tests for one material type.
macro_rules! material_tests {
    ($module:ident, $ty:ident, rotation_invariant: $rot:expr) => {
        mod $module {
            use super::*;

            fn materials() -> Vec<$ty> {
                lame_sets().into_iter().map($ty::new).collect()
            }

            /// Well-conditioned F (det > 0), and inverted ones for inversion-safe materials.
            fn samples(seed: u64) -> Vec<Mat3> {
                let mut rng = Rng(seed);
                let mut fs: Vec<Mat3> = (0..FD_SAMPLES).map(|_| rng.well_conditioned()).collect();
                if <$ty as Material>::INVERSION_SAFE {
                    fs.extend((0..FD_SAMPLES / 2).map(|_| rng.inverted()));
                }
                fs
            }

            #[test]
            fn pk1_matches_fd_of_psi() {
                let mut worst: f64 = 0.0;
                for m in materials() {
                    let mu = m.dpdf(&Mat3::identity()).amax() * 1e-3;
                    for f in samples(1) {
                        let err = rel(&m.pk1(&f), &fd_pk1(&m, &f), mu);
                        assert!(err <= 1e-6, "{m:?} F = {f}: rel err {err:e}");
                        worst = worst.max(err);
                    }
                }
                eprintln!(
                    "{}: max rel err of P vs FD(ψ) = {worst:.2e}",
                    stringify!($ty)
                );
            }

            #[test]
            fn dpdf_matches_fd_of_pk1() {
                let mut worst: f64 = 0.0;
                for m in materials() {
                    let mu = m.dpdf(&Mat3::identity()).amax() * 1e-3;
                    for f in samples(2) {
                        let err = rel(&m.dpdf(&f), &fd_dpdf(&m, &f), mu);
                        assert!(err <= 1e-6, "{m:?} F = {f}: rel err {err:e}");
                        worst = worst.max(err);
                    }
                }
                eprintln!(
                    "{}: max rel err of ∂P/∂F vs FD(P) = {worst:.2e}",
                    stringify!($ty)
                );
            }

            #[test]
            fn dpdf_is_symmetric() {
                for m in materials() {
                    for f in samples(3) {
                        let a = m.dpdf(&f);
                        assert!(
                            (a - a.transpose()).norm() <= 1e-13 * a.norm(),
                            "{m:?} F = {f}"
                        );
                    }
                }
            }

            #[test]
            fn dpdf_projected_is_symmetric_psd() {
                for m in materials() {
                    for f in samples(4) {
                        let p = m.dpdf_projected(&f);
                        assert_symmetric_psd(&p, &format!("{m:?} F = {f}"));
                        // Overrides (analytic eigensystems) agree with the generic projection.
                        let err = rel(&p, &project_psd(&m.dpdf(&f)), 1e-300);
                        assert!(err <= 1e-9, "{m:?} F = {f}: projection rel err {err:e}");
                    }
                }
            }

            #[test]
            fn dpdf_projected_equals_dpdf_when_psd() {
                let mut checked = 0;
                for m in materials() {
                    let mut fs = samples(5);
                    fs.push(Mat3::identity());
                    for f in fs {
                        let a = m.dpdf(&f);
                        if min_eigenvalue(&a) < -1e-12 * a.norm() {
                            continue;
                        }
                        checked += 1;
                        let err = rel(&m.dpdf_projected(&f), &a, 0.0);
                        assert!(err <= 1e-10, "{m:?} F = {f}: rel err {err:e}");
                    }
                }
                // At least F = I for each parameter set.
                assert!(checked >= lame_sets().len());
            }

            #[test]
            fn rest_state_is_energy_and_stress_free() {
                for m in materials() {
                    let i = Mat3::identity();
                    assert_eq!(m.psi(&i), 0.0, "{m:?}");
                    assert_eq!(m.pk1(&i), Mat3::zeros(), "{m:?}");
                    assert_eq!(m.psi_pk1(&i), (0.0, Mat3::zeros()), "{m:?}");
                }
            }

            #[test]
            fn rotation_invariance() {
                let mut rng = Rng(6);
                for m in materials() {
                    for f in samples(6) {
                        let r = rng.rotation();
                        let (a, b) = (m.psi(&(r * f)), m.psi(&f));
                        let scale = b.abs().max(m.dpdf(&Mat3::identity()).amax() * 1e-3);
                        if $rot {
                            assert!((a - b).abs() <= 1e-12 * scale, "{m:?} F = {f}: {a} vs {b}");
                            // P is frame-indifferent: P(RF) = R P(F).
                            let err = rel(&m.pk1(&(r * f)), &(r * m.pk1(&f)), scale);
                            assert!(err <= 1e-12, "{m:?} F = {f}: P rel err {err:e}");
                        } else {
                            // Small-strain elasticity is not invariant: rotations cost energy.
                            assert!((a - b).abs() > 1e-6 * scale, "{m:?} F = {f}");
                        }
                    }
                }
            }

            #[test]
            fn psi_pk1_agrees_with_psi_and_pk1() {
                for m in materials() {
                    let mut fs = samples(7);
                    fs.push(Mat3::identity());
                    for f in fs {
                        let (psi, p) = m.psi_pk1(&f);
                        let psi_ref = m.psi(&f);
                        assert!((psi - psi_ref).abs() <= 1e-13 * psi_ref.abs().max(1e-300));
                        assert!(rel(&p, &m.pk1(&f), 1e-300) <= 1e-13, "{m:?} F = {f}");
                    }
                }
            }
        }
    };
}

material_tests!(linear, LinearElastic, rotation_invariant: false);
material_tests!(corotated, Corotated, rotation_invariant: true);
material_tests!(stvk, StVenantKirchhoff, rotation_invariant: true);
material_tests!(neo_hookean, NeoHookean, rotation_invariant: true);
material_tests!(stable_neo_hookean, StableNeoHookean, rotation_invariant: true);

// ---------------------------------------------------------------------------------------------
// Small-strain limits.

#[test]
fn snh_small_strain_limit_is_linear_elasticity() {
    for lame in lame_sets() {
        let lin = LinearElastic::new(lame).dpdf(&Mat3::identity());
        let snh = StableNeoHookean::new(lame);
        let a = snh.dpdf(&Mat3::identity());
        let err = rel(&a, &lin, 0.0);
        assert!(err <= 1e-12, "{lame:?}: rel err {err:e}");
        assert_eq!(snh.lame(), lame);
        assert!((snh.alpha() - (1.0 + lame.mu / (lame.lambda + lame.mu))).abs() < 1e-15);
        // The same holds for the stress of a small strain, to first order.
        let mut rng = Rng(11);
        let mut du = Mat3::zeros();
        du.iter_mut().for_each(|x| *x = rng.uniform(-1e-7, 1e-7));
        let f = Mat3::identity() + du;
        let err = rel(
            &snh.pk1(&f),
            &LinearElastic::new(lame).pk1(&f),
            lin.amax() * 1e-7,
        );
        assert!(err <= 1e-6, "{lame:?}: small-strain stress rel err {err:e}");
    }
}

#[test]
fn rest_tangents_equal_linear_elasticity() {
    let i = Mat3::identity();
    for lame in lame_sets() {
        let lin = LinearElastic::new(lame).dpdf(&i);
        let cases = [
            ("corotated", Corotated::new(lame).dpdf(&i)),
            ("stvk", StVenantKirchhoff::new(lame).dpdf(&i)),
            ("neo-hookean", NeoHookean::new(lame).dpdf(&i)),
            ("stable-neo-hookean", StableNeoHookean::new(lame).dpdf(&i)),
        ];
        for (name, a) in cases {
            let err = rel(&a, &lin, 0.0);
            assert!(err <= 1e-12, "{name} {lame:?}: rel err {err:e}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Extreme deformations.

fn extreme_deformations() -> Vec<Mat3> {
    let mut rng = Rng(21);
    let mut fs = vec![
        Mat3::from_diagonal_element(0.05),
        Mat3::from_diagonal(&Vector3::new(1.0, 1.0, 0.01)),
        Mat3::new(1.0, 8.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0),
        Mat3::new(1.0, 3.0, -2.0, 0.0, 1.0, 4.0, 0.0, 0.0, 0.2),
        Mat3::from_diagonal(&Vector3::new(1.0, 1.0, -0.5)),
        Mat3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0)),
        Mat3::from_diagonal(&Vector3::new(3.0, 0.2, -0.1)),
        -Mat3::identity(),
        Mat3::zeros(),
        Mat3::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0),
        Mat3::from_diagonal(&Vector3::new(4.0, 4.0, 4.0)),
    ];
    for _ in 0..10 {
        let s = [
            rng.uniform(0.01, 3.0),
            rng.uniform(0.01, 3.0),
            rng.uniform(-2.0, 0.3),
        ];
        fs.push(rng.with_singular_values(s));
        let mut shear = Mat3::identity();
        shear[(0, 1)] = rng.uniform(-6.0, 6.0);
        shear[(1, 2)] = rng.uniform(-6.0, 6.0);
        fs.push(rng.rotation() * shear * Mat3::from_diagonal_element(rng.uniform(0.05, 0.5)));
    }
    fs
}

fn check_extreme<M: Material>(m: M) {
    assert!(M::INVERSION_SAFE);
    for f in extreme_deformations() {
        let what = format!("{m:?} F = {f}");
        assert!(m.psi(&f).is_finite(), "{what}");
        assert!(m.pk1(&f).iter().all(|x| x.is_finite()), "{what}");
        let a = m.dpdf(&f);
        assert!(a.iter().all(|x| x.is_finite()), "{what}");
        let p = m.dpdf_projected(&f);
        assert_symmetric_psd(&p, &what);
        // Whatever the projection's implementation, it is the clamped eigen-decomposition, to
        // within that decomposition's own error, about ε‖∂P/∂F‖ (‖∂P/∂F‖ ~ μ·10⁸ on the
        // corotated singular set, where the projection is O(μ)).
        let reference = project_psd(&a);
        let err = (p - reference).norm();
        let tolerance = 1e-9 * reference.norm() + 1e-15 * a.norm();
        assert!(err <= tolerance, "{what}: projection error {err:e}");
    }
}

#[test]
fn projected_tangent_is_psd_under_extreme_deformation() {
    for lame in lame_sets() {
        check_extreme(LinearElastic::new(lame));
        check_extreme(Corotated::new(lame));
        check_extreme(StVenantKirchhoff::new(lame));
        check_extreme(StableNeoHookean::new(lame));
    }
}

#[test]
fn neo_hookean_is_undefined_when_inverted() {
    let m = NeoHookean::new(lame_sets()[0]);
    for f in [
        Mat3::from_diagonal(&Vector3::new(1.0, 1.0, -0.5)),
        -Mat3::identity(),
        Mat3::zeros(),
    ] {
        assert_eq!(m.psi(&f), f64::INFINITY);
        assert_eq!(m.psi_pk1(&f).0, f64::INFINITY);
        assert!(m.pk1(&f).iter().all(|x| x.is_nan()));
        assert!(m.dpdf(&f).iter().all(|x| x.is_nan()));
        assert!(m.dpdf_projected(&f).iter().all(|x| x.is_nan()));
    }
}

// ---------------------------------------------------------------------------------------------
// Validation against the shared Neo-Hookean reference table.

mod neohookean_table {
    use super::*;
    use serde_json::Value;

    /// The table, or `None` (saying that `what` is skipped) without `shared/`.
    fn table(what: &str) -> Option<Value> {
        let path =
            super::super::shared_dir(what)?.join("validation/materials/neohookean_table.json");
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
        Some(serde_json::from_str(&text).expect("neohookean_table.json is valid JSON"))
    }

    fn num(v: &Value) -> f64 {
        v.as_f64()
            .unwrap_or_else(|| panic!("expected a number, got {v}"))
    }

    fn rows(v: &Value) -> Vec<Vec<f64>> {
        v.as_array()
            .expect("nested list")
            .iter()
            .map(|r| r.as_array().expect("row").iter().map(num).collect())
            .collect()
    }

    /// A 3×3 given as rows `[i][j]`.
    fn mat3(v: &Value) -> Mat3 {
        let r = rows(v);
        Mat3::from_fn(|i, j| r[i][j])
    }

    /// The 9×9 tangent given row-major (`[3i+j][3k+l]`) in our column-major flattening
    /// (`(i + 3j, k + 3l)`).
    fn tangent(v: &Value) -> Mat9 {
        let r = rows(v);
        let mut a = Mat9::zeros();
        for (i, j, k, l) in itertools(3) {
            a[(i + 3 * j, k + 3 * l)] = r[3 * i + j][3 * k + l];
        }
        a
    }

    fn itertools(n: usize) -> impl Iterator<Item = (usize, usize, usize, usize)> {
        (0..n).flat_map(move |i| {
            (0..n).flat_map(move |j| (0..n).flat_map(move |k| (0..n).map(move |l| (i, j, k, l))))
        })
    }

    /// max over entries of |x − ref| / max(|ref|, floor): the table's `scaling_note`.
    fn scaled_err<const R: usize, const C: usize>(
        x: &nalgebra::SMatrix<f64, R, C>,
        reference: &nalgebra::SMatrix<f64, R, C>,
        floor: f64,
    ) -> f64 {
        x.iter()
            .zip(reference.iter())
            .map(|(a, b)| (a - b).abs() / b.abs().max(floor))
            .fold(0.0, f64::max)
    }

    #[test]
    fn cases_match_reference_values() {
        let Some(t) = table("the Neo-Hookean reference table") else {
            return;
        };
        let mu = num(&t["parameters"]["mu"]);
        let lam = num(&t["parameters"]["lam"]);
        let m = NeoHookean::new(Lame { mu, lambda: lam });
        // A different Lamé pair, checked through the table's μ/λ decomposition.
        let (mu2, lam2) = (2.7e6, 4.1e7);
        let m2 = NeoHookean::new(Lame {
            mu: mu2,
            lambda: lam2,
        });
        let cases = t["cases"].as_array().expect("cases");
        assert_eq!(cases.len(), 8);
        let (mut worst_psi, mut worst_p, mut worst_a): (f64, f64, f64) = (0.0, 0.0, 0.0);
        for case in cases {
            let name = case["name"].as_str().unwrap_or("?");
            let f = mat3(&case["F"]);
            let psi_ref = num(&case["psi"]);
            let p_ref = mat3(&case["P"]);
            let a_ref = tangent(&case["A_9x9"]);

            let (psi, p) = m.psi_pk1(&f);
            let e_psi = (psi - psi_ref).abs() / psi_ref.abs().max(mu);
            let e_psi2 = (m.psi(&f) - psi_ref).abs() / psi_ref.abs().max(mu);
            let e_p = scaled_err(&p, &p_ref, mu).max(scaled_err(&m.pk1(&f), &p_ref, mu));
            let e_a = scaled_err(&m.dpdf(&f), &a_ref, mu);
            assert!(e_psi <= 1e-10 && e_psi2 <= 1e-10, "{name}: ψ err {e_psi:e}");
            assert!(e_p <= 1e-10, "{name}: P err {e_p:e}");
            assert!(e_a <= 1e-10, "{name}: A err {e_a:e}");
            assert!((num(&case["J"]) - f.determinant()).abs() <= 1e-14);
            worst_psi = worst_psi.max(e_psi).max(e_psi2);
            worst_p = worst_p.max(e_p);
            worst_a = worst_a.max(e_a);

            let psi2_ref = mu2 * num(&case["psi_mu_part"]) + lam2 * num(&case["psi_lam_part"]);
            let p2_ref = mat3(&case["P_mu_part"]) * mu2 + mat3(&case["P_lam_part"]) * lam2;
            let (psi2, p2) = m2.psi_pk1(&f);
            let e_psi2 = (psi2 - psi2_ref).abs() / psi2_ref.abs().max(mu2);
            let e_p2 = scaled_err(&p2, &p2_ref, mu2);
            assert!(e_psi2 <= 1e-10, "{name} (rescaled): ψ err {e_psi2:e}");
            assert!(e_p2 <= 1e-10, "{name} (rescaled): P err {e_p2:e}");
        }
        eprintln!(
            "neohookean_table: max scaled err ψ {worst_psi:.2e}, P {worst_p:.2e}, A {worst_a:.2e}"
        );
    }

    #[test]
    fn inverted_case_has_infinite_energy() {
        let Some(t) = table("the Neo-Hookean table's inverted case") else {
            return;
        };
        let m = NeoHookean::new(Lame {
            mu: num(&t["parameters"]["mu"]),
            lambda: num(&t["parameters"]["lam"]),
        });
        let cases = t["invalid_cases"].as_array().expect("invalid_cases");
        assert!(!cases.is_empty());
        for case in cases {
            let f = mat3(&case["F"]);
            assert!(f.determinant() < 0.0);
            assert_eq!(m.psi(&f), f64::INFINITY);
            assert_eq!(m.psi_pk1(&f).0, f64::INFINITY);
            assert!(m.pk1(&f).iter().all(|x| x.is_nan()));
        }
    }

    #[test]
    fn single_tet_energy_forces_and_hessian() {
        let Some(t) = table("the Neo-Hookean table's single tet") else {
            return;
        };
        let t = &t["single_tet_element"];
        let m = NeoHookean::new(Lame {
            mu: num(&t["mu"]),
            lambda: num(&t["lam"]),
        });
        let xs = rows(&t["X"]);
        let ys = rows(&t["x"]);
        let col = |p: &[Vec<f64>], a: usize| {
            Vector3::new(p[a][0] - p[0][0], p[a][1] - p[0][1], p[a][2] - p[0][2])
        };
        let dm = Mat3::from_columns(&[col(&xs, 1), col(&xs, 2), col(&xs, 3)]);
        let ds = Mat3::from_columns(&[col(&ys, 1), col(&ys, 2), col(&ys, 3)]);
        let bm = dm.try_inverse().expect("non-degenerate rest tet");
        let vol = dm.determinant().abs() / 6.0;
        let f = ds * bm;
        assert!((vol - num(&t["rest_volume"])).abs() <= 1e-14);
        assert!(scaled_err(&f, &mat3(&t["F"]), 1.0) <= 1e-14);

        // Shape gradients: g_a = row a−1 of Bm, g₀ = −(g₁ + g₂ + g₃).
        let mut g = [Vector3::zeros(); 4];
        for a in 1..4 {
            g[a] = bm.row(a - 1).transpose();
        }
        g[0] = -(g[1] + g[2] + g[3]);

        let energy = vol * m.psi(&f);
        let e_ref = num(&t["energy"]);
        let e_err = (energy - e_ref).abs() / e_ref.abs();
        assert!(e_err <= 1e-9, "energy rel err {e_err:e}");

        // forces_a = −V P g_a.
        let p = m.pk1(&f);
        let f_ref = rows(&t["forces"]);
        let f_scale = f_ref.iter().flatten().fold(0.0f64, |s, x| s.max(x.abs()));
        let mut f_err: f64 = 0.0;
        for a in 0..4 {
            let fa = -(p * g[a]) * vol;
            for i in 0..3 {
                f_err = f_err.max((fa[i] - f_ref[a][i]).abs() / f_scale);
            }
        }
        assert!(f_err <= 1e-9, "forces rel err {f_err:e}");

        // H = V Dᵀ A D with D = ∂vec(F)/∂x, D[(r + 3c, 3a + s)] = δ_rs g_a[c].
        let mut d = nalgebra::SMatrix::<f64, 9, 12>::zeros();
        for a in 0..4 {
            for c in 0..3 {
                for r in 0..3 {
                    d[(r + 3 * c, 3 * a + r)] = g[a][c];
                }
            }
        }
        let h = d.transpose() * m.dpdf(&f) * d * vol;
        let h_ref = rows(&t["hessian_12x12"]);
        let h_scale = h_ref.iter().flatten().fold(0.0f64, |s, x| s.max(x.abs()));
        let mut h_err: f64 = 0.0;
        for i in 0..12 {
            for j in 0..12 {
                h_err = h_err.max((h[(i, j)] - h_ref[i][j]).abs() / h_scale);
            }
        }
        assert!(h_err <= 1e-9, "hessian rel err {h_err:e}");
        eprintln!(
            "single tet: energy rel err {e_err:.2e}, forces {f_err:.2e}, hessian {h_err:.2e}"
        );
    }
}
