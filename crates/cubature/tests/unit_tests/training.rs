//! The training matrix against an independent whole-mesh assembly, pose handling and input errors.

use cubature::{
    CubatureConfig, CubatureError, CubatureRule, HeldOutForces, Poses, TrainingMatrix, fit,
};
use faer::{Mat, MatRef};
use fem_core::assembly::{self, AssemblyBuffers, ElementSet};
use fem_core::integrator::FullSpaceModel;
use fem_core::rng::SplitMix64;
use fem_core::with_material;

use super::{beam, modal_basis, norm, normal_mat, random_poses};

/// Uᵀ ∇V(Uq) through whole-mesh assembly, scatter and a dense projection (no per-element rows).
fn projected_gradient(model: &FullSpaceModel, basis: &[f64], k: usize, q: &[f64]) -> Vec<f64> {
    let nf = model.dofs.num_free();
    let u_free: Vec<f64> = (0..nf)
        .map(|r| (0..k).map(|j| basis[j * nf + r] * q[j]).sum())
        .collect();
    let mut u = vec![0.0; model.num_full()];
    model.dofs.scatter(&u_free, &mut u);
    let mut grad = vec![0.0; model.num_full()];
    let mut buf = AssemblyBuffers::default();
    with_material!(&model.material, |m| assembly::energy_gradient(
        m,
        &model.elements,
        ElementSet::All,
        &u,
        &mut grad,
        &mut buf
    ));
    let mut g_free = vec![0.0; nf];
    model.dofs.gather(&grad, &mut g_free);
    (0..k)
        .map(|j| (0..nf).map(|r| basis[j * nf + r] * g_free[r]).sum())
        .collect()
}

fn all_ones_rule(m: usize) -> CubatureRule {
    CubatureRule {
        elements: (0..m).collect(),
        weights: vec![1.0; m],
        training_error: 0.0,
        tolerance_met: true,
        error_curve: vec![],
    }
}

fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let d: Vec<f64> = a.iter().zip(b).map(|(x, y)| x - y).collect();
    norm(&d) / norm(b)
}

#[test]
fn linear_targets_match_whole_mesh_assembly() {
    let model = beam([8, 2, 2]);
    let (basis, k, lambda) = modal_basis(&model);
    let q = random_poses(&model, &basis, &lambda, 12, 3);
    let config = CubatureConfig::default();
    let data =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &config).unwrap();
    assert_eq!((data.num_poses(), data.dim(), data.rows()), (12, k, 12 * k));
    assert_eq!(data.num_elements(), model.elements.len());
    for (p, &i) in data.pose_indices().iter().enumerate() {
        let qi: Vec<f64> = q.col(i).iter().copied().collect();
        let expected = projected_gradient(&model, &basis, k, &qi);
        let got: Vec<f64> = data.b()[p * k..(p + 1) * k]
            .iter()
            .map(|x| x * data.pose_scales()[p])
            .collect();
        assert!(
            rel_diff(&got, &expected) <= 1e-12,
            "pose {i}: {got:?} vs {expected:?}"
        );
        assert!((data.pose_scales()[p] - norm(&expected)).abs() <= 1e-12 * norm(&expected));
        // Each normalised pose block has unit norm.
        assert!((norm(&data.b()[p * k..(p + 1) * k]) - 1.0).abs() < 1e-12);
    }
    // All elements with weight one reproduce b.
    let all = all_ones_rule(data.num_elements());
    assert!(all.evaluate(&data).unwrap() <= 1e-12);
    assert!(all.pose_errors(&data).unwrap().iter().all(|&e| e <= 1e-12));
}

#[test]
fn nonlinear_targets_are_jacobian_transposed() {
    let model = beam([8, 2, 2]);
    let (basis, k, lambda) = modal_basis(&model);
    let q = random_poses(&model, &basis, &lambda, 6, 4);
    let d = 3;
    let mut rng = SplitMix64::new(21);
    let js: Vec<Mat<f64>> = (0..6).map(|_| normal_mat(&mut rng, k, d)).collect();
    let views: Vec<MatRef<'_, f64>> = js.iter().map(|j| j.as_ref()).collect();
    let config = CubatureConfig::default();
    let data = TrainingMatrix::build(
        &model,
        &basis,
        k,
        Poses::nonlinear(q.as_ref(), &views),
        &config,
    )
    .unwrap();
    assert_eq!((data.num_poses(), data.dim()), (6, d));
    for (p, &i) in data.pose_indices().iter().enumerate() {
        let qi: Vec<f64> = q.col(i).iter().copied().collect();
        let g = projected_gradient(&model, &basis, k, &qi);
        let expected: Vec<f64> = (0..d)
            .map(|c| (0..k).map(|j| js[i][(j, c)] * g[j]).sum())
            .collect();
        let got: Vec<f64> = data.b()[p * d..(p + 1) * d]
            .iter()
            .map(|x| x * data.pose_scales()[p])
            .collect();
        assert!(
            rel_diff(&got, &expected) <= 1e-12,
            "pose {i}: {got:?} vs {expected:?}"
        );
    }
    assert!(all_ones_rule(data.num_elements()).evaluate(&data).unwrap() <= 1e-12);
}

#[test]
fn poses_at_rest_are_skipped() {
    let model = beam([6, 2, 2]);
    let (basis, k, lambda) = modal_basis(&model);
    let mut q = random_poses(&model, &basis, &lambda, 5, 8);
    for j in 0..k {
        q[(j, 2)] = 0.0;
    }
    let config = CubatureConfig::default();
    let data =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &config).unwrap();
    assert_eq!(data.skipped_poses(), &[2]);
    assert_eq!(data.pose_indices(), &[0, 1, 3, 4]);
    assert_eq!(data.rows(), 4 * k);

    let rest = Mat::<f64>::zeros(k, 3);
    assert_eq!(
        TrainingMatrix::build(&model, &basis, k, Poses::linear(rest.as_ref()), &config),
        Err(CubatureError::ZeroTarget { poses: 3 })
    );
}

#[test]
fn pose_subsample_is_seeded_and_consistent() {
    let model = beam([6, 2, 2]);
    let (basis, k, lambda) = modal_basis(&model);
    let q = random_poses(&model, &basis, &lambda, 30, 9);
    let full = TrainingMatrix::build(
        &model,
        &basis,
        k,
        Poses::linear(q.as_ref()),
        &CubatureConfig::default(),
    )
    .unwrap();
    let config = CubatureConfig {
        max_poses: 7,
        seed: 4,
        ..Default::default()
    };
    let sub = TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &config).unwrap();
    assert_eq!(sub.num_poses(), 7);
    let idx = sub.pose_indices().to_vec();
    assert!(idx.windows(2).all(|w| w[0] < w[1]) && *idx.last().unwrap() < 30);
    // Same rows as the full build.
    for (p, &i) in idx.iter().enumerate() {
        for e in [0, 17, sub.num_elements() - 1] {
            assert_eq!(
                &sub.column(e)[p * k..(p + 1) * k],
                &full.column(e)[i * k..(i + 1) * k]
            );
        }
    }
    let again =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &config).unwrap();
    assert_eq!(again, sub);
    let other = CubatureConfig { seed: 5, ..config };
    let other =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &other).unwrap();
    assert_ne!(other.pose_indices(), sub.pose_indices());
}

#[test]
fn the_memory_limit_shrinks_the_pose_subsample_and_below_the_minimum_is_an_error() {
    let model = beam([20, 4, 4]);
    let (basis, k, lambda) = modal_basis(&model);
    let q = random_poses(&model, &basis, &lambda, 40, 1);
    // 40 poses × 10 × 1920 elements × 8 bytes plus 40 displacements ≈ 6.3 MiB.
    let per_pose = 8 * (k * model.elements.len() + model.num_full());
    assert_eq!((40 * per_pose).div_ceil(1 << 20), 7);
    let all = TrainingMatrix::build(
        &model,
        &basis,
        k,
        Poses::linear(q.as_ref()),
        &CubatureConfig::default(),
    )
    .unwrap();
    assert_eq!(all.num_poses(), 40);
    let config = CubatureConfig {
        memory_limit_mb: 5,
        ..Default::default()
    };
    let fitted = TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &config)
        .expect("the subsample shrinks to what 5 MiB holds");
    assert_eq!(fitted.num_poses(), (5 << 20) / per_pose);
    assert!(fitted.num_poses() < 40);
    let tiny = CubatureConfig {
        memory_limit_mb: 1,
        ..Default::default()
    };
    assert!((1 << 20) / per_pose < cubature::training::MIN_POSES);
    let needed = (cubature::training::MIN_POSES * per_pose).div_ceil(1 << 20) as u64;
    match TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &tiny) {
        Err(e @ CubatureError::MemoryLimit { needed_mb, .. }) => {
            assert_eq!(needed_mb, needed);
            assert!(
                e.to_string()
                    .contains(&format!("`cubature.memory_limit_mb` to at least {needed}")),
                "{e}"
            );
            // The value that keeps every pose, which written back fits them all.
            let all = (40 * per_pose).div_ceil(1 << 20) as u64;
            assert!(
                e.to_string()
                    .contains(&format!("({all} keeps all 40 poses, which")),
                "{e}"
            );
            let roomy = CubatureConfig {
                memory_limit_mb: all,
                ..Default::default()
            };
            let fitted =
                TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &roomy)
                    .unwrap();
            assert_eq!(fitted.num_poses(), 40);
        }
        other => panic!("expected a memory-limit error, got {other:?}"),
    }
}

/// Poses formed only where the fit keeps them (`kept_poses`, marked `kept_of`) give the matrix
/// of every pose given, numbers included: with room for all it keeps, and where the memory
/// limit leaves room for fewer. A count that is not the kept one is refused.
#[test]
fn the_kept_poses_alone_give_the_matrix_of_all() {
    let model = beam([20, 4, 4]);
    let (basis, k, lambda) = modal_basis(&model);
    let q = random_poses(&model, &basis, &lambda, 60, 3);
    for memory_limit_mb in [2048, 4] {
        let config = CubatureConfig {
            max_poses: 30,
            memory_limit_mb,
            ..Default::default()
        };
        let kept = cubature::kept_poses(60, &config);
        assert_eq!(kept.len(), 30);
        let q_kept = Mat::from_fn(k, kept.len(), |i, j| q[(i, kept[j])]);
        let all =
            TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &config).unwrap();
        let some = TrainingMatrix::build(
            &model,
            &basis,
            k,
            Poses::linear(q_kept.as_ref()).kept_of(60),
            &config,
        )
        .unwrap();
        if memory_limit_mb == 4 {
            assert!(all.num_poses() < 30, "{}", all.num_poses());
        }
        assert_eq!(all, some, "memory limit {memory_limit_mb} MiB");
    }
    let config = CubatureConfig {
        max_poses: 30,
        ..Default::default()
    };
    assert!(matches!(
        TrainingMatrix::build(
            &model,
            &basis,
            k,
            Poses::linear(q.as_ref()).kept_of(60),
            &config
        ),
        Err(CubatureError::ShapeMismatch { .. })
    ));
}

/// Beyond the memory budget the matrix first keeps a seeded subsample of the elements as
/// candidates (down to 8 per element of the rule's budget) and every pose; its columns are the
/// full matrix's, its target still sums every element, and a rule fitted on it names the mesh's
/// elements and measures the same on the full matrix.
#[test]
fn the_memory_limit_keeps_every_pose_and_fewer_candidate_elements_first() {
    let model = beam([20, 4, 4]);
    let (basis, k, lambda) = modal_basis(&model);
    let q = random_poses(&model, &basis, &lambda, 40, 1);
    let m = model.elements.len();
    let config = CubatureConfig {
        max_elements: 100,
        ..Default::default()
    };
    let all = TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &config).unwrap();
    assert_eq!((all.num_columns(), all.num_elements()), (m, m));
    let tight = CubatureConfig {
        memory_limit_mb: 5,
        ..config.clone()
    };
    let sub = TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &tight).unwrap();
    // 40 displacements of 3n values, then as many columns of 40 × k values as 5 MiB holds.
    let columns = ((5 << 20) - 8 * 40 * model.num_full()) / (8 * 40 * k);
    assert!(columns < m && columns >= 8 * 100, "{columns}");
    assert_eq!(sub.num_poses(), 40);
    assert_eq!((sub.num_columns(), sub.num_elements()), (columns, m));
    assert_eq!(sub.pose_indices(), all.pose_indices());
    // The same to round-off: the targets that normalise each pose are summed in another order.
    let same = |x: &[f64], y: &[f64]| {
        let size = y.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        x.iter().zip(y).all(|(a, b)| (a - b).abs() <= 1e-12 * size)
    };
    for c in 0..sub.num_columns() {
        let e = sub.element_of(c);
        assert_eq!(sub.column_of(e), Some(c));
        assert!(same(sub.column(c), all.column(e)), "element {e}");
    }
    assert!(same(sub.b(), all.b()));
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-10 * y.abs();
    let rule = fit(&sub, &config).unwrap();
    assert!(rule.elements.iter().all(|&e| sub.column_of(e).is_some()));
    let (on_sub, on_all) = (rule.evaluate(&sub).unwrap(), rule.evaluate(&all).unwrap());
    assert!(close(on_sub, on_all), "{on_sub} against {on_all}");
    // An element the subsample left out is no part of its data.
    let left_out = (0..m).find(|&e| sub.column_of(e).is_none()).unwrap();
    let other = CubatureRule {
        elements: vec![left_out],
        weights: vec![1.0],
        ..rule.clone()
    };
    assert!(matches!(
        other.evaluate(&sub),
        Err(CubatureError::InvalidRule(_))
    ));
    assert!(other.evaluate(&all).is_ok());
    // With a tangent per pose (a nonlinear subspace's d = 3 forces), the elements not kept are
    // summed in the k coordinates and the tangent applied once: the same target to round-off.
    let tangents: Vec<Mat<f64>> = (0..40)
        .map(|p| Mat::from_fn(k, 3, |i, j| ((i + 2 * j + p) as f64 * 0.7).sin()))
        .collect();
    let refs: Vec<MatRef<'_, f64>> = tangents.iter().map(|t| t.as_ref()).collect();
    let nonlinear = || Poses::nonlinear(q.as_ref(), &refs);
    let all = TrainingMatrix::build(&model, &basis, k, nonlinear(), &config).unwrap();
    // 2 MiB hold every pose with 1,659 of the 1,920 columns of three forces.
    let tight = CubatureConfig {
        memory_limit_mb: 2,
        ..config.clone()
    };
    let sub = TrainingMatrix::build(&model, &basis, k, nonlinear(), &tight).unwrap();
    assert!(sub.num_columns() < m && sub.num_poses() == all.num_poses());
    assert!(same(sub.b(), all.b()));
    for c in 0..sub.num_columns() {
        assert!(same(sub.column(c), all.column(sub.element_of(c))));
    }
}

#[test]
fn bad_input_is_reported() {
    let model = beam([4, 1, 1]);
    let (basis, k, lambda) = modal_basis(&model);
    let q = random_poses(&model, &basis, &lambda, 3, 2);
    let c = CubatureConfig::default();
    let build = |basis: &[f64], k: usize, poses: Poses<'_>| {
        TrainingMatrix::build(&model, basis, k, poses, &c)
    };
    assert!(matches!(
        build(&basis[1..], k, Poses::linear(q.as_ref())),
        Err(CubatureError::ShapeMismatch { .. })
    ));
    let q_short = Mat::<f64>::zeros(k - 1, 3);
    assert!(matches!(
        build(&basis, k, Poses::linear(q_short.as_ref())),
        Err(CubatureError::ShapeMismatch { .. })
    ));
    let none = Mat::<f64>::zeros(k, 0);
    assert_eq!(
        build(&basis, k, Poses::linear(none.as_ref())),
        Err(CubatureError::NoPoses)
    );
    let mut q_nan = q.clone();
    q_nan[(1, 2)] = f64::NAN;
    assert!(matches!(
        build(&basis, k, Poses::linear(q_nan.as_ref())),
        Err(CubatureError::NonFiniteInput { index, .. }) if index == 2 * k + 1
    ));
    let j = Mat::<f64>::zeros(k, 2);
    let two = [j.as_ref(), j.as_ref()];
    assert!(matches!(
        build(&basis, k, Poses::nonlinear(q.as_ref(), &two)),
        Err(CubatureError::ShapeMismatch { .. })
    ));
    let bad_config = CubatureConfig {
        max_poses: 0,
        ..Default::default()
    };
    assert!(matches!(
        TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &bad_config),
        Err(CubatureError::InvalidConfig { .. })
    ));
}

#[test]
fn from_matrix_checks_its_input() {
    let a = faer::mat![[1.0, 2.0], [3.0, 4.0], [5.0, 6.0], [7.0, 8.0]];
    let data = TrainingMatrix::from_matrix(a.as_ref(), &[3.0, 7.0, 11.0, 15.0], 2).unwrap();
    assert_eq!(
        (data.rows(), data.num_poses(), data.num_elements()),
        (4, 2, 2)
    );
    assert_eq!(data.column(1), &[2.0, 4.0, 6.0, 8.0]);
    assert!(matches!(
        TrainingMatrix::from_matrix(a.as_ref(), &[1.0; 4], 3),
        Err(CubatureError::ShapeMismatch { .. })
    ));
    assert!(matches!(
        TrainingMatrix::from_matrix(a.as_ref(), &[0.0; 4], 2),
        Err(CubatureError::ZeroTarget { .. })
    ));
}

/// A classic Neo-Hookean beam (undefined where an element inverts), `n` poses of its modal
/// basis drawn with `seed`, and that basis with one more column, k0 + 1 in all: the column moves
/// the last free vertex (a tip corner) along x, and at a coefficient of −1 pushes it a whole
/// beam length back, through the opposite faces of its elements. Returns the model, the
/// extended basis, k0 and the poses (k0 + 1 rows, the last coefficient 0).
fn beam_with_an_inverting_column(
    n: usize,
    seed: u64,
) -> (FullSpaceModel, Vec<f64>, usize, Mat<f64>) {
    inverting_beam([8, 2, 2], n, seed)
}

/// [`beam_with_an_inverting_column`] on a beam of `cells`.
fn inverting_beam(
    cells: [usize; 3],
    n: usize,
    seed: u64,
) -> (FullSpaceModel, Vec<f64>, usize, Mat<f64>) {
    let fixture = beam(cells);
    let material = fem_core::material::MaterialConfig {
        model: fem_core::material::MaterialModel::NeoHookean,
        ..Default::default()
    };
    let model = FullSpaceModel::new(
        fixture.mesh.clone(),
        &material,
        fixture.pinned.clone(),
        [0.0, 0.0, 0.0].into(),
        vec![],
    )
    .unwrap();
    let (modes, k0, lambda) = modal_basis(&model);
    let modal = random_poses(&model, &modes, &lambda, n, seed);
    let nf = model.dofs.num_free();
    let mut basis = modes;
    basis.extend((0..nf).map(|r| if r == nf - 3 { 1.0 } else { 0.0 }));
    let poses = Mat::from_fn(k0 + 1, n, |i, j| if i < k0 { modal[(i, j)] } else { 0.0 });
    (model, basis, k0, poses)
}

/// Classic Neo-Hookean is undefined where an element inverts. A pose that inverts elements (a
/// PCA-reconstructed or decoded pose the full simulation never produced) is left out of the fit
/// and listed, the others give exactly the matrix they give alone; only when every pose is
/// invalid is the stage an error.
#[test]
fn poses_that_invert_an_element_under_classic_neo_hookean_are_left_out() {
    let (model, basis, k0, good) = beam_with_an_inverting_column(6, 5);
    let k = k0 + 1;
    let q = Mat::from_fn(k, 7, |i, j| match (i, j) {
        (i, 6) if i == k0 => -1.0,
        (i, 6) => good[(i, 0)],
        _ => good[(i, j)],
    });
    let config = CubatureConfig::default();
    let with_bad =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &config).unwrap();
    assert_eq!(with_bad.invalid_poses(), &[6]);
    assert_eq!(with_bad.pose_indices(), &[0, 1, 2, 3, 4, 5]);
    let alone =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(good.as_ref()), &config).unwrap();
    assert!(alone.invalid_poses().is_empty());
    assert_eq!(with_bad.b(), alone.b());
    let only_bad = Mat::from_fn(k, 1, |i, _| q[(i, 6)]);
    assert!(matches!(
        TrainingMatrix::build(&model, &basis, k, Poses::linear(only_bad.as_ref()), &config),
        Err(CubatureError::NonFiniteForce { pose: 0, .. })
    ));
}

/// The same on a matrix that keeps a subsample of the elements (1 MiB for 1,920 elements): a
/// pose is left out whether the inverted elements are among the candidates or only in the
/// target's sum, and the others give the target they give alone.
#[test]
fn inverting_poses_are_left_out_of_a_matrix_of_candidates_too() {
    let (model, basis, k0, good) = inverting_beam([20, 4, 4], 6, 5);
    let k = k0 + 1;
    let q = Mat::from_fn(k, 7, |i, j| match (i, j) {
        (i, 6) if i == k0 => -1.0,
        (i, 6) => good[(i, 0)],
        _ => good[(i, j)],
    });
    let config = CubatureConfig {
        max_elements: 10,
        memory_limit_mb: 1,
        ..Default::default()
    };
    let with_bad =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(q.as_ref()), &config).unwrap();
    assert!(with_bad.num_columns() < with_bad.num_elements());
    assert_eq!(with_bad.invalid_poses(), &[6]);
    assert_eq!(with_bad.pose_indices(), &[0, 1, 2, 3, 4, 5]);
    // Alone, six poses leave room for more candidates: the same target, summed in another
    // order.
    let alone =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(good.as_ref()), &config).unwrap();
    let size = alone.b().iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    assert!(
        with_bad
            .b()
            .iter()
            .zip(alone.b())
            .all(|(x, y)| (x - y).abs() <= 1e-12 * size)
    );
    // Every pose inverting (seven of the bad one, so that the matrix keeps candidates): the
    // error names an element of the vertex pushed through, among the candidates or not.
    let only_bad = Mat::from_fn(k, 7, |i, _| q[(i, 6)]);
    match TrainingMatrix::build(&model, &basis, k, Poses::linear(only_bad.as_ref()), &config) {
        Err(CubatureError::NonFiniteForce { element, pose: 0 }) => {
            // An element of the vertex the column pushes through its neighbours.
            let moved = model.dofs.free[model.dofs.num_free() - 3] / 3;
            assert!(
                model.mesh.tets[element].contains(&moved),
                "element {element}"
            );
        }
        other => panic!("expected a non-finite force, got {other:?}"),
    }
}

/// The held-out forces give a rule the error a matrix of every element gives it (targets from
/// one assembly of the whole mesh, columns only for the elements asked about), for linear and
/// nonlinear poses, with a pose at rest and one that inverts an element left out alike, and
/// whatever columns earlier calls computed.
#[test]
fn held_out_forces_match_the_matrix_of_every_element() {
    let (model, basis, k0, fitted) = beam_with_an_inverting_column(9, 7);
    let k = k0 + 1;
    // Pose 3 at rest, pose 5 inverted by the extra column at −1.
    let q = Mat::from_fn(k, 9, |i, j| match (i, j) {
        (_, 3) => 0.0,
        (i, 5) if i == k0 => -1.0,
        _ => fitted[(i, j)],
    });
    let config = CubatureConfig {
        tolerance: 0.05,
        ..Default::default()
    };
    let train =
        TrainingMatrix::build(&model, &basis, k, Poses::linear(fitted.as_ref()), &config).unwrap();
    let rule = fit(&train, &config).unwrap();
    let d = 3;
    let mut rng = SplitMix64::new(5);
    let js: Vec<Mat<f64>> = (0..9).map(|_| normal_mat(&mut rng, k, d)).collect();
    let views: Vec<MatRef<'_, f64>> = js.iter().map(|j| j.as_ref()).collect();
    // Every pose, and a seeded subsample of 6 of the 9.
    let subsample = CubatureConfig {
        max_poses: 6,
        ..config.clone()
    };
    for (poses, config) in [
        (Poses::linear(q.as_ref()), &config),
        (Poses::nonlinear(q.as_ref(), &views), &config),
        (Poses::linear(q.as_ref()), &subsample),
        (Poses::nonlinear(q.as_ref(), &views), &subsample),
    ] {
        let all = TrainingMatrix::build(&model, &basis, k, poses, config).unwrap();
        if config.max_poses > 9 {
            assert_eq!(all.invalid_poses(), &[5]);
            assert_eq!(all.skipped_poses(), &[3]);
        }
        let mut held = HeldOutForces::new(&model, &basis, k, poses, config).unwrap();
        assert_eq!(held.num_poses(), all.num_poses());
        assert_eq!(held.invalid_poses(), all.invalid_poses());
        assert!(rel_diff(held.b(), all.b()) <= 1e-12);
        let weights = match poses.jacobians {
            // The nonlinear poses' rule: the linear one's elements, other weights.
            Some(_) => rule.weights.iter().map(|w| 0.5 * w).collect(),
            None => rule.weights.clone(),
        };
        let check = CubatureRule {
            elements: rule.elements.clone(),
            weights: weights.clone(),
            ..rule.clone()
        };
        let expected = check.evaluate(&all).unwrap();
        // First a part of the rule (some columns computed), then all of it.
        let half = rule.len() / 2;
        let part = CubatureRule {
            elements: rule.elements[..half].to_vec(),
            weights: weights[..half].to_vec(),
            ..rule.clone()
        };
        let part_error = held.relative_error(&part.elements, &part.weights).unwrap();
        assert!((part_error - part.evaluate(&all).unwrap()).abs() <= 1e-12);
        let got = held.relative_error(&rule.elements, &weights).unwrap();
        assert!(
            (got - expected).abs() <= 1e-12,
            "held-out {got} against the whole matrix's {expected}"
        );
        // The greedy path's order (not increasing) gives the same figure.
        let (mut e_rev, mut w_rev) = (rule.elements.clone(), weights.clone());
        e_rev.reverse();
        w_rev.reverse();
        let reversed = held.relative_error(&e_rev, &w_rev).unwrap();
        assert!((reversed - expected).abs() <= 1e-12);
        // A rule that does not fit the mesh is an error, not a panic.
        let m = model.elements.len();
        assert!(matches!(
            held.relative_error(&[m], &[1.0]),
            Err(CubatureError::InvalidRule(_))
        ));
        assert!(matches!(
            held.relative_error(&[0, 1], &[1.0]),
            Err(CubatureError::InvalidRule(_))
        ));
    }
    // Only the inverted pose: an error naming it, as for the training matrix.
    let only_bad = Mat::from_fn(k, 1, |i, _| q[(i, 5)]);
    assert!(matches!(
        HeldOutForces::new(&model, &basis, k, Poses::linear(only_bad.as_ref()), &config),
        Err(CubatureError::NonFiniteForce { pose: 0, .. })
    ));
}
