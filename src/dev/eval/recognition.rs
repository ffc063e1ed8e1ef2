//! Face recognition on undistorted, sheared and corrected probes (`unshear eval recognition`):
//! the recognition rows of the paper's Table I, on data anyone can get.
//!
//! **Protocol** (as the paper): per identity the first 3 images by file name are the gallery,
//! the rest probes ([`crate::dev::dataset::gallery_probe_split`]). For each shear `k`, rank-1 is
//! measured on the undistorted probes (baseline), the sheared probes (raw: detection and eye
//! location on the sheared image) and the corrected probes (the tool estimates `k` on the sheared
//! image, de-shears the whole image, then detects and normalises again). A probe where no face
//! is found (or, for "corrected", no shear could be estimated) counts as a miss. Shears use the
//! documented convention (bilinear, pivot at the middle row), and each sheared probe is cut to
//! the rectangle a camera delivers (`shear::camera_window`: no empty corner).
//!
//! **Recogniser, after the paper's "G96"** (the paper does not spell it out; this is our
//! reading, documented so it can be changed):
//! 1. Geometric normalisation: a similarity transform puts the detected eye centres level at
//!    (19.2, 22.4) and (44.8, 22.4) of a 64 x 64 crop (eye distance 25.6 px), bilinear.
//! 2. Lighting: the Self-Quotient Image `I / (G_sigma * I)` with `sigma = 4` px, clamped to
//!    `[0, 3]`, then zero mean and unit variance.
//! 3. Gabor bank: 4 scales (wavelengths 4, 5.66, 8, 11.3 px, envelope `sigma = 0.56 lambda`,
//!    about one octave) x 6 orientations (0, 30, ..., 150 degrees) = 24 complex kernels. Their
//!    magnitudes are sampled on an 8 x 8 lattice over the crop and mean-pooled into `grid x
//!    grid` cells: with the default `grid = 2` (four quadrants) that is 4 x 6 x 4 = **96
//!    responses**; `grid = 4` or `8` gives 384 or 1536 for a stronger recogniser.
//! 4. Classifier: a multiclass linear SVM, one-vs-rest, trained on the gallery with Pegasos
//!    (primal stochastic sub-gradient, deterministic seed) on features standardised with the
//!    gallery's mean and deviation. Why our own: the problem is tiny (a few hundred gallery
//!    vectors), a linear SVM is 40 lines, and `smartcore`/`linfa-svm` would add a heavy
//!    dependency tree to the library's build for this one harness.

use std::fmt::Write as _;
use std::path::Path;

use image::{DynamicImage, GrayImage};
use rayon::prelude::*;
use serde::Serialize;

use super::shear::{camera_window, sheared_window};
use super::{fmt3, pct};
use crate::dev::dataset::{gallery_probe_split, LabelledImage};
use crate::geometry::Point;
use crate::imageio;
use crate::pipeline::{CorrectOptions, ImageReport, Region, Unshear};
use crate::stats::median;
use crate::warp::{Canvas, Interpolation};

/// Side of the normalised face crop, pixels.
pub const CROP: usize = 64;
/// Gabor wavelengths, pixels.
pub const WAVELENGTHS: [f64; 4] = [4.0, 5.657, 8.0, 11.314];
/// Gabor orientations.
pub const ORIENTATIONS: usize = 6;
/// Side of the lattice the Gabor magnitudes are sampled on.
pub const LATTICE: usize = 8;

/// The paper's Table I (FERET): shears, median estimated k, raw and corrected rank-1 (%).
pub const PAPER_TABLE: [(f64, f64, f64, f64); 4] = [
    (0.14, 0.15, 87.9, 90.7),
    (0.20, 0.19, 80.7, 90.8),
    (0.33, 0.30, 52.3, 83.8),
    (0.40, 0.37, 25.7, 83.6),
];
/// The paper's rank-1 on undistorted probes (FERET), %.
pub const PAPER_BASELINE: f64 = 94.09;

/// Options for [`evaluate_recognition`].
#[derive(Debug, Clone, PartialEq)]
pub struct RecognitionOptions {
    /// Shears applied to the probes.
    pub shears: Vec<f64>,
    /// Gallery images per identity.
    pub gallery: usize,
    /// Pooling grid of the Gabor magnitudes (2: the 96-response G96).
    pub grid: usize,
    /// Decoded-size limit.
    pub max_pixels: u64,
}

impl Default for RecognitionOptions {
    fn default() -> Self {
        Self {
            shears: vec![0.14, 0.20, 0.33, 0.40],
            gallery: 3,
            grid: 2,
            max_pixels: imageio::DEFAULT_MAX_PIXELS,
        }
    }
}

/// Rank-1 results at one shear.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ShearRow {
    /// The shear applied.
    pub k: f64,
    /// Median of the tool's estimates on the sheared probes.
    pub median_estimate: Option<f64>,
    /// Probes with a face found in the sheared image, %.
    pub raw_detected: f64,
    /// Rank-1 on the raw sheared probes, %.
    pub raw_rank1: f64,
    /// Rank-1 on the corrected probes, %.
    pub corrected_rank1: f64,
}

/// The whole table for one data set.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RecognitionResult {
    /// Identities enrolled.
    pub identities: usize,
    /// Gallery images, and how many of them gave a face.
    pub gallery: (usize, usize),
    /// Probe images.
    pub probes: usize,
    /// Feature length.
    pub features: usize,
    /// Probes with a face found undistorted, %.
    pub baseline_detected: f64,
    /// Rank-1 on undistorted probes, %.
    pub baseline_rank1: f64,
    /// One row per shear.
    pub rows: Vec<ShearRow>,
    /// Unreadable images, with the reason.
    pub unreadable: Vec<String>,
}

/// The face crop `CROP x CROP`, eyes level at fixed positions (see the module docs), as `f64`
/// row-major grey values; bilinear, border pixels repeated.
pub fn normalize_geometry(gray: &GrayImage, right_eye: Point, left_eye: Point) -> Vec<f64> {
    let s = CROP as f64;
    let (eye_y, eye_r, eye_l) = (0.35 * s, 0.3 * s, 0.7 * s);
    let (dx, dy) = (left_eye.x - right_eye.x, left_eye.y - right_eye.y);
    let d = dx.hypot(dy).max(1e-6);
    let scale = d / (eye_l - eye_r);
    let (c, sn) = (dx / d, dy / d); // cosine and sine of the eye line's angle
    let (w, h) = (gray.width() as i64, gray.height() as i64);
    let px = |x: i64, y: i64| {
        gray.get_pixel(x.clamp(0, w - 1) as u32, y.clamp(0, h - 1) as u32)[0] as f64
    };
    let mut out = vec![0.0; CROP * CROP];
    if w == 0 || h == 0 {
        return out;
    }
    for v in 0..CROP {
        for u in 0..CROP {
            let (a, b) = ((u as f64 - eye_r) * scale, (v as f64 - eye_y) * scale);
            let x = right_eye.x + a * c - b * sn;
            let y = right_eye.y + a * sn + b * c;
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = (x - x0, y - y0);
            let (x0, y0) = (x0 as i64, y0 as i64);
            out[v * CROP + u] = (1.0 - fy) * ((1.0 - fx) * px(x0, y0) + fx * px(x0 + 1, y0))
                + fy * ((1.0 - fx) * px(x0, y0 + 1) + fx * px(x0 + 1, y0 + 1));
        }
    }
    out
}

/// Separable Gaussian blur of a `CROP x CROP` image, borders repeated.
fn blur(img: &[f64], sigma: f64) -> Vec<f64> {
    let r = (3.0 * sigma).ceil() as i64;
    let k: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let ks: f64 = k.iter().sum();
    let n = CROP as i64;
    let pass = |src: &[f64], horizontal: bool| {
        let mut dst = vec![0.0; src.len()];
        for y in 0..n {
            for x in 0..n {
                let mut acc = 0.0;
                for (j, w) in k.iter().enumerate() {
                    let o = j as i64 - r;
                    let (sx, sy) = if horizontal {
                        ((x + o).clamp(0, n - 1), y)
                    } else {
                        (x, (y + o).clamp(0, n - 1))
                    };
                    acc += w * src[(sy * n + sx) as usize];
                }
                dst[(y * n + x) as usize] = acc / ks;
            }
        }
        dst
    };
    pass(&pass(img, true), false)
}

/// The Self-Quotient Image `I / (G_4 * I)`, clamped to `[0, 3]`, standardised.
pub fn self_quotient(img: &[f64]) -> Vec<f64> {
    let smooth = blur(img, 4.0);
    let q: Vec<f64> = img
        .iter()
        .zip(&smooth)
        .map(|(&i, &s)| ((i + 1.0) / (s + 1.0)).clamp(0.0, 3.0))
        .collect();
    let m = q.iter().sum::<f64>() / q.len() as f64;
    let sd = (q.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / q.len() as f64).sqrt();
    q.iter().map(|v| (v - m) / sd.max(1e-9)).collect()
}

/// Gabor magnitudes (4 scales x 6 orientations) on the [`LATTICE`], mean-pooled into
/// `grid x grid` cells: `24 grid^2` features, ordered cell, scale, orientation.
pub fn gabor_features(img: &[f64], grid: usize) -> Vec<f64> {
    let grid = grid.clamp(1, LATTICE);
    let n = CROP as i64;
    let step = CROP as f64 / LATTICE as f64;
    let mut out = vec![0.0; grid * grid * WAVELENGTHS.len() * ORIENTATIONS];
    let mut counts = vec![0usize; grid * grid];
    for ly in 0..LATTICE {
        for lx in 0..LATTICE {
            let cell = (ly * grid / LATTICE) * grid + lx * grid / LATTICE;
            counts[cell] += 1;
            let (cx, cy) = (
                (step * (lx as f64 + 0.5)) as i64,
                (step * (ly as f64 + 0.5)) as i64,
            );
            for (si, &lambda) in WAVELENGTHS.iter().enumerate() {
                let sigma = 0.56 * lambda;
                let r = (2.5 * sigma).ceil() as i64;
                for o in 0..ORIENTATIONS {
                    let th = std::f64::consts::PI * o as f64 / ORIENTATIONS as f64;
                    let (ct, st) = (th.cos(), th.sin());
                    let (mut re, mut im) = (0.0, 0.0);
                    for dy in -r..=r {
                        let y = (cy + dy).clamp(0, n - 1);
                        for dx in -r..=r {
                            let x = (cx + dx).clamp(0, n - 1);
                            let xr = dx as f64 * ct + dy as f64 * st;
                            let env = (-((dx * dx + dy * dy) as f64) / (2.0 * sigma * sigma)).exp();
                            let ph = 2.0 * std::f64::consts::PI * xr / lambda;
                            let v = img[(y * n + x) as usize] * env;
                            re += v * ph.cos();
                            im += v * ph.sin();
                        }
                    }
                    let idx = (cell * WAVELENGTHS.len() + si) * ORIENTATIONS + o;
                    out[idx] += re.hypot(im) / (sigma * sigma);
                }
            }
        }
    }
    let per = WAVELENGTHS.len() * ORIENTATIONS;
    for (cell, &c) in counts.iter().enumerate() {
        for v in &mut out[cell * per..(cell + 1) * per] {
            *v /= c.max(1) as f64;
        }
    }
    out
}

/// The G96-style feature vector of the face with these eyes.
pub fn face_features(gray: &GrayImage, right_eye: Point, left_eye: Point, grid: usize) -> Vec<f64> {
    gabor_features(
        &self_quotient(&normalize_geometry(gray, right_eye, left_eye)),
        grid,
    )
}

/// A one-vs-rest linear SVM trained with Pegasos on standardised features.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearSvm {
    mean: Vec<f64>,
    scale: Vec<f64>,
    /// One weight vector per class (last entry the bias).
    weights: Vec<Vec<f64>>,
}

impl LinearSvm {
    /// Trains on `(features, class)` pairs with `classes` classes; `lambda` the regulariser,
    /// `epochs` passes over the data. Deterministic (fixed xorshift seed).
    pub fn train(data: &[(Vec<f64>, usize)], classes: usize, lambda: f64, epochs: usize) -> Self {
        let d = data.first().map_or(0, |(x, _)| x.len());
        let n = data.len().max(1) as f64;
        let mut mean = vec![0.0; d];
        for (x, _) in data {
            for (m, v) in mean.iter_mut().zip(x) {
                *m += v / n;
            }
        }
        let mut scale = vec![0.0; d];
        for (x, _) in data {
            for ((s, v), m) in scale.iter_mut().zip(x).zip(&mean) {
                *s += (v - m) * (v - m) / n;
            }
        }
        for s in &mut scale {
            *s = 1.0 / s.sqrt().max(1e-9);
        }
        let std_data: Vec<(Vec<f64>, usize)> = data
            .iter()
            .map(|(x, c)| (standardise(x, &mean, &scale), *c))
            .collect();
        let weights = (0..classes)
            .into_par_iter()
            .map(|class| {
                let mut w = vec![0.0; d + 1];
                let mut seed = 0x9E37_79B9_7F4A_7C15u64 ^ class as u64;
                let steps = epochs * std_data.len();
                for t in 1..=steps {
                    seed ^= seed << 13;
                    seed ^= seed >> 7;
                    seed ^= seed << 17;
                    let (x, c) = &std_data[(seed % std_data.len() as u64) as usize];
                    let y = if *c == class { 1.0 } else { -1.0 };
                    let eta = 1.0 / (lambda * t as f64);
                    let margin = y * dot(&w, x);
                    let shrink = 1.0 - eta * lambda;
                    for v in w.iter_mut() {
                        *v *= shrink;
                    }
                    if margin < 1.0 {
                        for (wi, xi) in w.iter_mut().zip(x.iter().chain(std::iter::once(&1.0))) {
                            *wi += eta * y * xi;
                        }
                    }
                }
                w
            })
            .collect();
        Self {
            mean,
            scale,
            weights,
        }
    }

    /// The class with the highest score (rank 1); `None` without classes.
    pub fn predict(&self, x: &[f64]) -> Option<usize> {
        let z = standardise(x, &self.mean, &self.scale);
        self.weights
            .iter()
            .map(|w| dot(w, &z))
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    }
}

fn standardise(x: &[f64], mean: &[f64], scale: &[f64]) -> Vec<f64> {
    x.iter()
        .zip(mean)
        .zip(scale)
        .map(|((v, m), s)| (v - m) * s)
        .collect()
}

/// `w . [x, 1]` (the last weight is the bias).
fn dot(w: &[f64], x: &[f64]) -> f64 {
    w.iter().zip(x).map(|(a, b)| a * b).sum::<f64>() + w.last().copied().unwrap_or(0.0)
}

/// Features of the largest face with located eyes in `report` (the subject of a portrait).
fn largest_face(gray: &GrayImage, report: &ImageReport, grid: usize) -> Option<Vec<f64>> {
    let f = report
        .faces
        .iter()
        .max_by(|a, b| a.face_box.area().total_cmp(&b.face_box.area()))?;
    Some(face_features(gray, f.right_eye, f.left_eye, grid))
}

/// What one probe gave: baseline features, then per shear (raw features, estimate, corrected
/// features).
type ProbeOutcome = (
    Option<Vec<f64>>,
    Vec<(Option<Vec<f64>>, Option<f64>, Option<Vec<f64>>)>,
);

/// What one gallery image gave: its features and class, nothing without a face, or a read error.
type GalleryOutcome = Result<Option<(Vec<f64>, usize)>, String>;

fn run_probe(unshear: &Unshear, img: &DynamicImage, options: &RecognitionOptions) -> ProbeOutcome {
    let features = |img: &DynamicImage| {
        let gray = Unshear::gray(img);
        let report = unshear.estimate_gray(&gray);
        (largest_face(&gray, &report, options.grid), report)
    };
    let (base, _) = features(img);
    let per_k = options
        .shears
        .iter()
        .map(|&k| {
            // The rectangle a camera delivers of the sheared probe: no empty corner whose
            // slanted edge would show the shear.
            let Some(sheared) = camera_window(&[], img.width(), img.height(), k, 0.0)
                .and_then(|(shear, at, w, h)| sheared_window(img, shear, at, w, h).ok())
            else {
                return (None, None, None);
            };
            let (raw, report) = features(&sheared);
            let corrected = report.k.and_then(|_| {
                let opts = CorrectOptions {
                    region: Region::Image,
                    canvas: Canvas::Expand,
                    interpolation: Interpolation::Linear,
                    k: None,
                    blur: None,
                };
                let fixed = Unshear::correct(&sheared, &report, &opts).ok()?;
                features(&fixed).0
            });
            (raw, report.k, corrected)
        })
        .collect();
    (base, per_k)
}

/// Runs the protocol on `items`; `tick` is called once per image processed.
pub fn evaluate_recognition(
    unshear: &Unshear,
    items: Vec<LabelledImage>,
    options: &RecognitionOptions,
    tick: impl Fn() + Sync,
) -> RecognitionResult {
    let (gallery, probes) = gallery_probe_split(items, options.gallery);
    let mut ids: Vec<String> = gallery.iter().map(|g| g.identity.clone()).collect();
    ids.dedup();
    let class = |id: &str| ids.binary_search_by(|x| x.as_str().cmp(id)).ok();
    let read = |p: &Path| {
        imageio::read_image(p, options.max_pixels).map_err(|e| format!("{}: {e}", p.display()))
    };
    let gallery_out: Vec<GalleryOutcome> = gallery
        .par_iter()
        .map(|g| {
            let img = read(&g.image)?;
            tick();
            let gray = Unshear::gray(&img);
            let report = unshear.estimate_gray(&gray);
            Ok(largest_face(&gray, &report, options.grid)
                .and_then(|f| Some((f, class(&g.identity)?))))
        })
        .collect();
    let mut unreadable = Vec::new();
    let mut train = Vec::new();
    for g in gallery_out {
        match g {
            Ok(Some(x)) => train.push(x),
            Ok(None) => {}
            Err(e) => unreadable.push(e),
        }
    }
    let svm = LinearSvm::train(&train, ids.len(), 1e-3, 60);
    let probe_out: Vec<Result<(usize, ProbeOutcome), String>> = probes
        .par_iter()
        .filter_map(|p| Some((p, class(&p.identity)?)))
        .map(|(p, c)| {
            let img = read(&p.image)?;
            let out = run_probe(unshear, &img, options);
            tick();
            Ok((c, out))
        })
        .collect();
    let mut outcomes = Vec::new();
    for p in probe_out {
        match p {
            Ok(o) => outcomes.push(o),
            Err(e) => unreadable.push(e),
        }
    }
    let n = outcomes.len();
    let right = |f: &Option<Vec<f64>>, c: usize| f.as_ref().and_then(|f| svm.predict(f)) == Some(c);
    let rows = options
        .shears
        .iter()
        .enumerate()
        .map(|(i, &k)| {
            let at = |o: &ProbeOutcome| o.1.get(i).cloned().unwrap_or((None, None, None));
            ShearRow {
                k,
                median_estimate: median(outcomes.iter().filter_map(|(_, o)| at(o).1).collect()),
                raw_detected: pct(
                    outcomes.iter().filter(|(_, o)| at(o).0.is_some()).count(),
                    n,
                ),
                raw_rank1: pct(
                    outcomes.iter().filter(|(c, o)| right(&at(o).0, *c)).count(),
                    n,
                ),
                corrected_rank1: pct(
                    outcomes.iter().filter(|(c, o)| right(&at(o).2, *c)).count(),
                    n,
                ),
            }
        })
        .collect();
    RecognitionResult {
        identities: ids.len(),
        gallery: (gallery.len(), train.len()),
        probes: n,
        features: train.first().map_or(0, |(x, _)| x.len()),
        baseline_detected: pct(outcomes.iter().filter(|(_, o)| o.0.is_some()).count(), n),
        baseline_rank1: pct(outcomes.iter().filter(|(c, o)| right(&o.0, *c)).count(), n),
        rows,
        unreadable,
    }
}

impl RecognitionResult {
    /// The Table I layout, with the paper's FERET figures beside ours where the shear matches.
    pub fn markdown(&self, dataset: &str) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{dataset}: {} identities, gallery {} images ({} with a face found), {} probes; {} Gabor features; unreadable: {}\n",
            self.identities, self.gallery.0, self.gallery.1, self.probes, self.features, self.unreadable.len()
        );
        let _ = writeln!(
            s,
            "Rank-1 on undistorted probes: {:.1}% (face found in {:.1}%); paper (FERET): {PAPER_BASELINE:.2}%\n",
            self.baseline_rank1, self.baseline_detected
        );
        let paper = |k: f64| PAPER_TABLE.iter().find(|p| (p.0 - k).abs() < 1e-9);
        let cell = |ours: String, theirs: Option<String>| match theirs {
            Some(t) => format!("{ours} ({t})"),
            None => ours,
        };
        let _ = write!(s, "| ours (paper, FERET) |");
        for r in &self.rows {
            let _ = write!(s, " k = {:.2} |", r.k);
        }
        let _ = write!(s, "\n|---|");
        for _ in &self.rows {
            let _ = write!(s, "---:|");
        }
        let _ = write!(s, "\n| median estimated k |");
        for r in &self.rows {
            let _ = write!(
                s,
                " {} |",
                cell(
                    fmt3(r.median_estimate),
                    paper(r.k).map(|p| format!("{:.2}", p.1))
                )
            );
        }
        let _ = write!(s, "\n| face found, raw sheared |");
        for r in &self.rows {
            let _ = write!(s, " {:.1}% |", r.raw_detected);
        }
        let _ = write!(s, "\n| rank-1, raw sheared |");
        for r in &self.rows {
            let _ = write!(
                s,
                " {} |",
                cell(
                    format!("{:.1}%", r.raw_rank1),
                    paper(r.k).map(|p| format!("{:.1}%", p.2))
                )
            );
        }
        let _ = write!(s, "\n| rank-1, corrected |");
        for r in &self.rows {
            let _ = write!(
                s,
                " {} |",
                cell(
                    format!("{:.1}%", r.corrected_rank1),
                    paper(r.k).map(|p| format!("{:.1}%", p.3))
                )
            );
        }
        let _ = writeln!(s);
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svm_separates_clusters() {
        let mut data = Vec::new();
        for c in 0..3usize {
            for j in 0..3 {
                let mut x = vec![0.0; 5];
                x[c] = 5.0 + j as f64 * 0.1;
                x[4] = j as f64;
                data.push((x, c));
            }
        }
        let svm = LinearSvm::train(&data, 3, 1e-2, 50);
        for (x, c) in &data {
            assert_eq!(svm.predict(x), Some(*c));
        }
    }

    #[test]
    fn geometry_puts_eyes_at_fixed_positions() {
        // A bright 7 x 7 spot at each eye of a tilted pair (3.2 source pixels per crop pixel)
        // lands at the crop's eye positions.
        let mut g = GrayImage::new(200, 200);
        let (re, le) = (Point::new(60.0, 90.0), Point::new(140.0, 110.0));
        for p in [re, le] {
            for dy in -3..=3 {
                for dx in -3..=3 {
                    g.put_pixel(
                        (p.x as i32 + dx) as u32,
                        (p.y as i32 + dy) as u32,
                        image::Luma([255]),
                    );
                }
            }
        }
        let crop = normalize_geometry(&g, re, le);
        let at = |x: f64, y: f64| crop[y.round() as usize * CROP + x.round() as usize];
        assert!(at(19.2, 22.4) > 20.0, "{}", at(19.2, 22.4));
        assert!(at(44.8, 22.4) > 20.0, "{}", at(44.8, 22.4));
        assert_eq!(at(32.0, 50.0), 0.0);
    }

    #[test]
    fn g96_has_96_features_and_sqi_is_standardised() {
        let img: Vec<f64> = (0..CROP * CROP).map(|i| ((i * 37) % 251) as f64).collect();
        let q = self_quotient(&img);
        let m = q.iter().sum::<f64>() / q.len() as f64;
        assert!(m.abs() < 1e-9);
        assert_eq!(gabor_features(&q, 2).len(), 96);
        assert_eq!(gabor_features(&q, 4).len(), 384);
    }

    #[test]
    fn table_has_paper_figures() {
        let r = RecognitionResult {
            identities: 2,
            gallery: (6, 6),
            probes: 4,
            features: 96,
            baseline_detected: 100.0,
            baseline_rank1: 75.0,
            rows: vec![ShearRow {
                k: 0.14,
                median_estimate: Some(0.13),
                raw_detected: 100.0,
                raw_rank1: 50.0,
                corrected_rank1: 75.0,
            }],
            unreadable: vec![],
        };
        let md = r.markdown("x");
        assert!(
            md.contains("| rank-1, raw sheared | 50.0% (87.9%) |"),
            "{md}"
        );
        assert!(md.contains("| median estimated k | 0.130 (0.15) |"), "{md}");
        assert!(md.contains("94.09%"));
    }
}
