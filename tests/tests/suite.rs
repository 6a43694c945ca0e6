//! The mesh suite on the small real meshes (AutoDef's, in `shared/meshes`): the minimal scene
//! a user would write (mesh, material, bottom pinned, gravity, time step) runs from an empty
//! cache through every stage and every method, each mesh with another material.

use std::path::Path;

use fem_core::constraints::Axis;
use fem_core::mesh::generate::GeneratedShape;
use pipeline::simulate::Method;
use pipeline::suite::{
    MATERIALS, METHODS, StageHooks, SuiteMesh, SuiteRow, markdown, meshes, run_suite,
};
use pipeline::trust::COLLAPSED_SHARE;
use tests::{no_progress, scratch_dir, shared_dir};

/// The suite's minimal scenes (E = 10⁵ Pa, standing on y) on `meshes`, with `trajectories` test
/// trajectories each, quietly.
fn minimal_scenes(meshes: &[SuiteMesh], trajectories: usize, out: &Path) -> Vec<SuiteRow> {
    run_suite(
        meshes,
        1e5,
        Axis::Y,
        1.0,
        trajectories,
        out,
        &no_progress,
        &mut |_| {},
        StageHooks::none(),
    )
    .unwrap()
}

/// Meshes up to this size run in CI (a minute or two each on 2 cores); `cargo xtask suite`
/// runs them all.
const CI_MAX_VERTICES: usize = 1100;

#[test]
fn minimal_scenes_on_the_small_real_meshes_complete_every_method() {
    let Some(shared) = shared_dir("the mesh suite on AutoDef's meshes") else {
        return;
    };
    let meshes = meshes(&shared.join("meshes"), Some(CI_MAX_VERTICES)).unwrap();
    assert!(
        meshes.len() >= 2,
        "expected the small AutoDef meshes in {}, found {meshes:?}",
        shared.join("meshes").display()
    );
    let out = scratch_dir("suite");
    let meshes: Vec<SuiteMesh> = meshes.into_iter().map(SuiteMesh::File).collect();
    let rows = minimal_scenes(&meshes, 1, &out);
    assert_eq!(rows.len(), meshes.len());
    every_method_completed(&rows);
}

/// A generated figure, coarse enough for CI (14 × 14 × 5 cells, 30 cm tall), whose arms and
/// head swing about its trunk: the minimal scene completes every method without `shared/`.
#[test]
fn minimal_scene_on_a_generated_figure_completes_every_method() {
    let figure = SuiteMesh::Box {
        name: "figure-small".into(),
        kind: GeneratedShape::Figure,
        size: [0.3, 0.3, 0.1],
        cells: [14, 14, 5],
    };
    let out = scratch_dir("suite-figure");
    let rows = minimal_scenes(&[figure], 2, &out);
    assert_eq!(rows.len(), 1);
    assert_eq!((rows[0].vertices, rows[0].tets), (422, 1284));
    every_method_completed(&rows);
    // A second test trajectory: the spread starts from the table's errors, and its own run is
    // written beside the first.
    let r = &rows[0];
    assert!(r.trajectories_seconds.is_some_and(|s| s > 0.0));
    assert!(out.join(&r.scene).join("trajectory-1/report.json").exists());
    for m in METHODS {
        let spread = r.trajectories.iter().find(|t| t.method == m).unwrap();
        let first = r.methods.iter().find(|x| x.method == m).unwrap();
        assert_eq!(spread.errors.len(), 2, "{}", m.name());
        assert_eq!(spread.errors[0], Some(first.mean_rel_error), "{}", m.name());
        assert!(spread.errors[1].is_some_and(f64::is_finite), "{}", m.name());
    }
    let table = markdown(&rows);
    assert!(table.contains("On test trajectories 0..2"), "{table}");
    // The full simulation is measured for a collapse, and this one stands.
    let full = rows[0].methods.iter().find(|r| r.method == Method::Full);
    let compression = full
        .and_then(|r| r.compression)
        .expect("the full row's compression");
    assert!(compression.volume_ratio > 0.0, "{compression:?}");
    assert!(
        compression.squeezed_share < COLLAPSED_SHARE,
        "{compression:?}"
    );
}

/// Each row ran its material (`MATERIALS[i % 5]`) and every method to a finite error, and the
/// table has a line for it.
fn every_method_completed(rows: &[pipeline::suite::SuiteRow]) {
    let table = markdown(rows);
    println!("{table}");
    for (i, r) in rows.iter().enumerate() {
        assert!(r.failure.is_none(), "{}: {:?}", r.scene, r.failure);
        let material = serde_json::to_value(MATERIALS[i % MATERIALS.len()]).unwrap();
        assert!(
            r.scene.ends_with(material.as_str().unwrap()),
            "{} should use {material}",
            r.scene
        );
        for m in METHODS {
            let row = r
                .methods
                .iter()
                .find(|x| x.method == m)
                .unwrap_or_else(|| panic!("{}: no {} row", r.scene, m.name()));
            assert!(
                row.failure.is_none(),
                "{} {}: {:?}",
                r.scene,
                m.name(),
                row.failure
            );
            assert!(
                row.mean_rel_error.is_finite() && row.ms_per_step > 0.0,
                "{} {}: error {}, {} ms/step",
                r.scene,
                m.name(),
                row.mean_rel_error,
                row.ms_per_step
            );
        }
        assert!(table.contains(&format!("| {} |", r.scene)), "{table}");
    }
}
