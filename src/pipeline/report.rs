//! What the pipeline reports: each face's points and estimate, the image's shear, and how a
//! correction is to be applied.

use serde::Serialize;

use crate::annotate::FaceMarks;
use crate::config::Locator;
use crate::geometry::{Point, Rect};
use crate::warp::{Canvas, Interpolation};

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
    /// The mouth centre, when the filters have a mouth filter.
    pub mouth: Option<Point>,
    /// The shear estimated from this face, `None` when the estimate was refused for a
    /// confidence below the corrector's threshold ([`Config::min_confidence`](crate::Config::min_confidence)).
    pub k: Option<f64>,
    /// The shear measured, whether or not it was refused.
    pub k_measured: f64,
    /// The nose axis's own estimate (shear-and-roll model), if usable.
    pub k_nose: Option<f64>,
    /// The mouth axis's own estimate (shear-and-roll model), if usable.
    pub k_mouth: Option<f64>,
    /// The lower nose as the nose filter found it (the point that sets the view the other
    /// features are searched in).
    pub nose_tip: Option<Point>,
    /// The nose-tip axis's own estimate (shear-and-roll model), if usable.
    pub k_nose_tip: Option<f64>,
    /// The nose filter's peak-to-sidelobe ratio (0 when it did not run).
    pub nose_tip_psr: f64,
    /// The head's roll under that shear, degrees (positive: the subject's left eye, on the image
    /// right, lower); 0 with [`ShearModel::Equation5`](crate::estimate::ShearModel::Equation5).
    pub roll_degrees: f64,
    /// How far the estimate can be trusted, from 0 to 1 (see [`pipeline::confidence`](crate::pipeline::confidence)).
    pub confidence: f64,
    /// Peak-to-sidelobe ratios of right eye, left eye, right nostril, left nostril and mouth
    /// (0 without a mouth filter; with the landmark network, which has no correlation peaks for
    /// the eyes and the mouth, only the nostrils' are set).
    pub psr: [f64; 5],
    /// What located the eyes, the nose and the mouth.
    pub locator: Locator,
    /// The landmark network's own reading of the shear ([`Locator::Network`] only).
    pub k_network: Option<f64>,
    /// The shear the network's points give ([`Locator::Network`] only; see
    /// [`LocatedFace::k_points`](crate::locate::network::LocatedFace::k_points)).
    pub k_points: Option<f64>,
    /// How widely the network's heatmaps spread about the right eye, left eye, nose and mouth,
    /// in eye distances ([`Locator::Network`] only; small when it is sure).
    pub spread: Option<[f64; 4]>,
    /// The network's face score: the chance that the box shows a face at all
    /// ([`Locator::Network`] only; boxes below 0.9 are not reported).
    pub face_score: Option<f64>,
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
    /// The marks [`crate::annotate::draw_annotations`] draws for these faces (the face axis of
    /// a refused estimate is drawn too, with the shear that was measured: the picture shows what
    /// was found).
    pub fn marks(&self) -> Vec<FaceMarks> {
        self.faces
            .iter()
            .map(|f| FaceMarks {
                face_box: f.face_box,
                right_eye: f.right_eye,
                left_eye: f.left_eye,
                right_nostril: f.right_nostril,
                left_nostril: f.left_nostril,
                mouth: f.mouth,
                k: f.k.or(Some(f.k_measured)),
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

/// How [`Unshear::correct`](crate::Unshear::correct) warps.
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
