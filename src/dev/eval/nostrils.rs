//! Nostril (and eye) localisation against 68-point markup (`unshear eval nostrils`): the check
//! the shear estimate depends on most, since the nostrils are the weak features (their
//! correlation peaks are the least distinct).
//!
//! Each image runs through detection and feature location as a user's would; an annotated face
//! is matched to the detected box that contains both its true eye centres. Errors are the worse
//! of the two points, divided by the true eye distance (the standard normalisation). With
//! `upscale > 1` the image is enlarged (bilinear) before detection and the points mapped back:
//! dlib's example faces are tiny (eye distance about 15 px), below what the detector and the
//! 150-px face normalisation were built for.

use std::fmt::Write as _;
use std::path::PathBuf;

use rayon::prelude::*;
use serde::Serialize;

use super::{fmt3, pct};
use crate::dev::dataset::LandmarkFace;
use crate::geometry::Point;
use crate::imageio;
use crate::pipeline::Unshear;
use crate::stats::median;

/// One annotated face.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NostrilSample {
    /// The image.
    pub image: String,
    /// True eye distance, pixels of the original image.
    pub eye_distance: f64,
    /// A detected box contains both true eyes.
    pub detected: bool,
    /// The features were located (the pipeline gave an estimate for the face).
    pub located: bool,
    /// Worse eye's error / eye distance.
    pub eye_error: Option<f64>,
    /// Worse nostril's error / eye distance (nostrils: points 32 and 34).
    pub nostril_error: Option<f64>,
}

/// All samples of a nostril run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NostrilEvalResult {
    /// One per annotated face with both eyes and both nostrils marked.
    pub samples: Vec<NostrilSample>,
    /// Images that could not be read, with the reason.
    pub unreadable: Vec<String>,
    /// The enlargement applied before detection.
    pub upscale: f64,
}

/// Runs the check over `faces` (grouped per image, in parallel).
pub fn evaluate_nostrils(
    unshear: &Unshear,
    faces: &[LandmarkFace],
    upscale: f64,
    max_pixels: u64,
) -> NostrilEvalResult {
    let upscale = if upscale.is_finite() && upscale > 0.0 {
        upscale
    } else {
        1.0
    };
    let mut groups: std::collections::BTreeMap<PathBuf, Vec<&LandmarkFace>> = Default::default();
    for f in faces {
        groups.entry(f.image.clone()).or_default().push(f);
    }
    let groups: Vec<_> = groups.into_iter().collect();
    let results: Vec<Result<Vec<NostrilSample>, String>> = groups
        .par_iter()
        .map(|(path, faces)| {
            let img = imageio::read_image(path, max_pixels)
                .map_err(|e| format!("{}: {e}", path.display()))?;
            let img = if upscale != 1.0 {
                let w = ((img.width() as f64 * upscale).round() as u32).max(1);
                let h = ((img.height() as f64 * upscale).round() as u32).max(1);
                img.resize_exact(w, h, image::imageops::FilterType::Triangle)
            } else {
                img
            };
            // One detection per image: the boxes, each with its estimate if it gave one.
            let found = unshear.detect_and_estimate(&Unshear::gray(&img));
            // Map an original-image point into the enlarged image (pixel centres at integers).
            let up =
                |p: Point| Point::new((p.x + 0.5) * upscale - 0.5, (p.y + 0.5) * upscale - 0.5);
            Ok(faces
                .iter()
                .filter_map(|f| {
                    let (re, le) = (f.right_eye()?, f.left_eye()?);
                    let (rn, ln) = (f.right_nostril()?, f.left_nostril()?);
                    let (ure, ule) = (up(re), up(le));
                    let ed = re.distance(le) * upscale;
                    let detected = found
                        .iter()
                        .any(|f| f.face_box.contains(ure) && f.face_box.contains(ule));
                    let hit = found
                        .iter()
                        .filter_map(|f| f.report.as_ref())
                        .find(|d| d.face_box.contains(ure) && d.face_box.contains(ule));
                    Some(NostrilSample {
                        image: path.display().to_string(),
                        eye_distance: re.distance(le),
                        detected,
                        located: hit.is_some(),
                        eye_error: hit
                            .map(|d| d.right_eye.distance(ure).max(d.left_eye.distance(ule)) / ed),
                        nostril_error: hit.map(|d| {
                            d.right_nostril
                                .distance(up(rn))
                                .max(d.left_nostril.distance(up(ln)))
                                / ed
                        }),
                    })
                })
                .collect())
        })
        .collect();
    let mut samples = Vec::new();
    let mut unreadable = Vec::new();
    for r in results {
        match r {
            Ok(s) => samples.extend(s),
            Err(e) => unreadable.push(e),
        }
    }
    NostrilEvalResult {
        samples,
        unreadable,
        upscale,
    }
}

impl NostrilEvalResult {
    /// The summary as Markdown.
    pub fn markdown(&self) -> String {
        let n = self.samples.len();
        let mut s = String::new();
        let eds: Vec<f64> = self.samples.iter().map(|s| s.eye_distance).collect();
        let _ = writeln!(
            s,
            "Faces: {n} (median eye distance {} px, enlarged x{} before detection); unreadable images: {}\n",
            fmt3(median(eds)),
            self.upscale,
            self.unreadable.len()
        );
        let _ = writeln!(
            s,
            "Detected: {} of {n} ({:.1}%); features located: {} ({:.1}%)\n",
            self.samples.iter().filter(|s| s.detected).count(),
            pct(self.samples.iter().filter(|s| s.detected).count(), n),
            self.samples.iter().filter(|s| s.located).count(),
            pct(self.samples.iter().filter(|s| s.located).count(), n),
        );
        let _ = writeln!(
            s,
            "| feature (worse of two) | median error (located faces) | <= 0.10 (of all faces) | <= 0.25 (of all faces) | <= 0.25 (of located) |\n|---|---:|---:|---:|---:|"
        );
        let located = self.samples.iter().filter(|s| s.located).count();
        for (name, pick) in [
            (
                "eyes",
                (|s: &NostrilSample| s.eye_error) as fn(&NostrilSample) -> Option<f64>,
            ),
            ("nostrils", |s: &NostrilSample| s.nostril_error),
        ] {
            let e: Vec<f64> = self.samples.iter().filter_map(pick).collect();
            let within = |t: f64| e.iter().filter(|&&x| x <= t).count();
            let _ = writeln!(
                s,
                "| {name} | {} | {:.1}% | {:.1}% | {:.1}% |",
                fmt3(median(e.clone())),
                pct(within(0.10), n),
                pct(within(0.25), n),
                pct(within(0.25), located),
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(eye: Option<f64>, nose: Option<f64>) -> NostrilSample {
        NostrilSample {
            image: "a".into(),
            eye_distance: 15.0,
            detected: eye.is_some(),
            located: eye.is_some(),
            eye_error: eye,
            nostril_error: nose,
        }
    }

    #[test]
    fn table_reports_known_values() {
        let r = NostrilEvalResult {
            samples: vec![
                sample(Some(0.05), Some(0.2)),
                sample(Some(0.15), Some(0.3)),
                sample(None, None),
                sample(Some(0.01), Some(0.05)),
            ],
            unreadable: vec![],
            upscale: 1.0,
        };
        let md = r.markdown();
        assert!(md.contains("Detected: 3 of 4 (75.0%)"), "{md}");
        assert!(
            md.contains("| eyes | 0.050 | 50.0% | 75.0% | 100.0% |"),
            "{md}"
        );
        assert!(
            md.contains("| nostrils | 0.200 | 25.0% | 50.0% | 66.7% |"),
            "{md}"
        );
    }
}
