//! The linearised buckling load of gravity (`fem_core::stability`) against Greenhill's column
//! under its own weight, its scaling, and the bodies it must leave alone.

use fem_core::Vec3;
use fem_core::constraints::{Axis, Side, VertexSelection};
use fem_core::integrator::FullSpaceModel;
use fem_core::material::{MaterialConfig, MaterialModel};
use fem_core::mesh::generate::{BoxSpec, box_mesh};
use fem_core::stability::gravity_buckling;

/// A square column a = 2 cm wide and 1 m tall along y, of `model`, pinned at its `side` end,
/// under gravity g along −y.
fn column(model: MaterialModel, side: Side, youngs_modulus: f64, g: f64) -> FullSpaceModel {
    let mesh = box_mesh(&BoxSpec {
        size: [0.02, 1.0, 0.02],
        cells: [4, 100, 4],
        ..Default::default()
    })
    .unwrap();
    let pinned = VertexSelection::plane(Axis::Y, side, Some(1e-4))
        .select(&mesh, "pin")
        .unwrap();
    let material = MaterialConfig {
        model,
        youngs_modulus,
        poisson_ratio: 0.3,
        ..Default::default()
    };
    FullSpaceModel::new(mesh, &material, pinned, Vec3::new(0.0, -g, 0.0), vec![]).unwrap()
}

/// A column clamped at its foot buckles under its own weight q = ρgA per length once
/// qL³ = 7.837 EI (Greenhill, Timoshenko & Gere §2.13). Linear tets are stiffer in bending than
/// the beam, so the estimate lies above it and comes down as the mesh is refined (4 × 4 cells
/// across: 1.4 times; 2 × 2: 2.5 times).
#[test]
fn a_standing_column_buckles_near_greenhills_load() {
    let (a, rho, g, e): (f64, f64, f64, f64) = (0.02, 1000.0, 9.81, 1.0e8);
    let greenhill = 7.837 * e * a.powi(4) / 12.0 / (rho * g * a * a);
    for material in [
        MaterialModel::StableNeoHookean,
        MaterialModel::NeoHookean,
        MaterialModel::Corotated,
        MaterialModel::Stvk,
    ] {
        let b = gravity_buckling(&column(material, Side::Min, e, g))
            .unwrap()
            .unwrap();
        assert!(b.converged, "{material:?}: {b:?}");
        let ratio = b.load_factor.unwrap() / greenhill;
        assert!((1.0..1.6).contains(&ratio), "{material:?}: {ratio} ({b:?})");
    }
}

/// The load factor is E over the weight: twice the modulus stands twice the load, twice the
/// gravity buckles at half the factor (and sags twice as far).
#[test]
fn the_load_factor_scales_with_stiffness_over_weight() {
    let at = |e: f64, g: f64| {
        gravity_buckling(&column(MaterialModel::StableNeoHookean, Side::Min, e, g))
            .unwrap()
            .unwrap()
    };
    let base = at(1.0e8, 9.81);
    let (stiffer, heavier) = (at(2.0e8, 9.81), at(1.0e8, 19.62));
    let l = base.load_factor.unwrap();
    assert!(
        (stiffer.load_factor.unwrap() / l - 2.0).abs() < 1e-3,
        "{stiffer:?} {base:?}"
    );
    assert!(
        (heavier.load_factor.unwrap() / l - 0.5).abs() < 1e-3,
        "{heavier:?} {base:?}"
    );
    assert!((heavier.sag / base.sag - 2.0).abs() < 1e-9);
}

/// A column hung from its top is in tension and has no buckling load; the linear material's is
/// a nonlinear material's at the same modulus (both linearised at rest: the same K₀ and
/// stresses); without gravity there is nothing to estimate.
#[test]
fn a_hanging_body_and_the_linear_material_have_no_buckling_load() {
    let hanging = gravity_buckling(&column(
        MaterialModel::StableNeoHookean,
        Side::Max,
        1e8,
        9.81,
    ))
    .unwrap()
    .unwrap();
    assert_eq!(hanging.load_factor, None, "{hanging:?}");
    assert!(hanging.sag > 0.0);
    let linear = gravity_buckling(&column(MaterialModel::Linear, Side::Min, 1e8, 9.81))
        .unwrap()
        .unwrap();
    let nonlinear = gravity_buckling(&column(
        MaterialModel::StableNeoHookean,
        Side::Min,
        1e8,
        9.81,
    ))
    .unwrap()
    .unwrap();
    assert!(
        (linear.sag / nonlinear.sag - 1.0).abs() < 1e-6,
        "{linear:?} {nonlinear:?}"
    );
    let (l, n) = (linear.load_factor.unwrap(), nonlinear.load_factor.unwrap());
    assert!((l / n - 1.0).abs() < 1e-3, "{linear:?} {nonlinear:?}");
    let weightless = column(MaterialModel::StableNeoHookean, Side::Min, 1e8, 0.0);
    assert_eq!(gravity_buckling(&weightless).unwrap(), None);
}
