//! Accuracy on annotated faces sheared synthetically (`unshear eval shear`), the kind of table
//! the paper reports (Table I's median estimates), with detection included as a user runs it.
//!
//! For each image and each shear `k`: the image is sheared in memory with the documented
//! convention (bilinear, pivot at the middle row of what is sheared), the full pipeline runs on
//! the frame a camera would deliver of it, and for each annotated face we record whether a
//! detected box contains both (sheared) true eyes, the estimate of that face, and the
//! eye-localisation error.
//!
//! **The frame ([`EvalCanvas`]).** A rolling-shutter camera delivers a rectangle, every pixel of
//! it filled: the default, [`EvalCanvas::Crop`], hands the pipeline only the columns that every
//! row of the frame covers (about `|k|` times the frame's height narrower than the photo), never
//! a canvas with empty corners, whose edges slant by exactly `k` and so would give the shear
//! away. A face whose eye falls outside that frame or within [`FRAME_MARGIN`] eye distances of
//! its edge is *cut*: left out of every count (not scored as missed) and counted apart.
//! [`EvalCanvas::Expand`] shears onto a canvas widened so nothing is cut, empty corners and all
//! (the paper's setting).
//!
//! **Speed-up (context crop).** Caltech images are up to 2300 px wide; most of the run time went
//! into scanning background. With [`evaluate_shear_in_context`] and `context > 0` the pipeline
//! sees only the union of the annotated faces' surroundings (a square `context` times the
//! nominal face box — two eye distances wide, centred a little below the eye midpoint — on each
//! face). With [`EvalCanvas::Crop`] that square is taken around the sheared faces, within the
//! columns the sheared photo covers in its rows ([`camera_window`]), so a face keeps the
//! surroundings it has at `k = 0` wherever the photo has them. With [`EvalCanvas::Expand`] the
//! image is cropped to it (clipped to the image) and only then sheared. `k` is unchanged by
//! either (the pivot moves with the crop, which shifts rows by a constant and is irrelevant to
//! the estimate); compare with `--context 0`, which gives the whole photo.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use rayon::prelude::*;
use serde::Serialize;

use super::camera::{CameraFrame, CameraLike};
use super::{fmt3, mean, pct};
use crate::dev::dataset::{by_image, AnnotatedFace};
use crate::error::{Error, Result};
use crate::geometry::{Point, Shear};
use crate::imageio;
use crate::pipeline::confidence::{box_outside_share, face_layout};
use crate::pipeline::{FaceReport, Unshear};
use crate::stats::median;
use crate::warp::rotate::{rotate_gray, Rotation};
use crate::warp::{try_apply_shear, Canvas, Interpolation, Placement};

/// Default context crop: 3 nominal face boxes around each annotated face.
pub const DEFAULT_CONTEXT: f64 = 3.0;

/// How near the frame's edge, in eye distances, an annotated eye may lie for its face to be
/// scored ([`ShearSample::cut`] otherwise). Every one of the 928 measured development faces has
/// both eyes at least 0.38 eye distances inside its photo, so at `k = 0` none is cut; an eye a
/// quarter eye distance from the edge leaves the face box (half an eye distance beyond each eye)
/// half cut away.
pub const FRAME_MARGIN: f64 = 0.25;

/// What `eval shear` hands the pipeline of each sheared photo.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum EvalCanvas {
    /// The rectangle a rolling-shutter camera delivers: of the frame's rows, only the columns
    /// every one of them covers, no empty pixel ([`camera_window`]).
    #[default]
    Crop,
    /// The sheared photo on a canvas widened so nothing is cut (the paper's setting): its empty
    /// corners' edges slant by exactly `k`, a cue no real photo has.
    Expand,
}

/// Options for [`evaluate_shear`].
#[derive(Debug, Clone, PartialEq)]
pub struct ShearEvalOptions {
    /// The shears applied.
    pub shears: Vec<f64>,
    /// Decoded-size limit for the images.
    pub max_pixels: u64,
    /// Faces annotated in the evaluated images but not evaluated themselves (too small, or
    /// beyond a limit): a detection of one of them is a real face, not counted as unmatched.
    pub also_annotated: Vec<AnnotatedFace>,
    /// Also run each whole photo once with its annotated faces painted over
    /// ([`face_free`]), to count false faces.
    pub face_free: bool,
    /// Turn each (cropped) photo by this many degrees before shearing it: the heads rolled,
    /// then read out by a rolling shutter (0: as they are).
    pub roll_degrees: f64,
    /// The frame the pipeline is given.
    pub canvas: EvalCanvas,
    /// Make each frame as a panning camera would beyond one shear (a pan changing speed during
    /// the readout, a vertical drift, motion blur, noise, JPEG; [`CameraLike`]) and score each
    /// face against the shear at its eyes' row; `None`: a plain shear.
    pub camera: Option<CameraLike>,
    /// Look for a motion blur along each frame's rows and remove it before the pipeline reads
    /// the frame (its length per row from bands of rows, [`crate::deblur::blur_lengths`]).
    pub deblur: bool,
}

/// One photo with its annotated faces painted over ([`face_free`]), and what the pipeline
/// reported on it.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct FaceFreeSample {
    /// The image.
    pub image: String,
    /// Faces reported, accepted or refused.
    pub faces: usize,
    /// Faces with an accepted estimate.
    pub accepted: usize,
    /// The image's accepted shear, which `correct` would undo.
    pub k: Option<f64>,
    /// Every face reported (at `true_k` 0, centres in the photo's pixels): false faces, or
    /// real faces the annotations leave out.
    pub found: Vec<UnmatchedDetection>,
}

/// How far each way across from the eyes' midpoint [`face_free`] paints, in eye distances
/// (hair, ears and chin are covered with the limits below).
pub const FACE_FREE_HALF_WIDTH: f64 = 1.8;
/// How far above the eyes' midpoint [`face_free`] paints, in eye distances.
pub const FACE_FREE_ABOVE: f64 = 1.8;
/// How far below the eyes' midpoint [`face_free`] paints, in eye distances.
pub const FACE_FREE_BELOW: f64 = 2.4;

/// `img` with each of `faces` painted over by a flat rectangle of the image's mean colour
/// (eyes' midpoint +-[`FACE_FREE_HALF_WIDTH`] eye distances across, [`FACE_FREE_ABOVE`] above and
/// [`FACE_FREE_BELOW`] below, grown by the face's roll): a photo of the same scene without the
/// annotated people's faces. Faces the annotations leave out stay.
pub fn face_free(img: &image::DynamicImage, faces: &[&AnnotatedFace]) -> image::RgbImage {
    let mut rgb = img.to_rgb8();
    let n = f64::from(rgb.width()) * f64::from(rgb.height());
    let mut sum = [0.0f64; 3];
    for p in rgb.pixels() {
        for (total, &v) in sum.iter_mut().zip(&p.0) {
            *total += f64::from(v);
        }
    }
    let mean = image::Rgb(sum.map(|v| (v / n.max(1.0)).round() as u8));
    for f in faces {
        let (d, mid) = (f.eye_distance(), f.right_eye.midpoint(f.left_eye));
        // A rolled face's rectangle, turned, fits in one this much larger.
        let roll = (f.left_eye.y - f.right_eye.y).atan2(f.left_eye.x - f.right_eye.x);
        let grow = 1.0 + roll.sin().abs();
        let x0 = (mid.x - FACE_FREE_HALF_WIDTH * d * grow).max(0.0) as u32;
        let x1 = (mid.x + FACE_FREE_HALF_WIDTH * d * grow).max(0.0) as u32;
        let y0 = (mid.y - FACE_FREE_ABOVE * d * grow).max(0.0) as u32;
        let y1 = (mid.y + FACE_FREE_BELOW * d * grow).max(0.0) as u32;
        for y in y0..y1.min(rgb.height()) {
            for x in x0..x1.min(rgb.width()) {
                rgb.put_pixel(x, y, mean);
            }
        }
    }
    rgb
}

/// What the pipeline read on a face besides its shear: the inputs of the confidence models
/// (`pipeline::confidence`), which `scripts/fit_confidence.py` fits to. Each is `None` when the
/// face was not found or the locator does not give it.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Reading {
    /// The nose axis's and the mouth axis's own estimates.
    pub k_nose: Option<f64>,
    /// See `k_nose`.
    pub k_mouth: Option<f64>,
    /// The nose-tip axis's own estimate (the nose filter's point).
    pub k_nose_tip: Option<f64>,
    /// The nose filter's peak-to-sidelobe ratio.
    pub nose_tip_psr: Option<f64>,
    /// Peak-to-sidelobe ratios (eyes, nostrils, mouth).
    pub psr: Option<[f64; 5]>,
    /// Located eye distance over the face box width.
    pub eye_box_ratio: Option<f64>,
    /// Located eye distance in the sheared image, pixels.
    pub located_eye_distance: Option<f64>,
    /// The landmark network's own reading of the shear (network locator only).
    pub k_network: Option<f64>,
    /// The shear the network's points give (network locator only).
    pub k_points: Option<f64>,
    /// The network's heatmap spreads, eye distances (network locator only).
    pub spread: Option<[f64; 4]>,
}

impl Reading {
    /// What `report` read on its face.
    fn of(report: &FaceReport) -> Self {
        let eyes = report.right_eye.distance(report.left_eye);
        Self {
            k_nose: report.k_nose,
            k_mouth: report.k_mouth,
            k_nose_tip: report.k_nose_tip,
            nose_tip_psr: Some(report.nose_tip_psr),
            psr: Some(report.psr),
            eye_box_ratio: Some(eyes / report.face_box.width),
            located_eye_distance: Some(eyes),
            k_network: report.k_network,
            k_points: report.k_points,
            spread: report.spread,
        }
    }
}

/// A detection, kept by the pipeline, that contains no annotated face of its image (both eyes
/// of none in its box). The data sets do not annotate every face (background and profile
/// faces go without), so these bound the false faces from above: each is a false face or an
/// unannotated real one.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct UnmatchedDetection {
    /// The image.
    pub image: String,
    /// The shear applied.
    pub true_k: f64,
    /// The box's centre, in the original (unsheared, uncropped) image's pixels.
    pub centre: [f64; 2],
    /// The box's width, pixels.
    pub width: f64,
    /// The estimate measured on it, accepted or refused.
    pub measured: f64,
    /// Whether that estimate was accepted (confident enough to report and correct by).
    pub accepted: bool,
    /// The roll measured on it, degrees.
    pub roll_degrees: f64,
    /// Its confidence.
    pub confidence: f64,
    /// The network's face score (network locator only).
    pub face_score: Option<f64>,
    /// Why its estimate was refused (`low_confidence`, ...), when it was.
    pub refused: Option<String>,
    /// What the pipeline read on it.
    #[serde(flatten)]
    pub reading: Reading,
}

impl UnmatchedDetection {
    /// The detection of `report` in `image` at shear `k`, its box centred at `centre` (in the
    /// original image's pixels) and as wide as the report's.
    fn of(image: &str, k: f64, centre: Point, report: &FaceReport) -> Self {
        Self {
            image: image.to_string(),
            true_k: k,
            centre: [centre.x, centre.y],
            width: report.face_box.width,
            measured: report.k_measured,
            accepted: report.k.is_some(),
            roll_degrees: report.roll_degrees,
            confidence: report.confidence,
            face_score: report.face_score,
            refused: report.refused.map(|r| r.name().to_string()),
            reading: Reading::of(report),
        }
    }
}

/// One face under one shear.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct ShearSample {
    /// The image.
    pub image: String,
    /// Index of the face among the image's annotations.
    pub face: usize,
    /// The shear applied (with a camera-like frame, its nominal shear: the middle row's).
    pub true_k: f64,
    /// The shear at the face's eyes, which its estimate is scored against: `true_k`, or with
    /// a camera-like frame the local shear at the eyes' row.
    pub local_k: f64,
    /// Eye distance in the image, pixels.
    pub eye_distance: f64,
    /// The motion blur at the face's eyes' row, pixels (camera-like frames).
    pub true_blur: Option<f64>,
    /// The blur found in the frame and removed (with [`ShearEvalOptions::deblur`]), pixels.
    pub blur: Option<f64>,
    /// The frame cut the face: an eye lies outside it or within [`FRAME_MARGIN`] eye distances
    /// of its edge. Such a face is not scored (every other field is empty) and not counted as
    /// missed.
    pub cut: bool,
    /// A detected box contained both true eyes.
    pub detected: bool,
    /// Further reported faces whose boxes also contain both true eyes: the same face reported
    /// more than once.
    pub duplicates: usize,
    /// The accepted estimate for that face, if any (a detected face may give none: the located
    /// points are unusable, or the estimate was refused for low confidence).
    pub estimate: Option<f64>,
    /// The estimate measured, accepted or refused.
    pub measured: Option<f64>,
    /// The face's confidence (0 to 1), when it was found.
    pub confidence: Option<f64>,
    /// The face's roll under the estimated shear, degrees.
    pub roll_degrees: Option<f64>,
    /// What the pipeline read on the face, when it was found.
    #[serde(flatten)]
    pub reading: Reading,
    /// The network's face score (network locator only).
    pub face_score: Option<f64>,
    /// Worst of the two eyes' localisation errors, as a fraction of the eye distance.
    pub eye_error: Option<f64>,
    /// Where each located eye lies from its annotation, in eye distances of the sheared image:
    /// right eye `dx, dy`, then left eye `dx, dy` (image axes, y down).
    pub eye_offsets: Option<[f64; 4]>,
    /// Where the located mouth lies from the annotated mouth centre, in eye distances.
    pub mouth_offset: Option<[f64; 2]>,
    /// The same formula on the annotated points (eye midpoint over the nose point): what
    /// perfect feature locations would give.
    pub oracle: Option<f64>,
    /// Why the estimate was refused (`low_confidence`, ...), when it was.
    pub refused: Option<String>,
    /// The share of the face box outside the (sheared) image, when the face was found.
    pub box_outside: Option<f64>,
    /// Where the located nose and mouth lie from the eyes' midpoint in the face's own frame
    /// (measured shear and roll undone), in eye distances: nose `x, y`, mouth `x, y`
    /// (`pipeline::confidence::face_layout`).
    pub layout: Option<[f64; 4]>,
    /// The shear the image's correction applies at the face's eyes' row: the image's `k`, or
    /// where the faces at different heights disagree ([`crate::RowShear`]) its value there.
    pub image_k: Option<f64>,
    /// The image's one shear from its faces without the change down the rows (the faces'
    /// consensus), to compare with `image_k`.
    pub image_k_one: Option<f64>,
    /// Whether the image's shear changes down its rows.
    pub bent: bool,
    /// Milliseconds the pipeline took on the whole image (detection included).
    pub millis: f64,
}

/// How far (in shear) an accepted estimate must be from the truth to count as a gross error:
/// a correction that leaves (or adds) a visible shear of more than 0.15, worse than most
/// uncorrected photos.
pub const GROSS_ERROR: f64 = 0.15;

/// All samples, with the summary tables.
#[derive(Debug, Clone, PartialEq)]
pub struct ShearEvalResult {
    /// Every face x shear.
    pub samples: Vec<ShearSample>,
    /// The shears, in the order given.
    pub shears: Vec<f64>,
    /// Images that could not be read.
    pub unreadable: Vec<String>,
    /// Detections matching no annotated face, every shear.
    pub unmatched: Vec<UnmatchedDetection>,
    /// The photos with their faces painted over, when asked for
    /// ([`ShearEvalOptions::face_free`]).
    pub face_free: Vec<FaceFreeSample>,
}

/// Runs the evaluation on whole images (no context crop), in parallel over images; `tick` is
/// called once per face and shear.
pub fn evaluate_shear(
    unshear: &Unshear,
    faces: &[AnnotatedFace],
    options: &ShearEvalOptions,
    tick: impl Fn() + Sync,
) -> ShearEvalResult {
    evaluate_shear_in_context(unshear, faces, options, 0.0, tick)
}

/// [`evaluate_shear`] with each image first cropped to `context` nominal face boxes around its
/// annotated faces (see the module docs; `context <= 0`: whole images).
pub fn evaluate_shear_in_context(
    unshear: &Unshear,
    faces: &[AnnotatedFace],
    options: &ShearEvalOptions,
    context: f64,
    tick: impl Fn() + Sync,
) -> ShearEvalResult {
    let groups = by_image(faces.to_vec());
    // Parallel over images, the shears of one image in turn: each image is decoded (and
    // cropped) once, not once per shear, which was a third of the run time.
    type Found = (
        Vec<ShearSample>,
        Vec<UnmatchedDetection>,
        Option<FaceFreeSample>,
    );
    let results: Vec<std::result::Result<Found, String>> = groups
        .par_iter()
        .map(|(path, annotated)| {
            let known: Vec<&AnnotatedFace> = annotated
                .iter()
                .chain(options.also_annotated.iter().filter(|f| &f.image == path))
                .collect();
            let face_free = if options.face_free {
                let full = imageio::read_image(path, options.max_pixels)
                    .map_err(|e| format!("{}: {e}", path.display()))?;
                let painted = image::DynamicImage::ImageRgb8(face_free(&full, &known));
                let report = unshear.estimate(&painted);
                let image = path.display().to_string();
                Some(FaceFreeSample {
                    faces: report.faces.len(),
                    accepted: report.faces.iter().filter(|f| f.k.is_some()).count(),
                    k: report.k,
                    found: report
                        .faces
                        .iter()
                        .map(|f| UnmatchedDetection::of(&image, 0.0, f.face_box.center(), f))
                        .collect(),
                    image,
                })
            } else {
                None
            };
            let rolled = options.roll_degrees != 0.0;
            // The camera's frame is taken around the sheared faces in the whole photo (their
            // surroundings as at k = 0 wherever the photo has them); a turned photo is turned
            // after its context crop, as with the widened canvas, and then framed whole, as is
            // a camera-like frame.
            let window_context = match options.canvas {
                EvalCanvas::Crop if !rolled && options.camera.is_none() => context,
                _ => 0.0,
            };
            let crop_first = if window_context > 0.0 { 0.0 } else { context };
            let (img, origin) = load_cropped(path, annotated, options, crop_first)?;
            let (img, rotation) = if !rolled {
                (img, None)
            } else {
                let (turned, rotation) =
                    rotate_gray(&img.to_luma8(), options.roll_degrees.to_radians())
                        .map_err(|e| format!("{}: {e}", path.display()))?;
                (image::DynamicImage::ImageLuma8(turned), Some(rotation))
            };
            let photo = Photo {
                path,
                img: &img,
                origin,
                rotation,
                canvas: options.canvas,
                context: window_context,
                camera: options.camera,
                deblur: options.deblur,
            };
            let mut out: Found = (Vec::new(), Vec::new(), face_free);
            for &k in &options.shears {
                let (samples, unmatched) = run_one(unshear, &photo, annotated, &known, k)?;
                out.0.extend(samples);
                out.1.extend(unmatched);
                for _ in annotated.iter() {
                    tick();
                }
            }
            Ok(out)
        })
        .collect();
    let mut samples = Vec::new();
    let mut unmatched = Vec::new();
    let mut unreadable = Vec::new();
    let mut face_free = Vec::new();
    for r in results {
        match r {
            Ok((s, u, f)) => {
                samples.extend(s);
                unmatched.extend(u);
                face_free.extend(f);
            }
            Err(e) => {
                if !unreadable.contains(&e) {
                    unreadable.push(e);
                }
            }
        }
    }
    ShearEvalResult {
        samples,
        shears: options.shears.clone(),
        unreadable,
        unmatched,
        face_free,
    }
}

/// The image, cropped to the faces' context (see [`context_crop`]), and where the crop's
/// top-left pixel lies in the original.
fn load_cropped(
    path: &Path,
    annotated: &[AnnotatedFace],
    options: &ShearEvalOptions,
    context: f64,
) -> std::result::Result<(image::DynamicImage, Point), String> {
    let full = imageio::read_image(path, options.max_pixels)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(
        match context_crop(annotated, full.width(), full.height(), context) {
            Some((x, y, w, h)) => (full.crop_imm(x, y, w, h), Point::new(x as f64, y as f64)),
            None => (full, Point::new(0.0, 0.0)),
        },
    )
}

/// One photo as the eval shears it: perhaps cropped (its top-left pixel at `origin` in the file)
/// and turned (`rotation`, from the crop to `img`), then framed by `canvas` (with
/// [`EvalCanvas::Crop`], `context` nominal face boxes around the faces; 0: the whole frame).
struct Photo<'a> {
    path: &'a Path,
    img: &'a image::DynamicImage,
    origin: Point,
    rotation: Option<Rotation>,
    canvas: EvalCanvas,
    context: f64,
    camera: Option<CameraLike>,
    deblur: bool,
}

/// Where the photo's points land in the frame the pipeline is given.
#[derive(Clone, Copy)]
enum FrameMap {
    /// A shear, and where the frame lies in the sheared photo.
    Shear(Shear, Placement),
    /// A camera-like frame.
    Camera(CameraFrame),
}

impl FrameMap {
    fn apply(&self, p: Point) -> Point {
        match self {
            Self::Shear(shear, placement) => placement.from_frame(shear.apply(p)),
            Self::Camera(frame) => frame.apply(p),
        }
    }

    fn invert(&self, q: Point) -> Point {
        match self {
            Self::Shear(shear, placement) => shear.invert(placement.to_frame(q)),
            Self::Camera(frame) => frame.invert(q),
        }
    }

    /// The shear at frame row `y`.
    fn local_k(&self, k: f64, y: f64) -> f64 {
        match self {
            Self::Shear(..) => k,
            Self::Camera(frame) => frame.local_k(y),
        }
    }

    /// The motion blur at frame row `y`, pixels (`None`: none was made).
    fn blur(&self, y: f64) -> Option<f64> {
        match self {
            Self::Shear(..) => None,
            Self::Camera(frame) => Some(frame.blur(y)),
        }
    }
}

/// A noise seed fixed by the photo and the shear, so runs repeat.
fn frame_seed(path: &Path, k: f64) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in path
        .to_string_lossy()
        .bytes()
        .chain(k.to_bits().to_le_bytes())
    {
        h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// Where an eye may lie in a `width` x `height` frame for its face, `eye_distance` wide, to be
/// scored: at least [`FRAME_MARGIN`] eye distances inside each edge.
fn in_frame(p: Point, eye_distance: f64, width: u32, height: u32) -> bool {
    let m = FRAME_MARGIN * eye_distance;
    p.x >= m && p.y >= m && p.x <= f64::from(width) - 1.0 - m && p.y <= f64::from(height) - 1.0 - m
}

/// The frame a rolling-shutter camera delivers of a `width` x `height` photo sheared by `k`
/// around faces (each its eyes' midpoint and eye distance, in the photo's pixels): the shear
/// (pivot at the frame's middle row), where the frame lies in the sheared photo, and its width
/// and height; `None` if no column is covered.
///
/// The rows are those of `context` nominal face boxes around the faces (as [`context_crop`]
/// takes them; `context <= 0` or no faces: every row). The columns are those of the same boxes
/// around the sheared faces, cut to the columns every one of these rows covers entirely
/// (`|k|` times the rows' span narrower than the photo): no pixel of the frame lies outside the
/// photo.
pub fn camera_window(
    faces: &[(Point, f64)],
    width: u32,
    height: u32,
    k: f64,
    context: f64,
) -> Option<(Shear, Placement, u32, u32)> {
    if width == 0 || height == 0 || !k.is_finite() {
        return None;
    }
    let (w, h) = (f64::from(width), f64::from(height));
    let rows = context_bounds(faces, context, |p| p).map_or((0.0, h), |[_, y0, _, y1]| {
        (y0.floor().clamp(0.0, h), y1.ceil().clamp(0.0, h))
    });
    if rows.1 <= rows.0 {
        return None;
    }
    let shear = Shear::new(k, rows.0 + (rows.1 - rows.0) / 2.0);
    // The warp treats shifts within 1e-9 of a whole number as that number.
    let snap = |v: f64| {
        if (v - v.round()).abs() < 1e-9 {
            v.round()
        } else {
            v
        }
    };
    let (a, b) = (
        snap(shear.row_shift(rows.0)),
        snap(shear.row_shift(rows.1 - 1.0)),
    );
    let (covered_x0, covered_x1) = (a.max(b).ceil(), (a.min(b) + w - 1.0).floor() + 1.0);
    let cols = context_bounds(faces, context, |p| shear.apply(p))
        .map_or((covered_x0, covered_x1), |[x0, _, x1, _]| {
            (x0.floor().max(covered_x0), x1.ceil().min(covered_x1))
        });
    if cols.1 <= cols.0 {
        return None;
    }
    Some((
        shear,
        Placement {
            offset_x: cols.0,
            offset_y: rows.0,
        },
        (cols.1 - cols.0) as u32,
        (rows.1 - rows.0) as u32,
    ))
}

/// The `width` x `height` window at `placement` of `img` sheared by `shear` (bilinear), every
/// pixel as [`try_apply_shear`] gives it on the whole image; the window must lie where every
/// row is covered ([`camera_window`]). Only the rows and columns the window needs are sheared.
pub(crate) fn sheared_window(
    img: &image::DynamicImage,
    shear: Shear,
    placement: Placement,
    width: u32,
    height: u32,
) -> Result<image::DynamicImage> {
    let (x0, y0) = (placement.offset_x, placement.offset_y);
    let (a, b) = (
        shear.row_shift(y0),
        shear.row_shift(y0 + f64::from(height) - 1.0),
    );
    // The source columns of the window's rows, and one more each side for the bilinear taps.
    let first = ((x0 - a.max(b)).floor() - 1.0).max(0.0);
    let last = ((x0 + f64::from(width) - 1.0 - a.min(b)).ceil() + 2.0).min(f64::from(img.width()));
    let bad = || {
        Error::InvalidArgument(format!(
            "window {width}x{height} at ({x0}, {y0}) is not inside the sheared {}x{} image",
            img.width(),
            img.height()
        ))
    };
    if last <= first || y0 < 0.0 || y0 + f64::from(height) > f64::from(img.height()) {
        return Err(bad());
    }
    let part = img.crop_imm(first as u32, y0 as u32, (last - first) as u32, height);
    let (sheared, at) = try_apply_shear(
        &part,
        Shear::new(shear.k, shear.pivot_y - y0),
        Interpolation::Linear,
        Canvas::Expand,
    )?;
    let x = x0 - first - at.offset_x;
    if x < 0.0 || x + f64::from(width) > f64::from(sheared.width()) {
        return Err(bad());
    }
    Ok(sheared.crop_imm(x as u32, 0, width, height))
}

fn run_one(
    unshear: &Unshear,
    photo: &Photo,
    annotated: &[AnnotatedFace],
    known: &[&AnnotatedFace],
    k: f64,
) -> std::result::Result<(Vec<ShearSample>, Vec<UnmatchedDetection>), String> {
    let Photo {
        path,
        img,
        origin,
        rotation,
        canvas,
        context,
        camera,
        deblur,
    } = *photo;
    let failed = |e: Error| format!("{}: {e}", path.display());
    let in_view = |p: Point| {
        let p = Point::new(p.x - origin.x, p.y - origin.y);
        rotation.map_or(p, |r| r.to_view(p))
    };
    let (map, sheared) = match (camera, canvas) {
        (Some(camera), _) => {
            let (frame, map) = camera.render(img, k, frame_seed(path, k)).map_err(failed)?;
            (FrameMap::Camera(map), image::DynamicImage::ImageRgb8(frame))
        }
        (None, EvalCanvas::Expand) => {
            let shear = Shear::about_middle(k, img.height());
            let (sheared, placement) =
                try_apply_shear(img, shear, Interpolation::Linear, Canvas::Expand)
                    .map_err(failed)?;
            (FrameMap::Shear(shear, placement), sheared)
        }
        (None, EvalCanvas::Crop) => {
            let faces: Vec<(Point, f64)> = annotated
                .iter()
                .map(|f| {
                    let mid = in_view(f.right_eye).midpoint(in_view(f.left_eye));
                    (mid, f.eye_distance())
                })
                .collect();
            let (shear, placement, w, h) =
                camera_window(&faces, img.width(), img.height(), k, context).ok_or_else(|| {
                    format!(
                        "{}: no column of the photo stays in the frame at k = {k}",
                        path.display()
                    )
                })?;
            let sheared = sheared_window(img, shear, placement, w, h).map_err(failed)?;
            (FrameMap::Shear(shear, placement), sheared)
        }
    };
    let start = Instant::now();
    let blurs = deblur
        .then(|| {
            let gray = Unshear::gray(&sheared);
            crate::deblur::blur_lengths(&gray, f64::from(gray.width()) / 4.0)
        })
        .flatten();
    let sheared = match &blurs {
        Some(lengths) => {
            let mut sharp = sheared;
            crate::deblur::deblur_image(
                &mut sharp,
                lengths,
                crate::deblur::DEFAULT_NOISE_TO_SIGNAL,
            )
            .map_err(failed)?;
            sharp
        }
        None => sheared,
    };
    let blur_at = |y: f64| {
        let lengths = blurs.as_ref()?;
        lengths
            .get((y.round().max(0.0) as usize).min(lengths.len() - 1))
            .copied()
    };
    // Boxes with their estimates, so a face that is detected but yields no estimate still counts
    // as detected.
    let found = unshear.detect_and_estimate(&Unshear::gray(&sheared));
    let millis = start.elapsed().as_secs_f64() * 1e3;
    let moved = |p: Point| map.apply(in_view(p));
    let (image_k_one, rows) = crate::pipeline::faces_shear(
        found.iter().filter_map(|f| f.report).collect(),
        sheared.height(),
    );
    let image_k_at = |y: f64| rows.map(|r| r.k_at(y)).or(image_k_one);
    let unmatched = found
        .iter()
        .filter_map(|found| {
            let (b, r) = (&found.face_box, found.report.as_ref()?);
            let real = known
                .iter()
                .any(|f| b.contains(moved(f.right_eye)) && b.contains(moved(f.left_eye)));
            if real {
                return None;
            }
            let c = map.invert(b.center());
            let c = rotation.map_or(c, |r| r.to_input(c));
            let c = Point::new(c.x + origin.x, c.y + origin.y);
            Some(UnmatchedDetection {
                width: b.width,
                ..UnmatchedDetection::of(&path.display().to_string(), k, c, r)
            })
        })
        .collect();
    let samples = annotated
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let (re, le) = (moved(f.right_eye), moved(f.left_eye));
            let ed = f.eye_distance();
            let (w, h) = (sheared.width(), sheared.height());
            let local_k = map.local_k(k, re.midpoint(le).y);
            let true_blur = map.blur(re.midpoint(le).y);
            if !(in_frame(re, ed, w, h) && in_frame(le, ed, w, h)) {
                return ShearSample {
                    image: path.display().to_string(),
                    face: i,
                    true_k: k,
                    local_k,
                    eye_distance: ed,
                    true_blur,
                    cut: true,
                    millis,
                    ..Default::default()
                };
            }
            let mut hits = found
                .iter()
                .filter(|f| f.face_box.contains(re) && f.face_box.contains(le));
            let hit = hits.next();
            let duplicates = hits.filter(|f| f.report.is_some()).count();
            let report = hit.and_then(|f| f.report.as_ref());
            let oracle = f.nose.and_then(|n| {
                let n = moved(n);
                let mid = re.midpoint(le);
                let dy = n.y - mid.y;
                (dy > 1.0).then(|| (n.x - mid.x) / dy)
            });
            ShearSample {
                image: path.display().to_string(),
                face: i,
                true_k: k,
                local_k,
                eye_distance: ed,
                true_blur,
                blur: blur_at(re.midpoint(le).y),
                cut: false,
                detected: hit.is_some(),
                duplicates,
                estimate: report.and_then(|d| d.k),
                measured: report.map(|d| d.k_measured),
                confidence: report.map(|d| d.confidence),
                roll_degrees: report.map(|d| d.roll_degrees),
                reading: report.map(Reading::of).unwrap_or_default(),
                face_score: report.and_then(|d| d.face_score),
                eye_error: report
                    .map(|d| d.right_eye.distance(re).max(d.left_eye.distance(le)) / ed),
                eye_offsets: report.map(|d| {
                    [
                        (d.right_eye.x - re.x) / ed,
                        (d.right_eye.y - re.y) / ed,
                        (d.left_eye.x - le.x) / ed,
                        (d.left_eye.y - le.y) / ed,
                    ]
                }),
                mouth_offset: report.and_then(|d| {
                    let (m, truth) = (d.mouth?, moved(f.mouth?));
                    Some([(m.x - truth.x) / ed, (m.y - truth.y) / ed])
                }),
                oracle,
                image_k: image_k_at(re.midpoint(le).y),
                image_k_one,
                bent: rows.is_some(),
                refused: report.and_then(|d| d.refused.map(|r| r.name().to_string())),
                box_outside: report
                    .map(|d| box_outside_share(d.face_box, sheared.width(), sheared.height())),
                layout: report.and_then(|d| {
                    let l = face_layout(
                        d.right_eye,
                        d.left_eye,
                        d.nose_tip?,
                        d.mouth?,
                        d.k_measured,
                        d.roll_degrees.to_radians(),
                    )?;
                    Some([l.nose.x, l.nose.y, l.mouth.x, l.mouth.y])
                }),
                millis,
            }
        })
        .collect();
    Ok((samples, unmatched))
}

/// The crop `(x, y, width, height)` holding `context` nominal face boxes around every face of
/// one image, or `None` for the whole image (`context <= 0`, or the crop would be the image).
///
/// The nominal face box is what a frontal detector reports for eyes `d` apart: about `2 d`
/// wide and high, centred `0.4 d` below the eye midpoint.
pub fn context_crop(
    faces: &[AnnotatedFace],
    width: u32,
    height: u32,
    context: f64,
) -> Option<(u32, u32, u32, u32)> {
    let faces: Vec<(Point, f64)> = faces
        .iter()
        .map(|f| (f.right_eye.midpoint(f.left_eye), f.eye_distance()))
        .collect();
    let [x0, y0, x1, y1] = context_bounds(&faces, context, |p| p)?;
    let cx0 = x0.floor().max(0.0) as u32;
    let cy0 = y0.floor().max(0.0) as u32;
    let cx1 = (x1.ceil().max(0.0) as u32).min(width);
    let cy1 = (y1.ceil().max(0.0) as u32).min(height);
    if cx1 <= cx0 || cy1 <= cy0 || (cx0, cy0, cx1, cy1) == (0, 0, width, height) {
        return None;
    }
    Some((cx0, cy0, cx1 - cx0, cy1 - cy0))
}

/// The bounds `[x0, y0, x1, y1]` of `context` nominal face boxes around each of `faces` (eyes'
/// midpoint and eye distance), the midpoints moved by `at`, unclipped; `None` for
/// `context <= 0` or no faces.
fn context_bounds(
    faces: &[(Point, f64)],
    context: f64,
    at: impl Fn(Point) -> Point,
) -> Option<[f64; 4]> {
    if context.is_nan() || context <= 0.0 || faces.is_empty() {
        return None;
    }
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for &(mid, d) in faces {
        let c = at(mid);
        let half = context * d; // half of `context` boxes of side 2 d
        x0 = x0.min(c.x - half);
        x1 = x1.max(c.x + half);
        y0 = y0.min(c.y + 0.4 * d - half);
        y1 = y1.max(c.y + 0.4 * d + half);
    }
    Some([x0, y0, x1, y1])
}

impl ShearSample {
    /// How far the accepted estimate is from the shear at the face ([`Self::local_k`]).
    pub fn error(&self) -> Option<f64> {
        self.estimate.map(|e| (e - self.local_k).abs())
    }
}

impl ShearEvalResult {
    /// The scored samples of one shear (the faces the frame cut left out).
    fn at(&self, k: f64) -> Vec<&ShearSample> {
        self.samples
            .iter()
            .filter(|s| s.true_k == k && !s.cut)
            .collect()
    }

    /// The summary as Markdown tables.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let first = self.shears.first().copied().unwrap_or(0.0);
        let faces = self.samples.iter().filter(|s| s.true_k == first).count();
        let _ = writeln!(
            s,
            "Faces: {faces}; unreadable images: {}\n",
            self.unreadable.len()
        );
        let _ = writeln!(
            s,
            "| true k | faces | detected | estimated | median k | median abs err | mean abs err | within 0.02 | within 0.05 | tracking median abs err | oracle median abs err |"
        );
        let _ = writeln!(
            s,
            "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
        );
        let zero: Vec<&ShearSample> = self.at(0.0);
        for &k in &self.shears {
            let at = self.at(k);
            let n = at.len();
            let est: Vec<f64> = at.iter().filter_map(|s| s.estimate).collect();
            let err: Vec<f64> = at.iter().filter_map(|s| s.error()).collect();
            // Tracking: estimate at k minus the same face's estimate at 0, minus k.
            let tracking: Vec<f64> = at
                .iter()
                .filter_map(|s| {
                    let z = zero
                        .iter()
                        .find(|z| z.image == s.image && z.face == s.face)?;
                    Some((s.estimate? - z.estimate? - (s.local_k - z.local_k)).abs())
                })
                .collect();
            let oracle: Vec<f64> = at
                .iter()
                .filter_map(|s| s.oracle.map(|o| (o - s.local_k).abs()))
                .collect();
            let _ = writeln!(
                s,
                "| {k:+.2} | {n} | {:.1}% | {:.1}% | {} | {} | {} | {:.1}% | {:.1}% | {} | {} |",
                pct(at.iter().filter(|s| s.detected).count(), n),
                pct(est.len(), n),
                fmt3(median(est.clone())),
                fmt3(median(err.clone())),
                fmt3(mean(&err)),
                pct(err.iter().filter(|&&e| e <= 0.02).count(), n),
                pct(err.iter().filter(|&&e| e <= 0.05).count(), n),
                fmt3(median(tracking)),
                fmt3(median(oracle)),
            );
        }
        self.cut_tables(&mut s);
        let _ = writeln!(
            s,
            "\nEye localisation per shear (worst eye / eye distance; share of all faces at that k, misses count as failures):\n\n| true k | median eye error | <= 0.05 | <= 0.10 | <= 0.25 |\n|---:|---:|---:|---:|---:|"
        );
        for &k in &self.shears {
            let at = self.at(k);
            let e: Vec<f64> = at.iter().filter_map(|s| s.eye_error).collect();
            let share = |t: f64| pct(e.iter().filter(|&&x| x <= t).count(), at.len());
            let _ = writeln!(
                s,
                "| {k:+.2} | {} | {:.1}% | {:.1}% | {:.1}% |",
                fmt3(median(e.clone())),
                share(0.05),
                share(0.10),
                share(0.25)
            );
        }
        let _ = writeln!(
            s,
            "\nConfidence and refusal per shear (*measured*: faces with an estimate, refused or not; *refused*: below the confidence threshold, reported as `k: null`; *wrong but accepted*: accepted estimates more than 0.10 off; *tracking slope*: median over faces of (measured at k - measured at 0) / k):\n\n| true k | measured | refused | accepted within 0.05 | wrong but accepted | tracking slope |\n|---:|---:|---:|---:|---:|---:|"
        );
        for &k in &self.shears {
            let at = self.at(k);
            let measured = at.iter().filter(|s| s.measured.is_some()).count();
            let refused = at
                .iter()
                .filter(|s| s.measured.is_some() && s.estimate.is_none())
                .count();
            let accepted_err: Vec<f64> = at.iter().filter_map(|s| s.error()).collect();
            let slope = (k != 0.0).then(|| {
                median(
                    at.iter()
                        .filter_map(|s| {
                            let z = zero
                                .iter()
                                .find(|z| z.image == s.image && z.face == s.face)?;
                            Some((s.measured? - z.measured?) / (s.local_k - z.local_k))
                        })
                        .collect(),
                )
            });
            let _ = writeln!(
                s,
                "| {k:+.2} | {measured} | {refused} | {} | {} | {} |",
                accepted_err.iter().filter(|&&e| e <= 0.05).count(),
                accepted_err.iter().filter(|&&e| e > 0.10).count(),
                slope.flatten().map_or("-".into(), |v| format!("{v:.3}")),
            );
        }
        let _ = writeln!(
            s,
            "\nGross errors per shear (*accepted*: faces with an accepted estimate; *gross errors*: accepted estimates more than {GROSS_ERROR} from the true k, which a correction would make worse than no correction; *refused by rule*: estimates refused as implausible, outside the image or not face-like rather than for low confidence):\n\n| true k | faces | accepted | within 0.05 | gross errors | refused by rule |\n|---:|---:|---:|---:|---:|---:|"
        );
        for &k in &self.shears {
            let at = self.at(k);
            let accepted: Vec<f64> = at.iter().filter_map(|s| s.error()).collect();
            let ruled = at
                .iter()
                .filter(|s| s.refused.as_deref().is_some_and(|r| r != "low_confidence"))
                .count();
            let _ = writeln!(
                s,
                "| {k:+.2} | {} | {} | {} | {} | {ruled} |",
                at.len(),
                accepted.len(),
                accepted.iter().filter(|&&e| e <= 0.05).count(),
                accepted.iter().filter(|&&e| e > GROSS_ERROR).count(),
            );
        }
        let photos = {
            let mut images: Vec<&str> = self.samples.iter().map(|s| s.image.as_str()).collect();
            images.sort_unstable();
            images.dedup();
            images.len()
        };
        let _ = writeln!(
            s,
            "\nDetections matching no annotated face per shear (no annotated face, small ones included, has both eyes in the box; the data set does not annotate every face, so each is a false face or an unannotated real one: an upper bound on false faces; *accepted*: with an accepted estimate; *duplicates*: further reported faces whose boxes hold both eyes of an evaluated face already found, the same face reported twice; *per 100 photos*: unmatched and accepted per 100 of the {photos} photos):\n\n| true k | unmatched | accepted | images with one | duplicates | per 100 photos |\n|---:|---:|---:|---:|---:|---:|"
        );
        for &k in &self.shears {
            let at: Vec<&UnmatchedDetection> =
                self.unmatched.iter().filter(|u| u.true_k == k).collect();
            let mut images: Vec<&str> = at.iter().map(|u| u.image.as_str()).collect();
            images.sort_unstable();
            images.dedup();
            let accepted = at.iter().filter(|u| u.accepted).count();
            let per_100 = |n: usize| 100.0 * n as f64 / photos.max(1) as f64;
            let _ = writeln!(
                s,
                "| {k:+.2} | {} | {accepted} | {} | {} | {:.1} ({:.1}) |",
                at.len(),
                images.len(),
                self.at(k).iter().map(|s| s.duplicates).sum::<usize>(),
                per_100(at.len()),
                per_100(accepted),
            );
        }
        if !self.face_free.is_empty() {
            let n = self.face_free.len();
            let with = |f: &dyn Fn(&FaceFreeSample) -> bool| {
                self.face_free.iter().filter(|s| f(s)).count()
            };
            let accepted = with(&|s| s.accepted > 0);
            let _ = writeln!(
                s,
                "\nFace-free photos (each whole photo once, unsheared, its annotated faces, and those listed with `--unannotated`, painted over with its mean colour, `eval::shear::face_free`; faces left out of both stay, so these bound false faces from above):\n\n| photos | with a reported face | with an accepted face | without an accepted face | with an accepted shear |\n|---:|---:|---:|---:|---:|\n| {n} | {} | {accepted} | {:.1}% | {} |",
                with(&|s| s.faces > 0),
                100.0 - pct(accepted, n),
                with(&|s| s.k.is_some()),
            );
        }
        let located: Vec<f64> = self.samples.iter().filter_map(|s| s.eye_error).collect();
        let all = self.samples.iter().filter(|s| !s.cut).count();
        let _ = writeln!(
            s,
            "\nEye localisation over all shears (worst eye, fraction of the eye distance; of all {all} samples): <= 0.05: {:.1}%, <= 0.10: {:.1}%, <= 0.25: {:.1}%",
            pct(located.iter().filter(|&&e| e <= 0.05).count(), all),
            pct(located.iter().filter(|&&e| e <= 0.10).count(), all),
            pct(located.iter().filter(|&&e| e <= 0.25).count(), all),
        );
        self.blur_line(&mut s);
        self.rows_line(&mut s);
        let mut times: Vec<f64> = self.samples.iter().map(|s| s.millis).collect();
        times.sort_by(f64::total_cmp);
        if let Some(m) = median(times) {
            let _ = writeln!(
                s,
                "Median wall time per image (detection + estimate, measured inside the parallel run): {m:.1} ms"
            );
        }
        s
    }

    /// The blur made (camera-like frames) and found (`deblur`) at the scored faces; nothing
    /// when neither.
    fn blur_line(&self, s: &mut String) {
        let scored: Vec<&ShearSample> = self.samples.iter().filter(|s| !s.cut).collect();
        let made: Vec<f64> = scored.iter().filter_map(|s| s.true_blur).collect();
        let found: Vec<f64> = scored.iter().filter_map(|s| s.blur).collect();
        if made.is_empty() && found.is_empty() {
            return;
        }
        // Of the faces with a blur of at least 4 px (the smallest `blur_length` looks for),
        // the share whose frame gave a length, and its error against the blur at the eyes.
        let blurred: Vec<&&ShearSample> = scored
            .iter()
            .filter(|s| s.true_blur.is_some_and(|b| b >= 4.0))
            .collect();
        let errors: Vec<f64> = blurred
            .iter()
            .filter_map(|s| Some((s.blur? - s.true_blur?).abs() / s.true_blur?))
            .collect();
        let _ = writeln!(
            s,
            "Motion blur: made at the faces' eyes, median {} px (max {}); found in {} of {} frames with at least 4 px at the face ({:.1}%), median relative error {}; found in {} frames in all",
            fmt3(median(made.clone())),
            fmt3(made.iter().copied().reduce(f64::max)),
            errors.len(),
            blurred.len(),
            pct(errors.len(), blurred.len()),
            fmt3(median(errors)),
            found.len(),
        );
    }

    /// How the image's correction fares at its faces where faces at different heights bend the
    /// rows' offsets ([`crate::RowShear`]), against one shear for the whole image; nothing when
    /// no image bent.
    fn rows_line(&self, s: &mut String) {
        let bent: Vec<&ShearSample> = self
            .samples
            .iter()
            .filter(|s| s.bent && !s.cut && s.detected)
            .collect();
        if bent.is_empty() {
            return;
        }
        let images: std::collections::BTreeSet<(&str, u64)> = bent
            .iter()
            .map(|s| (s.image.as_str(), s.true_k.to_bits()))
            .collect();
        type Pick = fn(&ShearSample) -> Option<f64>;
        let within = |pick: Pick| {
            bent.iter()
                .filter(|s| pick(s).is_some_and(|k| (k - s.local_k).abs() <= 0.05))
                .count()
        };
        let errors = |pick: Pick| {
            median(
                bent.iter()
                    .filter_map(|s| Some((pick(s)? - s.local_k).abs()))
                    .collect(),
            )
        };
        let (bent_k, one_k): (Pick, Pick) = (|s| s.image_k, |s| s.image_k_one);
        let _ = writeln!(
            s,
            "Shear changing down the rows: {} of {} frames bent (faces at different heights disagreeing); at their {} found faces the correction's shear is within 0.05 of the shear at the face for {} ({:.1}%, median error {}) bent, {} ({:.1}%, median error {}) with one shear for the frame",
            images.len(),
            self.samples
                .iter()
                .map(|s| (s.image.as_str(), s.true_k.to_bits()))
                .collect::<std::collections::BTreeSet<_>>()
                .len(),
            bent.len(),
            within(bent_k),
            pct(within(bent_k), bent.len()),
            fmt3(errors(bent_k)),
            within(one_k),
            pct(within(one_k), bent.len()),
            fmt3(errors(one_k)),
        );
    }

    /// The faces the frame cut per shear, and how the faces in the frame at every shear fared
    /// (the same faces at every shear, so the rows compare); nothing when no face was cut.
    fn cut_tables(&self, s: &mut String) {
        let cut = |k: f64| {
            self.samples
                .iter()
                .filter(|s| s.true_k == k && s.cut)
                .count()
        };
        if self.shears.iter().all(|&k| cut(k) == 0) {
            return;
        }
        let _ = writeln!(
            s,
            "\nFaces the frame cut (an eye outside the frame the camera delivers, or within {FRAME_MARGIN} eye distances of its edge): left out of every table here, not counted as missed:\n\n| true k | in the frame | cut |\n|---:|---:|---:|"
        );
        for &k in &self.shears {
            let _ = writeln!(s, "| {k:+.2} | {} | {} |", self.at(k).len(), cut(k));
        }
        let mut everywhere: Vec<(&str, usize)> = self
            .samples
            .iter()
            .filter(|s| s.cut)
            .map(|s| (s.image.as_str(), s.face))
            .collect();
        everywhere.sort_unstable();
        everywhere.dedup();
        let same = |k: f64| -> Vec<&ShearSample> {
            self.at(k)
                .into_iter()
                .filter(|s| {
                    everywhere
                        .binary_search(&(s.image.as_str(), s.face))
                        .is_err()
                })
                .collect()
        };
        let n = same(self.shears[0]).len();
        let _ = writeln!(
            s,
            "\nThe {n} faces in the frame at every shear (*wrong*: accepted estimates more than 0.10 off):\n\n| true k | detected | within 0.05 | wrong |\n|---:|---:|---:|---:|"
        );
        for &k in &self.shears {
            let at = same(k);
            let _ = writeln!(
                s,
                "| {k:+.2} | {} | {} | {} |",
                at.iter().filter(|s| s.detected).count(),
                at.iter()
                    .filter(|s| s.error().is_some_and(|e| e <= 0.05))
                    .count(),
                at.iter()
                    .filter(|s| s.error().is_some_and(|e| e > 0.10))
                    .count(),
            );
        }
    }

    /// Every sample as a JSON array.
    pub fn json(&self) -> String {
        serde_json::to_string_pretty(&self.samples).unwrap_or_else(|_| "[]".into())
    }

    /// Writes `samples.csv`, `samples.json`, `unmatched.csv` (see [`Self::unmatched_csv`]) and
    /// `unmatched.json` (every field, with what the pipeline read),
    /// `face_free.csv` and `face_free.json` (with [`ShearEvalOptions::face_free`]: image, faces,
    /// accepted, k; the JSON also every face found),
    /// `summary.md`, `estimates.png` (estimated vs true k) and `errors.png` (estimate-error
    /// histograms per k) into `dir` (created if needed).
    pub fn write_outputs(&self, dir: &Path) -> Result<()> {
        let io = |path: &Path, e: std::io::Error| Error::Io {
            path: path.to_path_buf(),
            source: e,
        };
        std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
        let write = |name: &str, text: String| {
            let path = dir.join(name);
            std::fs::write(&path, text).map_err(|e| io(&path, e))
        };
        write("samples.csv", self.csv())?;
        write("samples.json", self.json())?;
        write("unmatched.csv", self.unmatched_csv())?;
        write(
            "unmatched.json",
            serde_json::to_string_pretty(&self.unmatched).unwrap_or_else(|_| "[]".into()),
        )?;
        if !self.face_free.is_empty() {
            let mut csv = String::from("image,faces,accepted,k\n");
            for f in &self.face_free {
                let k = f.k.map_or(String::new(), |k| format!("{k:.5}"));
                let _ = writeln!(csv, "{},{},{},{k}", f.image, f.faces, f.accepted);
            }
            write("face_free.csv", csv)?;
            write(
                "face_free.json",
                serde_json::to_string_pretty(&self.face_free).unwrap_or_else(|_| "[]".into()),
            )?;
        }
        let mut md = self.markdown();
        let _ = write!(
            md,
            "\n## Plots\n\n* `estimates.png`: estimated k (vertical) against true k (horizontal, jittered by up to +-0.012 so each column shows its spread), both from -0.6 to 0.6, grid every 0.1, red identity line; one dot per estimate.\n* `errors.png`: one panel per true k, in the order {:?}, top to bottom: histogram of estimate - true k from -0.2 to 0.2 in 0.01 bins (grid every 0.05, red line at zero); bar height is the share of that k's estimates, a full panel being 50%.\n",
            self.shears
        );
        write("summary.md", md)?;
        let points: Vec<(f64, f64)> = self
            .samples
            .iter()
            .filter_map(|s| Some((s.local_k, s.estimate?)))
            .collect();
        let save = |name: &str, img: image::RgbImage| {
            let path = dir.join(name);
            img.save(&path)
                .map_err(|e| io(&path, std::io::Error::other(e.to_string())))
        };
        save(
            "estimates.png",
            super::plot::scatter_estimates(&points, 0.6),
        )?;
        let groups: Vec<Vec<f64>> = self
            .shears
            .iter()
            .map(|&k| {
                self.at(k)
                    .iter()
                    .filter_map(|s| Some(s.estimate? - s.local_k))
                    .collect()
            })
            .collect();
        save(
            "errors.png",
            super::plot::error_histograms(&groups, 0.2, 40, 0.5),
        )?;
        Ok(())
    }

    /// The detections matching no annotated face as CSV, one per line: image, true k, box
    /// centre in the original image (x, y), box width, measured k, accepted, roll (degrees),
    /// confidence, face score.
    pub fn unmatched_csv(&self) -> String {
        let mut s = String::from(
            "image,true_k,centre_x,centre_y,width,measured,accepted,roll_degrees,confidence,face_score\n",
        );
        for u in &self.unmatched {
            let _ = writeln!(
                s,
                "{},{},{:.1},{:.1},{:.1},{:.5},{},{:.2},{:.4},{}",
                u.image,
                u.true_k,
                u.centre[0],
                u.centre[1],
                u.width,
                u.measured,
                u.accepted,
                u.roll_degrees,
                u.confidence,
                u.face_score.map_or(String::new(), |f| format!("{f:.4}"))
            );
        }
        s
    }

    /// Every sample as CSV.
    pub fn csv(&self) -> String {
        let mut s = String::from(
            "image,face,true_k,eye_distance,detected,estimate,eye_error,oracle,millis,measured,confidence,refused,gross_error,cut\n",
        );
        let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.5}"));
        for x in &self.samples {
            let _ = writeln!(
                s,
                "{},{},{},{:.2},{},{},{},{},{:.2},{},{},{},{},{}",
                x.image,
                x.face,
                x.true_k,
                x.eye_distance,
                x.detected,
                opt(x.estimate),
                opt(x.eye_error),
                opt(x.oracle),
                x.millis,
                opt(x.measured),
                opt(x.confidence),
                x.refused.as_deref().unwrap_or(""),
                x.estimate
                    .is_some_and(|e| (e - x.local_k).abs() > GROSS_ERROR),
                x.cut
            );
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(k: f64, face: usize, estimate: Option<f64>) -> ShearSample {
        ShearSample {
            image: "a".into(),
            face,
            true_k: k,
            local_k: k,
            eye_distance: 50.0,
            detected: estimate.is_some(),
            estimate,
            measured: estimate,
            eye_error: estimate.map(|_| 0.04),
            oracle: Some(k),
            millis: 1.0,
            ..Default::default()
        }
    }

    #[test]
    fn table_reports_known_values() {
        let r = ShearEvalResult {
            samples: vec![
                ShearSample {
                    duplicates: 1,
                    ..sample(0.0, 0, Some(0.01))
                },
                sample(0.0, 1, Some(-0.03)),
                sample(0.2, 0, Some(0.22)),
                sample(0.2, 1, None),
            ],
            shears: vec![0.0, 0.2],
            unreadable: vec![],
            // Two unmatched boxes at k = 0.2 in one image, one of them accepted.
            unmatched: vec![
                UnmatchedDetection {
                    image: "b".into(),
                    true_k: 0.2,
                    accepted: true,
                    ..Default::default()
                },
                UnmatchedDetection {
                    image: "b".into(),
                    true_k: 0.2,
                    ..Default::default()
                },
            ],
            // Four face-free photos: one with a refused face, one with an accepted one.
            face_free: vec![
                FaceFreeSample::default(),
                FaceFreeSample {
                    faces: 1,
                    ..Default::default()
                },
                FaceFreeSample {
                    faces: 2,
                    accepted: 1,
                    k: Some(0.3),
                    ..Default::default()
                },
                FaceFreeSample::default(),
            ],
        };
        assert!(r.json().contains("\"true_k\": 0.2"));
        let md = r.markdown();
        // k = 0: both detected, errors 0.01 and 0.03: median 0.02, all within 0.05, half within 0.02.
        assert!(md.contains("| +0.00 | 2 | 100.0% | 100.0% | -0.010 | 0.020 | 0.020 | 50.0% | 100.0% | 0.000 | 0.000 |"), "{md}");
        // k = 0.2: one of two detected; tracking 0.22 - 0.01 - 0.2 = 0.01.
        assert!(md.contains("| +0.20 | 2 | 50.0% | 50.0% | 0.220 | 0.020 | 0.020 | 50.0% | 50.0% | 0.010 | 0.000 |"), "{md}");
        assert!(md.contains("<= 0.05: 75.0%"), "{md}");
        // One photo ("a") evaluated: two unmatched per 100 photos is 200.
        assert!(md.contains("| +0.00 | 0 | 0 | 0 | 1 | 0.0 (0.0) |"), "{md}");
        assert!(
            md.contains("| +0.20 | 2 | 1 | 1 | 0 | 200.0 (100.0) |"),
            "{md}"
        );
        assert!(md.contains("| 4 | 2 | 1 | 75.0% | 1 |"), "{md}");
        assert_eq!(r.csv().lines().count(), 5);
        assert_eq!(r.unmatched_csv().lines().count(), 3);
    }
}

#[cfg(test)]
mod protocol_tests {
    use super::*;
    use std::path::PathBuf;

    /// The painted rectangle covers the face's extent around the eyes with the mean colour and
    /// leaves the rest of the photo as it was.
    #[test]
    fn face_free_paints_the_face_and_nothing_else() {
        let img = image::RgbImage::from_fn(200, 200, |x, _| image::Rgb([(x % 2 * 200) as u8; 3]));
        let f = face(80.0, 80.0, 20.0);
        let out = face_free(&image::DynamicImage::ImageRgb8(img.clone()), &[&f]);
        // Mean of alternating 0 and 200 columns.
        let mean = image::Rgb([100u8; 3]);
        // Eyes' midpoint (90, 80), eye distance 20: x 54..126, y 44..128.
        for (x, y) in [(55, 45), (125, 127), (90, 80), (90, 120)] {
            assert_eq!(*out.get_pixel(x, y), mean, "({x}, {y})");
        }
        for (x, y) in [(52, 80), (128, 80), (90, 42), (90, 130), (0, 0)] {
            assert_eq!(out.get_pixel(x, y), img.get_pixel(x, y), "({x}, {y})");
        }
    }

    fn face(x: f64, y: f64, d: f64) -> AnnotatedFace {
        AnnotatedFace {
            image: PathBuf::from("a"),
            right_eye: Point::new(x, y),
            left_eye: Point::new(x + d, y),
            nose: Some(Point::new(x + d / 2.0, y + d / 2.0)),
            mouth: None,
        }
    }

    #[test]
    fn perfect_estimator_scores_zero_error() {
        let shears = vec![0.0, -0.2, 0.33];
        let samples = shears
            .iter()
            .flat_map(|&k| {
                (0..3).map(move |f| ShearSample {
                    image: "a".into(),
                    face: f,
                    true_k: k,
                    local_k: k,
                    eye_distance: 40.0,
                    detected: true,
                    estimate: Some(k),
                    measured: Some(k),
                    eye_error: Some(0.0),
                    oracle: Some(k),
                    millis: 1.0,
                    ..Default::default()
                })
            })
            .collect();
        let r = ShearEvalResult {
            samples,
            shears,
            unreadable: vec![],
            unmatched: vec![],
            face_free: vec![],
        };
        let md = r.markdown();
        for row in [
            "| +0.00 | 3 | 100.0% | 100.0% | 0.000 | 0.000 | 0.000 | 100.0% | 100.0% | 0.000 | 0.000 |",
            "| -0.20 | 3 | 100.0% | 100.0% | -0.200 | 0.000 | 0.000 | 100.0% | 100.0% | 0.000 | 0.000 |",
            "| +0.33 | 3 | 100.0% | 100.0% | 0.330 | 0.000 | 0.000 | 100.0% | 100.0% | 0.000 | 0.000 |",
        ] {
            assert!(md.contains(row), "{row}\n{md}");
        }
        let dir = tempfile::tempdir().expect("tempdir");
        r.write_outputs(dir.path()).expect("outputs");
        for f in [
            "samples.csv",
            "samples.json",
            "unmatched.csv",
            "unmatched.json",
            "summary.md",
            "estimates.png",
            "errors.png",
        ] {
            assert!(dir.path().join(f).is_file(), "{f}");
        }
    }

    #[test]
    fn readings_are_flat_fields_of_the_json() {
        // scripts/fit_confidence.py reads the confidence models' inputs as top-level keys.
        let reading = Reading {
            spread: Some([0.2, 0.2, 0.3, 0.3]),
            located_eye_distance: Some(41.0),
            ..Default::default()
        };
        let sample = ShearSample {
            reading: reading.clone(),
            ..Default::default()
        };
        let unmatched = UnmatchedDetection {
            reading,
            refused: Some("low_confidence".into()),
            ..Default::default()
        };
        for json in [
            serde_json::to_value(&sample).expect("serializes"),
            serde_json::to_value(&unmatched).expect("serializes"),
        ] {
            assert_eq!(json["located_eye_distance"], 41.0);
            assert_eq!(json["spread"][2], 0.3);
            assert!(json["k_points"].is_null());
        }
    }

    /// A 100 x 50 photo sheared by 0.4 about its middle row (25) shifts its first row by -10 and
    /// its last by +9.6: the camera's frame keeps the frame columns 10..=89 of every row.
    #[test]
    fn camera_window_keeps_the_columns_every_row_covers() {
        let (shear, at, w, h) = camera_window(&[], 100, 50, 0.4, 3.0).expect("a window");
        assert_eq!((shear.k, shear.pivot_y), (0.4, 25.0));
        assert_eq!((at.offset_x, at.offset_y, w, h), (10.0, 0.0, 80, 50));
        // An eye on the pivot row keeps its column; 20 rows below it moves 8 px right.
        let moved = |p: Point| at.from_frame(shear.apply(p));
        assert_eq!(moved(Point::new(50.0, 25.0)), Point::new(40.0, 25.0));
        assert_eq!(moved(Point::new(50.0, 45.0)), Point::new(48.0, 45.0));
        // Negative k: the same width, the other way round.
        let (_, at, w, _) = camera_window(&[], 100, 50, -0.4, 0.0).expect("a window");
        assert_eq!((at.offset_x, w), (10.0, 80));
        // Unsheared, the whole photo; sheared past its width, nothing.
        let (_, at, w, h) = camera_window(&[], 100, 50, 0.0, 0.0).expect("a window");
        assert_eq!((at.offset_x, at.offset_y, w, h), (0.0, 0.0, 100, 50));
        assert!(camera_window(&[], 100, 50, 2.1, 0.0).is_none());
    }

    /// Around one face the window takes the rows of the context boxes (as `context_crop`) and
    /// their columns around the sheared face, within the columns those rows cover.
    #[test]
    fn camera_window_frames_the_sheared_face() {
        // Eyes 10 px apart, midpoint (105, 100): boxes rows 74..134, columns 75..135 at k = 0.
        let faces = [(Point::new(105.0, 100.0), 10.0)];
        let (shear, at, w, h) = camera_window(&faces, 1000, 1000, 0.0, 3.0).expect("window");
        assert_eq!((at.offset_x, at.offset_y, w, h), (75.0, 74.0, 60, 60));
        assert_eq!(shear.pivot_y, 104.0);
        // k = 0.5 about row 104 moves the midpoint 2 px left; rows 74..134 cover every column
        // from 15 (row 74 shifts by -15) to 984 (row 133 by +14.5): the boxes fit.
        let (shear, at, w, h) = camera_window(&faces, 1000, 1000, 0.5, 3.0).expect("window");
        assert_eq!((at.offset_x, at.offset_y, w, h), (73.0, 74.0, 60, 60));
        assert_eq!(
            shear.apply(Point::new(105.0, 100.0)),
            Point::new(103.0, 100.0)
        );
        // Near the photo's left edge the covered columns cut the boxes: from 15 on.
        let faces = [(Point::new(20.0, 100.0), 10.0)];
        let (_, at, w, _) = camera_window(&faces, 1000, 1000, 0.5, 3.0).expect("window");
        assert_eq!((at.offset_x, w), (15.0, 33));
    }

    /// The window is pixel for pixel the same part of the whole photo sheared on a widened
    /// canvas, and holds no empty (fill) pixel.
    #[test]
    fn sheared_window_matches_the_whole_sheared_photo() {
        let img = image::DynamicImage::ImageRgb8(image::RgbImage::from_fn(97, 61, |x, y| {
            image::Rgb([
                (x * 7 + y * 3) as u8 | 1,
                (x * y % 251) as u8 | 1,
                (x + 5 * y) as u8 | 1,
            ])
        }));
        let faces = [(Point::new(40.0, 30.0), 8.0)];
        for k in [0.0, 0.14, -0.33, 0.4, 0.5] {
            for context in [0.0, 1.5, 3.0] {
                let (shear, at, w, h) = camera_window(&faces, 97, 61, k, context).expect("window");
                let part = sheared_window(&img, shear, at, w, h).expect("window pixels");
                let (whole, whole_at) =
                    try_apply_shear(&img, shear, Interpolation::Linear, Canvas::Expand)
                        .expect("whole");
                let x = (at.offset_x - whole_at.offset_x) as u32;
                let y = at.offset_y as u32;
                let expected = whole.crop_imm(x, y, w, h).to_rgb8();
                let got = part.to_rgb8();
                assert_eq!(got.dimensions(), (w, h), "k = {k}, context {context}");
                assert_eq!(
                    got.as_raw(),
                    expected.as_raw(),
                    "k = {k}, context {context}"
                );
                // Every source pixel is odd in each channel, the fill is 0.
                assert!(got.pixels().all(|p| p.0.iter().all(|&c| c > 0)), "k = {k}");
            }
        }
    }

    /// A face the camera's frame cuts is counted apart, not as missed: it is in no row of the
    /// tables, while at k = 0 the same face is scored.
    #[test]
    fn a_face_the_frame_cuts_is_counted_apart() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("grey.png");
        image::GrayImage::from_pixel(200, 200, image::Luma([128]))
            .save(&path)
            .expect("saved");
        // Eyes 40 px apart, the right one 20 px from the left edge: inside the photo by half an
        // eye distance, but k = 0.4 about row 100 cuts the first 40 columns of every row.
        let f = AnnotatedFace {
            image: path.clone(),
            right_eye: Point::new(20.0, 100.0),
            left_eye: Point::new(60.0, 100.0),
            nose: None,
            mouth: None,
        };
        let options = ShearEvalOptions {
            shears: vec![0.0, 0.4],
            max_pixels: 1 << 24,
            also_annotated: vec![],
            face_free: false,
            roll_degrees: 0.0,
            canvas: EvalCanvas::Crop,
            camera: None,
            deblur: false,
        };
        let unshear = Unshear::new(crate::Config::default()).expect("built-in models");
        let r = evaluate_shear_in_context(&unshear, &[f], &options, 3.0, || {});
        assert!(r.unreadable.is_empty(), "{:?}", r.unreadable);
        let at = |k: f64| r.samples.iter().find(|s| s.true_k == k).expect("sample");
        assert!(!at(0.0).cut);
        assert!(at(0.4).cut && !at(0.4).detected);
        let md = r.markdown();
        assert!(md.starts_with("Faces: 1;"), "{md}");
        // The cut table: in the frame, cut.
        assert!(md.contains("| +0.00 | 1 | 0 |"), "{md}");
        assert!(md.contains("| +0.40 | 0 | 1 |"), "{md}");
        assert!(
            md.contains("The 0 faces in the frame at every shear"),
            "{md}"
        );
        // On the widened canvas nothing is cut.
        let options = ShearEvalOptions {
            canvas: EvalCanvas::Expand,
            ..options
        };
        let f = AnnotatedFace {
            image: path,
            right_eye: Point::new(20.0, 100.0),
            left_eye: Point::new(60.0, 100.0),
            nose: None,
            mouth: None,
        };
        let r = evaluate_shear_in_context(&unshear, std::slice::from_ref(&f), &options, 3.0, || {});
        assert!(r.samples.iter().all(|s| !s.cut));
        // A camera-like frame scores each face against the shear at its eyes' row: here above
        // the frame's middle row (one nominal face box around the eyes reaches further below
        // them than above), where a speeding pan shears less than at the middle.
        let options = ShearEvalOptions {
            canvas: EvalCanvas::Crop,
            camera: Some(CameraLike::default()),
            ..options
        };
        let r = evaluate_shear_in_context(&unshear, &[f], &options, 1.0, || {});
        assert!(r.unreadable.is_empty(), "{:?}", r.unreadable);
        let at = |k: f64| r.samples.iter().find(|s| s.true_k == k).expect("sample");
        assert_eq!(at(0.0).local_k, 0.0);
        let local = at(0.4).local_k;
        assert!(local > 0.4 * 0.8 && local < 0.4, "{local}");
    }

    #[test]
    fn context_crop_known_values() {
        // Eyes 10 px apart at (100, 100): nominal box centre (105, 104); context 3: +-30 px.
        let f = face(100.0, 100.0, 10.0);
        assert_eq!(
            context_crop(std::slice::from_ref(&f), 1000, 1000, 3.0),
            Some((75, 74, 60, 60))
        );
        // Clipped at the image border; whole image or no context: None.
        assert_eq!(
            context_crop(std::slice::from_ref(&f), 120, 1000, 3.0),
            Some((75, 74, 45, 60))
        );
        assert_eq!(
            context_crop(std::slice::from_ref(&f), 1000, 1000, 0.0),
            None
        );
        assert_eq!(context_crop(&[f], 50, 50, 100.0), None);
    }
}
