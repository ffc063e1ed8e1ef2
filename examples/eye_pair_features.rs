//! Training data for the eye-pair score (`features::EYE_PAIR_WEIGHTS`): every candidate pair the
//! eye search weighs on annotated Caltech faces, with its features and how far it lies from the
//! annotated eyes, as CSV on stdout.
//!
//! The faces are those with eyes `MIN_EYES` (default 25) to 40 px apart: none of them is among
//! the faces `eval shear` measures (eyes at least 40 px apart), so the weights fitted to them
//! are checked on faces they never saw. Each image is cropped and sheared as `eval shear` does
//! it, at k = 0, +0.4 and -0.4; each face is found by the default detector (under its shear
//! hypotheses), and its candidates are taken in the view and the turn the detection was made
//! in, as the pipeline's first eye search takes them.
//!
//! ```sh
//! cargo run --release --example eye_pair_features -- [MIN_EYES] > target/eye_pairs.csv
//! python3 scripts/fit_eye_pairs.py target/eye_pairs.csv
//! ```
//!
//! Columns: `sample` (one face at one shear), `true_k`, `pair`, `error` (the worse eye's
//! distance from its annotation, in eye distances), each eye's offset from its annotation
//! (`right_dx` .. `left_dy`, eye distances, image axes), then the features in the order of
//! `features::EYE_PAIR_FEATURES`. Faces whose search returns the highest values unpaired are
//! left out (the score plays no part there). Needs `../shared/data/caltech-webfaces`.

use std::path::PathBuf;

use anyhow::{Context, Result};
use rayon::prelude::*;
use unshear::dev::dataset::{by_image, CaltechWebFaces, FaceDataset};
use unshear::dev::eval::shear::{context_crop, DEFAULT_CONTEXT};
use unshear::internals::{
    expected_eyes, EyeSearch, FeatureLocator, NormalizedFace, EYE_CANDIDATES, EYE_PAIR_FEATURES,
};
use unshear::pipeline::Unshear;
use unshear::warp::{try_apply_shear, Canvas, Interpolation};
use unshear::{Point, Shear};

const SHEARS: [f64; 3] = [0.0, 0.4, -0.4];

fn main() -> Result<()> {
    let min_eyes: f64 = match std::env::args().nth(1) {
        Some(s) => s.parse().context("MIN_EYES must be a number")?,
        None => 25.0,
    };
    let data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/caltech-webfaces");
    let faces: Vec<_> = CaltechWebFaces::new(&data)
        .faces()
        .with_context(|| format!("reading {}", data.display()))?
        .into_iter()
        .filter(|f| (min_eyes..40.0).contains(&f.eye_distance()))
        .collect();
    let unshear = Unshear::new(unshear::Config::default())?;
    let groups = by_image(faces);
    // One CSV block per image and shear, in the images' order.
    let blocks: Vec<Vec<(f64, Vec<String>)>> = groups
        .par_iter()
        .map(|(path, annotated)| {
            let Ok(full) = unshear::imageio::read_image(path, unshear::imageio::DEFAULT_MAX_PIXELS)
            else {
                eprintln!("skipping unreadable {}", path.display());
                return Vec::new();
            };
            let (img, origin) =
                match context_crop(annotated, full.width(), full.height(), DEFAULT_CONTEXT) {
                    Some((x, y, w, h)) => {
                        (full.crop_imm(x, y, w, h), Point::new(x as f64, y as f64))
                    }
                    None => (full, Point::new(0.0, 0.0)),
                };
            let mut locator = FeatureLocator::new(unshear.filters());
            let mut out = Vec::new();
            for k in SHEARS {
                let shear = Shear::about_middle(k, img.height());
                let Ok((sheared, placement)) =
                    try_apply_shear(&img, shear, Interpolation::Linear, Canvas::Expand)
                else {
                    continue;
                };
                let gray = Unshear::gray(&sheared);
                let detections = unshear.detect(&gray);
                let moved = |p: Point| {
                    placement.from_frame(shear.apply(Point::new(p.x - origin.x, p.y - origin.y)))
                };
                for f in annotated {
                    let (re, le) = (moved(f.right_eye), moved(f.left_eye));
                    let Some(d) = detections
                        .iter()
                        .find(|d| d.face_box.contains(re) && d.face_box.contains(le))
                    else {
                        continue;
                    };
                    let face = NormalizedFace::rotated(&gray, d.face_box, d.view_roll);
                    let EyeSearch::Pairs(pairs) =
                        locator.eye_pairs(&face, d.view_k, EYE_CANDIDATES)
                    else {
                        continue;
                    };
                    // The annotations in the view the candidates were found in.
                    let (exp_right, exp_left) = expected_eyes(&face);
                    let pivot_v = (exp_right.y + exp_left.y) / 2.0;
                    let in_view = |p: Point| {
                        let n = face.from_image(p);
                        Point::new(n.x - d.view_k * (n.y - pivot_v), n.y)
                    };
                    let (tr, tl) = (in_view(re), in_view(le));
                    let eye_distance = tr.distance(tl).max(1.0);
                    let rows = pairs
                        .iter()
                        .enumerate()
                        .map(|(i, p)| {
                            let error = p
                                .right
                                .position
                                .distance(tr)
                                .max(p.left.position.distance(tl))
                                / eye_distance;
                            let features: Vec<String> =
                                p.features.iter().map(|v| format!("{v:.5}")).collect();
                            let off = |a: Point, b: Point| {
                                format!(
                                    "{:.4},{:.4}",
                                    (a.x - b.x) / eye_distance,
                                    (a.y - b.y) / eye_distance
                                )
                            };
                            format!(
                                "{i},{error:.4},{},{},{}",
                                off(p.right.position, tr),
                                off(p.left.position, tl),
                                features.join(",")
                            )
                        })
                        .collect();
                    out.push((k, rows));
                }
            }
            out
        })
        .collect();
    println!(
        "sample,true_k,pair,error,right_dx,right_dy,left_dx,left_dy,{}",
        EYE_PAIR_FEATURES.join(",")
    );
    for (sample, (k, rows)) in blocks.into_iter().flatten().enumerate() {
        for row in rows {
            println!("{sample},{k},{row}");
        }
    }
    Ok(())
}
