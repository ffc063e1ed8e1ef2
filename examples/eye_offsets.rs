//! Where the eye filters put the eyes of annotated Caltech faces when the detector plays no part:
//! each face is normalised through the box drawn from its annotated eyes (the training
//! normalisation, `features::face_box_from_eyes`), the eyes are located in it, and the median
//! offsets from the annotations (fractions of the eye distance; +x is image right, +y down) and
//! the share of faces with both eyes within 0.05 / 0.10 / 0.25 are printed. This is the
//! measurement behind `dataset::CALTECH_PIXEL_ORIGIN`.
//!
//! ```sh
//! cargo run --release --example eye_offsets -- [FACES] [FILTERS]
//! ```
//!
//! `FACES` (default 300): the first faces with eyes at least 40 px apart, as `eval shear
//! --limit`; `FILTERS`: a filter file (default: the built-in MOSSE set). Needs
//! `../shared/data/caltech-webfaces`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use unshear::detect::boxes::face_box_from_eyes;
use unshear::dev::dataset::{CaltechWebFaces, FaceDataset};
use unshear::filters::EyeFilters;
use unshear::internals::{median, FeatureLocator, NormalizedFace};

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let limit: usize = match args.get(1) {
        Some(s) => s.parse().context("FACES must be a count")?,
        None => 300,
    };
    let filters = match args.get(2) {
        Some(p) => EyeFilters::from_file(Path::new(p)).context("reading the filters")?,
        None => EyeFilters::embedded()?,
    };
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/caltech-webfaces");
    let faces: Vec<_> = CaltechWebFaces::new(&data)
        .faces()
        .with_context(|| format!("reading {}", data.display()))?
        .into_iter()
        .filter(|f| f.eye_distance() >= 40.0)
        .take(limit)
        .collect();
    let mut locator = FeatureLocator::new(&filters);
    let mut decoded: Option<(PathBuf, image::GrayImage)> = None;
    // Per face: right eye dx, dy, left eye dx, dy, as fractions of the eye distance.
    let mut offsets = Vec::with_capacity(faces.len());
    for f in &faces {
        if decoded.as_ref().map(|(p, _)| p != &f.image).unwrap_or(true) {
            let img = unshear::imageio::read_image(&f.image, unshear::imageio::DEFAULT_MAX_PIXELS)
                .with_context(|| format!("reading {}", f.image.display()))?;
            decoded = Some((f.image.clone(), unshear::detect::to_gray_opencv(&img)));
        }
        let Some((_, gray)) = decoded.as_ref() else {
            continue;
        };
        let face = NormalizedFace::new(gray, face_box_from_eyes(f.right_eye, f.left_eye));
        let found = locator.locate(&face, Some(0.0));
        let d = f.eye_distance();
        offsets.push([
            (found.right_eye.x - f.right_eye.x) / d,
            (found.right_eye.y - f.right_eye.y) / d,
            (found.left_eye.x - f.left_eye.x) / d,
            (found.left_eye.y - f.left_eye.y) / d,
        ]);
    }
    let column = |i: usize| median(offsets.iter().map(|o| o[i]).collect()).unwrap_or(f64::NAN);
    println!(
        "{} faces; median offset, right eye ({:+.4}, {:+.4}), left eye ({:+.4}, {:+.4})",
        offsets.len(),
        column(0),
        column(1),
        column(2),
        column(3)
    );
    let within = |t: f64| {
        let n = offsets
            .iter()
            .filter(|o| o[0].hypot(o[1]).max(o[2].hypot(o[3])) <= t)
            .count();
        100.0 * n as f64 / offsets.len().max(1) as f64
    };
    println!(
        "both eyes within 0.05: {:.1}%, 0.10: {:.1}%, 0.25: {:.1}%",
        within(0.05),
        within(0.10),
        within(0.25)
    );
    Ok(())
}
