//! Training the eye filters (`unshear train`): from faces with annotated eye centres, each face is
//! normalised to 150 px wide through the face box the detector would draw for those eyes
//! ([`crate::detect::boxes::face_box_from_eyes`]), a `64 x 64` patch is cut centred on each eye, and
//! one filter is synthesised per eye, one for the nose from patches centred on the annotated
//! nose point and one for the mouth from patches centred on the annotated mouth centre, of the
//! type asked for ([`TrainOptions::filter_type`]: UMACE, ASEF or MOSSE, see
//! [`crate::filters`]).
//!
//! Images are converted to grey with OpenCV's weights ([`crate::detect::to_gray_opencv`]), the
//! conversion the detector and the feature locator use at run time, so the filters are trained on
//! what they will see.
//!
//! **Translations.** UMACE averages centred features and needs nothing else. ASEF and MOSSE learn
//! to put their peak where the feature is, so they are also shown [`TRANSLATIONS`] crops per
//! feature displaced by up to [`MAX_TRANSLATION`] pixels each way (uniform, sub-pixel), with the
//! desired peak moved with the feature, as Bolme et al. train on perturbed copies.
//!
//! Deterministic: images are decoded in parallel but patches are added in data-set order, and the
//! translations come from a fixed-seed generator seeded per image, so the same data gives the
//! same filter file, byte for byte.

use rayon::prelude::*;

use crate::detect::boxes::face_box_from_eyes;
use crate::dev::dataset::{by_image, AnnotatedFace};
use crate::error::{Error, Result};
use crate::filters::{EyeFilters, FilterTrainer, FilterType};
use crate::imageio;
use crate::locate::filters::{NormalizedFace, FACE_WIDTH, MOUTH_BELOW_EYES, NOSE_BELOW_EYES};
use crate::rng::SplitMix64;

/// Side of the eye patches and filters (the paper's 64).
pub const PATCH_SIZE: usize = 64;

/// Translated crops per feature and face for the types that learn localisation (ASEF, MOSSE),
/// besides the centred one: 4, so each filter sees five times as many patches as faces.
pub const TRANSLATIONS: usize = 4;

/// Largest translation of a training crop, pixels of the 150-px normalised face, each axis: 8,
/// about the run-time eye search window's reach (`crate::locate::filters::EYE_SEARCH`, 14 x 12) less
/// a margin, so the filters learn peaks where they will be looked for.
pub const MAX_TRANSLATION: f64 = 8.0;

/// Images decoded at a time: bounds memory (ASEF and MOSSE keep five crops per feature).
const CHUNK: usize = 128;

/// Seed of the translations: the generator for image `i` of the data set is seeded with
/// `TRANSLATION_SEED + i`.
const TRANSLATION_SEED: u64 = 0x756e_7368_6561_7266;

/// Which faces of the data set [`train_eye_filters`] may train on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TrainFaces {
    /// Every face (of at least [`TrainOptions::min_eye_distance`]).
    All,
    /// The faces the landmark network trains on
    /// ([`crate::dev::landmark_crops::trained_faces`]): faces with eyes 15 px apart or more in
    /// photos whose faces all have eyes under 40 px apart, less the faces its trainer holds out.
    /// No face that `eval shear` measures by default, nor one the confidence models are fitted
    /// on (`--faces unseen`), is trained on.
    /// The data set must be given whole and in its order (the held-out rule goes by index).
    Unmeasured,
}

/// Options for [`train_eye_filters`].
#[derive(Debug, Clone, PartialEq)]
pub struct TrainOptions {
    /// Which faces to train on.
    pub faces: TrainFaces,
    /// Faces whose eye distance is below this (pixels) are skipped: each face is enlarged to
    /// about 57 px between the eyes (the 150-px normalised face), and smaller faces add blur
    /// rather than detail.
    pub min_eye_distance: f64,
    /// Also add each face's mirror image (the mirrored left eye trains the right-eye filter and
    /// vice versa), doubling the training set and making the left-eye filter the mirror image
    /// of the right-eye one, so that a mirrored face gives (nearly) the opposite shear. On by
    /// default; measured on the first 150 Caltech faces (eye distance >= 40 px) at k = 0 the
    /// median absolute error fell from 0.118 to 0.102, and on the 15 Yale faces the estimates
    /// within 0.05 rose from 36 to 42 of 75.
    pub mirror: bool,
    /// Refuse to write filters made from fewer face crops per eye than this (the paper used
    /// 1500); translated copies do not count.
    pub min_patches: u32,
    /// Which filters to synthesise.
    pub filter_type: FilterType,
}

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            faces: TrainFaces::Unmeasured,
            min_eye_distance: MIN_EYE_DISTANCE,
            mirror: true,
            min_patches: 1500,
            filter_type: FilterType::DEFAULT,
        }
    }
}

/// [`TrainOptions::min_eye_distance`]'s default, pixels.
pub const MIN_EYE_DISTANCE: f64 = 25.0;

/// What training used.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrainSummary {
    /// Faces used.
    pub faces: usize,
    /// Faces left out by [`TrainOptions::faces`].
    pub not_selected: usize,
    /// Faces skipped for a small eye distance.
    pub too_small: usize,
    /// Images that could not be read (skipped).
    pub unreadable: Vec<String>,
    /// Face crops per filter (mirror images included, translated copies not).
    pub crops: u32,
}

/// Trains the pair of eye filters from `faces`.
pub fn train_eye_filters(
    faces: Vec<AnnotatedFace>,
    options: &TrainOptions,
) -> Result<(EyeFilters, TrainSummary)> {
    let mut summary = TrainSummary::default();
    let selected = match options.faces {
        TrainFaces::All => vec![true; faces.len()],
        TrainFaces::Unmeasured => crate::dev::landmark_crops::trained_faces(
            &faces,
            &crate::dev::landmark_crops::ExportOptions::default(),
        ),
    };
    summary.not_selected = selected.iter().filter(|&&s| !s).count();
    let usable: Vec<AnnotatedFace> = faces
        .into_iter()
        .zip(selected)
        .filter(|(_, s)| *s)
        .map(|(f, _)| f)
        .filter(|f| {
            let ok = f.eye_distance() >= options.min_eye_distance;
            summary.too_small += usize::from(!ok);
            ok
        })
        .collect();
    let groups = by_image(usable);
    let kind = options.filter_type;
    let translations = if kind.learns_localisation() {
        TRANSLATIONS
    } else {
        0
    };
    let mut right = FilterTrainer::new(kind, PATCH_SIZE);
    let mut left = FilterTrainer::new(kind, PATCH_SIZE);
    let mut nose = FilterTrainer::new(kind, PATCH_SIZE);
    let mut mouth = FilterTrainer::new(kind, PATCH_SIZE);
    for (chunk_index, chunk) in groups.chunks(CHUNK).enumerate() {
        // Decode and cut in parallel; the order of `chunk` is kept by collect.
        let cut: Vec<Result<Vec<FaceCrops>, String>> = chunk
            .par_iter()
            .enumerate()
            .map(|(i, (path, faces))| {
                let img = imageio::read_image(path, imageio::DEFAULT_MAX_PIXELS)
                    .map_err(|e| e.to_string())?;
                let gray = crate::detect::to_gray_opencv(&img);
                let mirrored = options
                    .mirror
                    .then(|| image::imageops::flip_horizontal(&gray));
                let index = (chunk_index * CHUNK + i) as u64;
                let mut rng = SplitMix64::new(TRANSLATION_SEED.wrapping_add(index));
                let mut crops = Vec::new();
                for f in faces {
                    crops.push(face_crops(
                        &gray,
                        f.right_eye,
                        f.left_eye,
                        f.nose,
                        f.mouth,
                        translations,
                        &mut rng,
                    ));
                    if let Some(m) = &mirrored {
                        // In the mirror the subject's left eye appears on the image left.
                        let w = f64::from(gray.width()) - 1.0;
                        let flip = |p: crate::Point| crate::Point::new(w - p.x, p.y);
                        crops.push(face_crops(
                            m,
                            flip(f.left_eye),
                            flip(f.right_eye),
                            f.nose.map(flip),
                            f.mouth.map(flip),
                            translations,
                            &mut rng,
                        ));
                    }
                }
                Ok(crops)
            })
            .collect();
        for ((path, faces), result) in chunk.iter().zip(cut) {
            match result {
                Ok(crops) => {
                    summary.faces += faces.len();
                    summary.crops += crops.len() as u32;
                    for [r, l, n, m] in crops {
                        for (trainer, patches) in [
                            (&mut right, r),
                            (&mut left, l),
                            (&mut nose, n),
                            (&mut mouth, m),
                        ] {
                            for p in patches {
                                trainer.add(&p.pixels, p.dx, p.dy);
                            }
                        }
                    }
                }
                Err(e) => summary.unreadable.push(format!("{}: {e}", path.display())),
            }
        }
    }
    if summary.crops < options.min_patches {
        return Err(Error::Training(format!(
            "only {} eye patches per eye (need {}): lower --min-eye-distance or add data",
            summary.crops, options.min_patches
        )));
    }
    let filters = EyeFilters {
        right_eye: right
            .finish()
            .ok_or_else(|| Error::Training("no right-eye patches".into()))?,
        left_eye: left
            .finish()
            .ok_or_else(|| Error::Training("no left-eye patches".into()))?,
        nose: nose
            .finish()
            .ok_or_else(|| Error::Training("no nose patches".into()))?,
        mouth: Some(
            mouth
                .finish()
                .ok_or_else(|| Error::Training("no mouth patches".into()))?,
        ),
        face_width: FACE_WIDTH as u32,
        kind,
    };
    Ok((filters, summary))
}

/// One training crop: pixels, and where the feature is from the crop centre.
struct Crop {
    pixels: Vec<f32>,
    dx: f64,
    dy: f64,
}

/// A face's crops for the right eye, the left eye, the nose and the mouth.
type FaceCrops = [Vec<Crop>; 4];

/// The `PATCH_SIZE` crops of one face for each of its right eye, left eye, nose and mouth: first
/// one centred exactly on the annotated point, then `translations` with the point displaced by
/// up to [`MAX_TRANSLATION`] each way (drawn from `rng`). A face without a nose or mouth
/// annotation gets those crops from where they usually are ([`NOSE_BELOW_EYES`],
/// [`MOUTH_BELOW_EYES`] below the eyes' midpoint).
fn face_crops(
    gray: &image::GrayImage,
    right_eye: crate::Point,
    left_eye: crate::Point,
    nose: Option<crate::Point>,
    mouth: Option<crate::Point>,
    translations: usize,
    rng: &mut SplitMix64,
) -> FaceCrops {
    let face = NormalizedFace::new(gray, face_box_from_eyes(right_eye, left_eye));
    let mut cut = |p| {
        let at = face.from_image(p);
        let mut crops = Vec::with_capacity(1 + translations);
        for t in 0..=translations {
            let (dx, dy) = if t == 0 {
                (0.0, 0.0)
            } else {
                (
                    rng.symmetric(MAX_TRANSLATION),
                    rng.symmetric(MAX_TRANSLATION),
                )
            };
            let mut pixels = vec![0f32; PATCH_SIZE * PATCH_SIZE];
            // The crop centre sits at the feature less (dx, dy): the feature is (dx, dy) from it.
            face.patch(
                crate::Point::new(at.x - dx, at.y - dy),
                PATCH_SIZE,
                0.0,
                0.0,
                &mut pixels,
            );
            crops.push(Crop { pixels, dx, dy });
        }
        crops
    };
    let mid = right_eye.midpoint(left_eye);
    let below = |d: f64| crate::Point::new(mid.x, mid.y + d * right_eye.distance(left_eye));
    let nose = nose.unwrap_or_else(|| below(NOSE_BELOW_EYES));
    let mouth = mouth.unwrap_or_else(|| below(MOUTH_BELOW_EYES));
    [cut(right_eye), cut(left_eye), cut(nose), cut(mouth)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dev::dataset::AnnotatedFace;
    use crate::filters::{normalize_patch, Correlator};
    use crate::Point;

    /// A synthetic face: two dark elliptical "eyes" and a darker "nose" on a light background.
    fn synthetic_face(w: u32, h: u32, re: Point, le: Point, nose: Point) -> image::GrayImage {
        image::GrayImage::from_fn(w, h, |x, y| {
            let blob = |c: Point, sx: f64, sy: f64| {
                let (dx, dy) = ((f64::from(x) - c.x) / sx, (f64::from(y) - c.y) / sy);
                (-(dx * dx + dy * dy)).exp()
            };
            let v = 200.0
                - 150.0 * blob(re, 5.0, 3.0)
                - 150.0 * blob(le, 5.0, 3.0)
                - 120.0 * blob(nose, 4.0, 2.5);
            image::Luma([v.clamp(0.0, 255.0) as u8])
        })
    }

    fn dataset(dir: &std::path::Path, n: usize) -> Vec<AnnotatedFace> {
        (0..n)
            .map(|i| {
                let shift = i as f64 * 0.7;
                let (re, le) = (
                    Point::new(60.0 + shift, 70.0),
                    Point::new(110.0 + shift, 71.0),
                );
                let nose = Point::new(85.0 + shift, 108.0);
                let path = dir.join(format!("face{i:02}.png"));
                synthetic_face(200, 200, re, le, nose)
                    .save(&path)
                    .expect("save");
                AnnotatedFace {
                    image: path,
                    right_eye: re,
                    left_eye: le,
                    nose: Some(nose),
                    mouth: None,
                }
            })
            .collect()
    }

    #[test]
    fn trains_filters_of_each_type_that_find_the_eye_and_is_deterministic() {
        let dir = tempfile::tempdir().expect("temp dir");
        let faces = dataset(dir.path(), 8);
        for kind in FilterType::ALL {
            let options = TrainOptions {
                faces: TrainFaces::All,
                min_eye_distance: 30.0,
                mirror: true,
                min_patches: 16,
                filter_type: kind,
            };
            let (filters, summary) = train_eye_filters(faces.clone(), &options).expect("trained");
            assert_eq!(filters.kind, kind);
            assert_eq!(summary.faces, 8);
            assert_eq!(summary.crops, 16, "8 faces and their mirrors");
            let per_crop = if kind.learns_localisation() {
                1 + TRANSLATIONS as u32
            } else {
                1
            };
            assert_eq!(filters.right_eye.training_count, 16 * per_crop, "{kind}");
            assert_eq!(filters.nose.training_count, 16 * per_crop, "{kind}");
            let (again, _) = train_eye_filters(faces.clone(), &options).expect("trained");
            assert_eq!(filters.to_bytes(), again.to_bytes(), "{kind}");

            // The right-eye filter peaks on a right eye displaced from the crop centre.
            let f = &faces[0];
            let gray = image::open(&f.image).expect("open").to_luma8();
            let face = NormalizedFace::new(&gray, face_box_from_eyes(f.right_eye, f.left_eye));
            let eye = face.from_image(f.right_eye);
            let mut patch = vec![0f32; PATCH_SIZE * PATCH_SIZE];
            face.patch(
                Point::new(eye.x - 6.0, eye.y + 4.0),
                PATCH_SIZE,
                0.0,
                0.0,
                &mut patch,
            );
            normalize_patch(&mut patch);
            let peak = Correlator::new(PATCH_SIZE).correlate(&patch, &filters.right_eye, 12, 12);
            assert!(
                (peak.dx - 6.0).abs() <= 1.0 && (peak.dy + 4.0).abs() <= 1.0,
                "{kind}: {peak:?}"
            );
        }
    }

    #[test]
    fn translated_crops_put_the_feature_where_they_say() {
        let dir = tempfile::tempdir().expect("temp dir");
        let f = &dataset(dir.path(), 1)[0];
        let gray = image::open(&f.image).expect("open").to_luma8();
        let mut rng = SplitMix64::new(3);
        let [right, _, nose, _] =
            face_crops(&gray, f.right_eye, f.left_eye, f.nose, f.mouth, 4, &mut rng);
        assert_eq!((right.len(), nose.len()), (5, 5));
        assert_eq!((right[0].dx, right[0].dy), (0.0, 0.0));
        let c = (PATCH_SIZE / 2) as f64;
        for crop in &right {
            assert!(crop.dx.abs() <= MAX_TRANSLATION && crop.dy.abs() <= MAX_TRANSLATION);
            // The synthetic eye is a dark Gaussian blob: its darkest pixel is within a pixel of
            // (centre + (dx, dy)). The other eye is a whole eye distance (> 40 px) away.
            let (i, _) = crop
                .pixels
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1))
                .expect("non-empty");
            let (x, y) = ((i % PATCH_SIZE) as f64, (i / PATCH_SIZE) as f64);
            assert!(
                (x - c - crop.dx).abs() <= 1.0 && (y - c - crop.dy).abs() <= 1.0,
                "darkest at ({x}, {y}) for offset ({}, {})",
                crop.dx,
                crop.dy
            );
        }
        assert!(right[1..]
            .iter()
            .any(|p| p.dx.abs() > 2.0 || p.dy.abs() > 2.0));
        // The generator is deterministic: the same seed gives the same offsets.
        let mut rng2 = SplitMix64::new(3);
        let [again, _, _, _] = face_crops(
            &gray,
            f.right_eye,
            f.left_eye,
            f.nose,
            f.mouth,
            4,
            &mut rng2,
        );
        assert!(right
            .iter()
            .zip(&again)
            .all(|(a, b)| a.dx == b.dx && a.dy == b.dy));
    }

    #[test]
    fn splitmix_matches_its_reference_stream() {
        // First outputs of SplitMix64 seeded with 0 (the reference C implementation).
        let mut r = SplitMix64::new(0);
        assert_eq!(r.next_u64(), 0xe220_a839_7b1d_cdaf);
        assert_eq!(r.next_u64(), 0x6e78_9e6a_a1b9_65f4);
        let mut r = SplitMix64::new(42);
        assert!((0..1000)
            .map(|_| r.next_f64())
            .all(|v| (0.0..1.0).contains(&v)));
    }

    #[test]
    fn too_few_patches_and_unreadable_images_are_reported() {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut faces = dataset(dir.path(), 3);
        faces[2].image = dir.path().join("missing.png");
        let small = AnnotatedFace {
            left_eye: Point::new(faces[0].right_eye.x + 10.0, 70.0),
            ..faces[0].clone()
        };
        faces.push(small);
        let options = TrainOptions {
            faces: TrainFaces::All,
            min_patches: 2,
            ..Default::default()
        };
        let (_, summary) = train_eye_filters(faces.clone(), &options).expect("trained on two");
        assert_eq!(
            (summary.faces, summary.too_small, summary.unreadable.len()),
            (2, 1, 1)
        );
        // Every photo here holds a face with eyes 50 px apart, one that `eval shear` measures:
        // the default selection leaves all of them out, and too few patches remain.
        let unmeasured = TrainOptions {
            min_patches: 2,
            ..Default::default()
        };
        assert!(matches!(
            train_eye_filters(faces.clone(), &unmeasured),
            Err(Error::Training(_))
        ));
        let strict = TrainOptions {
            faces: TrainFaces::All,
            min_patches: 1500,
            ..Default::default()
        };
        assert!(matches!(
            train_eye_filters(faces, &strict),
            Err(Error::Training(_))
        ));
    }
}
