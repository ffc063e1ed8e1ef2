//! Tests on the development data in `../shared/data` (not part of the repository). Each test
//! prints "skipped" and passes when the data are absent, so a fresh clone's suite still runs.

use std::path::PathBuf;

use unshear::dataset::{CaltechWebFaces, FaceDataset};
use unshear::eval::{evaluate_shear, ShearEvalOptions};
use unshear::Unshear;

fn shared(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!(
            "skipped: {} not found (../shared is not checked out)",
            p.display()
        );
        None
    }
}

/// `unshear train` is deterministic and the committed filters are what it makes.
#[test]
fn retraining_reproduces_the_committed_filters() {
    let Some(root) = shared("caltech-webfaces") else {
        return;
    };
    let faces = CaltechWebFaces::new(root).faces().expect("annotations");
    let (filters, summary) =
        unshear::train::train_eye_filters(faces, &Default::default()).expect("training");
    assert!(summary.unreadable.is_empty(), "{:?}", summary.unreadable);
    assert!(filters.right_eye.training_count >= 1500);
    let committed =
        std::fs::read(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("models/eye_filters.bin"))
            .expect("committed filters");
    assert!(
        filters.to_bytes() == committed,
        "retrained filters differ from models/eye_filters.bin"
    );
}

/// A small slice of the shear evaluation: on the first 60 Caltech faces with an eye distance of
/// at least 40 px the detector finds most faces, and the median estimate follows the shear.
/// Bounds are loose (the full table is in the README): they catch a broken pipeline, not noise.
#[test]
fn caltech_slice_tracks_the_shear() {
    let Some(root) = shared("caltech-webfaces") else {
        return;
    };
    let faces: Vec<_> = CaltechWebFaces::new(root)
        .faces()
        .expect("annotations")
        .into_iter()
        .filter(|f| f.eye_distance() >= 40.0)
        .take(60)
        .collect();
    let unshear = Unshear::with_defaults().expect("models");
    let options = ShearEvalOptions {
        shears: vec![0.0, 0.3],
        max_pixels: unshear::imageio::DEFAULT_MAX_PIXELS,
    };
    let result = evaluate_shear(&unshear, &faces, &options, || {});
    for k in [0.0, 0.3] {
        let at: Vec<_> = result.samples.iter().filter(|s| s.true_k == k).collect();
        let detected = at.iter().filter(|s| s.detected).count() as f64 / at.len() as f64;
        assert!(detected >= 0.8, "k {k}: detection rate {detected}");
        let est: Vec<f64> = at.iter().filter_map(|s| s.estimate).collect();
        let median = unshear::pipeline::median(est).expect("estimates");
        assert!(
            (median - k).abs() <= 0.12,
            "k {k}: median estimate {median}"
        );
    }
}
