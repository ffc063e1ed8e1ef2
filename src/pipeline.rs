//! The whole method behind one value: detect faces, locate eyes and nostrils, estimate the shear
//! and undo it.
//!
//! ```no_run
//! use unshear::{Unshear, warp::{Canvas, Interpolation}};
//!
//! # fn main() -> unshear::Result<()> {
//! let unshear = Unshear::with_defaults()?;
//! let img = unshear::imageio::read_image("photo.jpg".as_ref(), unshear::imageio::DEFAULT_MAX_PIXELS)?;
//! let report = unshear.estimate(&img);
//! if let Some(k) = report.k {
//!     let fixed = unshear.correct(&img, &report, &unshear::pipeline::CorrectOptions::default())?;
//!     println!("k = {k:.3}, corrected {}x{}", fixed.width(), fixed.height());
//! }
//! # Ok(())
//! # }
//! ```

use std::cell::RefCell;

use image::{DynamicImage, GrayImage};
use serde::Serialize;

use crate::annotate::FaceMarks;
use crate::detect::FaceDetector;
use crate::error::{Error, Result};
use crate::estimate::shear_from_sides;
use crate::features::{FacePoints, FeatureLocator, NormalizedFace};
use crate::filters::{Correlator, EyeFilters};
use crate::geometry::{Point, Rect, Shear};
use crate::warp::{self, Canvas, Interpolation};

/// How much a face box is enlarged (each side, as a fraction of its size) to make the region
/// that `--region face` corrects: the box covers brows to chin; the margin takes in the hair and
/// jaw line, and the feathered edge of the warp lies outside the face.
pub const FACE_REGION_MARGIN: f64 = 0.3;

/// Default number of refinement passes (see [`Unshear::set_refinements`]).
pub const DEFAULT_REFINEMENTS: usize = 0;

/// What was found for one face.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FaceReport {
    /// The face box from the detector, input-image pixels.
    pub face_box: Rect,
    /// Subject's right eye centre (image left).
    pub right_eye: Point,
    /// Subject's left eye centre (image right).
    pub left_eye: Point,
    /// Subject's right nostril (image left).
    pub right_nostril: Point,
    /// Subject's left nostril (image right).
    pub left_nostril: Point,
    /// The shear estimated from this face (equation 5, both sides averaged).
    pub k: f64,
    /// The weakest of the four correlation peaks' peak-to-sidelobe ratios (eyes and nostrils):
    /// a face is only as trustworthy as its least certain feature. Measured on Caltech web
    /// faces, eye peaks reach PSRs of about 2 to 15 and nostril peaks (found with an eye filter)
    /// 1 to 4, so this is usually the nostrils' value; below about 1.5 a feature barely stands out
    /// from the correlation background.
    pub confidence: f64,
    /// Peak-to-sidelobe ratios of right eye, left eye, right nostril, left nostril.
    pub psr: [f64; 4],
}

/// What was found in one image.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImageReport {
    /// The image's shear: the median of the faces' estimates, `None` without a usable face.
    pub k: Option<f64>,
    /// Every face with an estimate.
    pub faces: Vec<FaceReport>,
    /// Input width, pixels.
    pub width: u32,
    /// Input height, pixels.
    pub height: u32,
}

impl ImageReport {
    /// The marks [`crate::annotate::draw_annotations`] draws for these faces.
    pub fn marks(&self) -> Vec<FaceMarks> {
        self.faces
            .iter()
            .map(|f| FaceMarks {
                face_box: f.face_box,
                right_eye: f.right_eye,
                left_eye: f.left_eye,
                right_nostril: f.right_nostril,
                left_nostril: f.left_nostril,
                k: Some(f.k),
            })
            .collect()
    }
}

/// Which part of the image a correction changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Region {
    /// The whole image with one shear (global motion, e.g. a panning camera).
    #[default]
    Image,
    /// Each face region with its own shear, the rest untouched (a moving subject).
    Face,
}

/// How [`Unshear::correct`] warps.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CorrectOptions {
    /// Whole image or faces only.
    pub region: Region,
    /// Output canvas (whole-image correction only; face-region correction keeps the size).
    pub canvas: Canvas,
    /// Row resampling.
    pub interpolation: Interpolation,
    /// Use this shear instead of the estimate (for the whole image, or every face).
    pub k: Option<f64>,
}

/// The rolling-shutter corrector: a face detector and the correlation filters.
#[derive(Debug)]
pub struct Unshear {
    detector: FaceDetector,
    filters: EyeFilters,
    refinements: usize,
}

thread_local! {
    /// One correlator (FFT plans and buffers) per thread, reused by every face it processes.
    static CORRELATOR: RefCell<Option<Correlator>> = const { RefCell::new(None) };
}

impl Unshear {
    /// A corrector from a detector and filters.
    pub fn new(detector: FaceDetector, filters: EyeFilters) -> Self {
        Self {
            detector,
            filters,
            refinements: DEFAULT_REFINEMENTS,
        }
    }

    /// Sets how many times the features are located again in the face de-sheared by the
    /// previous estimate (0: the nose filter's first estimate alone sets the nostril crops).
    pub fn set_refinements(&mut self, refinements: usize) {
        self.refinements = refinements;
    }

    /// The built-in models: OpenCV's `haarcascade_frontalface_alt2` and the trained eye filters.
    pub fn with_defaults() -> Result<Self> {
        Ok(Self::new(
            FaceDetector::frontal_face(),
            EyeFilters::embedded()?,
        ))
    }

    /// The face detector.
    pub fn detector(&self) -> &FaceDetector {
        &self.detector
    }

    /// The filters.
    pub fn filters(&self) -> &EyeFilters {
        &self.filters
    }

    /// The greyscale image the detector and the filters work on.
    pub fn gray(img: &DynamicImage) -> GrayImage {
        crate::detect::to_gray_opencv(img)
    }

    /// Detects the faces in `img` and estimates the shear from each.
    pub fn estimate(&self, img: &DynamicImage) -> ImageReport {
        self.estimate_gray(&Self::gray(img))
    }

    /// [`Self::estimate`] on a greyscale image.
    pub fn estimate_gray(&self, gray: &GrayImage) -> ImageReport {
        let faces: Vec<FaceReport> = self
            .detect_and_estimate(gray)
            .into_iter()
            .filter_map(|(_, face)| face)
            .collect();
        ImageReport {
            k: median(faces.iter().map(|f| f.k).collect()),
            faces,
            width: gray.width(),
            height: gray.height(),
        }
    }

    /// Every detected face box with its estimate, if it gave one (the evaluation needs to tell a
    /// face that was not found from one that was found but gave no estimate).
    pub fn detect_and_estimate(&self, gray: &GrayImage) -> Vec<(Rect, Option<FaceReport>)> {
        self.detector
            .detect(gray)
            .into_iter()
            .map(|b| (b, self.estimate_face(gray, b)))
            .collect()
    }

    /// Locates the features in one face box and estimates its shear; `None` when the points do
    /// not allow an estimate (the nose not below the eyes).
    pub fn estimate_face(&self, gray: &GrayImage, face_box: Rect) -> Option<FaceReport> {
        let positive = |v: f64| v > 0.0 && v.is_finite();
        if gray.width() == 0
            || gray.height() == 0
            || !positive(face_box.width)
            || !positive(face_box.height)
        {
            return None;
        }
        let face = NormalizedFace::new(gray, face_box);
        let size = self.filters.size();
        let points = CORRELATOR.with(|cell| {
            let mut slot = cell.borrow_mut();
            let correlator = match slot.take() {
                Some(c) if c.size() == size => c,
                _ => Correlator::new(size),
            };
            let mut locator = FeatureLocator::with_correlator(&self.filters, correlator);
            let mut points = locator.locate(&face, None);
            for _ in 0..self.refinements {
                match points_shear(&points) {
                    Some(k) => points = locator.locate(&face, Some(k)),
                    None => break,
                }
            }
            *slot = Some(locator.into_correlator());
            points
        });
        let k = points_shear(&points)?;
        Some(FaceReport {
            face_box,
            right_eye: points.right_eye,
            left_eye: points.left_eye,
            right_nostril: points.right_nostril,
            left_nostril: points.left_nostril,
            k,
            confidence: points.psr.iter().copied().fold(f64::INFINITY, f64::min),
            psr: points.psr,
        })
    }

    /// Undoes the shear found in `report` (or `options.k`) on `img` (equation 6).
    ///
    /// Whole image: rows shifted by `-k (y - H/2)`. Faces: each face region (its box enlarged by
    /// [`FACE_REGION_MARGIN`]) de-sheared about its own centre with its own `k`, feathered into the
    /// untouched surroundings. Fails with [`Error::InvalidArgument`] when there is no shear to
    /// apply (no face and no `options.k`) or the shear is not finite.
    pub fn correct(
        &self,
        img: &DynamicImage,
        report: &ImageReport,
        options: &CorrectOptions,
    ) -> Result<DynamicImage> {
        if let Some(k) = options.k {
            if !k.is_finite() {
                return Err(Error::InvalidArgument(format!("shear {k} is not finite")));
            }
        }
        match options.region {
            Region::Image => {
                let k = options.k.or(report.k).ok_or_else(|| {
                    Error::InvalidArgument("no face found and no shear given".into())
                })?;
                let shear = Shear::about_middle(k, img.height());
                Ok(warp::try_remove_shear(img, shear, options.interpolation, options.canvas)?.0)
            }
            Region::Face => {
                if report.faces.is_empty() {
                    return Err(Error::InvalidArgument(
                        "no face found: --region face needs a detected face".into(),
                    ));
                }
                let mut out = img.clone();
                for face in &report.faces {
                    let k = options.k.unwrap_or(face.k);
                    let b = face.face_box;
                    let region = Rect::new(
                        b.x - FACE_REGION_MARGIN * b.width,
                        b.y - FACE_REGION_MARGIN * b.height,
                        b.width * (1.0 + 2.0 * FACE_REGION_MARGIN),
                        b.height * (1.0 + 2.0 * FACE_REGION_MARGIN),
                    );
                    let shear = Shear::new(k, b.center().y);
                    out = warp::remove_shear_in_region(&out, shear, region, options.interpolation);
                }
                Ok(out)
            }
        }
    }
}

/// Equation 5 on located points.
fn points_shear(p: &FacePoints) -> Option<f64> {
    shear_from_sides(
        p.right_eye_point,
        p.right_nose_point,
        p.left_eye_point,
        p.left_nose_point,
    )
}

/// Median of finite values (mean of the middle two for an even count); `None` when empty.
pub fn median(mut values: Vec<f64>) -> Option<f64> {
    values.retain(|v| v.is_finite());
    if values.is_empty() {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    Some(if n % 2 == 1 {
        values[n / 2]
    } else {
        (values[n / 2 - 1] + values[n / 2]) / 2.0
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_even_and_empty() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(vec![]), None);
        assert_eq!(median(vec![f64::NAN, 1.0]), Some(1.0));
    }

    #[test]
    fn no_face_means_no_k_and_correction_needs_one() {
        let unshear = Unshear::with_defaults().expect("built-in models");
        let img = DynamicImage::ImageLuma8(GrayImage::from_pixel(120, 90, image::Luma([128])));
        let report = unshear.estimate(&img);
        assert!(report.faces.is_empty() && report.k.is_none());
        assert!(unshear
            .correct(&img, &report, &CorrectOptions::default())
            .is_err());
        let forced = CorrectOptions {
            k: Some(0.2),
            ..Default::default()
        };
        let out = unshear.correct(&img, &report, &forced).expect("k given");
        assert_eq!((out.width(), out.height()), (120, 90));
        let bad = CorrectOptions {
            k: Some(f64::NAN),
            ..Default::default()
        };
        assert!(unshear.correct(&img, &report, &bad).is_err());
    }

    #[test]
    fn degenerate_boxes_give_no_estimate() {
        let unshear = Unshear::with_defaults().expect("built-in models");
        let gray = GrayImage::from_pixel(50, 50, image::Luma([0]));
        assert!(unshear
            .estimate_face(&gray, Rect::new(0.0, 0.0, 0.0, 10.0))
            .is_none());
        assert!(unshear
            .estimate_face(&gray, Rect::new(0.0, 0.0, f64::NAN, 10.0))
            .is_none());
    }
}
