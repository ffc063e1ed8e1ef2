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

use std::borrow::Cow;
use std::cell::RefCell;

use image::{DynamicImage, GrayImage};
use rayon::prelude::*;
use serde::Serialize;

use crate::annotate::FaceMarks;
use crate::detect::{Cascade, DetectorParams, FaceDetector, ProposalNet, ProposalParams};
use crate::error::{Error, Result};
use crate::estimate::shear_and_roll;
use crate::estimate::{estimate_face, FaceEstimate, FeatureGeometry, ShearModel};
use crate::features::{
    FacePoints, FeatureLocator, NormalizedFace, EYE_DISTANCE_PER_BOX_WIDTH, LEFT_EYE_IN_BOX,
    RIGHT_EYE_IN_BOX,
};
use crate::filters::{Correlator, EyeFilters, FilterType};
use crate::geometry::{Point, Rect, Shear};
use crate::landmarks::{self, Budget, LandmarkNet, LocatedFace};
use crate::warp::{self, Canvas, Interpolation, Placement};

/// `b` scaled by `factor` about its centre (a fallback detector's box mapped onto the main
/// detector's; `factor` 1 returns `b` exactly).
fn scaled_about_centre(b: Rect, factor: f64) -> Rect {
    if factor == 1.0 {
        return b;
    }
    let (w, h) = (b.width * factor, b.height * factor);
    Rect::new(b.x + (b.width - w) / 2.0, b.y + (b.height - h) / 2.0, w, h)
}

/// `values` in groups of equal magnitude, the smallest first, each group in the given order.
fn groups_by_magnitude(values: &[f64]) -> Vec<Vec<f64>> {
    let mut sorted = values.to_vec();
    sorted.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    let mut groups: Vec<Vec<f64>> = Vec::new();
    for v in sorted {
        match groups.last_mut() {
            Some(g) if g[0].abs() == v.abs() => g.push(v),
            _ => groups.push(vec![v]),
        }
    }
    groups
}

/// Where the eyes' midpoint sits in a detector box, as fractions of its width and height.
fn eyes_in_box() -> (f64, f64) {
    (
        (RIGHT_EYE_IN_BOX.0 + LEFT_EYE_IN_BOX.0) / 2.0,
        (RIGHT_EYE_IN_BOX.1 + LEFT_EYE_IN_BOX.1) / 2.0,
    )
}

/// The `width x height` box that, turned by `roll` radians about its centre (see
/// [`NormalizedFace::rotated`]), has its eye row's midpoint at `eyes`.
fn box_around_eyes(eyes: Point, width: f64, height: f64, roll: f64) -> Rect {
    let (at_x, at_y) = eyes_in_box();
    // The eyes' offset from the box centre, turned as the face is in the input.
    let (ox, oy) = ((at_x - 0.5) * width, (at_y - 0.5) * height);
    let (s, c) = roll.sin_cos();
    let centre = Point::new(eyes.x - (c * ox - s * oy), eyes.y - (s * ox + c * oy));
    Rect::new(
        centre.x - width / 2.0,
        centre.y - height / 2.0,
        width,
        height,
    )
}

/// How far (degrees) the roll measured on a face may be from the roll its features were searched
/// at before they are searched again in the face turned upright by it
/// ([`Unshear::estimate_face_in_turned_view`]). The eye and nose filters were trained on faces
/// as the detector boxes them, mostly within a few degrees of upright.
///
/// Chosen on the first 300 Caltech development faces (k = 0 and +-0.40, `eval shear --limit
/// 300`), with the Yale recognition check (`eval recognition`, which aligns faces on the
/// located eyes) as a guard. Of all faces within 0.05 at k = 0 / +0.4 / -0.4: 39.3 / 36.3 /
/// 36.3% without the second search; with it, the box turned about its centre, 46.7 / 42.7 /
/// 42.3% at 2.5 degrees, 47.3 / 43.3 / 44.0% at 1 and 49.0 / 44.3 / 44.3% at 0 (every face
/// searched four times). Re-centring the box on the eyes found first measured worse (41.1% of
/// all faces at 5 degrees, 42.6% at 2.5) and moved the eyes of nearly upright Yale faces
/// (rank-1 undistorted 59.2% at 2.5, against 65.0% without the second search; 65.0% with the
/// box turned about its centre). 2.5 keeps faces within a few degrees of upright at one search.
pub const REALIGN_ROLL_DEGREES: f64 = 2.5;

/// How far (as a fraction) the located eye distance over the box width may be from
/// [`EYE_DISTANCE_PER_BOX_WIDTH`] before the features are searched again in the detector's box
/// scaled about its centre to match the eyes found ([`Unshear::estimate_face_in_turned_view`]),
/// the more confident search being kept. The filters were trained at one scale (the eyes
/// [`EYE_DISTANCE_PER_BOX_WIDTH`] box widths apart), and the detector's box varies by about 9%
/// (one std) around it, so a face boxed small or large is seen by the filters enlarged or
/// shrunk. The box is scaled, not re-centred on the eyes (re-centring measured worse, see
/// [`REALIGN_ROLL_DEGREES`]).
///
/// Chosen on the first 300 Caltech development faces (k = 0 and +-0.40, `eval shear --limit
/// 300`): of all faces within 0.05 at k = 0 / +0.4 / -0.4, 47.0 / 42.7 / 43.3% without the
/// second search, 47.7 / 43.3 / 45.0% at 0.05, 47.3 / 44.0 / 44.3% at 0.10 and 47.7 / 43.3 /
/// 44.7% at 0 (every face searched twice); at 0.05, 246 wrong estimates (more than 0.10 off)
/// were accepted of the 900 samples, against 242, and the median time per image rose from 50 to
/// 59 ms.
pub const RESCALE_EYE_RATIO: f64 = 0.05;

/// Most searches in a face turned upright by its measured roll (see [`REALIGN_ROLL_DEGREES`]):
/// a strongly rolled face's first roll reading is short of the truth (its features were searched
/// for upright), so the next search, turned by it, reads more of the roll.
pub const REALIGN_PASSES: usize = 3;

/// How much a face box is enlarged (each side, as a fraction of its size) to make the region
/// that `--region face` corrects: the box covers brows to chin; the margin takes in the hair and
/// jaw line, and the feathered edge of the warp lies outside the face.
pub const FACE_REGION_MARGIN: f64 = 0.3;

/// Shears whose de-sheared views the quick search ([`FaceSearch::Quick`]) tries when the
/// image as it is gives no face with an accepted estimate (the thorough search's are
/// [`THOROUGH_SHEAR_HYPOTHESES`]): the image is de-sheared by each and searched again. The
/// frontal-face cascade tolerates about |k| = 0.15 (detection falls from 92% unsheared to 89%
/// at 0.20 and 68-74% at 0.40 on the Caltech development faces), so views de-sheared by +-0.3 and then, if those give no trusted face,
/// +-0.5 leave at most 0.1 of residual shear for every |k| from 0.2 to 0.6. Costs nothing on
/// images where a face is found and measured at once, and one detection per hypothesis (on a
/// canvas up to `0.5 * height` wider) where none is. Measured effect in the README's
/// *Accuracy*.
pub const DEFAULT_SHEAR_HYPOTHESES: [f64; 4] = [0.3, -0.3, 0.5, -0.5];

/// Head rolls (degrees) whose turned views are searched, after the de-sheared ones, when no view
/// found any face: the image is turned by minus each roll, so that a head tilted that far stands
/// upright for the cascade (which tolerates about 10 degrees of roll). Each costs one more
/// detection on a canvas of about 1.5 times the image's pixels, on images where nothing else
/// found a face. Measured in the README's *Accuracy*.
///
/// Turned views of each de-sheared view as well (ten detections more instead of two) found a
/// few more sheared faces but made an image without a face 3.3-4.2 times slower to search than
/// without turned views (`unshear estimate` on 1920x1080 noise), so they are not searched.
pub const DEFAULT_ROLL_HYPOTHESES: [f64; 2] = [12.0, -12.0];

/// Where the scale ladder of every other de-sheared view of the thorough search (+-0.15 and
/// +-0.45) starts, in steps of the scale factor ([`DetectorParams::scale_offset`]): halfway
/// between OpenCV's rungs.
///
/// A face the cascade barely sees is found at one scale and one resampling of the image or
/// not at all, and a face sheared by `k` is searched mostly in the two views nearest to `k`.
/// With neighbouring views on different ladders those two scan different scales, at no extra
/// cost. Measured on the 928 Caltech development faces (README, *Detection under shear*). The
/// turned views stay on OpenCV's ladder: with the turned view of 25 degrees on the half-step
/// one as well, blurred noise gave a false face (face score 0.92, refused;
/// `tests/end_to_end.rs::the_thorough_search_reports_no_false_faces`).
pub const THOROUGH_HALF_STEP_LADDER: f64 = 0.5;

/// The smallest head roll (degrees) of the thorough search's roll hypotheses whose turned view
/// is also searched de-sheared ([`Unshear::detect_and_estimate`]): the cascade tolerates about
/// 10 degrees of roll and |k| = 0.15 of shear, and a face rolled 12 degrees and sheared is
/// found in a de-sheared view, one rolled 25 or 45 degrees only when turned as well.
///
/// Measured on the 928 Caltech development faces: of the ten rolled 25 degrees or more, the
/// thirteen views alone found all ten at k = 0 but six at k = -0.40; with these views, all ten
/// at eight of the nine shears and eight at -0.40 (README, *Detection under shear*; all ten at
/// -0.40 too with the 25-degree turned views on the half-step ladder, not kept for the reason
/// [`THOROUGH_HALF_STEP_LADDER`] gives).
pub const TURNED_DESHEARED_MIN_ROLL: f64 = 20.0;

/// The shears of the de-sheared turned views when no face of the image was accepted (when one
/// was, its measured shear is used instead): one step each way, which leaves a true |k| of up
/// to 0.45 within the cascade's tolerance of 0.15.
pub const TURNED_DESHEARED_SHEARS: [f64; 2] = [0.3, -0.3];

/// The shear (absolute) measured on the faces found in the image as it is from which the image
/// de-sheared by it is searched for more faces ([`Unshear::detect_and_estimate`]). The
/// cascade tolerates about |k| = 0.15, so below 0.1 the view would show nothing new.
///
/// Measured on the 928 Caltech development faces: at |k| = 0.33-0.40, 22-28 of the 53-63 faces
/// missed per shear were in images where another face had been found and accepted, and 11-13 of
/// those were found unsheared.
pub const MEASURED_VIEW_MIN_SHEAR: f64 = 0.1;

/// How hard [`Unshear::detect_and_estimate`] looks for faces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FaceSearch {
    /// Every view, for every image: the image as it is, each de-sheared view
    /// ([`THOROUGH_SHEAR_HYPOTHESES`]) and each turned view ([`THOROUGH_ROLL_HYPOTHESES`]; these
    /// twelve from boxes of [`THOROUGH_VIEW_MIN_FACE`] up),
    /// with the landmark network's face score (not the detector's neighbour count) deciding
    /// what is a face: the detector is asked for boxes of [`THOROUGH_MIN_NEIGHBORS`] raw hit and
    /// for its near misses ([`THOROUGH_STAGE_SLACK`]), the network looks at up to
    /// [`THOROUGH_BOX_TRIES`] of a face's overlapping boxes, and drops the boxes that show
    /// no face ([`MIN_FACE_SCORE`], [`NEAR_MISS_MIN_FACE_SCORE`]). Needs the network:
    /// with the filters ([`Locator::Filters`]), which can neither tell a false box nor re-crop a
    /// face found in a warped view, the search is quick with these turned views (and the quick
    /// search's de-sheared views, which found more sheared faces with the filters).
    ///
    /// Neighbouring views scan different scales ([`THOROUGH_HALF_STEP_LADDER`]), and the turned
    /// views of strong rolls are searched again de-sheared ([`TURNED_DESHEARED_MIN_ROLL`]).
    /// After the first thirteen views, the windows of the proposal classifier
    /// ([`crate::detect::ProposalNet`], trained on sheared and rolled faces), run once over the
    /// image as it is, are candidates too, strongest first, each where no face has been found
    /// yet, judged like a near miss ([`NEAR_MISS_MIN_FACE_SCORE`]) and kept only if the network
    /// locates the face the window shows ([`PROPOSAL_MAX_OFFSET`], [`PROPOSAL_MAX_SCALE`]): the
    /// marginal faces that one resampling more or less hides from the cascade in every view.
    ///
    /// Measured on the 928 Caltech development faces (README, *Detection under shear*): 98.9 /
    /// 98.4 / 98.4% found at k = 0 / +0.40 / -0.40, 98.4-99.1% at every |k| <= 0.40 (97.7 /
    /// 97.2 / 97.3% at the first three with eleven views and neither near misses nor several
    /// boxes tried), against 94.9 / 94.2 / 94.1% with [`FaceSearch::Quick`], for many times the
    /// time per image (thirteen to seventeen detections instead of usually one).
    #[default]
    Thorough,
    /// The image as it is; the de-sheared and turned views only when it gives no face with an
    /// accepted estimate, and the view de-sheared by the shear measured when it does (see
    /// [`Unshear::detect_and_estimate`]). Misses faces the cascade cannot see as they are in
    /// images where another face was found, and heads rolled more than about 25 degrees.
    Quick,
}

/// Shears whose de-sheared views [`FaceSearch::Thorough`] searches: every 0.15 up to 0.45 each
/// way, so that every |k| up to about 0.5 is left with at most 0.075 of residual shear (the
/// quick search's +-0.3 and +-0.5 leave up to 0.15, and 0.1 at |k| = 0.2 and 0.4). The cascade
/// tolerates about |k| = 0.15, but its marginal faces (found in one view of many, by a
/// couple of windows) are lost to less: of the 928 Caltech development faces, 907-912 were
/// found at each shear against 912 unsheared with the quick search's views, the fewest at
/// +-0.20 and +-0.40; with these views (and [`THOROUGH_BOX_TRIES`]) 910-918 against 915
/// (README, *Detection under shear*).
pub const THOROUGH_SHEAR_HYPOTHESES: [f64; 6] = [0.15, -0.15, 0.3, -0.3, 0.45, -0.45];

/// Head rolls (degrees) whose turned views [`FaceSearch::Thorough`] searches: the cascade
/// tolerates about 10 degrees of roll, so views at 12, 25 and 45 degrees each way reach heads
/// rolled up to about 55 degrees. Of the 47 Caltech development faces the quick search missed
/// unsheared, 20 had a roll of 11 to 51 degrees.
pub const THOROUGH_ROLL_HYPOTHESES: [f64; 6] = [12.0, -12.0, 25.0, -25.0, 45.0, -45.0];

/// The smallest box (pixels wide) of fewer raw hits than the main detector asks for (a lenient
/// box of [`FaceSearch::Thorough`]) that is kept. Most of a detector's windows, and so most of
/// its false alarms, are small, and faces under about 60 px are too small to measure the shear
/// well anyway (see `--min-face`): a lenient detector's small boxes would add false faces and
/// little else. On textured wall beside a Yale face (`tests/properties.rs`) lenient boxes of 21
/// and 26 px gave face scores of 0.94 and 0.95; no face of the evaluation (eyes 40 px apart or
/// more, boxes of about 100 px) is this small.
pub const WEAK_BOX_MIN_WIDTH: f64 = 60.0;

/// The smallest face box (pixels) that [`FaceSearch::Thorough`] looks for in its de-sheared and
/// turned views (the image as it is is searched down to the detector's own smallest box, 20
/// px by default). Most of a detector's time goes to the smallest boxes: without this floor the
/// thorough search took 4.0 s on a 1920x1080 frame against 0.32 s for the quick one
/// (`cargo bench --bench pipeline`). Faces under about 60 px are measured poorly anyway, and
/// `unshear eval shear` already searches from 60 px (1.5 times its 40 px eye distance), so its
/// figures are unchanged by it.
pub const THOROUGH_VIEW_MIN_FACE: u32 = 60;

/// Photos larger than this (pixels) have their warped views searched one after the other rather
/// than in parallel, to bound the memory of the search (each view is a warped copy of the whole
/// photo); 1920x1080 frames stay below it.
pub const PARALLEL_VIEWS_MAX_PIXELS: u64 = 4_000_000;

/// The detector's least number of raw hits for a box in [`FaceSearch::Thorough`] with the
/// landmark network (OpenCV's `minNeighbors`; 3 by default): faces the cascade barely sees
/// gather one or two hits, and the network's face score rejects the false boxes that a
/// lenient count lets through.
pub const THOROUGH_MIN_NEIGHBORS: u32 = 1;

/// How many of the cascade's last stages a window may fail and still count towards a near miss
/// in [`FaceSearch::Thorough`] (see [`DetectorParams::stage_slack`]). Faces the cascade barely
/// sees come and go with small changes of the image, a shear and a de-shear's resampling
/// among them: of the 928 Caltech development faces, 11 found unsheared were missed at
/// k = +0.40 (and 6 the other way round). Near misses bring back faces whose windows fail only
/// the last stages; the network judges them more strictly ([`NEAR_MISS_MIN_FACE_SCORE`]).
/// Measured on the 49 development faces missed at one of k = 0 / +-0.40 (README, *Detection
/// under shear*): found 28 / 23 / 24 with no slack, 31 / 29 / 28 with 1 stage, 32 / 28 / 30
/// with 2, 37 / 31 / 31 with 3, 36 / 32 / 31 with 5 (5 stages: 1.17 times 3's time per image
/// with the final build, README).
pub const THOROUGH_STAGE_SLACK: u32 = 3;

/// The network's face score a near miss of the detector (see [`THOROUGH_STAGE_SLACK`]) needs to
/// be taken for a face, stricter than [`MIN_FACE_SCORE`] as the cascade itself turned its
/// windows down. On the development photos the near misses' false faces (ties, collars, fur,
/// patterned cloth, by eye) scored 0.93-0.994 and most real faces they found over 0.996.
pub const NEAR_MISS_MIN_FACE_SCORE: f64 = 0.995;

/// How many of a group of overlapping boxes [`FaceSearch::Thorough`] lets the network look at,
/// each from a different view, until one shows it a face: the strongest box (most neighbours)
/// is not always the one the network crops well, and a face was lost when another view's box,
/// added to the group, outranked the box that had shown it.
pub const THOROUGH_BOX_TRIES: usize = 3;

/// One view the face search scans: the image de-sheared by `k` about its middle row, then
/// turned against a head roll of `roll` radians, scanned from the scale `scale_offset` steps up
/// the detector's ladder ([`DetectorParams::scale_offset`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct View {
    k: f64,
    roll: f64,
    scale_offset: f64,
}

impl View {
    /// The view on OpenCV's scale ladder.
    fn on_default_ladder(k: f64, roll: f64) -> Self {
        Self {
            k,
            roll,
            scale_offset: 0.0,
        }
    }
}

/// A detected face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// The face box in input-image pixels: where the detector's box lies in the de-sheared view,
    /// moved back so that its eye row is where the face's eyes are in the input.
    pub face_box: Rect,
    /// The shear the view was de-sheared by when the face was found (0: the image as it is).
    pub view_k: f64,
    /// The head roll the view was turned against when the face was found, radians (0: not
    /// turned; see [`DEFAULT_ROLL_HYPOTHESES`]).
    pub view_roll: f64,
    /// The detector's neighbour count (raw hits merged into the box; more is surer).
    pub neighbors: u32,
    /// Whether the box is a near miss of the detector, not one of its detections (see
    /// [`FaceDetector::detect_with_near_misses`] and [`THOROUGH_STAGE_SLACK`]).
    pub near_miss: bool,
}

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
    /// The mouth centre, when the filters have a mouth filter.
    pub mouth: Option<Point>,
    /// The shear estimated from this face, `None` when the estimate was refused for a
    /// confidence below the corrector's threshold ([`Unshear::set_min_confidence`]).
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
    /// right, lower); 0 with [`ShearModel::Equation5`].
    pub roll_degrees: f64,
    /// How far the estimate can be trusted, from 0 to 1 (see [`confidence`]).
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
    /// [`LocatedFace::k_points`]).
    pub k_points: Option<f64>,
    /// How widely the network's heatmaps spread about the right eye, left eye, nose and mouth,
    /// in eye distances ([`Locator::Network`] only; small when it is sure).
    pub spread: Option<[f64; 4]>,
    /// The network's face score: the chance that the box shows a face at all
    /// ([`Locator::Network`] only; boxes below [`MIN_FACE_SCORE`] are not reported).
    pub face_score: Option<f64>,
}

/// What locates a face's features.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Locator {
    /// The landmark network ([`crate::landmarks`]): eyes, nose and mouth from one small
    /// convolutional network, and the shear both from those points and as the network reads it,
    /// cropped again around the face until the estimate settles; the nostrils are still found
    /// with the eye filter, as the paper does, for the report and the annotated picture.
    #[default]
    Network,
    /// The correlation filters throughout, as the paper does (eyes, nostrils; the nose and
    /// mouth filters of this project), with the shear from `ShearModel`.
    Filters,
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

/// A second face detector, asked only when the main one finds no face with an accepted
/// estimate, and how its boxes are mapped onto the main detector's.
///
/// The features are looked for where they sit in the main detector's boxes, so a fallback box is
/// first scaled about its centre by `box_scale` to the size the main detector would give the
/// same face.
#[derive(Debug, Clone)]
pub struct FallbackDetector {
    /// The detector.
    pub detector: FaceDetector,
    /// Main-detector box size over this detector's, for the same face.
    pub box_scale: f64,
}

/// Box size of alt2 over `haarcascade_frontalface_default` for the same face: the median over
/// 455 faces both find (IoU > 0.5) in the first 400 Caltech development images, as OpenCV 4
/// reports them (quartiles 0.943 and 1.0; the centres agree to under 1% of the box);
/// `scripts/cascade_box_scale.py` measures it.
pub const DEFAULT_CASCADE_BOX_SCALE: f64 = 0.968;

impl FallbackDetector {
    /// The embedded `haarcascade_frontalface_default` with `params`, mapped onto alt2's boxes.
    pub fn frontal_face_default(params: DetectorParams) -> Self {
        Self {
            detector: FaceDetector::new(Cascade::frontal_face_default(), params),
            box_scale: DEFAULT_CASCADE_BOX_SCALE,
        }
    }
}

/// The rolling-shutter corrector: a face detector and the correlation filters.
#[derive(Debug)]
pub struct Unshear {
    detector: FaceDetector,
    fallback: Option<FallbackDetector>,
    filters: EyeFilters,
    network: Option<LandmarkNet>,
    locator: Locator,
    refinements: usize,
    model: ShearModel,
    min_confidence: f64,
    shear_hypotheses: Vec<f64>,
    roll_hypotheses: Vec<f64>,
    search_every_view: bool,
    /// The detectors of [`FaceSearch::Thorough`], when it is set (they are used with the
    /// network only).
    thorough: Option<ThoroughDetectors>,
    /// The face proposal classifier of the thorough search ([`Self::set_proposals`]).
    proposals: Option<ProposalNet>,
    /// The landmark network's work per face in a still ([`Self::set_network_budget`]).
    network_budget: Budget,
}

/// The detectors of [`FaceSearch::Thorough`]: both lenient ([`THOROUGH_MIN_NEIGHBORS`]); the
/// one for the de-sheared and turned views also skips boxes under [`THOROUGH_VIEW_MIN_FACE`].
#[derive(Debug, Clone)]
struct ThoroughDetectors {
    as_is: FaceDetector,
    views: FaceDetector,
    /// The de-sheared views ([`THOROUGH_SHEAR_HYPOTHESES`] unless set otherwise): kept here,
    /// not in `Unshear::shear_hypotheses`, so that the filters' quick search (which the
    /// thorough setting falls back to) keeps its own, measured to suit it better.
    shear_hypotheses: Vec<f64>,
}

thread_local! {
    /// One correlator (FFT plans and buffers) per thread, reused by every face it processes.
    static CORRELATOR: RefCell<Option<Correlator>> = const { RefCell::new(None) };
    /// One landmark-network workspace per thread.
    static NET_WORKSPACE: RefCell<landmarks::Workspace> = RefCell::new(landmarks::Workspace::default());
}

impl Unshear {
    /// A corrector from a detector and filters, locating features with the filters
    /// ([`Locator::Filters`]); [`Self::set_network`] adds the landmark network.
    pub fn new(detector: FaceDetector, filters: EyeFilters) -> Self {
        Self {
            detector,
            fallback: None,
            filters,
            network: None,
            locator: Locator::Filters,
            refinements: DEFAULT_REFINEMENTS,
            model: ShearModel::default(),
            min_confidence: DEFAULT_MIN_CONFIDENCE,
            shear_hypotheses: DEFAULT_SHEAR_HYPOTHESES.to_vec(),
            roll_hypotheses: DEFAULT_ROLL_HYPOTHESES.to_vec(),
            search_every_view: false,
            thorough: None,
            proposals: None,
            network_budget: Budget::STILL,
        }
    }

    /// Sets how hard faces are searched for (see [`FaceSearch`]; the corrector of [`Self::new`]
    /// searches quickly, that of [`Self::with_defaults`] thoroughly). Also sets the turned views
    /// and, for the thorough search, its de-sheared views ([`Self::set_roll_hypotheses`] and
    /// [`Self::set_shear_hypotheses`], which may change them afterwards). The thorough search
    /// needs the landmark network to judge its lenient boxes and to re-crop a face found in a
    /// warped view until its estimate settles; with the filters ([`Locator::Filters`]) the
    /// search stays quick, with the thorough search's turned views.
    pub fn set_face_search(&mut self, search: FaceSearch) {
        match search {
            FaceSearch::Thorough => {
                self.roll_hypotheses = THOROUGH_ROLL_HYPOTHESES.to_vec();
                let params = DetectorParams {
                    min_neighbors: THOROUGH_MIN_NEIGHBORS,
                    stage_slack: THOROUGH_STAGE_SLACK,
                    ..*self.detector.params()
                };
                let (w, h) = params.min_size;
                let views = DetectorParams {
                    min_size: (w.max(THOROUGH_VIEW_MIN_FACE), h.max(THOROUGH_VIEW_MIN_FACE)),
                    ..params
                };
                let cascade = self.detector.cascade();
                self.thorough = Some(ThoroughDetectors {
                    as_is: FaceDetector::new(cascade.clone(), params),
                    views: FaceDetector::new(cascade.clone(), views),
                    shear_hypotheses: THOROUGH_SHEAR_HYPOTHESES.to_vec(),
                });
            }
            FaceSearch::Quick => {
                self.roll_hypotheses = DEFAULT_ROLL_HYPOTHESES.to_vec();
                self.thorough = None;
            }
        }
    }

    /// The lenient detectors when the thorough search is on and the network judges their boxes.
    fn thorough_detectors(&self) -> Option<&ThoroughDetectors> {
        self.thorough
            .as_ref()
            .filter(|_| self.locator() == Locator::Network)
    }

    /// Searches every view (the image as it is, each de-sheared and each turned view) for every
    /// image, instead of only when the views before found no trusted face (see
    /// [`Self::detect_and_estimate`]). Finds the faces that the retries miss because another
    /// face of the image was found first, and the faces one view misses that another shows, at
    /// the cost of a detection per view on every image.
    pub fn set_search_every_view(&mut self, every_view: bool) {
        self.search_every_view = every_view;
    }

    /// Sets the shears whose de-sheared views are searched, by the quick and the thorough
    /// search alike (defaults: [`DEFAULT_SHEAR_HYPOTHESES`], and [`THOROUGH_SHEAR_HYPOTHESES`],
    /// which [`Self::set_face_search`] sets again: call this after it); empty, with no roll
    /// hypotheses either ([`Self::set_roll_hypotheses`]): the paper's single detection pass.
    /// Non-finite values are ignored.
    pub fn set_shear_hypotheses(&mut self, hypotheses: &[f64]) {
        self.shear_hypotheses = hypotheses
            .iter()
            .copied()
            .filter(|k| k.is_finite())
            .collect();
        if let Some(thorough) = self.thorough.as_mut() {
            thorough.shear_hypotheses = self.shear_hypotheses.clone();
        }
    }

    /// Sets the head rolls (degrees) whose turned views are searched after the de-sheared ones
    /// (see [`DEFAULT_ROLL_HYPOTHESES`]); empty: none. Non-finite values and 0 are ignored.
    pub fn set_roll_hypotheses(&mut self, degrees: &[f64]) {
        self.roll_hypotheses = degrees
            .iter()
            .copied()
            .filter(|r| r.is_finite() && *r != 0.0)
            .collect();
    }

    /// Sets the detector asked when the main one finds no face with an accepted estimate (see
    /// [`Self::detect_and_estimate`]); `None` (the default of [`Self::new`]) for none.
    pub fn set_fallback_detector(&mut self, fallback: Option<FallbackDetector>) {
        self.fallback = fallback;
    }

    /// Detects the faces in `gray`: first in the image as it is; when that finds none, in the
    /// image de-sheared by the shear hypotheses, smallest |k| first (both signs together), until
    /// a view finds a face, keeping the strongest of overlapping detections; when that finds
    /// none either, the same with the fallback detector.
    pub fn detect(&self, gray: &GrayImage) -> Vec<Detection> {
        for pass in self.detector_passes() {
            let as_is = self.detect_as_is(pass, gray);
            if !as_is.is_empty() {
                return as_is;
            }
            for group in self.view_groups() {
                let found = self.detect_under_hypotheses(pass, gray, &group);
                if !found.is_empty() {
                    return found;
                }
            }
        }
        Vec::new()
    }

    /// Every view searched after the image as it is, as `(shear, roll in radians)` groups in
    /// search order: the de-sheared views ([`Self::hypothesis_groups`]), then for each roll
    /// magnitude (smallest first) the turned image (see [`DEFAULT_ROLL_HYPOTHESES`] for why
    /// the de-sheared views are not turned too).
    fn view_groups(&self) -> Vec<Vec<(f64, f64)>> {
        let sheared = self
            .hypothesis_groups()
            .into_iter()
            .map(|g| g.into_iter().map(|k| (k, 0.0)).collect());
        let turned = groups_by_magnitude(&self.roll_hypotheses)
            .into_iter()
            .map(|g| g.into_iter().map(|r| (0.0, r.to_radians())).collect());
        sheared.chain(turned).collect()
    }

    /// Every view after the image as it is ([`Self::view_groups`], in search order). With
    /// `alternate_ladders` (the thorough search) the de-sheared groups take turns on the
    /// half-step scale ladder and OpenCV's, starting with the half-step one: see
    /// [`THOROUGH_HALF_STEP_LADDER`]. The turned views stay on OpenCV's.
    fn every_view(&self, alternate_ladders: bool) -> Vec<View> {
        self.view_groups()
            .into_iter()
            .enumerate()
            .flat_map(|(i, group)| {
                let de_sheared = group.iter().all(|&(_, roll)| roll == 0.0);
                let scale_offset = if alternate_ladders && de_sheared && i % 2 == 0 {
                    THOROUGH_HALF_STEP_LADDER
                } else {
                    0.0
                };
                group.into_iter().map(move |(k, roll)| View {
                    k,
                    roll,
                    scale_offset,
                })
            })
            .collect()
    }

    /// The shear hypotheses in groups of equal magnitude, the smallest first: the views nearest
    /// to the image as it is are searched first, and farther ones only if those fail, so a face
    /// is measured from the least warped view that finds it.
    fn hypothesis_groups(&self) -> Vec<Vec<f64>> {
        let shears = self
            .thorough_detectors()
            .map_or(&self.shear_hypotheses, |t| &t.shear_hypotheses);
        groups_by_magnitude(shears)
    }

    /// The main detector (boxes as they are; the lenient one of [`FaceSearch::Thorough`] when
    /// the network judges the boxes), then the fallback if there is one.
    fn detector_passes(&self) -> impl Iterator<Item = (&FaceDetector, f64)> {
        let main = self
            .thorough_detectors()
            .map_or(&self.detector, |t| &t.as_is);
        std::iter::once((main, 1.0))
            .chain(self.fallback.as_ref().map(|f| (&f.detector, f.box_scale)))
    }

    fn detect_as_is(
        &self,
        (detector, box_scale): (&FaceDetector, f64),
        gray: &GrayImage,
    ) -> Vec<Detection> {
        tagged_boxes(detector, gray)
            .map(|(face_box, neighbors, near_miss)| Detection {
                face_box: scaled_about_centre(face_box, box_scale),
                view_k: 0.0,
                view_roll: 0.0,
                neighbors,
                near_miss,
            })
            .collect()
    }

    /// Detections in the views de-sheared and turned by each of `hypotheses` (shear, roll), the
    /// strongest of overlapping ones kept (most neighbours, then the smaller hypothesis).
    fn detect_under_hypotheses(
        &self,
        pass: (&FaceDetector, f64),
        gray: &GrayImage,
        hypotheses: &[(f64, f64)],
    ) -> Vec<Detection> {
        let views: Vec<View> = hypotheses
            .iter()
            .map(|&(k, roll)| View::on_default_ladder(k, roll))
            .collect();
        strongest_of_overlapping(self.detect_in_views(pass, gray, &views))
    }

    /// Every detection in `views`, moved back to `gray`, overlapping ones included.
    fn detect_in_views(
        &self,
        pass: (&FaceDetector, f64),
        gray: &GrayImage,
        views: &[View],
    ) -> Vec<Detection> {
        let search = |view: &View| {
            if view.scale_offset == pass.0.params().scale_offset {
                return self.detect_desheared(pass, gray, view.k, view.roll);
            }
            // The same cascade (shared, not copied) on the view's own scale ladder.
            let params = DetectorParams {
                scale_offset: view.scale_offset,
                ..*pass.0.params()
            };
            let detector = FaceDetector::new(pass.0.cascade().clone(), params);
            self.detect_desheared((&detector, pass.1), gray, view.k, view.roll)
        };
        // The views are independent detections: in parallel, so that one image's search uses
        // every core (a batch of images keeps them busy anyway; rayon shares the pool). A large
        // photo's views are searched one at a time, each view's scales still in parallel: a
        // view of a 12 MP photo turned by 45 degrees is about 35 MB, and the detections come
        // out the same in the same order either way.
        let found: Vec<Vec<Detection>> =
            if u64::from(gray.width()) * u64::from(gray.height()) > PARALLEL_VIEWS_MAX_PIXELS {
                views.iter().map(search).collect()
            } else {
                views.par_iter().map(search).collect()
            };
        found.into_iter().flatten().collect()
    }

    /// Detections in `gray` de-sheared by `k` about its middle row and then turned against a
    /// head roll of `roll` radians, moved back to `gray`.
    fn detect_desheared(
        &self,
        (detector, box_scale): (&FaceDetector, f64),
        gray: &GrayImage,
        k: f64,
        roll: f64,
    ) -> Vec<Detection> {
        let shear = Shear::about_middle(k, gray.height());
        // No shear: the image itself (the warp would be an exact copy, with the default
        // placement: `warp`'s test `zero_shear_is_identity_for_every_variant`).
        let (view, placement) = if k == 0.0 {
            (Cow::Borrowed(gray), Placement::default())
        } else {
            match warp::try_remove_shear_gray(gray, shear, Interpolation::Linear, Canvas::Expand) {
                Ok((view, placement)) => (Cow::Owned(view), placement),
                Err(_) => return Vec::new(),
            }
        };
        let (view, rotation) = if roll == 0.0 {
            (view, None)
        } else {
            let turned = warp::rotate::rotate_gray(&view, -roll);
            // Freed before the search rather than at the end of the function, where a shadowed
            // binding would go: on a 12 MP photo, 16 MB for each view searched at once.
            drop(view);
            match turned {
                Ok((turned, rotation)) => (Cow::Owned(turned), Some(rotation)),
                Err(_) => return Vec::new(),
            }
        };
        tagged_boxes(detector, &view)
            .map(|(b, neighbors, near_miss)| {
                let b = scaled_about_centre(b, box_scale);
                // The eye row's midpoint, from the view back to the input; the box keeps its
                // size and is placed around it as the detector placed it (for a turned view,
                // turned about its centre: see `NormalizedFace::rotated`).
                let eyes_in_box = eyes_in_box();
                let in_view = Point::new(
                    b.x + eyes_in_box.0 * b.width,
                    b.y + eyes_in_box.1 * b.height,
                );
                let desheared = rotation.map_or(in_view, |r| r.to_input(in_view));
                let eyes = shear.apply(placement.to_frame(desheared));
                Detection {
                    face_box: box_around_eyes(eyes, b.width, b.height, roll),
                    view_k: k,
                    view_roll: roll,
                    neighbors,
                    near_miss,
                }
            })
            .collect()
    }

    /// Sets the formula that turns the located points into `k` (default
    /// [`ShearModel::ShearRollYaw`]).
    pub fn set_model(&mut self, model: ShearModel) {
        self.model = model;
    }

    /// Sets the confidence below which a face's estimate is refused (`k: None`, and the face does
    /// not count towards the image's shear). 0 accepts every estimate.
    pub fn set_min_confidence(&mut self, min_confidence: f64) {
        self.min_confidence = min_confidence;
    }

    /// Sets how many times the features are located again in the face de-sheared by the
    /// previous estimate (0: the nose filter's first estimate alone sets the nostril crops).
    pub fn set_refinements(&mut self, refinements: usize) {
        self.refinements = refinements;
    }

    /// Sets how much work the landmark network may spend on each face of a still, the
    /// candidate boxes of the face search included (default [`Budget::STILL`]). Fewer crops
    /// (`max_passes`) trade accuracy for time: one crop costs about one forward pass of the
    /// network (README, *Performance*), and the estimate then rests on a crop placed from the
    /// detector's box instead of around the eyes found (README, *Accuracy*, for what that
    /// costs). Video has its own budget (`video::ProcessOptions::network_budget`).
    pub fn set_network_budget(&mut self, budget: Budget) {
        self.network_budget = budget;
    }

    /// The landmark network's work per face in a still (see [`Self::set_network_budget`]).
    pub fn network_budget(&self) -> Budget {
        self.network_budget
    }

    /// The built-in models: OpenCV's `haarcascade_frontalface_alt2`, the trained eye filters,
    /// the landmark network, which locates the features ([`Locator::Network`]), and the face
    /// proposal classifier, searching thoroughly ([`FaceSearch::Thorough`]).
    pub fn with_defaults() -> Result<Self> {
        let mut unshear = Self::new(FaceDetector::frontal_face(), EyeFilters::embedded()?);
        unshear.set_network(Some(LandmarkNet::embedded()?));
        unshear.set_face_search(FaceSearch::Thorough);
        unshear.set_proposals(Some(ProposalNet::embedded()?));
        Ok(unshear)
    }

    /// Sets the face proposal classifier whose windows the thorough search
    /// ([`FaceSearch::Thorough`], with the network) adds to the cascade's boxes as candidates,
    /// where no face has been found yet (see [`FaceSearch::Thorough`]); `None`: the cascade's
    /// boxes only. [`Self::with_defaults`] sets the built-in one ([`ProposalNet::embedded`]).
    pub fn set_proposals(&mut self, proposals: Option<ProposalNet>) {
        self.proposals = proposals;
    }

    /// Sets the landmark network; with one, the features are located by it
    /// ([`Locator::Network`]), without, by the filters. [`Self::set_locator`] chooses between
    /// them afterwards.
    pub fn set_network(&mut self, network: Option<LandmarkNet>) {
        self.locator = if network.is_some() {
            Locator::Network
        } else {
            Locator::Filters
        };
        self.network = network;
    }

    /// Chooses what locates the features; [`Locator::Network`] needs a network
    /// ([`Self::set_network`]) and falls back to the filters without one.
    pub fn set_locator(&mut self, locator: Locator) {
        self.locator = locator;
    }

    /// What locates the features.
    pub fn locator(&self) -> Locator {
        match (self.locator, &self.network) {
            (Locator::Network, Some(_)) => Locator::Network,
            _ => Locator::Filters,
        }
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
            k: combined_shear(&faces),
            faces,
            width: gray.width(),
            height: gray.height(),
        }
    }

    /// Every detected face box with its estimate, if it gave one (the evaluation needs to tell a
    /// face that was not found from one that was found but gave no estimate). With the landmark
    /// network, boxes it finds no face in are left out (see [`MIN_FACE_SCORE`]).
    ///
    /// The de-sheared retries (see [`Self::detect`]) also run when every face found in the image
    /// as it is gave no accepted estimate: a false detection, or a sheared face found but poorly
    /// measured, must not hide a face the retries would find. The views are searched in groups
    /// of equal |k|, nearest first, until one gives an accepted estimate. Of overlapping faces
    /// the one with the higher confidence is kept.
    ///
    /// When the main detector's faces (as they are and in the retries) still give no accepted
    /// estimate, the fallback detector, if set, goes through the same two steps and its faces
    /// join the others.
    ///
    /// The thorough search ([`FaceSearch::Thorough`]) instead searches every view at once, and
    /// then the turned views of strong rolls again in the image de-sheared by the shear its faces
    /// measured (or one step each way if none was accepted): a face both rolled and sheared is
    /// upright in neither kind of view alone.
    pub fn detect_and_estimate(&self, gray: &GrayImage) -> Vec<(Rect, Option<FaceReport>)> {
        // With the network, a box that gives no face (its face score below MIN_FACE_SCORE, or
        // no crop) is dropped: the network looked and saw no face there.
        let network = self.locator() == Locator::Network;
        let strict_neighbors = self.detector.params().min_neighbors;
        // A box the main detector's count would not have given (the thorough search's lenient
        // boxes) is kept only at a size where a face can be measured: dropped before it is
        // merged with others or costs the network a look.
        let measurable = |d: &Detection| {
            (d.neighbors >= strict_neighbors && !d.near_miss)
                || d.face_box.width >= WEAK_BOX_MIN_WIDTH
        };
        let estimate = |d: Detection| {
            let report = self.estimate_detection(gray, &d).filter(|r| {
                // A near miss stands as a face only on the network's strong word.
                !d.near_miss || r.face_score.is_some_and(|s| s >= NEAR_MISS_MIN_FACE_SCORE)
            });
            (!network || report.is_some()).then_some((d.face_box, report))
        };
        let accepted = |found: &[(Rect, Option<FaceReport>)]| {
            found
                .iter()
                .any(|(_, r)| r.as_ref().is_some_and(|r| r.k.is_some()))
        };
        let mut all: Vec<(Rect, Option<FaceReport>)> = Vec::new();
        let thorough = self.thorough_detectors();
        if self.search_every_view || thorough.is_some() {
            // A face is the first of its group's boxes that the network takes for one: the
            // strongest box can be cropped worse than a weaker one from another view.
            let faces = |mut found: Vec<Detection>| {
                found.retain(measurable);
                overlapping_groups(found)
                    .into_iter()
                    .filter_map(|group| tries_of_group(group).into_iter().find_map(estimate))
                    .collect::<Vec<_>>()
            };
            let views = self.every_view(thorough.is_some());
            for (i, pass) in self.detector_passes().enumerate() {
                let views_pass = match (i, thorough) {
                    (0, Some(t)) => (&t.views, 1.0),
                    _ => pass,
                };
                let mut found = self.detect_as_is(pass, gray);
                found.extend(self.detect_in_views(views_pass, gray, &views));
                all.extend(faces(found));
                if let (0, Some(_), Some(net)) = (i, thorough, &self.proposals) {
                    // Strongest first, each judged against the faces found so far (the
                    // cascade's and the stronger windows').
                    for d in proposal_detections(net, gray, WEAK_BOX_MIN_WIDTH) {
                        if !proposal_is_new(&d, &all) {
                            continue;
                        }
                        if let Some((b, Some(r))) = estimate(d) {
                            if proposal_shows(&d, &r) {
                                all.push((b, Some(r)));
                            }
                        }
                    }
                }
                if accepted(&all) {
                    break;
                }
            }
            if let Some(t) = thorough {
                let views = self.turned_desheared_views(&all);
                if !views.is_empty() {
                    // These views look for faces not found yet: a box, or the face it gives,
                    // holding the eyes of a face already found is that face again.
                    let found_eyes: Vec<(Point, Point)> = all
                        .iter()
                        .filter_map(|(_, r)| r.map(|r| (r.right_eye, r.left_eye)))
                        .collect();
                    let holds_found = |b: &Rect| {
                        found_eyes
                            .iter()
                            .any(|&(r, l)| b.contains(r) && b.contains(l))
                    };
                    let mut found = self.detect_in_views((&t.views, 1.0), gray, &views);
                    found.retain(|d| !holds_found(&d.face_box));
                    // The boxes kept hold no found face; the face a box gave may still be one.
                    let new = faces(found)
                        .into_iter()
                        .filter(|(_, r)| !r.as_ref().is_some_and(|r| holds_found(&r.face_box)));
                    all.extend(new.collect::<Vec<_>>());
                }
            }
            return most_confident_of_overlapping(all);
        }
        for (i, pass) in self.detector_passes().enumerate() {
            all.extend(
                self.detect_as_is(pass, gray)
                    .into_iter()
                    .filter_map(estimate),
            );
            if accepted(&all) {
                if i == 0 {
                    // The usual case: the image as it is, in the detector's order, and any
                    // faces the shear measured on these hid from the cascade after them.
                    let more: Vec<Detection> = self.detections_in_measured_view(gray, &all);
                    all.extend(more.into_iter().filter_map(estimate));
                    return all;
                }
                break;
            }
            for group in self.view_groups() {
                let turned = group.iter().any(|&(_, roll)| roll != 0.0);
                if turned && !all.is_empty() {
                    // Turned views look for faces the cascade cannot see upright; a face already
                    // found (if not trusted) is not searched for again at this extra cost.
                    break;
                }
                all.extend(
                    self.detect_under_hypotheses(pass, gray, &group)
                        .into_iter()
                        .filter_map(estimate),
                );
                if accepted(&all) {
                    break;
                }
            }
            if accepted(&all) {
                break;
            }
        }
        most_confident_of_overlapping(all)
    }

    /// The views, de-sheared and turned at once, that the thorough search adds after its
    /// thirteen: a strongly rolled face that is also sheared is neither upright in a turned view
    /// (still sheared) nor in a de-sheared one (still rolled). Each roll hypothesis of at least
    /// [`TURNED_DESHEARED_MIN_ROLL`] degrees is combined with the shear measured on the accepted
    /// faces of `found` (rolling-shutter skew is one per frame) when that is at least
    /// [`MEASURED_VIEW_MIN_SHEAR`], or with each of [`TURNED_DESHEARED_SHEARS`] when no face was
    /// accepted; none when the faces found measure no shear. Each keeps its turned view's scale
    /// ladder (OpenCV's).
    fn turned_desheared_views(&self, found: &[(Rect, Option<FaceReport>)]) -> Vec<View> {
        let shears = match measured_shear(found) {
            Some(k) if k.abs() >= MEASURED_VIEW_MIN_SHEAR => vec![k],
            Some(_) => return Vec::new(),
            None => TURNED_DESHEARED_SHEARS.to_vec(),
        };
        // Each turned view keeps its scale ladder (`every_view`).
        let turned: Vec<View> = self
            .every_view(true)
            .into_iter()
            .filter(|v| v.k == 0.0 && v.roll.to_degrees().abs() >= TURNED_DESHEARED_MIN_ROLL)
            .collect();
        shears
            .iter()
            .flat_map(|&k| turned.iter().map(move |v| View { k, ..*v }))
            .collect()
    }

    /// Faces of `found`'s image that the image de-sheared by the shear measured on `found`'s
    /// accepted faces shows and `found` lacks.
    ///
    /// Rolling-shutter skew is the same for every face of a frame, so when the faces found
    /// measure a shear of at least [`MEASURED_VIEW_MIN_SHEAR`], other faces in the image are
    /// sheared as much and may have been missed by the cascade (each face's own pose decides
    /// whether the cascade tolerates it); one more detection in the view de-sheared by that shear
    /// finds them.
    fn detections_in_measured_view(
        &self,
        gray: &GrayImage,
        found: &[(Rect, Option<FaceReport>)],
    ) -> Vec<Detection> {
        let Some(k) = measured_shear(found) else {
            return Vec::new();
        };
        if k.abs() < MEASURED_VIEW_MIN_SHEAR {
            return Vec::new();
        }
        self.detect_under_hypotheses((&self.detector, 1.0), gray, &[(k, 0.0)])
            .into_iter()
            .filter(|d| found.iter().all(|(b, _)| b.iou(&d.face_box) < 0.3))
            .collect()
    }

    /// Locates the features in one detected face, starting from the view its detection was made
    /// in, and estimates its shear.
    pub fn estimate_detection(
        &self,
        gray: &GrayImage,
        detection: &Detection,
    ) -> Option<FaceReport> {
        self.estimate_face_in_turned_view(
            gray,
            detection.face_box,
            detection.view_k,
            detection.view_roll,
        )
    }

    /// Locates the features in one face box and estimates its shear; `None` when the points do
    /// not allow an estimate (the nose not below the eyes).
    pub fn estimate_face(&self, gray: &GrayImage, face_box: Rect) -> Option<FaceReport> {
        self.estimate_face_in_view(gray, face_box, 0.0)
    }

    /// [`Self::estimate_face`] starting from the face de-sheared by `start_k` (a shear already
    /// known roughly, e.g. from the detection hypothesis or the previous video frame), so that
    /// the filters see nearly upright features from the first pass.
    pub fn estimate_face_in_view(
        &self,
        gray: &GrayImage,
        face_box: Rect,
        start_k: f64,
    ) -> Option<FaceReport> {
        self.estimate_face_in_turned_view(gray, face_box, start_k, 0.0)
    }

    /// [`Self::estimate_face_in_view`] with the landmark network limited to `budget` (see
    /// [`landmarks::Budget`]; video uses [`Budget::VIDEO`]); the same as
    /// [`Self::estimate_face_in_view`] with the filters.
    pub fn estimate_face_in_view_within(
        &self,
        gray: &GrayImage,
        face_box: Rect,
        start_k: f64,
        budget: Budget,
    ) -> Option<FaceReport> {
        self.estimate_turned_within(gray, face_box, start_k, 0.0, budget)
    }

    /// [`Self::estimate_face_in_view`] with the features searched in the face turned against a
    /// head roll of `roll` radians about the box centre (where a turned view found it), so that
    /// the filters see an upright face; the points, and so the estimate, are in the input's
    /// pixels.
    ///
    /// While the roll measured differs from the roll searched at by [`REALIGN_ROLL_DEGREES`] or
    /// more, the features are searched again in the face turned upright by the measured roll
    /// (the box turned about its centre, starting from the shear measured), at most
    /// [`REALIGN_PASSES`] times; then, when the eyes found are [`RESCALE_EYE_RATIO`] or more
    /// off the box's scale, once more in the box scaled to them. The estimate with the highest
    /// confidence is kept, reported with the detector's box.
    pub fn estimate_face_in_turned_view(
        &self,
        gray: &GrayImage,
        face_box: Rect,
        start_k: f64,
        roll: f64,
    ) -> Option<FaceReport> {
        self.estimate_turned_within(gray, face_box, start_k, roll, self.network_budget)
    }

    /// [`Self::estimate_face_in_turned_view`] with the landmark network limited to `budget`
    /// (the filters have no budget).
    fn estimate_turned_within(
        &self,
        gray: &GrayImage,
        face_box: Rect,
        start_k: f64,
        roll: f64,
        budget: Budget,
    ) -> Option<FaceReport> {
        if let (Locator::Network, Some(net)) = (self.locator(), &self.network) {
            return self.network_estimate(net, gray, face_box, start_k, roll, budget);
        }
        let mut best = self.locate_and_estimate(gray, face_box, start_k, roll)?;
        let (mut last, mut searched_roll) = (best, roll);
        let mut best_roll = roll;
        for _ in 0..REALIGN_PASSES {
            let measured_roll = last.roll_degrees.to_radians();
            if (measured_roll - searched_roll).abs() < REALIGN_ROLL_DEGREES.to_radians()
                || !measured_roll.is_finite()
            {
                break;
            }
            // The detector's box, turned about its centre: re-centring it on the eyes found
            // measured worse (see REALIGN_ROLL_DEGREES).
            let Some(next) =
                self.locate_and_estimate(gray, face_box, last.k_measured, measured_roll)
            else {
                break;
            };
            if next.confidence > best.confidence {
                best = next;
                best_roll = measured_roll;
            }
            (last, searched_roll) = (next, measured_roll);
        }
        // The box scaled about its centre to the eyes found (see RESCALE_EYE_RATIO).
        let ratio =
            best.right_eye.distance(best.left_eye) / face_box.width / EYE_DISTANCE_PER_BOX_WIDTH;
        if (ratio - 1.0).abs() >= RESCALE_EYE_RATIO && (0.5..2.0).contains(&ratio) {
            let scaled = face_box.scaled_about_center(ratio);
            let next =
                self.locate_and_estimate_in(gray, scaled, face_box, best.k_measured, best_roll);
            if let Some(next) = next.filter(|n| n.confidence > best.confidence) {
                best = next;
            }
        }
        Some(best)
    }

    /// The features located in `face_box` turned by `roll` (see
    /// [`Self::estimate_face_in_turned_view`]), starting from the view de-sheared by `start_k`,
    /// and the estimate from them.
    fn locate_and_estimate(
        &self,
        gray: &GrayImage,
        face_box: Rect,
        start_k: f64,
        roll: f64,
    ) -> Option<FaceReport> {
        self.locate_and_estimate_in(gray, face_box, face_box, start_k, roll)
    }

    /// [`Self::locate_and_estimate`] with the features searched in `search_box` while the
    /// report, and the confidence's eye-distance term, keep the detector's `face_box`.
    fn locate_and_estimate_in(
        &self,
        gray: &GrayImage,
        search_box: Rect,
        face_box: Rect,
        start_k: f64,
        roll: f64,
    ) -> Option<FaceReport> {
        if !can_search(gray, search_box) {
            return None;
        }
        let face = NormalizedFace::rotated(gray, search_box, roll);
        let size = self.filters.size();
        let points = CORRELATOR.with(|cell| {
            let mut slot = cell.borrow_mut();
            let correlator = match slot.take() {
                Some(c) if c.size() == size => c,
                _ => Correlator::new(size),
            };
            let mut locator = FeatureLocator::with_correlator(&self.filters, correlator);
            let mut points = locator.locate_from(&face, start_k);
            for _ in 0..self.refinements {
                match estimate_face(&geometry(&points), self.model) {
                    Some(e) => {
                        // The nose filter ran in the first pass only; its point stays.
                        points = FacePoints {
                            nose_tip: points.nose_tip,
                            nose_tip_psr: points.nose_tip_psr,
                            ..locator.locate(&face, Some(e.k))
                        }
                    }
                    None => break,
                }
            }
            *slot = Some(locator.into_correlator());
            points
        });
        let estimate = estimate_face(&geometry(&points), self.model)?;
        let psr = [
            points.psr[0],
            points.psr[1],
            points.psr[2],
            points.psr[3],
            points.mouth_psr,
        ];
        let model = ConfidenceModel::for_filters(self.filters.kind);
        let confidence = confidence(&points, &estimate, face_box, &model);
        Some(FaceReport {
            face_box,
            right_eye: points.right_eye,
            left_eye: points.left_eye,
            right_nostril: points.right_nostril,
            left_nostril: points.left_nostril,
            mouth: points.mouth,
            k: (confidence >= self.min_confidence).then_some(estimate.k),
            k_measured: estimate.k,
            k_nose: estimate.k_nose,
            k_mouth: estimate.k_mouth,
            nose_tip: points.nose_tip,
            k_nose_tip: estimate.k_nose_tip,
            nose_tip_psr: points.nose_tip_psr,
            roll_degrees: estimate.roll.to_degrees(),
            confidence,
            psr,
            locator: Locator::Filters,
            k_network: None,
            k_points: None,
            spread: None,
            face_score: None,
        })
    }

    /// The landmark network's estimate for the face in `face_box` (turned by `roll` about its
    /// centre, where a turned view found it), starting from the view de-sheared by `start_k`:
    /// the first crop is placed where the box predicts the eyes, and [`landmarks::locate`]
    /// crops again around the eyes it finds until the estimate settles (which also takes care
    /// of a tilted head and a box of the wrong size, the filters' second searches). The
    /// nostrils are then found with the eye filter below the network's eyes.
    fn network_estimate(
        &self,
        net: &LandmarkNet,
        gray: &GrayImage,
        face_box: Rect,
        start_k: f64,
        roll: f64,
        budget: Budget,
    ) -> Option<FaceReport> {
        if !can_search(gray, face_box) || !start_k.is_finite() || !roll.is_finite() {
            return None;
        }
        // Where the box predicts the eyes' midpoint, turned with the box about its centre.
        let (at_x, at_y) = eyes_in_box();
        let centre = face_box.center();
        let (ox, oy) = (
            (at_x - 0.5) * face_box.width,
            (at_y - 0.5) * face_box.height,
        );
        let (s, c) = roll.sin_cos();
        let eyes = Point::new(centre.x + c * ox - s * oy, centre.y + s * ox + c * oy);
        let start = net.frame(
            eyes,
            EYE_DISTANCE_PER_BOX_WIDTH * face_box.width,
            start_k,
            roll,
        );
        let found = NET_WORKSPACE
            .with(|ws| landmarks::locate_within(net, gray, start, budget, &mut ws.borrow_mut()))?;
        if found.face < MIN_FACE_SCORE {
            // Not a face: a false detection, which must not report a shear.
            return None;
        }
        if found.roll.abs() > crate::estimate::MAX_ROLL {
            // A face rolled beyond what the search looks for (turned views up to 45 degrees and
            // the cascade's tolerance about them) and where shear and roll stop being separable
            // (see MAX_ROLL): on the development photos these were patterns the network read
            // sideways or upside down, and copies of faces found upright in another box.
            return None;
        }
        let nostrils = self.nostrils_below(gray, &found);
        let eye_line = Point::new(
            found.left_eye.x - found.right_eye.x,
            found.left_eye.y - found.right_eye.y,
        );
        let mid = found.right_eye.midpoint(found.left_eye);
        let nostril_mid = nostrils[0].0.midpoint(nostrils[1].0);
        let k_nostrils = shear_and_roll(
            eye_line,
            Point::new(nostril_mid.x - mid.x, nostril_mid.y - mid.y),
        )
        .map(|r| r.k);
        let confidence = network_confidence(&found, face_box, &ConfidenceModel::NETWORK);
        Some(FaceReport {
            face_box,
            right_eye: found.right_eye,
            left_eye: found.left_eye,
            right_nostril: nostrils[0].0,
            left_nostril: nostrils[1].0,
            mouth: Some(found.mouth),
            k: (confidence >= self.min_confidence).then_some(found.k),
            k_measured: found.k,
            k_nose: k_nostrils,
            k_mouth: found.k_mouth,
            nose_tip: Some(found.nose),
            k_nose_tip: found.k_nose,
            nose_tip_psr: 0.0,
            roll_degrees: found.roll.to_degrees(),
            confidence,
            psr: [0.0, 0.0, nostrils[0].1, nostrils[1].1, 0.0],
            locator: Locator::Network,
            k_network: Some(found.k_network),
            k_points: found.k_points,
            spread: Some(found.spread),
            face_score: Some(found.face),
        })
    }

    /// The paper's nostrils below the network's eyes, in the face de-sheared by its estimate.
    fn nostrils_below(&self, gray: &GrayImage, found: &LocatedFace) -> [(Point, f64); 2] {
        let face_box = crate::features::face_box_from_eyes(found.right_eye, found.left_eye);
        let size = self.filters.size();
        // Only the rows the two nostril patches read: about a third of the face, the same
        // values there (a whole normalised face was about a tenth of a face's estimate).
        let (v_lo, v_hi) =
            crate::features::nostril_band(face_box, found.right_eye, found.left_eye, found.k, size);
        let face = NormalizedFace::band(gray, face_box, v_lo, v_hi);
        CORRELATOR.with(|cell| {
            let mut slot = cell.borrow_mut();
            let correlator = match slot.take() {
                Some(c) if c.size() == size => c,
                _ => Correlator::new(size),
            };
            let mut locator = FeatureLocator::with_correlator(&self.filters, correlator);
            let nostrils = locator.nostrils_below(&face, found.right_eye, found.left_eye, found.k);
            *slot = Some(locator.into_correlator());
            nostrils
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
                    let Some(k) = options.k.or(face.k) else {
                        continue;
                    };
                    let b = face.face_box;
                    let region = b.scaled_about_center(1.0 + 2.0 * FACE_REGION_MARGIN);
                    let shear = Shear::new(k, b.center().y);
                    out = warp::remove_shear_in_region(&out, shear, region, options.interpolation);
                }
                Ok(out)
            }
        }
    }
}

/// The points the estimators use.
fn geometry(p: &FacePoints) -> FeatureGeometry {
    FeatureGeometry {
        right_eye: p.right_eye,
        left_eye: p.left_eye,
        right_pair: (p.right_eye_point, p.right_nose_point),
        left_pair: (p.left_eye_point, p.left_nose_point),
        nose: p.right_nostril.midpoint(p.left_nostril),
        mouth: p.mouth,
        nose_tip: p.nose_tip,
    }
}

/// Default for [`Unshear::set_min_confidence`]: refuses about the least trustworthy fifth of the
/// estimates on web photos (see [`confidence`] for what the threshold buys).
pub const DEFAULT_MIN_CONFIDENCE: f64 = 0.25;

/// A logistic confidence model: weights of [`confidence`]'s features, in their order, and the
/// intercept. Printed by `scripts/fit_confidence.py`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConfidenceModel {
    /// One weight per feature.
    pub weights: [f64; 7],
    /// The intercept.
    pub intercept: f64,
}

impl ConfidenceModel {
    /// The logistic model's probability for `features` (0 when not finite).
    pub fn probability(&self, features: &[f64; 7]) -> f64 {
        let z = self.intercept
            + features
                .iter()
                .zip(self.weights)
                .map(|(x, w)| x * w)
                .sum::<f64>();
        let p = 1.0 / (1.0 + (-z).exp());
        if p.is_finite() {
            p
        } else {
            0.0
        }
    }

    /// The model fitted for filters of type `kind`: the peak-to-sidelobe ratios of the three
    /// filter types live on different scales, so each has its own fit (see [`confidence`]).
    pub fn for_filters(kind: FilterType) -> Self {
        match kind {
            // Each fitted on the estimates of the first 300 faces in image-path order
            // (`fit_confidence.py --fit-first 300`), with the filters trained on the annotations
            // read as 1-based (see `dataset::CALTECH_PIXEL_ORIGIN`), and checked on the other
            // 628 faces' estimates. UMACE: fitted on 845, AUC 0.836 on 1777.
            FilterType::Umace => Self {
                weights: [0.452, -0.137, 3.087, 0.938, -6.348, -0.636, -0.134],
                intercept: -4.204,
            },
            // ASEF: fitted on 848, AUC 0.825 on 1776.
            FilterType::Asef => Self {
                weights: [1.021, 0.070, 2.528, 0.937, -8.181, -0.310, -0.046],
                intercept: -3.803,
            },
            // MOSSE: fitted on 847, AUC 0.818 on 1782.
            FilterType::Mosse => Self {
                weights: [1.042, 0.238, 3.019, 1.074, -9.038, -0.327, -0.558],
                intercept: -4.348,
            },
        }
    }
}

/// A face's confidence, 0 to 1: a logistic model of the chance that its estimate is within 0.10
/// of the true shear, from how clearly each feature stood out and whether the face's geometry is
/// consistent:
///
/// 1. `ln` of the weaker eye peak's peak-to-sidelobe ratio (PSRs below 0.1 count as 0.1);
/// 2. `ln` of the weaker nostril peak's PSR;
/// 3. `ln` of the mouth peak's PSR (0.1 without a mouth filter);
/// 4. `ln` of the nose filter's PSR (0.1 when it did not run);
/// 5. how far the nose tip's and the mouth's own estimates disagree, `|k_nose_tip - k_mouth|`
///    (0.5 when either is missing);
/// 6. the roll, `|degrees| / 10` (frontal faces in photos rarely roll much);
/// 7. how far the located eye distance over the box width is from the detector's 0.381, times 10.
///
/// Each filter type's model ([`ConfidenceModel::for_filters`]) was fitted by logistic regression
/// (`scripts/fit_confidence.py`, which documents the commands) on the estimates of 300 of the 928
/// Caltech development faces with eyes at least 40 px apart, at k = 0 and +-0.40, with the
/// default pipeline and those filters, and checked on the estimates of the other 628 faces,
/// which were not used to fit it (the first 300 by image path for every type). The mouth's PSR
/// and the nose/mouth disagreement weigh most. With MOSSE filters (the default), on its 1782
/// check estimates, the default threshold of 0.25 keeps 83% of them with 69% within 0.10 (all:
/// 61%); 0.3 keeps 79% with 71%, 0.5 keeps 63% with 78%. With UMACE, 0.25 keeps 84% of 1777
/// with 66% within 0.10 (all: 59%). (A refused face is retried in de-sheared views, so in the
/// whole pipeline fewer faces end up refused than these shares suggest.)
pub fn confidence(
    points: &FacePoints,
    estimate: &FaceEstimate,
    face_box: Rect,
    model: &ConfidenceModel,
) -> f64 {
    let ln = |v: f64| v.max(0.1).ln();
    let eyes = points.psr[0].min(points.psr[1]);
    let nostrils = points.psr[2].min(points.psr[3]);
    let disagreement = match (estimate.k_nose_tip, estimate.k_mouth) {
        (Some(n), Some(m)) => (n - m).abs(),
        _ => 0.5,
    };
    let ratio = points.right_eye.distance(points.left_eye) / face_box.width.max(1.0);
    let features = [
        ln(eyes),
        ln(nostrils),
        ln(points.mouth_psr),
        ln(points.nose_tip_psr),
        disagreement,
        estimate.roll.to_degrees().abs() / 10.0,
        (ratio - EYE_DISTANCE_PER_BOX_WIDTH).abs() * 10.0,
    ];
    model.probability(&features)
}

/// Whether a face can be searched for in `b` of `gray`: a non-empty image and a box of finite,
/// positive size.
fn can_search(gray: &GrayImage, b: Rect) -> bool {
    let positive = |v: f64| v > 0.0 && v.is_finite();
    gray.width() > 0 && gray.height() > 0 && positive(b.width) && positive(b.height)
}

/// `detector`'s boxes in `gray` with their neighbour counts, its near misses (none unless its
/// [`DetectorParams::stage_slack`] is set) tagged `true`.
fn tagged_boxes(
    detector: &FaceDetector,
    gray: &GrayImage,
) -> impl Iterator<Item = (Rect, u32, bool)> {
    let found = detector.detect_with_near_misses(gray);
    let detected = found.detected.into_iter().map(|(b, n)| (b, n, false));
    detected.chain(found.near_misses.into_iter().map(|(b, n)| (b, n, true)))
}

/// How far (in the window's eye distances) the eyes the network located from a proposal
/// window may be from where the window expects them, for the face to count as the window's.
pub const PROPOSAL_MAX_OFFSET: f64 = 0.5;

/// How much larger or smaller than the window expects the located eye distance may be.
pub const PROPOSAL_MAX_SCALE: f64 = 1.5;

/// Where a proposal (see [`proposal_detections`]) expects the eyes' midpoint, and their
/// distance.
fn proposal_eyes(proposal: &Detection) -> (Point, f64) {
    let b = proposal.face_box;
    let (at_x, at_y) = eyes_in_box();
    (
        Point::new(b.x + at_x * b.width, b.y + at_y * b.height),
        b.width * EYE_DISTANCE_PER_BOX_WIDTH,
    )
}

/// Whether a proposal may show a face not among `found`: its box holds the eyes of none of
/// about its size ([`PROPOSAL_MAX_SCALE`]; that face again), and its eyes are inside the box of
/// none of about its size or larger (part of that face at a smaller scale: a large face's nose
/// and nostrils can look like a small face to the classifier and the network alike). A much
/// larger window around a smaller face found is still searched: that "face" can be the nose of
/// the larger one.
fn proposal_is_new(proposal: &Detection, found: &[(Rect, Option<FaceReport>)]) -> bool {
    let (eyes, distance) = proposal_eyes(proposal);
    let b = proposal.face_box;
    found.iter().all(|(_, r)| {
        r.is_none_or(|r| {
            let holds_it = holds_eyes(&b, &r);
            let ratio = r.right_eye.distance(r.left_eye) / distance;
            let at_least_as_large = ratio * PROPOSAL_MAX_SCALE >= 1.0;
            let about_as_large = at_least_as_large && ratio <= PROPOSAL_MAX_SCALE;
            let same_face = holds_it && about_as_large;
            let part_of_it = at_least_as_large && r.face_box.contains(eyes);
            !(same_face || part_of_it)
        })
    })
}

/// Whether the face the network located from a proposal (see [`proposal_detections`]) is the
/// one its window shows: its eyes' midpoint within [`PROPOSAL_MAX_OFFSET`] of where the window
/// expects it and its eye distance within [`PROPOSAL_MAX_SCALE`] of the window's. The network
/// can walk from a window beside a face to part of it, or to another face.
fn proposal_shows(proposal: &Detection, face: &FaceReport) -> bool {
    let (expected_eyes, expected) = proposal_eyes(proposal);
    let distance = face.right_eye.distance(face.left_eye);
    face.right_eye
        .midpoint(face.left_eye)
        .distance(expected_eyes)
        < PROPOSAL_MAX_OFFSET * expected
        && (distance / expected).ln().abs() < PROPOSAL_MAX_SCALE.ln()
}

/// The proposal classifier's windows in `gray` (see [`ProposalNet`]) as
/// candidate boxes of at least `min_width` pixels: each the box a detector would draw around
/// the eyes the window expects, upright and unsheared, marked as a near miss (the network
/// must be as sure of it as of the cascade's near misses, [`NEAR_MISS_MIN_FACE_SCORE`]).
fn proposal_detections(net: &ProposalNet, gray: &GrayImage, min_width: f64) -> Vec<Detection> {
    let params = ProposalParams {
        min_eye_distance: min_width * EYE_DISTANCE_PER_BOX_WIDTH,
        ..ProposalParams::default()
    };
    net.propose(gray, &params)
        .into_iter()
        .map(|p| proposal_detection(p.eyes_midpoint, p.eye_distance))
        .collect()
}

/// The candidate box of a proposal window expecting eyes `eye_distance` apart with their
/// midpoint at `eyes` (see [`proposal_detections`]); [`proposal_eyes`] reads them back.
fn proposal_detection(eyes: Point, eye_distance: f64) -> Detection {
    let width = eye_distance / EYE_DISTANCE_PER_BOX_WIDTH;
    Detection {
        face_box: box_around_eyes(eyes, width, width, 0.0),
        view_k: 0.0,
        view_roll: 0.0,
        neighbors: 0,
        near_miss: true,
    }
}

/// Of detections whose boxes overlap (IoU 0.3 or more), the strongest: a detection before a
/// near miss, then most detector neighbours, then the view least warped (smaller |shear|, then
/// smaller |roll|).
fn strongest_of_overlapping(found: Vec<Detection>) -> Vec<Detection> {
    overlapping_groups(found)
        .into_iter()
        .filter_map(|group| group.into_iter().next())
        .collect()
}

/// Detections grouped by overlap, each group strongest first (see [`strongest_of_overlapping`]
/// for the order): a detection joins the first group whose strongest box it overlaps (IoU 0.3
/// or more), or starts a new one.
fn overlapping_groups(mut found: Vec<Detection>) -> Vec<Vec<Detection>> {
    found.sort_by(|a, b| {
        a.near_miss
            .cmp(&b.near_miss)
            .then(b.neighbors.cmp(&a.neighbors))
            .then(a.view_k.abs().total_cmp(&b.view_k.abs()))
            .then(a.view_roll.abs().total_cmp(&b.view_roll.abs()))
    });
    let mut groups: Vec<Vec<Detection>> = Vec::new();
    for d in found {
        match groups
            .iter_mut()
            .find(|g| g[0].face_box.iou(&d.face_box) >= 0.3)
        {
            Some(group) => group.push(d),
            None => groups.push(vec![d]),
        }
    }
    groups
}

/// The first of a group of overlapping detections (strongest first, [`overlapping_groups`])
/// and the next ones from views not yet tried, at most [`THOROUGH_BOX_TRIES`] in all: the
/// boxes worth a look when the ones before gave no face.
fn tries_of_group(group: Vec<Detection>) -> Vec<Detection> {
    let mut tries: Vec<Detection> = Vec::new();
    for d in group {
        let new_view = tries
            .iter()
            .all(|t| (t.view_k, t.view_roll) != (d.view_k, d.view_roll));
        if new_view && tries.len() < THOROUGH_BOX_TRIES {
            tries.push(d);
        }
    }
    tries
}

/// Whether `b` holds both eyes that `report` located.
fn holds_eyes(b: &Rect, report: &FaceReport) -> bool {
    b.contains(report.right_eye) && b.contains(report.left_eye)
}

/// How close (in eye distances, the smaller of the two faces') the eye midpoints of two
/// estimates must be for them to be one face found twice (`same_face` in this module). Two
/// people's eye midpoints are two or more eye distances apart even in a crowd.
pub const SAME_FACE_EYE_DISTANCES: f64 = 0.5;

/// Whether two estimates located the same face: their eye midpoints within
/// [`SAME_FACE_EYE_DISTANCES`]. Their boxes can still differ much: a turned view's box around
/// a whole head, say, from which the features were followed to the face that another box holds
/// tightly.
fn same_face(a: &FaceReport, b: &FaceReport) -> bool {
    let eye_distance = a
        .right_eye
        .distance(a.left_eye)
        .min(b.right_eye.distance(b.left_eye));
    let apart = a
        .right_eye
        .midpoint(a.left_eye)
        .distance(b.right_eye.midpoint(b.left_eye));
    apart < SAME_FACE_EYE_DISTANCES * eye_distance
}

/// Of faces whose boxes overlap (IoU 0.3 or more), whose estimates located the same face
/// ([`same_face`]), or of which one's box holds both eyes located in another kept before it, the
/// one with the most confident estimate (a face without an estimate last), preferring one whose
/// box holds both eyes it located: a box the features were followed out of (from a false alarm
/// beside the face, say) does not show where the face is. A box holding both eyes of a face
/// already kept is that face seen again, often from a view that takes in the whole head, whose
/// walk of crops may have stopped on something else (eyes of two faces, say) before reaching
/// it; two people's faces cannot both fit in one face box.
fn most_confident_of_overlapping(
    mut all: Vec<(Rect, Option<FaceReport>)>,
) -> Vec<(Rect, Option<FaceReport>)> {
    let confidence = |r: &Option<FaceReport>| r.as_ref().map_or(-1.0, |r| r.confidence);
    let holds_its_eyes =
        |(b, r): &(Rect, Option<FaceReport>)| r.as_ref().is_some_and(|r| holds_eyes(b, r));
    all.sort_by(|a, b| {
        holds_its_eyes(b)
            .cmp(&holds_its_eyes(a))
            .then(confidence(&b.1).total_cmp(&confidence(&a.1)))
    });
    let mut kept: Vec<(Rect, Option<FaceReport>)> = Vec::new();
    for f in all {
        let duplicate = |k: &(Rect, Option<FaceReport>)| {
            k.0.iou(&f.0) >= 0.3
                || matches!((&k.1, &f.1), (Some(a), Some(b)) if same_face(a, b))
                || matches!(&k.1, Some(a) if holds_eyes(&f.0, a))
        };
        if !kept.iter().any(duplicate) {
            kept.push(f);
        }
    }
    kept
}

/// The network's face score below which a detection is taken for something else and dropped
/// (see [`FaceReport::face_score`]): the score is the network's chance that its crop shows a
/// face, trained on face crops against crops of the detector's false alarms and of random
/// places.
///
/// Chosen with the thorough search's lenient boxes in view ([`FaceSearch::Thorough`]): of the
/// 2717 true faces it found in the 928 Caltech development faces at k = 0 and +-0.40, 4 scored
/// under 0.9 (1 under 0.7), while a patch of textured wall beside a Yale face enlarged twice
/// (`tests/properties.rs`) scored 0.73. 0.5 let that wall through.
pub const MIN_FACE_SCORE: f64 = 0.9;

impl ConfidenceModel {
    /// The model fitted for the landmark network (see [`network_confidence`]).
    ///
    /// Fitted by `scripts/fit_confidence.py target/d3 --fit-first 300 --locator network` on
    /// `unshear eval shear --k=0,0.4,-0.4 --min-confidence 0 --out target/d3`: 848 estimates of
    /// the first 300 faces, only 5 of them more than 0.10 off, so the weights are loose (the nose
    /// and mouth axes' disagreement even gets a positive weight); checked on the other 628
    /// faces (1782 estimates, 98.5% within 0.10): AUC 0.762, and at the default threshold it
    /// refuses 12 good estimates and keeps 25 bad ones. The network rarely fails on a face; the
    /// face score, the other factor, is what refuses non-faces.
    pub const NETWORK: Self = Self {
        weights: [-44.117, -12.666, -46.895, -34.514, 23.092, 0.843, -0.628],
        intercept: 27.316,
    };
}

/// A landmark-network face's confidence, 0 to 1: its face score (the chance that it is a face at
/// all) times a logistic model of the chance that, being a face, its estimate is within 0.10 of
/// the true shear, from
///
/// 1. the wider of the two eye heatmaps' spreads (eye distances);
/// 2. the nose heatmap's spread;
/// 3. the mouth heatmap's spread;
/// 4. how far the network's own reading and the points' shear disagree,
///    `|k_network - k_points|` (0.5 without `k_points`);
/// 5. how far the nose axis and the mouth axis disagree (0.5 when either is missing);
/// 6. the roll, `|degrees| / 10`;
/// 7. how far the located eye distance over the detector's box width is from 0.381, times 10
///    (a box that does not fit the eyes found: a false detection, or eyes found elsewhere).
pub fn network_confidence(found: &LocatedFace, face_box: Rect, model: &ConfidenceModel) -> f64 {
    let ratio = found.right_eye.distance(found.left_eye) / face_box.width.max(1.0);
    let features = [
        found.spread[0].max(found.spread[1]),
        found.spread[2],
        found.spread[3],
        found.k_points.map_or(0.5, |p| (found.k_network - p).abs()),
        match (found.k_nose, found.k_mouth) {
            (Some(n), Some(m)) => (n - m).abs(),
            _ => 0.5,
        },
        found.roll.to_degrees().abs() / 10.0,
        (ratio - EYE_DISTANCE_PER_BOX_WIDTH).abs() * 10.0,
    ];
    let c = found.face * model.probability(&features);
    if c.is_finite() {
        c
    } else {
        0.0
    }
}

/// [`combined_shear`] of the faces in `found` that gave an estimate.
fn measured_shear(found: &[(Rect, Option<FaceReport>)]) -> Option<f64> {
    let reports: Vec<FaceReport> = found.iter().filter_map(|(_, r)| *r).collect();
    combined_shear(&reports)
}

/// The image's shear from its faces' accepted estimates: their confidence-weighted median (the
/// value where half of the total confidence lies on either side), robust to a minority of faces
/// whose features were mislocated, and led by the faces the estimator trusts most. Faces with
/// refused estimates do not count; `None` when no face has an accepted estimate.
pub fn combined_shear(faces: &[FaceReport]) -> Option<f64> {
    let mut weighted: Vec<(f64, f64)> = faces
        .iter()
        .filter_map(|f| Some((f.k?, f.confidence.max(1e-6))))
        .filter(|(k, w)| k.is_finite() && w.is_finite())
        .collect();
    if weighted.is_empty() {
        return None;
    }
    weighted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = weighted.iter().map(|(_, w)| w).sum();
    let mut below = 0.0;
    for (i, &(k, w)) in weighted.iter().enumerate() {
        below += w;
        if below > total / 2.0 + 1e-12 {
            return Some(k);
        }
        if (below - total / 2.0).abs() <= 1e-12 {
            // Exactly half below: midway to the next value, as an ordinary median does.
            return Some(weighted.get(i + 1).map_or(k, |n| (k + n.0) / 2.0));
        }
    }
    weighted.last().map(|(k, _)| *k)
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

    fn face(k: Option<f64>, confidence: f64) -> FaceReport {
        let p = Point::new(0.0, 0.0);
        FaceReport {
            face_box: Rect::new(0.0, 0.0, 10.0, 10.0),
            right_eye: p,
            left_eye: p,
            right_nostril: p,
            left_nostril: p,
            mouth: None,
            k,
            k_measured: k.unwrap_or(0.9),
            k_nose: None,
            k_mouth: None,
            nose_tip: None,
            k_nose_tip: None,
            nose_tip_psr: 0.0,
            roll_degrees: 0.0,
            confidence,
            psr: [0.0; 5],
            locator: Locator::Filters,
            k_network: None,
            k_points: None,
            spread: None,
            face_score: None,
        }
    }

    #[test]
    fn confidence_rises_with_clear_peaks_and_falls_with_disagreement_for_every_filter_type() {
        let p = |x: f64, y: f64| Point::new(x, y);
        let points = |mouth_psr: f64| FacePoints {
            right_eye: p(81.0, 100.0),
            left_eye: p(138.0, 100.0),
            right_nostril: p(100.0, 140.0),
            left_nostril: p(119.0, 140.0),
            right_eye_point: p(94.0, 100.0),
            left_eye_point: p(125.0, 100.0),
            right_nose_point: p(94.0, 140.0),
            left_nose_point: p(125.0, 140.0),
            psr: [8.0, 8.0, 4.0, 4.0],
            mouth: Some(p(110.0, 163.0)),
            mouth_psr,
            nose_tip: Some(p(110.0, 143.0)),
            nose_tip_psr: 5.0,
            view_k: 0.0,
        };
        let estimate = |disagreement: f64| FaceEstimate {
            k: 0.0,
            roll: 0.0,
            k_nose: Some(0.0),
            k_mouth: Some(0.0),
            k_nose_tip: Some(disagreement),
        };
        // A box the detector would draw for eyes 57 px apart.
        let face_box = Rect::new(60.0, 60.0, 57.0 / EYE_DISTANCE_PER_BOX_WIDTH, 150.0);
        for kind in FilterType::ALL {
            let model = ConfidenceModel::for_filters(kind);
            let c = |mouth_psr, disagreement| {
                confidence(
                    &points(mouth_psr),
                    &estimate(disagreement),
                    face_box,
                    &model,
                )
            };
            let (clear, faint, split) = (c(6.0, 0.0), c(2.0, 0.0), c(6.0, 0.3));
            for v in [clear, faint, split] {
                assert!(v > 0.0 && v < 1.0, "{kind:?}: {v}");
            }
            assert!(clear > faint, "{kind:?}: mouth PSR {clear} vs {faint}");
            assert!(clear > split, "{kind:?}: disagreement {clear} vs {split}");
        }
    }

    #[test]
    fn the_thorough_search_is_lenient_only_with_the_network() {
        let mut u = Unshear::with_defaults().expect("built-in models");
        let t = u.thorough_detectors().expect("thorough by default");
        assert_eq!(t.as_is.params().min_neighbors, THOROUGH_MIN_NEIGHBORS);
        assert_eq!(t.views.params().min_neighbors, THOROUGH_MIN_NEIGHBORS);
        assert_eq!(t.as_is.params().stage_slack, THOROUGH_STAGE_SLACK);
        assert_eq!(t.views.params().stage_slack, THOROUGH_STAGE_SLACK);
        assert_eq!(t.as_is.params().min_size, (0, 0));
        let floor = THOROUGH_VIEW_MIN_FACE;
        assert_eq!(t.views.params().min_size, (floor, floor));
        assert_eq!(u.roll_hypotheses, THOROUGH_ROLL_HYPOTHESES.to_vec());
        assert_eq!(t.shear_hypotheses, THOROUGH_SHEAR_HYPOTHESES.to_vec());
        assert_eq!(
            u.hypothesis_groups(),
            vec![vec![0.15, -0.15], vec![0.3, -0.3], vec![0.45, -0.45]]
        );
        assert_eq!(u.shear_hypotheses, DEFAULT_SHEAR_HYPOTHESES.to_vec());
        assert_eq!(
            u.detector.params().min_neighbors,
            3,
            "the main detector unchanged"
        );
        assert_eq!(u.detector.params().stage_slack, 0);
        u.set_locator(Locator::Filters);
        assert!(
            u.thorough_detectors().is_none(),
            "the filters cannot judge boxes"
        );
        assert_eq!(
            u.hypothesis_groups(),
            vec![vec![0.3, -0.3], vec![0.5, -0.5]]
        );
        u.set_locator(Locator::Network);
        u.set_face_search(FaceSearch::Quick);
        assert!(u.thorough_detectors().is_none());
        assert_eq!(u.roll_hypotheses, DEFAULT_ROLL_HYPOTHESES.to_vec());
        assert_eq!(u.shear_hypotheses, DEFAULT_SHEAR_HYPOTHESES.to_vec());
    }

    #[test]
    fn hypotheses_are_grouped_by_magnitude_nearest_first() {
        let mut unshear = Unshear::new(
            FaceDetector::frontal_face(),
            EyeFilters::embedded().expect("built-in filters"),
        );
        unshear.set_shear_hypotheses(&[0.5, 0.3, -0.5, f64::NAN, -0.3, 0.1]);
        assert_eq!(
            unshear.hypothesis_groups(),
            vec![vec![0.1], vec![0.3, -0.3], vec![0.5, -0.5]]
        );
        unshear.set_shear_hypotheses(&[]);
        assert!(unshear.hypothesis_groups().is_empty());
    }

    #[test]
    fn turned_views_follow_the_de_sheared_ones_nearest_first() {
        let mut unshear = Unshear::new(
            FaceDetector::frontal_face(),
            EyeFilters::embedded().expect("built-in filters"),
        );
        unshear.set_shear_hypotheses(&[0.3, -0.3]);
        unshear.set_roll_hypotheses(&[30.0, -10.0, 10.0, f64::NAN, 0.0]);
        let r = |d: f64| d.to_radians();
        assert_eq!(
            unshear.view_groups(),
            vec![
                vec![(0.3, 0.0), (-0.3, 0.0)],
                vec![(0.0, r(-10.0)), (0.0, r(10.0))],
                vec![(0.0, r(30.0))],
            ]
        );
        unshear.set_roll_hypotheses(&[]);
        assert_eq!(unshear.view_groups(), vec![vec![(0.3, 0.0), (-0.3, 0.0)]]);
    }

    #[test]
    fn the_thorough_views_take_turns_on_the_two_scale_ladders() {
        let unshear = Unshear::with_defaults().expect("built-in models");
        let views = unshear.every_view(true);
        let groups = unshear.view_groups();
        assert_eq!(views.len(), groups.iter().map(Vec::len).sum::<usize>());
        let mut at = 0;
        for (i, group) in groups.iter().enumerate() {
            let de_sheared = group.iter().all(|&(_, roll)| roll == 0.0);
            let ladder = if de_sheared && i % 2 == 0 {
                THOROUGH_HALF_STEP_LADDER
            } else {
                0.0
            };
            for &(k, roll) in group {
                assert_eq!(
                    views[at],
                    View {
                        k,
                        roll,
                        scale_offset: ladder
                    },
                    "group {i}"
                );
                at += 1;
            }
        }
        // The views of +-0.15 and +-0.3 (the two nearest to k = 0.2) differ in ladder, and so
        // do +-0.3 and +-0.45; the turned views are on OpenCV's.
        assert_eq!(views[0].scale_offset, THOROUGH_HALF_STEP_LADDER);
        assert_eq!(views[2].scale_offset, 0.0);
        assert_eq!(views[4].scale_offset, THOROUGH_HALF_STEP_LADDER);
        assert!(views
            .iter()
            .filter(|v| v.roll != 0.0)
            .all(|v| v.scale_offset == 0.0));
        // Without the alternation (the filters' search of every view), OpenCV's ladder only.
        assert!(unshear
            .every_view(false)
            .iter()
            .all(|v| v.scale_offset == 0.0));
    }

    #[test]
    fn strong_rolls_are_searched_again_de_sheared_by_the_measured_shear() {
        let unshear = Unshear::with_defaults().expect("built-in models");
        let strong: Vec<View> = unshear
            .every_view(true)
            .into_iter()
            .filter(|v| v.k == 0.0 && v.roll.to_degrees().abs() >= TURNED_DESHEARED_MIN_ROLL)
            .collect();
        assert_eq!(strong.len(), 4, "+-25 and +-45 degrees: {strong:?}");
        let found = |k: Option<f64>| vec![(Rect::new(0.0, 0.0, 10.0, 10.0), Some(face(k, 0.8)))];
        // An accepted face measured 0.37: the strong rolls at that shear, each on its ladder.
        let views = unshear.turned_desheared_views(&found(Some(0.37)));
        assert_eq!(views.len(), strong.len());
        for (v, s) in views.iter().zip(&strong) {
            assert_eq!(*v, View { k: 0.37, ..*s });
        }
        // A shear the cascade tolerates: nothing new to see.
        assert!(unshear
            .turned_desheared_views(&found(Some(0.05)))
            .is_empty());
        // No accepted face (refused, or none at all): one step each way.
        for nothing in [found(None), Vec::new()] {
            let views = unshear.turned_desheared_views(&nothing);
            assert_eq!(views.len(), TURNED_DESHEARED_SHEARS.len() * strong.len());
            for k in TURNED_DESHEARED_SHEARS {
                assert_eq!(views.iter().filter(|v| v.k == k).count(), strong.len());
            }
        }
    }

    #[test]
    fn a_box_around_eyes_puts_them_where_the_turned_face_expects() {
        let eyes = Point::new(200.0, 150.0);
        for degrees in [0.0f64, 12.0, -25.0] {
            let roll = degrees.to_radians();
            let b = box_around_eyes(eyes, 120.0, 120.0, roll);
            assert_eq!((b.width, b.height), (120.0, 120.0));
            let gray = GrayImage::new(400, 300);
            let face = NormalizedFace::rotated(&gray, b, roll);
            let (at_x, at_y) = eyes_in_box();
            let expected = face.to_image(Point::new(
                at_x * crate::features::FACE_WIDTH,
                at_y * crate::features::FACE_WIDTH,
            ));
            assert!(expected.distance(eyes) < 1e-9, "{degrees}: {expected:?}");
        }
    }

    #[test]
    fn boxes_scale_about_their_centre() {
        let b = Rect::new(10.0, 20.0, 100.0, 50.0);
        assert_eq!(scaled_about_centre(b, 1.0), b);
        let s = scaled_about_centre(b, 0.9);
        assert!((s.width - 90.0).abs() < 1e-12 && (s.height - 45.0).abs() < 1e-12);
        assert!((s.x - 15.0).abs() < 1e-12 && (s.y - 22.5).abs() < 1e-12);
    }

    /// A detection of a 100 px box at `x`, from the view de-sheared by `view_k`.
    fn detection_at(x: f64, neighbors: u32, view_k: f64) -> Detection {
        Detection {
            face_box: Rect::new(x, 0.0, 100.0, 100.0),
            view_k,
            view_roll: 0.0,
            neighbors,
            near_miss: false,
        }
    }

    #[test]
    fn overlapping_detections_keep_the_strongest_and_least_warped() {
        let d = detection_at;
        // Two overlapping boxes (IoU 0.82) and one apart.
        let kept =
            strongest_of_overlapping(vec![d(0.0, 3, 0.0), d(10.0, 7, 0.3), d(300.0, 1, 0.5)]);
        assert_eq!(kept.len(), 2);
        assert_eq!((kept[0].neighbors, kept[0].view_k), (7, 0.3));
        assert_eq!(kept[1].face_box.x, 300.0);
        // Equal neighbours: the view nearer the image as it is.
        let kept = strongest_of_overlapping(vec![d(0.0, 4, -0.5), d(5.0, 4, 0.3)]);
        assert_eq!((kept.len(), kept[0].view_k), (1, 0.3));
        // A detection before a near miss, whatever their neighbours.
        let near = Detection {
            near_miss: true,
            ..d(5.0, 9, 0.0)
        };
        let kept = strongest_of_overlapping(vec![near, d(0.0, 2, 0.5)]);
        assert_eq!(
            (kept.len(), kept[0].near_miss, kept[0].neighbors),
            (1, false, 2)
        );
    }

    #[test]
    fn a_group_of_overlapping_boxes_is_tried_strongest_first_one_box_per_view() {
        let d = detection_at;
        let groups = overlapping_groups(vec![
            d(0.0, 2, 0.0),
            d(400.0, 1, 0.0),
            d(10.0, 9, 0.3),
            d(5.0, 5, 0.3),
            d(8.0, 4, -0.15),
            d(3.0, 3, 0.45),
            d(2.0, 1, -0.45),
        ]);
        assert_eq!(groups.len(), 2, "the face's boxes and the one apart");
        let strengths: Vec<u32> = groups[0].iter().map(|g| g.neighbors).collect();
        assert_eq!(strengths, vec![9, 5, 4, 3, 2, 1]);
        assert_eq!(groups[1].len(), 1);
        // The second box of the +0.3 view is skipped; the tries stop at THOROUGH_BOX_TRIES.
        let tries: Vec<(u32, f64)> = tries_of_group(groups[0].clone())
            .iter()
            .map(|t| (t.neighbors, t.view_k))
            .collect();
        assert_eq!(THOROUGH_BOX_TRIES, 3);
        assert_eq!(tries, vec![(9, 0.3), (4, -0.15), (3, 0.45)]);
        // Every group's first box is what `strongest_of_overlapping` keeps.
        let kept = strongest_of_overlapping(groups.concat());
        assert_eq!(kept, vec![groups[0][0], groups[1][0]]);
    }

    #[test]
    fn overlapping_faces_keep_the_most_confident_estimate() {
        let at = |x: f64| Rect::new(x, 0.0, 100.0, 100.0);
        let kept = most_confident_of_overlapping(vec![
            (at(0.0), None),
            (at(10.0), Some(face(Some(0.1), 0.4))),
            (at(5.0), Some(face(None, 0.9))),
            (at(400.0), None),
        ]);
        assert_eq!(kept.len(), 2);
        assert_eq!(
            kept[0].0.x, 5.0,
            "the most confident of the three overlapping"
        );
        assert!(kept[1].1.is_none() && kept[1].0.x == 400.0);
    }

    #[test]
    fn a_proposal_counts_only_for_the_face_its_window_shows() {
        let window = proposal_detection(Point::new(200.0, 100.0), 40.0);
        let (eyes, distance) = proposal_eyes(&window);
        assert!(eyes.distance(Point::new(200.0, 100.0)) < 1e-9 && (distance - 40.0).abs() < 1e-9);
        let located = |dx: f64, dy: f64, d: f64| FaceReport {
            right_eye: Point::new(200.0 + dx - d / 2.0, 100.0 + dy),
            left_eye: Point::new(200.0 + dx + d / 2.0, 100.0 + dy),
            ..face(Some(0.1), 0.9)
        };
        assert!(proposal_shows(&window, &located(0.0, 0.0, 40.0)));
        // Up to half the window's eye distance away, and 1.5 times larger or smaller.
        assert!(proposal_shows(&window, &located(12.0, 12.0, 30.0)));
        assert!(!proposal_shows(&window, &located(0.0, 21.0, 40.0)));
        assert!(!proposal_shows(&window, &located(-21.0, 0.0, 40.0)));
        assert!(!proposal_shows(&window, &located(0.0, 0.0, 61.0)));
        assert!(!proposal_shows(&window, &located(0.0, 0.0, 26.0)));
    }

    #[test]
    fn a_proposal_on_a_face_found_or_inside_it_is_not_searched() {
        // A face found with eyes 60 px apart at (300, 200), in its detector's box.
        let width = 60.0 / EYE_DISTANCE_PER_BOX_WIDTH;
        let found_box = box_around_eyes(Point::new(300.0, 200.0), width, width, 0.0);
        let found = vec![(
            found_box,
            Some(FaceReport {
                face_box: found_box,
                right_eye: Point::new(270.0, 200.0),
                left_eye: Point::new(330.0, 200.0),
                ..face(Some(0.1), 0.9)
            }),
        )];
        // The same face, a little off: its box holds both eyes.
        assert!(!proposal_is_new(
            &proposal_detection(Point::new(305.0, 195.0), 55.0),
            &found
        ));
        // A small window on the face's nose, whose box holds neither eye.
        let nose = proposal_detection(Point::new(300.0, 240.0), 20.0);
        assert!(!nose.face_box.contains(Point::new(270.0, 200.0)));
        assert!(!proposal_is_new(&nose, &found));
        // A face beside it, two and a half eye distances away, and any face where none was
        // found (or only a box that gave no face).
        assert!(proposal_is_new(
            &proposal_detection(Point::new(450.0, 200.0), 60.0),
            &found
        ));
        assert!(proposal_is_new(&nose, &[]));
        assert!(proposal_is_new(&nose, &[(found_box, None)]));
        // A window about a small "face" found on a large face's nose, holding neither of its
        // eyes: the large face is searched.
        let small_box = box_around_eyes(Point::new(300.0, 240.0), 50.0, 50.0, 0.0);
        let small = vec![(
            small_box,
            Some(FaceReport {
                face_box: small_box,
                right_eye: Point::new(290.0, 240.0),
                left_eye: Point::new(310.0, 240.0),
                ..face(Some(0.1), 0.9)
            }),
        )];
        let large = proposal_detection(Point::new(300.0, 225.0), 60.0);
        assert!(small_box.contains(proposal_eyes(&large).0));
        assert!(large.face_box.contains(Point::new(290.0, 240.0)));
        assert!(proposal_is_new(&large, &small));
        // The same window at the small face's size is not.
        assert!(!proposal_is_new(
            &proposal_detection(Point::new(300.0, 240.0), 20.0),
            &small
        ));
    }

    #[test]
    fn one_face_found_in_two_boxes_is_reported_once() {
        let located = |x: f64, confidence: f64| FaceReport {
            right_eye: Point::new(x, 50.0),
            left_eye: Point::new(x + 40.0, 50.0),
            ..face(Some(0.1), confidence)
        };
        let tight = Rect::new(80.0, 20.0, 105.0, 105.0);
        // A box three times as large (IoU 0.11) whose features led to the same eyes, 4 px off.
        let around_the_head = Rect::new(0.0, -60.0, 315.0, 315.0);
        assert!(tight.iou(&around_the_head) < 0.3);
        let kept = most_confident_of_overlapping(vec![
            (around_the_head, Some(located(104.0, 0.6))),
            (tight, Some(located(100.0, 0.9))),
            // Another face beside it, one eye distance and a half away: kept.
            (
                Rect::new(150.0, 20.0, 105.0, 105.0),
                Some(located(160.0, 0.5)),
            ),
        ]);
        assert_eq!(kept.len(), 2, "{kept:?}");
        assert_eq!(kept[0].0, tight, "the more confident of the two copies");
        assert_eq!(kept[1].0.x, 150.0);
        // A more confident copy from a box beside the face, which does not hold the eyes it
        // located, gives way to the box that does.
        let beside = Rect::new(135.0, 20.0, 105.0, 105.0);
        let kept = most_confident_of_overlapping(vec![
            (beside, Some(located(102.0, 0.99))),
            (tight, Some(located(100.0, 0.9))),
        ]);
        assert_eq!(kept.len(), 1, "{kept:?}");
        assert_eq!(kept[0].0, tight);
        // A large box around the head whose walk stopped on other points (its located eyes far
        // from the face's, not the same face by `same_face`) but which holds the kept face's
        // eyes: the same face seen again, not reported.
        let stopped_elsewhere = FaceReport {
            right_eye: Point::new(90.0, 40.0),
            left_eye: Point::new(230.0, 0.0),
            ..face(Some(-0.5), 0.01)
        };
        let kept = most_confident_of_overlapping(vec![
            (around_the_head, Some(stopped_elsewhere)),
            (tight, Some(located(100.0, 0.9))),
        ]);
        assert_eq!(kept.len(), 1, "{kept:?}");
        assert_eq!(kept[0].0, tight);
        // Without the tight face, it is reported (its own box holds its eyes).
        let alone = most_confident_of_overlapping(vec![(around_the_head, Some(stopped_elsewhere))]);
        assert_eq!(alone.len(), 1);
    }

    #[test]
    fn combined_shear_is_a_confidence_weighted_median_of_accepted_faces() {
        assert_eq!(combined_shear(&[]), None);
        assert_eq!(combined_shear(&[face(None, 0.9)]), None);
        // Equal weights: the ordinary median.
        let even = [face(Some(0.1), 0.5), face(Some(0.3), 0.5)];
        assert!((combined_shear(&even).expect("k") - 0.2).abs() < 1e-12);
        // One confident face outweighs two doubtful ones that agree with each other.
        let faces = [
            face(Some(0.40), 0.9),
            face(Some(0.05), 0.2),
            face(Some(0.06), 0.2),
            face(None, 1.0),
        ];
        assert_eq!(combined_shear(&faces), Some(0.40));
        // Three similar weights: the middle value, whatever the outlier.
        let faces = [
            face(Some(0.2), 0.5),
            face(Some(0.22), 0.6),
            face(Some(-3.0), 0.55),
        ];
        assert_eq!(combined_shear(&faces), Some(0.2));
    }

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
