//! What the pipeline reports: each face's points and estimate, the image's shear, and how a
//! correction is to be applied.

use serde::{Deserialize, Serialize};

use super::row_shear::RowShear;
use crate::annotate::FaceMarks;
use crate::config::Locator;
use crate::geometry::{Point, Rect};
use crate::scene::SceneShear;
use crate::warp::{Canvas, Interpolation};

/// Why a face's estimate was refused (its `k` is `None`, [`FaceReport::k_measured`] kept).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum Refusal {
    /// The learned confidence is below the threshold
    /// ([`Config::min_confidence`](crate::Config::min_confidence)).
    LowConfidence,
    /// |k| beyond [`Config::max_shear`](crate::Config::max_shear), or not finite: no real
    /// camera produces it in a usable picture.
    ImplausibleShear,
    /// The face box or its located points lie largely outside the image: what is measured there
    /// is not seen.
    OutsideImage,
    /// The located points are not laid out as a face's are (eye distance against the box, the
    /// nose and mouth below the eyes), so whatever they found is not a face; or the face's box
    /// holds another face's eyes, or the other way round, and one of the two is not a face.
    NotFaceLike,
    /// A head tipped far back or forward, or foreshortened and rolled, or, found by the network
    /// detector, rolled beyond 35 degrees or beyond 25 and measured strongly sheared, or read
    /// as a face only from a start turned away from the detector's: its shear reading is
    /// unreliable.
    UnreliablePose,
}

impl Refusal {
    /// The name printed in the JSON output (`"low_confidence"`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Self::LowConfidence => "low_confidence",
            Self::ImplausibleShear => "implausible_shear",
            Self::OutsideImage => "outside_image",
            Self::NotFaceLike => "not_face_like",
            Self::UnreliablePose => "unreliable_pose",
        }
    }
}

/// What was found for one face.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[non_exhaustive]
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
    /// Why `k` is `None` (`None` when it was accepted).
    pub refused: Option<Refusal>,
    /// Whether the image's shear was taken from other faces that agree with each other and
    /// outweigh this one's accepted estimate, which disagrees with them beyond both
    /// estimates' uncertainty. Its
    /// own `k` is kept: `--region face` corrects it by it.
    pub outvoted: bool,
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
    /// How far the estimate can be trusted, from 0 to 1: a learned model of the chance that the
    /// estimate is within 0.10 of the truth, times the ruled checks' factor.
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
    /// `LocatedFace::k_points`).
    pub k_points: Option<f64>,
    /// How widely the network's heatmaps spread about the right eye, left eye, nose and mouth,
    /// in eye distances ([`Locator::Network`] only; small when it is sure).
    pub spread: Option<[f64; 4]>,
    /// The network's face score: the chance that the box shows a face at all
    /// ([`Locator::Network`] only; boxes below 0.9 are not reported).
    pub face_score: Option<f64>,
}

/// A face box the search found and the face read in it, if the box gave one (the evaluation
/// tells a face not found from one found without an estimate).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FoundBox {
    /// The box, input-image pixels.
    pub(crate) face_box: Rect,
    /// The face read in it, if any.
    pub(crate) report: Option<FaceReport>,
}

impl FoundBox {
    /// The box `face_box` that gave the face `report`.
    pub(crate) fn face(face_box: Rect, report: FaceReport) -> Self {
        Self {
            face_box,
            report: Some(report),
        }
    }
}

/// Which way the camera read the picture out, and so which way `k` shears it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Readout {
    /// Row by row, as every camera reads its sensor: `x' = x + k y`.
    #[default]
    Rows,
    /// Column by column: a picture its EXIF orientation turns a quarter (a phone held
    /// upright), whose sensor rows are its columns; `y' = y + k x` (see
    /// [`Unshear::estimate_photo`](crate::Unshear::estimate_photo)).
    Columns,
}

/// Which rulers made an image's shear ([`ImageReport::k_source`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[non_exhaustive]
pub enum ShearSource {
    /// The faces alone.
    #[serde(rename = "faces")]
    Faces,
    /// The faces and the scene's verticals, which agreed, combined.
    #[serde(rename = "faces+scene")]
    FacesAndScene,
    /// The scene's verticals alone (no face; [`Ruler::Scene`](crate::config::Ruler::Scene)).
    #[serde(rename = "scene")]
    Scene,
}

impl ShearSource {
    /// The name printed in the JSON output: `"faces"`, `"faces+scene"` or `"scene"`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Faces => "faces",
            Self::FacesAndScene => "faces+scene",
            Self::Scene => "scene",
        }
    }
}

/// What was found in one image.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[non_exhaustive]
pub struct ImageReport {
    /// The image's shear: the confidence-weighted median of the consistent majority of the
    /// faces' accepted estimates, `None` without one.
    pub k: Option<f64>,
    /// Every face with an estimate.
    pub faces: Vec<FaceReport>,
    /// Whether faces had accepted estimates that disagree beyond their uncertainty with no
    /// consistent majority, so the image has no shear.
    pub faces_disagree: bool,
    /// What the caller should know about this result (a search cut short by the image's shape,
    /// say), one sentence each.
    pub warnings: Vec<String>,
    /// Input width, pixels.
    pub width: u32,
    /// Input height, pixels.
    pub height: u32,
    /// Which way the picture was read out: the direction of every `k` here.
    #[serde(default)]
    pub readout: Readout,
    /// The shear the scene's verticals give, when they give one that can be trusted (not read
    /// with [`Ruler::Faces`](crate::config::Ruler::Faces), nor for a picture read out by
    /// columns).
    #[serde(default)]
    pub scene: Option<SceneShear>,
    /// Which rulers made `k` (`None` when `k` is).
    #[serde(default)]
    pub k_source: Option<ShearSource>,
    /// Whether the faces and the scene both gave a shear and these disagree beyond their
    /// uncertainties: the faces decided (the subject moved differently from the camera).
    #[serde(default)]
    pub scene_disagrees: bool,
    /// How the shear changes down the rows, when faces at different heights disagree beyond
    /// their uncertainty (a pan changing speed during the readout); `k` is then its value at
    /// the middle row, and a whole-image correction shifts each row by its own offset.
    #[serde(default)]
    pub row_shear: Option<RowShear>,
}

impl ImageReport {
    /// The report of a `width` x `height` image with nothing found in it (nothing looked
    /// for, say, when a correction's shear is given).
    pub fn empty(width: u32, height: u32) -> Self {
        Self {
            k: None,
            faces: Vec::new(),
            faces_disagree: false,
            warnings: Vec::new(),
            width,
            height,
            readout: Readout::Rows,
            scene: None,
            k_source: None,
            scene_disagrees: false,
            row_shear: None,
        }
    }

    /// The marks [`crate::annotate::draw_annotations`] draws for these faces (the face axis of
    /// a refused estimate is drawn too, with the shear that was measured: the picture shows what
    /// was found; not for a picture read out by columns, whose axis a row shear does not draw).
    pub fn marks(&self) -> Vec<FaceMarks> {
        let rows = self.readout == Readout::Rows;
        self.faces
            .iter()
            .map(|f| FaceMarks {
                face_box: f.face_box,
                right_eye: f.right_eye,
                left_eye: f.left_eye,
                right_nostril: f.right_nostril,
                left_nostril: f.left_nostril,
                mouth: f.mouth,
                k: f.k.or(Some(f.k_measured)).filter(|_| rows),
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
    /// Remove a horizontal motion blur this many pixels long from every row first (whole-image
    /// correction; [`crate::deblur`]); [`Unshear::find_blur`](crate::Unshear::find_blur)
    /// measures it.
    pub blur: Option<f64>,
}

impl CorrectOptions {
    /// Whether correcting with `report` changes anything: a shear is given, or the report has
    /// an accepted estimate for the image (whole-image correction) or for a face (face
    /// regions; a face region also needs a face found). Otherwise the image would come back
    /// as it was, which callers report as "no face" rather than as a correction.
    pub fn changes(&self, report: &ImageReport) -> bool {
        match self.region {
            Region::Image => self.k.is_some() || report.k.is_some(),
            Region::Face => {
                !report.faces.is_empty()
                    && (self.k.is_some() || report.faces.iter().any(|f| f.k.is_some()))
            }
        }
    }
}
