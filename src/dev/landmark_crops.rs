//! Training crops for the landmark network: each annotated face cut many times through a crop
//! frame whose placement, scale, shear and roll are drawn at random around what the pipeline
//! will ask for, with the annotated points and the crop's shear as labels.
//!
//! The crops are cut with the same code the run-time locator uses
//! ([`crate::locate::network::CropFrame::render`]), so the network is trained on exactly what it will see. The
//! distributions:
//!
//! * **placement**: the frame is built around the annotated eyes ([`frame_around_eyes`]) with
//!   the eyes' midpoint moved by a normal offset of [`CENTRE_JITTER`] eye distances (std) each
//!   way, and the eye distance scaled by `exp(N(0, SCALE_JITTER))`: the first search starts
//!   from a detector's box, whose eyes lie about 0.07-0.09 eye distances (std) from where the
//!   box predicts them and whose size varies by about 9% (`features::RIGHT_EYE_IN_BOX`,
//!   `features::EYE_DISTANCE_PER_BOX_WIDTH`); later searches start from located eyes;
//! * **shear**: half of the crops are cut from the photo sheared as a rolling shutter would
//!   shear it (by a shear drawn uniformly from `+-PHOTO_SHEAR` per image, in the rectangle a
//!   camera delivers: no empty corner whose slanted edge would give the shear away), half from
//!   the photo as it is (all of a face's crops from the photo as it is when the sheared copy's
//!   frame cuts one of its eyes away); the crop then removes that shear
//!   less a residual, which the face shows in the crop: drawn uniformly from `+-WIDE_SHEAR`
//!   for half of the crops (the first search, in a view up to about 0.3 from the face's
//!   shear), with std [`NARROW_SHEAR`] for the others (later searches, in the view the
//!   estimate de-sheared). Shearing the photo itself teaches the network what a sheared
//!   image's pixels look like after the crop removes the shear (its pixel grid and blur
//!   stay in the image's axes), as it will see them at run time;
//! * **roll**: half of the crops are not turned (the first search: the head's own roll shows),
//!   half are turned by the head's roll (the eye line's angle) plus a normal error of
//!   [`ROLL_JITTER`] radians.
//!
//! **Shear-only faces.** Shear is its own label: any upright face photo, sheared by a known
//! `k`, teaches the shear head. Besides the Caltech faces, [`export_crops_with_extra`] cuts
//! crops of *extra* faces whose points are pseudo-labels (found by the pipeline itself on the
//! photo as it is, [`extra_faces`]), the photo taken as unsheared. Their crops are cut exactly as
//! the Caltech faces' (same distributions), marked `shear_only` (label field 13), and the
//! trainer learns only the shear and the face score from them, never the points. Their face
//! indices start at [`EXTRA_FACE_INDEX`]; their photos give no non-face crops, and the
//! Caltech rule that skips photos holding a face 40 px or more apart does not apply to them
//! (it only keeps the Caltech accuracy tables' photos out of training; the extra photos are in
//! no table).
//!
//! Mirror images are left to the trainer (the crop is symmetric about its vertical mid-line, so
//! flipping a crop is the crop of the flipped photo).
//!
//! Deterministic: each face draws from its own generator, seeded from its index in the data
//! set, and the crops are written in data-set order.

use std::io::Write;

use rayon::prelude::*;

use crate::dev::dataset::AnnotatedFace;
use crate::dev::eval::shear::{camera_window, sheared_window};
use crate::error::{Error, Result};
use crate::geometry::{Point, Shear};
use crate::imageio;
use crate::locate::network::{
    crop_shear, frame_around_eyes, CROP_EYE_DISTANCES, CROP_SIZE, EYES_ABOVE_CENTRE,
};
use crate::rng::SplitMix64;
use crate::warp::Placement;

/// Std of the eyes' midpoint's offset from where the crop expects it, eye distances, each axis.
pub const CENTRE_JITTER: f64 = 0.08;
/// Std of the log of the eye distance's scale error.
pub const SCALE_JITTER: f64 = 0.09;
/// Half-range of the residual shear of half of the crops.
pub const WIDE_SHEAR: f64 = 0.35;
/// Std of the residual shear of the other half.
pub const NARROW_SHEAR: f64 = 0.05;
/// Half-range of the shear applied to a photo's sheared copy.
pub const PHOTO_SHEAR: f64 = 0.5;
/// Std of the roll error of the turned crops, radians (about 3.4 degrees).
pub const ROLL_JITTER: f64 = 0.06;

/// The values stored per crop in `labels.f32` (little-endian `f32`), in this order.
pub const LABEL_FIELDS: [&str; 14] = [
    "right_eye_x",
    "right_eye_y",
    "left_eye_x",
    "left_eye_y",
    "nose_x",
    "nose_y",
    "mouth_x",
    "mouth_y",
    "crop_shear",
    "crop_roll",
    "eye_distance_px",
    "face_index",
    "is_face",
    "shear_only",
];

/// The face index of the first extra (shear-only) face: the extra faces are numbered from here
/// in their order, after every Caltech face (5094), so their seeds and the trainer's held-out
/// hash differ from the Caltech faces'. Exact in the `f32` labels (below 2^24).
pub const EXTRA_FACE_INDEX: usize = 1_000_000;

/// The extra (shear-only) faces of the file `ground_truth`, in the Caltech format with image
/// names relative to the folder `images` (`scripts/pseudo_annotations.py` writes it from an
/// `unshear estimate --json` run at `k = 0`; `assets/train/` holds the committed network's).
/// When the folder holding `images` has an `identity.txt`, as the LFW subset has, it is the
/// subset's identity list (`<image> <identity>`, names relative to `images` too) and only the
/// faces of photos of the identities the networks may train on are kept
/// ([`crate::dev::dataset::lfw_trained_identity`]: even positions in the sorted names); a photo
/// the list does not name is dropped.
pub fn extra_faces(
    ground_truth: &std::path::Path,
    images: &std::path::Path,
) -> Result<Vec<AnnotatedFace>> {
    let text = std::fs::read_to_string(ground_truth).map_err(|source| Error::Io {
        path: ground_truth.to_path_buf(),
        source,
    })?;
    let faces = crate::dev::dataset::CaltechWebFaces::parse(&text, images)?;
    let beside = images
        .canonicalize()
        .map_err(|source| Error::Io {
            path: images.to_path_buf(),
            source,
        })?
        .parent()
        .map(|p| p.join("identity.txt"));
    let Some(identities_path) = beside.filter(|p| p.exists()) else {
        return Ok(faces);
    };
    let text = std::fs::read_to_string(&identities_path).map_err(|source| Error::Io {
        path: identities_path.clone(),
        source,
    })?;
    let identities = crate::dev::dataset::parse_identity_list(&text, images)?;
    let trained: std::collections::HashSet<&std::path::Path> = identities
        .iter()
        .filter(|i| crate::dev::dataset::lfw_trained_identity(&identities, &i.identity))
        .map(|i| i.image.as_path())
        .collect();
    Ok(faces
        .into_iter()
        .filter(|f| trained.contains(f.image.as_path()))
        .collect())
}

/// What to export.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportOptions {
    /// Side of the crops, pixels.
    pub size: usize,
    /// Crops per face.
    pub per_face: usize,
    /// Faces whose eye distance (pixels) is below this are skipped.
    pub min_eye_distance: f64,
    /// Faces whose eye distance is at or above this are skipped (to keep the faces an
    /// evaluation measures out of training).
    pub max_eye_distance: f64,
    /// Non-face crops per photo and kind (see `negative_samples` in this module; 0: none).
    pub negatives_per_image: usize,
    /// Seed of the generators.
    pub seed: u64,
    /// Crops per extra (shear-only) face ([`export_crops_with_extra`]).
    pub extra_per_face: usize,
}

impl Default for ExportOptions {
    fn default() -> Self {
        Self {
            size: CROP_SIZE,
            per_face: 24,
            min_eye_distance: 15.0,
            max_eye_distance: 40.0,
            negatives_per_image: 2,
            seed: 0x6c61_6e64_6d61_726b,
            extra_per_face: 8,
        }
    }
}

/// Percentage of the faces that `scripts/train_landmarks.py` holds out of training (its
/// `--val-percent` default).
pub const HELD_OUT_PERCENT: u64 = 10;

/// Whether `scripts/train_landmarks.py` holds the face with this index in the data set out of
/// training: its rule `face * 2654435761 % 100 < 10`, a multiplicative hash that spreads the
/// held-out faces over the data set.
pub fn held_out_of_training(face_index: usize) -> bool {
    (face_index as u64).wrapping_mul(2_654_435_761) % 100 < HELD_OUT_PERCENT
}

/// Which faces of a data set (all of its faces, in its order) the landmark network exported with
/// `options` was never trained on, in photos no accuracy table measures: in the photos whose
/// every face has eyes under `options.max_eye_distance` apart (the photos the export keeps, none
/// of which `eval shear` measures by default), the faces with eyes under
/// `options.min_eye_distance` (never exported) and those the trainer holds out. What is fitted
/// to the pipeline's estimates (the confidence models) is fitted on these faces.
pub fn unseen_faces(faces: &[AnnotatedFace], options: &ExportOptions) -> Vec<bool> {
    trainer_sees(faces, options)
        .into_iter()
        .map(|seen| seen == Some(false))
        .collect()
}

/// Which faces of a data set (all of its faces, in its order) the landmark network exported with
/// `options` is trained on: the faces of [`unseen_faces`]' photos with eyes at least
/// `options.min_eye_distance` apart that the trainer does not hold out. The eye filters are
/// trained on these faces too ([`crate::dev::train::TrainFaces::Unmeasured`]), so that neither
/// the faces the accuracy tables measure nor those the confidence models are fitted on are
/// trained on.
pub fn trained_faces(faces: &[AnnotatedFace], options: &ExportOptions) -> Vec<bool> {
    trainer_sees(faces, options)
        .into_iter()
        .map(|seen| seen == Some(true))
        .collect()
}

/// For each face: `None` when its photo holds a face with eyes `options.max_eye_distance` apart
/// or more (a photo the accuracy tables measure), else whether the trainer sees it (exported
/// and not held out).
fn trainer_sees(faces: &[AnnotatedFace], options: &ExportOptions) -> Vec<Option<bool>> {
    let mut widest: std::collections::HashMap<&std::path::Path, f64> =
        std::collections::HashMap::new();
    for f in faces {
        let d = widest.entry(f.image.as_path()).or_insert(0.0);
        *d = d.max(f.eye_distance());
    }
    faces
        .iter()
        .enumerate()
        .map(|(i, f)| {
            (widest[f.image.as_path()] < options.max_eye_distance)
                .then(|| f.eye_distance() >= options.min_eye_distance && !held_out_of_training(i))
        })
        .collect()
}

/// What the export wrote.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ExportSummary {
    /// Faces used.
    pub faces: usize,
    /// Face crops written.
    pub crops: usize,
    /// Non-face crops written.
    pub negatives: usize,
    /// Extra (shear-only) faces used (also counted in `faces`).
    pub extra_faces: usize,
    /// Shear-only crops written (also counted in `crops`).
    pub extra_crops: usize,
    /// Images that could not be read (skipped).
    pub unreadable: Vec<String>,
}

/// The faces of one photo, each with its index (its seed).
type IndexedFaces = Vec<(usize, AnnotatedFace)>;

/// A standard normal draw (Box-Muller).
fn normal(rng: &mut SplitMix64) -> f64 {
    let u1 = rng.next_f64().max(f64::MIN_POSITIVE);
    let u2 = rng.next_f64();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// One crop: grey levels rounded to bytes, and its labels ([`LABEL_FIELDS`]).
struct Sample {
    pixels: Vec<u8>,
    labels: [f32; LABEL_FIELDS.len()],
}

/// A photo as the crops are cut from it: the grey image, sheared by `k` (0: as it is), and
/// where a point of the unsheared photo lies in it.
struct Version {
    gray: image::GrayImage,
    k: f64,
    shear: Shear,
    placement: Placement,
}

impl Version {
    fn unsheared(gray: image::GrayImage) -> Self {
        Self {
            gray,
            k: 0.0,
            shear: Shear::new(0.0, 0.0),
            placement: Placement::default(),
        }
    }

    /// `gray` sheared by `k` about its middle row, as a rolling-shutter camera delivers it:
    /// every row, and only the columns every row covers (`eval::shear::camera_window`). A
    /// canvas widened to keep every pixel would have empty corners whose edges slant by `k`,
    /// and a crop reaching one would show its label's shear outright (the crop removes the
    /// photo's shear less the residual, so the edge slants by the residual in the crop); the
    /// camera's frame has upright edges, as a photo at run time has.
    fn sheared(gray: &image::GrayImage, k: f64) -> Option<Self> {
        let (shear, placement, w, h) = camera_window(&[], gray.width(), gray.height(), k, 0.0)?;
        let img = sheared_window(
            &image::DynamicImage::ImageLuma8(gray.clone()),
            shear,
            placement,
            w,
            h,
        )
        .ok()?;
        Some(Self {
            gray: img.into_luma8(),
            k,
            shear,
            placement,
        })
    }

    fn point(&self, p: Point) -> Point {
        self.placement.from_frame(self.shear.apply(p))
    }

    /// Whether both of `face`'s eyes lie in this version's frame (a sheared copy's frame can
    /// cut a face near the photo's side away).
    fn shows(&self, face: &AnnotatedFace) -> bool {
        let (w, h) = (
            f64::from(self.gray.width()) - 1.0,
            f64::from(self.gray.height()) - 1.0,
        );
        [face.right_eye, face.left_eye].iter().all(|&p| {
            let p = self.point(p);
            p.x >= 0.0 && p.y >= 0.0 && p.x <= w && p.y <= h
        })
    }
}

/// The `per_face` crops of one face, each cut from one of `versions` of its photo.
fn face_samples(
    versions: &[Version],
    face: &AnnotatedFace,
    face_index: usize,
    options: &ExportOptions,
    shear_only: bool,
) -> Vec<Sample> {
    let per_face = if shear_only {
        options.extra_per_face
    } else {
        options.per_face
    };
    let mut rng = SplitMix64::new(options.seed.wrapping_add(face_index as u64));
    let distance = face.eye_distance();
    let head_roll = (face.left_eye.y - face.right_eye.y).atan2(face.left_eye.x - face.right_eye.x);
    let mut out = Vec::with_capacity(per_face);
    // The versions whose frame holds the face (the photo as it is always does).
    let versions: Vec<&Version> = versions.iter().filter(|v| v.shows(face)).collect();
    if versions.is_empty() {
        return out;
    }
    for _ in 0..per_face {
        let version = versions[(rng.next_f64() * versions.len() as f64) as usize % versions.len()];
        let (re, le) = (version.point(face.right_eye), version.point(face.left_eye));
        let midpoint = re.midpoint(le);
        let residual = if rng.next_f64() < 0.5 {
            rng.symmetric(WIDE_SHEAR)
        } else {
            NARROW_SHEAR * normal(&mut rng)
        };
        // The crop removes the version's shear less the residual, which the face then shows.
        let k = version.k - residual;
        let roll = if rng.next_f64() < 0.5 {
            0.0
        } else {
            head_roll + ROLL_JITTER * normal(&mut rng)
        };
        let scaled = distance * (SCALE_JITTER * normal(&mut rng)).exp();
        // The eyes' midpoint's offset, drawn in the upright face and shown through the frame.
        let (dx, dy) = (
            CENTRE_JITTER * distance * normal(&mut rng),
            CENTRE_JITTER * distance * normal(&mut rng),
        );
        let (s, c) = roll.sin_cos();
        let (tx, ty) = (c * dx - s * dy, s * dx + c * dy);
        let offset_mid = Point::new(midpoint.x + tx + k * ty, midpoint.y + ty);
        let frame = frame_around_eyes(offset_mid, scaled, k, roll, options.size);
        let Some(pixels) = frame.render(&version.gray) else {
            continue;
        };
        let nose = face
            .nose
            .map_or(Point::new(f64::NAN, f64::NAN), |p| version.point(p));
        let mouth = face
            .mouth
            .map_or(Point::new(f64::NAN, f64::NAN), |p| version.point(p));
        let points = [re, le, nose, mouth].map(|p| frame.from_image(p));
        let mut labels = [0f32; LABEL_FIELDS.len()];
        for (i, p) in points.iter().enumerate() {
            labels[2 * i] = p.x as f32;
            labels[2 * i + 1] = p.y as f32;
        }
        labels[8] = crop_shear(residual, roll) as f32;
        labels[9] = (head_roll - roll) as f32;
        labels[10] = distance as f32;
        labels[11] = face_index as f32;
        labels[12] = 1.0;
        labels[13] = f32::from(u8::from(shear_only));
        out.push(Sample {
            pixels: to_bytes(&pixels),
            labels,
        });
    }
    out
}

/// Cuts the training crops of every face of `faces` within the options' eye-distance range,
/// and the non-face crops (`negative_samples` in this module), and writes them to `out_dir`:
/// `crops.u8` (each crop `size * size` bytes, row-major), `labels.f32` ([`LABEL_FIELDS`] per
/// crop) and `meta.json` (the options and counts).
///
/// Images holding a face at or above `max_eye_distance` are skipped whole, faces of every
/// size and background alike, so that no pixel of an image the accuracy tables measure is
/// trained on.
pub fn export_crops(
    faces: Vec<AnnotatedFace>,
    options: &ExportOptions,
    out_dir: &std::path::Path,
) -> Result<ExportSummary> {
    export_crops_with_extra(faces, Vec::new(), options, out_dir)
}

/// [`export_crops`] of the Caltech faces `faces` (written first, exactly as without extras),
/// then `options.extra_per_face` shear-only crops of each face of `extra` (see the module's
/// documentation; [`extra_faces`] reads them) with eyes at least `options.min_eye_distance`
/// apart, numbered from [`EXTRA_FACE_INDEX`] in their order: no maximum eye distance, no photo
/// skipped for a large face, no non-face crops.
pub fn export_crops_with_extra(
    faces: Vec<AnnotatedFace>,
    extra: Vec<AnnotatedFace>,
    options: &ExportOptions,
    out_dir: &std::path::Path,
) -> Result<ExportSummary> {
    let io_error = |path: &std::path::Path| {
        let path = path.to_path_buf();
        move |source| Error::Io { path, source }
    };
    std::fs::create_dir_all(out_dir).map_err(io_error(out_dir))?;
    // Every face keeps its index in the data set as its seed, whatever the range asked for.
    let indexed: Vec<(usize, AnnotatedFace)> = faces.into_iter().enumerate().collect();
    let mut groups: std::collections::BTreeMap<std::path::PathBuf, Vec<(usize, AnnotatedFace)>> =
        std::collections::BTreeMap::new();
    for (i, f) in indexed {
        groups.entry(f.image.clone()).or_default().push((i, f));
    }
    // The Caltech photos (marked `false`: not shear-only), then the extra ones.
    let mut groups: Vec<(std::path::PathBuf, IndexedFaces, bool)> = groups
        .into_iter()
        .filter(|(_, faces)| {
            faces
                .iter()
                .all(|(_, f)| f.eye_distance() < options.max_eye_distance)
        })
        .map(|(path, faces)| (path, faces, false))
        .collect();
    let mut extra_groups: std::collections::BTreeMap<
        std::path::PathBuf,
        Vec<(usize, AnnotatedFace)>,
    > = std::collections::BTreeMap::new();
    for (i, f) in extra.into_iter().enumerate() {
        extra_groups
            .entry(f.image.clone())
            .or_default()
            .push((EXTRA_FACE_INDEX + i, f));
    }
    groups.extend(
        extra_groups
            .into_iter()
            .map(|(path, faces)| (path, faces, true)),
    );
    let crops_path = out_dir.join("crops.u8");
    let labels_path = out_dir.join("labels.f32");
    let mut crops =
        std::io::BufWriter::new(std::fs::File::create(&crops_path).map_err(io_error(&crops_path))?);
    let mut labels = std::io::BufWriter::new(
        std::fs::File::create(&labels_path).map_err(io_error(&labels_path))?,
    );
    let mut summary = ExportSummary::default();
    let detector = crate::detect::FaceDetector::new(
        crate::detect::Cascade::frontal_face_alt2(),
        crate::detect::DetectorParams {
            min_neighbors: 1,
            min_size: (30, 30),
            ..crate::detect::DetectorParams::default()
        },
    );
    for chunk in groups.chunks(256) {
        let cut: Vec<std::result::Result<(usize, Vec<Sample>), String>> = chunk
            .par_iter()
            .map(|(path, faces, shear_only)| {
                let shear_only = *shear_only;
                let img = imageio::read_image(path, imageio::DEFAULT_MAX_PIXELS)
                    .map_err(|e| e.to_string())?;
                let gray = crate::detect::to_gray_opencv(&img);
                let first = faces.first().map_or(0, |(i, _)| *i);
                // The sheared copy's shear, from a generator of the image's own.
                let mut rng =
                    SplitMix64::new(options.seed.wrapping_add(first as u64).rotate_left(17));
                let photo_k = rng.symmetric(PHOTO_SHEAR);
                let mut versions = vec![];
                if let Some(v) = Version::sheared(&gray, photo_k) {
                    versions.push(v);
                }
                versions.push(Version::unsheared(gray));
                let in_range = |f: &AnnotatedFace| {
                    let d = f.eye_distance();
                    d >= options.min_eye_distance && (shear_only || d < options.max_eye_distance)
                };
                let mut samples: Vec<Sample> = faces
                    .iter()
                    .filter(|(_, f)| in_range(f))
                    .flat_map(|(i, f)| face_samples(&versions, f, *i, options, shear_only))
                    .collect();
                let used = faces.iter().filter(|(_, f)| in_range(f)).count();
                if !shear_only {
                    let all: Vec<&AnnotatedFace> = faces.iter().map(|(_, f)| f).collect();
                    samples.extend(negative_samples(
                        &versions, &all, &detector, &mut rng, options,
                    ));
                }
                Ok((used, samples))
            })
            .collect();
        for ((path, _, shear_only), result) in chunk.iter().zip(cut) {
            match result {
                Ok((used, samples)) => {
                    summary.faces += used;
                    if *shear_only {
                        summary.extra_faces += used;
                    }
                    for s in samples {
                        crops.write_all(&s.pixels).map_err(io_error(&crops_path))?;
                        for v in s.labels {
                            labels
                                .write_all(&v.to_le_bytes())
                                .map_err(io_error(&labels_path))?;
                        }
                        if s.labels[12] > 0.5 {
                            summary.crops += 1;
                            if s.labels[13] > 0.5 {
                                summary.extra_crops += 1;
                            }
                        } else {
                            summary.negatives += 1;
                        }
                    }
                }
                Err(e) => summary.unreadable.push(format!("{}: {e}", path.display())),
            }
        }
    }
    crops.flush().map_err(io_error(&crops_path))?;
    labels.flush().map_err(io_error(&labels_path))?;
    let meta = serde_json::json!({
        "size": options.size,
        "per_face": options.per_face,
        "negatives_per_image": options.negatives_per_image,
        "min_eye_distance": options.min_eye_distance,
        "max_eye_distance": options.max_eye_distance,
        "seed": options.seed,
        "faces": summary.faces,
        "crops": summary.crops,
        "negatives": summary.negatives,
        "extra_per_face": options.extra_per_face,
        "extra_faces": summary.extra_faces,
        "extra_crops": summary.extra_crops,
        "extra_face_index": EXTRA_FACE_INDEX,
        "label_fields": LABEL_FIELDS,
        "crop_eye_distances": CROP_EYE_DISTANCES,
        "eyes_above_centre": EYES_ABOVE_CENTRE,
    });
    let meta_path = out_dir.join("meta.json");
    std::fs::write(&meta_path, meta.to_string()).map_err(io_error(&meta_path))?;
    Ok(summary)
}

/// Crops of one photo that show no annotated face, labelled as non-faces (points and shear
/// unknown): where the detector, asked leniently (one merged hit), fires on something that is
/// not an annotated face (the kind of box the network must turn away at run time), and boxes of
/// random size and place that hold no annotated eye; up to `negatives_per_image` of each kind,
/// cut from a version of the photo at random, through the frame a detection's first search
/// uses, with a random residual shear and roll as for the faces.
fn negative_samples(
    versions: &[Version],
    faces: &[&AnnotatedFace],
    detector: &crate::detect::FaceDetector,
    rng: &mut SplitMix64,
    options: &ExportOptions,
) -> Vec<Sample> {
    let mut out = Vec::new();
    if options.negatives_per_image == 0 {
        return out;
    }
    for version in versions {
        let eyes: Vec<Point> = faces
            .iter()
            .flat_map(|f| [version.point(f.right_eye), version.point(f.left_eye)])
            .collect();
        let clear = |b: &crate::geometry::Rect| {
            // No annotated eye within the box grown by a quarter each way (a box half on a
            // face is not a clean negative).
            let g = b.scaled_about_center(1.5);
            eyes.iter().all(|e| !g.contains(*e))
        };
        let (w, h) = (
            f64::from(version.gray.width()),
            f64::from(version.gray.height()),
        );
        let mut boxes: Vec<crate::geometry::Rect> = detector
            .detect(&version.gray)
            .into_iter()
            .filter(|b| clear(b))
            .take(options.negatives_per_image)
            .collect();
        for _ in 0..4 * options.negatives_per_image {
            if boxes.len() >= 2 * options.negatives_per_image {
                break;
            }
            let side = 30.0 + rng.next_f64() * (w.min(h) - 30.0).max(0.0);
            let b = crate::geometry::Rect::new(
                rng.next_f64() * (w - side).max(0.0),
                rng.next_f64() * (h - side).max(0.0),
                side,
                side,
            );
            if side >= 30.0 && clear(&b) {
                boxes.push(b);
            }
        }
        for b in boxes {
            let residual = rng.symmetric(WIDE_SHEAR);
            let roll = ROLL_JITTER * normal(rng);
            let eyes = Point::new(
                b.x + 0.5
                    * (crate::detect::boxes::RIGHT_EYE_IN_BOX.0
                        + crate::detect::boxes::LEFT_EYE_IN_BOX.0)
                    * b.width,
                b.y + 0.5
                    * (crate::detect::boxes::RIGHT_EYE_IN_BOX.1
                        + crate::detect::boxes::LEFT_EYE_IN_BOX.1)
                    * b.height,
            );
            let frame = frame_around_eyes(
                eyes,
                crate::detect::boxes::EYE_DISTANCE_PER_BOX_WIDTH * b.width,
                version.k - residual,
                roll,
                options.size,
            );
            let Some(pixels) = frame.render(&version.gray) else {
                continue;
            };
            let mut labels = [f32::NAN; LABEL_FIELDS.len()];
            labels[10] = 0.0;
            labels[11] = -1.0;
            labels[12] = 0.0;
            labels[13] = 0.0;
            out.push(Sample {
                pixels: to_bytes(&pixels),
                labels,
            });
        }
    }
    out
}

/// Grey levels rounded to bytes.
fn to_bytes(pixels: &[f32]) -> Vec<u8> {
    pixels
        .iter()
        .map(|v| v.round().clamp(0.0, 255.0) as u8)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_held_out_faces_are_the_trainers() {
        // The indices scripts/train_landmarks.py holds out among the first 60 (computed there).
        let held: Vec<usize> = (0..60).filter(|&i| held_out_of_training(i)).collect();
        assert_eq!(held, [0, 5, 23, 28, 41, 46]);
        let share = (0..10_000).filter(|&i| held_out_of_training(i)).count();
        assert!((900..=1100).contains(&share), "{share}");
    }

    #[test]
    fn unseen_faces_are_small_or_held_out_in_photos_of_small_faces_only() {
        let face = |image: &str, eyes: f64| AnnotatedFace {
            image: image.into(),
            right_eye: Point::new(0.0, 0.0),
            left_eye: Point::new(eyes, 0.0),
            nose: None,
            mouth: None,
        };
        let faces = [
            face("a", 20.0), // 0: held out, in a photo of small faces
            face("a", 12.0), // 1: too small to be exported
            face("a", 30.0), // 2: trained on
            face("b", 20.0), // 3: a photo with a large face: measured, not fitted on
            face("b", 50.0), // 4
            face("b", 12.0), // 5: held out, but beside a large face
        ];
        assert!(held_out_of_training(0) && held_out_of_training(5));
        assert!(!held_out_of_training(2));
        let unseen = unseen_faces(&faces, &ExportOptions::default());
        assert_eq!(unseen, [true, true, false, false, false, false]);
        // The trained faces are the rest of the small-face photo's faces of exportable size:
        // never a face that is unseen, nor one beside a large face.
        let trained = trained_faces(&faces, &ExportOptions::default());
        assert_eq!(trained, [false, false, true, false, false, false]);
    }

    /// Extra faces add shear-only crops after the Caltech ones, which stay byte for byte what
    /// they are without extras; a photo with an extra face 45 px apart is not skipped.
    #[test]
    fn extra_faces_add_shear_only_crops_and_leave_the_caltech_crops_alone() {
        let dir = tempfile::tempdir().expect("tempdir");
        let images = dir.path().join("images");
        std::fs::create_dir(&images).expect("mkdir");
        let gray = image::GrayImage::from_fn(160, 160, |x, y| {
            image::Luma([((x * 3 + y * 7) % 251) as u8])
        });
        for name in ["a.png", "b.png"] {
            gray.save(images.join(name)).expect("save");
        }
        let face = |name: &str, eyes: f64| AnnotatedFace {
            image: images.join(name),
            right_eye: Point::new(60.0, 70.0),
            left_eye: Point::new(60.0 + eyes, 70.0),
            nose: Some(Point::new(60.0 + eyes / 2.0, 90.0)),
            mouth: Some(Point::new(60.0 + eyes / 2.0, 100.0)),
        };
        let options = ExportOptions {
            size: 32,
            per_face: 3,
            extra_per_face: 2,
            negatives_per_image: 1,
            ..ExportOptions::default()
        };
        let read = |out: &std::path::Path| {
            let crops = std::fs::read(out.join("crops.u8")).expect("crops");
            let labels: Vec<f32> = std::fs::read(out.join("labels.f32"))
                .expect("labels")
                .chunks(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            (crops, labels)
        };
        let (plain, mixed) = (dir.path().join("plain"), dir.path().join("mixed"));
        let alone = export_crops(vec![face("a.png", 20.0)], &options, &plain).expect("export");
        let summary = export_crops_with_extra(
            vec![face("a.png", 20.0)],
            vec![face("b.png", 45.0), face("b.png", 10.0)],
            &options,
            &mixed,
        )
        .expect("export");
        assert_eq!((alone.crops, alone.extra_crops), (3, 0));
        // The face 10 px apart is under the minimum; the one 45 px apart is kept.
        assert_eq!(
            (
                summary.faces,
                summary.extra_faces,
                summary.crops,
                summary.extra_crops
            ),
            (2, 1, 5, 2)
        );
        assert_eq!(summary.negatives, alone.negatives);
        let ((c1, l1), (c2, l2)) = (read(&plain), read(&mixed));
        let n = LABEL_FIELDS.len();
        assert_eq!(c2[..c1.len()], c1[..]);
        let same = l1.iter().zip(&l2).all(|(a, b)| a.to_bits() == b.to_bits());
        assert!(same && l2.len() == l1.len() + 2 * n);
        for row in l1.chunks(n) {
            assert_eq!(row[13], 0.0);
        }
        for row in l2[l1.len()..].chunks(n) {
            assert_eq!(
                (row[11], row[12], row[13]),
                (EXTRA_FACE_INDEX as f32, 1.0, 1.0)
            );
        }
        let meta: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(mixed.join("meta.json")).expect("meta"))
                .expect("json");
        assert_eq!(meta["extra_crops"], 2);
        assert_eq!(meta["label_fields"][13], "shear_only");
    }

    /// Extra faces whose image folder has an LFW identity list beside it keep only the trained
    /// identities' photos.
    #[test]
    fn extra_faces_keep_only_the_lfw_identities_trained_on() {
        let dir = tempfile::tempdir().expect("tempdir");
        let images = dir.path().join("images");
        std::fs::create_dir(&images).expect("mkdir");
        let line = |name: &str| format!("{name} 10 20 30 20 20 30 20 40\n");
        let text: String = ["alice0.jpg", "bob0.jpg", "carol0.jpg", "zed0.jpg"]
            .iter()
            .map(|n| line(n))
            .collect();
        let truth = dir.path().join("pseudo.txt");
        std::fs::write(&truth, &text).expect("write");
        let names = |faces: Vec<AnnotatedFace>| -> Vec<String> {
            faces
                .iter()
                .map(|f| f.image.file_name().unwrap().to_string_lossy().into_owned())
                .collect()
        };
        // Without an identity list: every face.
        assert_eq!(names(extra_faces(&truth, &images).expect("faces")).len(), 4);
        std::fs::write(
            dir.path().join("identity.txt"),
            "alice0.jpg Alice\nbob0.jpg Bob\ncarol0.jpg Carol\n",
        )
        .expect("write");
        // Alice (0) and Carol (2) are trained on; Bob (1) is not; zed0.jpg is not listed.
        let kept = extra_faces(&truth, &images).expect("faces");
        assert_eq!(kept[0].image, images.join("alice0.jpg"));
        assert_eq!(names(kept), ["alice0.jpg", "carol0.jpg"]);
    }

    #[test]
    fn normal_draws_have_unit_spread() {
        let mut rng = SplitMix64::new(7);
        let draws: Vec<f64> = (0..20000).map(|_| normal(&mut rng)).collect();
        let mean = draws.iter().sum::<f64>() / draws.len() as f64;
        let var = draws.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / draws.len() as f64;
        assert!(
            mean.abs() < 0.03 && (var - 1.0).abs() < 0.05,
            "{mean} {var}"
        );
    }

    /// The sheared copy is the rectangle a camera delivers: every pixel from the photo (none
    /// of the widened canvas's empty corners, whose edges slant by the shear), `|k| (H - 1)`
    /// narrower, every row kept.
    #[test]
    fn the_sheared_copy_has_no_empty_corner() {
        let gray = image::GrayImage::from_fn(200, 100, |x, y| image::Luma([(x + y) as u8 | 1]));
        for k in [0.5, -0.3, 0.137] {
            let v = Version::sheared(&gray, k).expect("shear");
            assert!(v.gray.pixels().all(|p| p.0[0] > 0), "k = {k}");
            let narrower = 200.0 - f64::from(v.gray.width());
            assert!(
                narrower >= k.abs() * 99.0 && narrower <= k.abs() * 99.0 + 2.0,
                "k = {k}: {narrower}"
            );
            assert_eq!(v.gray.height(), 100);
            // A point on the middle row keeps its place up to the cut on the left.
            let p = v.point(Point::new(100.0, 50.0));
            assert!((p.x + v.placement.offset_x - 100.0).abs() < 1e-9, "k = {k}");
        }
    }

    /// A face the sheared copy's frame cuts is cut from the photo as it is only.
    #[test]
    fn a_face_the_sheared_frame_cuts_comes_from_the_photo_as_it_is() {
        let bright = image::GrayImage::from_pixel(200, 200, image::Luma([200]));
        let dark = image::GrayImage::from_pixel(200, 200, image::Luma([50]));
        let sheared = Version {
            gray: Version::sheared(&bright, 0.5).expect("shear").gray,
            ..Version::sheared(&dark, 0.5).expect("shear")
        };
        // Shifted by -50 on row 0 and +49.5 on row 199: the frame keeps columns 50..=149.
        let face = |x: f64| AnnotatedFace {
            image: "synthetic".into(),
            right_eye: Point::new(x, 100.0),
            left_eye: Point::new(x + 20.0, 100.0),
            nose: None,
            mouth: None,
        };
        let versions = [Version::unsheared(dark), sheared];
        let options = ExportOptions {
            size: 48,
            per_face: 16,
            ..ExportOptions::default()
        };
        let levels = |x: f64| -> Vec<u8> {
            face_samples(&versions, &face(x), 0, &options, false)
                .iter()
                .flat_map(|s| s.pixels.clone())
                .collect()
        };
        // At the photo's side: the dark photo only. In the middle: both.
        let side = levels(20.0);
        assert_eq!(side.len(), 16 * 48 * 48);
        assert!(side.iter().all(|&v| v == 50));
        assert!(versions[1].shows(&face(90.0)) && !versions[1].shows(&face(20.0)));
        assert!(levels(90.0).contains(&200));
    }

    #[test]
    fn labels_are_the_annotated_points_in_the_crop() {
        // A synthetic face: the labels must be the crop points that show the annotations.
        let gray = image::GrayImage::from_fn(200, 200, |x, y| image::Luma([((x + y) % 256) as u8]));
        let face = AnnotatedFace {
            image: "synthetic".into(),
            right_eye: Point::new(80.0, 90.0),
            left_eye: Point::new(120.0, 92.0),
            nose: Some(Point::new(100.0, 120.0)),
            mouth: Some(Point::new(101.0, 135.0)),
        };
        let options = ExportOptions {
            size: 48,
            per_face: 20,
            ..ExportOptions::default()
        };
        let versions = [
            Version::unsheared(gray.clone()),
            Version::sheared(&gray, 0.3).expect("shear"),
        ];
        let samples = face_samples(&versions, &face, 3, &options, false);
        assert_eq!(samples.len(), 20);
        let unit = 48.0 / CROP_EYE_DISTANCES;
        let own = crate::estimate::shear_and_roll(Point::new(40.0, 2.0), Point::new(1.0, 44.0))
            .expect("solvable")
            .k;
        for s in &samples {
            let l = &s.labels;
            let (re, le) = (
                Point::new(l[0].into(), l[1].into()),
                Point::new(l[2].into(), l[3].into()),
            );
            // The eyes are about a crop eye distance apart (scale jitter aside) and near the
            // expected place.
            let d = re.distance(le) / unit;
            assert!(d > 0.6 && d < 1.6, "{d}");
            assert!((re.midpoint(le).x - 23.5).abs() < 0.5 * unit);
            // The mouth is below the eyes in every crop (rolls are small), and the points show
            // the label's shear: solved for shear and roll (the eye line and the mouth axis
            // perpendicular in the upright face), they give the label plus what the annotated
            // points give in the photo (the face's own apparent shear), to 0.02: the two add
            // exactly only without roll (a turned crop scales its axes unequally, which moves
            // the face's own lean a little).
            assert!(l[7] > l[1] && l[7] > l[3]);
            let mid = re.midpoint(le);
            let solved = crate::estimate::shear_and_roll(
                Point::new(le.x - re.x, le.y - re.y),
                Point::new(f64::from(l[6]) - mid.x, f64::from(l[7]) - mid.y),
            )
            .expect("solvable");
            assert!(
                (solved.k - f64::from(l[8]) - own).abs() < 0.02,
                "points {} label {} own {own}",
                solved.k,
                l[8]
            );
            assert!(l[8].abs() <= 0.6 && (l[11] - 3.0).abs() < 1e-6);
        }
        // Deterministic per face index.
        let again = face_samples(&versions, &face, 3, &options, false);
        assert!(samples
            .iter()
            .zip(&again)
            .all(|(a, b)| a.labels == b.labels && a.pixels == b.pixels));
    }
}
