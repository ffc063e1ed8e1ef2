//! The whole method behind one value: detect faces, locate their features, estimate the shear
//! and undo it. Data flows one way through the submodules: `search` finds candidate boxes,
//! `face` estimates one face, `combine` reduces the faces to the image's shear, and
//! `correct` undoes it; `report` holds what they report.
//!
//! ```no_run
//! use unshear::{imageio, Config, CorrectOptions, Unshear};
//!
//! # fn main() -> unshear::Result<()> {
//! let unshear = Unshear::new(Config::default())?;
//! let img = imageio::read_image("photo.jpg".as_ref(), imageio::DEFAULT_MAX_PIXELS)?;
//! let report = unshear.estimate(&img);
//! if let Some(k) = report.k {
//!     let fixed = Unshear::correct(&img, &report, &CorrectOptions::default())?;
//!     println!("k = {k:.3}, corrected {}x{}", fixed.width(), fixed.height());
//! }
//! # Ok(())
//! # }
//! ```

mod combine;
pub mod confidence;
mod correct;
mod face;
mod photo;
mod proposals;
mod report;
mod search;
#[cfg(test)]
mod tests;

use image::{DynamicImage, GrayImage};
use rayon::prelude::*;

pub use combine::{combined_shear, consensus, mark_consensus, Consensus, FACE_UNCERTAINTY};
pub use correct::FACE_REGION_MARGIN;
pub use face::FaceStart;
pub use photo::FileOptions;
pub use proposals::{box_from_eyes, follows, FOLLOW_MAX_MOVE, FOLLOW_MAX_SCALE};
pub use report::{CorrectOptions, FaceReport, ImageReport, Readout, Refusal, Region};
pub use search::{
    Detection, DEFAULT_ROLL_HYPOTHESES, DEFAULT_SHEAR_HYPOTHESES, MAX_VIEW_PIXELS_RATIO,
    THOROUGH_ROLL_HYPOTHESES, THOROUGH_SHEAR_HYPOTHESES, WEAK_BOX_MIN_WIDTH,
};

use crate::config::{Config, MIN_NETWORK_FACE};
pub use crate::config::{Detector, FaceSearch, Locator};
use crate::detect::boxes::EYE_DISTANCE_PER_BOX_WIDTH;
use crate::detect::{Cascade, FaceDetector, ProposalNet};
use crate::error::Result;
use crate::filters::{EyeFilters, FilterType};
use crate::geometry::{Point, Rect};
use crate::locate::network::{Budget, LandmarkNet};
use combine::{holds_eyes, measured_shear, most_confident_of_overlapping};
use proposals::{
    network_windows, network_windows_desheared, proposal_detection, proposal_detections,
    proposal_is_new, proposal_shows, settle_unsure_faces, window_is_face, window_is_new,
};
use search::{
    overlapping_groups, tries_of_group, FallbackDetector, ThoroughDetectors,
    MEASURED_VIEW_MIN_SHEAR, NEAR_MISS_MIN_FACE_SCORE, THOROUGH_MIN_NEIGHBORS,
    THOROUGH_ROLL_HYPOTHESES as THOROUGH_ROLLS, THOROUGH_SHEAR_HYPOTHESES as THOROUGH_SHEARS,
    THOROUGH_STAGE_SLACK, THOROUGH_VIEW_MIN_FACE,
};

/// A network detector's window whose look was doubtful: the landmark network's face score
/// short of a face's but not far short ([`face::RETRY_MIN_FACE_SCORE`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct DoubtfulWindow {
    window: Detection,
    logit: f32,
    /// The shear the window was read from, when known better than its own.
    start_k: Option<f64>,
}

/// The smallest face the network detector's pass over the image de-sheared by the measured
/// shear looks for, as a share of the smallest face found
/// ([`Unshear::judge_measured_view`]): the faces of one photo are mostly at like distances
/// from the camera, and a face under half the size of every other was searched for by the
/// first pass all the same.
pub(crate) const MEASURED_VIEW_MIN_FACE_RATIO: f64 = 0.5;

/// The widest image (columns) whose faces the pass over the image de-sheared by the measured
/// shear looks for from the first pass's smallest face: on a wider image it looks from the
/// face that small in the image shrunk to this width (from about 83 px on a 4000x3000 photo),
/// so that it costs at most about what the first pass costs on a 1920x1080 frame, where a
/// second pass over all of a large photo's scales would double its search.
pub(crate) const MEASURED_VIEW_FULL_COLUMNS: f64 = 1920.0;

/// The smallest face (box width) the pass over an image `width` columns wide, de-sheared by
/// the measured shear, looks for when the first pass looked from `min_width` (at least
/// [`MIN_NETWORK_FACE`]) on pyramid levels `step` apart and the smallest face found is
/// `smallest` wide: [`MEASURED_VIEW_MIN_FACE_RATIO`] times `smallest` (and at least the bound
/// of [`MEASURED_VIEW_FULL_COLUMNS`]), taken down to the first pass's level holding it, so
/// that both passes see faces at the same scales (a borderline face's window comes and goes
/// with them).
pub(crate) fn measured_view_min_width(min_width: f64, smallest: f64, width: u32, step: f64) -> f64 {
    let min_width = min_width.max(f64::from(MIN_NETWORK_FACE));
    let wide = (f64::from(width) / MEASURED_VIEW_FULL_COLUMNS).max(1.0);
    let wanted = (MEASURED_VIEW_MIN_FACE_RATIO * smallest).max(min_width * wide);
    let levels = (wanted / min_width).ln() / step.ln();
    // The tolerance keeps a face exactly on a level on it (the logarithms' rounding).
    min_width * step.powf((levels + 1e-9).floor().max(0.0))
}

/// The largest head roll (degrees) of a face found by the network detector whose estimate is
/// accepted: at 45 degrees, two of the six fixture cases
/// (`the_network_detector_finds_small_and_rolled_faces`) were read as rolled about 39 degrees and
/// sheared by 0.16-0.22, with high confidence; at 30 degrees none was.
pub const NETWORK_DETECTOR_MAX_ROLL: f64 = 35.0;

/// The head roll (degrees) beyond which a face found by the network detector keeps its
/// estimate only when that is a small shear ([`ROLLED_HEAD_MAX_SHEAR`]): a head rolled 40-50
/// degrees can be read as rolled about 33 and sheared, stably (a second reading from a crop
/// turned by the measured roll, or 12 degrees more, repeats it). On the development faces
/// turned by 30 and +-45 degrees and sheared by 0, +-0.40 (`eval shear --roll`), this refuses
/// 56 of 70 accepted estimates more than 0.15 off; unturned (all nine shears), 16 of 8071
/// accepted estimates, none of them more than 0.15 off (docs/accuracy.md).
pub const ROLLED_HEAD: f64 = 25.0;

/// The largest shear (absolute) a face rolled beyond [`ROLLED_HEAD`] may be measured with.
pub const ROLLED_HEAD_MAX_SHEAR: f64 = 0.1;

/// The models a corrector runs: the built-in ones ([`Models::builtin`]) or files of the user's
/// (a cascade XML, a filter file from `unshear train`, a network from
/// `scripts/train_landmarks.py`).
#[derive(Debug, Clone)]
pub struct Models {
    /// The Viola-Jones cascade (OpenCV's XML format).
    pub cascade: Cascade,
    /// The correlation filters for eyes, nostrils, nose and mouth.
    pub filters: EyeFilters,
    /// The landmark network.
    pub network: LandmarkNet,
    /// The face proposal classifier of the thorough search.
    pub proposals: ProposalNet,
    /// The single-pass face detector ([`Detector::Network`]).
    pub detector: ProposalNet,
}

impl Models {
    /// The models compiled into the crate, with the built-in filters of type `filters`.
    pub fn builtin(filters: FilterType) -> Result<Self> {
        Ok(Self {
            cascade: Cascade::frontal_face_alt2(),
            filters: EyeFilters::builtin(filters)?,
            network: LandmarkNet::embedded()?,
            proposals: ProposalNet::embedded()?,
            detector: ProposalNet::embedded_detector()?,
        })
    }
}

/// The rolling-shutter corrector: the models and the [`Config`] they run with. Built once and
/// shared (it is `Sync`; every method takes `&self`).
#[derive(Debug)]
pub struct Unshear {
    config: Config,
    detector: FaceDetector,
    fallback: Option<FallbackDetector>,
    filters: EyeFilters,
    network: LandmarkNet,
    /// The quick search's de-sheared views (also the filters' with the thorough setting).
    shear_hypotheses: Vec<f64>,
    roll_hypotheses: Vec<f64>,
    /// The lenient detectors of [`FaceSearch::Thorough`], when it is set (used with the network
    /// only).
    thorough: Option<ThoroughDetectors>,
    /// The face proposal classifier of the thorough search, when [`Config::proposals`] is set.
    proposals: Option<ProposalNet>,
    /// The single-pass face detector, with [`Detector::Network`].
    face_detector: Option<ProposalNet>,
}

impl Unshear {
    /// A corrector with the built-in models.
    pub fn new(config: Config) -> Result<Self> {
        let models = Models::builtin(config.filter_type)?;
        Self::with_models(config, models)
    }

    /// A corrector with `models`, running `config` resolved ([`Config::resolve`]); fails when
    /// it does not validate.
    pub fn with_models(config: Config, models: Models) -> Result<Self> {
        let config = config.resolve()?;
        let detector = FaceDetector::new(models.cascade, config.cascade);
        let finite = |v: &[f64]| {
            v.iter()
                .copied()
                .filter(|k| k.is_finite())
                .collect::<Vec<_>>()
        };
        let shear_hypotheses = finite(
            config
                .shear_hypotheses
                .as_deref()
                .unwrap_or(&DEFAULT_SHEAR_HYPOTHESES),
        );
        let default_rolls: &[f64] = match config.search {
            FaceSearch::Thorough => &THOROUGH_ROLLS,
            FaceSearch::Quick => &DEFAULT_ROLL_HYPOTHESES,
        };
        let roll_hypotheses = config
            .roll_hypotheses
            .as_deref()
            .unwrap_or(default_rolls)
            .iter()
            .copied()
            .filter(|r| r.is_finite() && *r != 0.0)
            .collect();
        let thorough = (config.search == FaceSearch::Thorough).then(|| {
            let params = crate::detect::DetectorParams {
                min_neighbors: THOROUGH_MIN_NEIGHBORS,
                stage_slack: THOROUGH_STAGE_SLACK,
                ..config.cascade
            };
            let (w, h) = params.min_size;
            let views = crate::detect::DetectorParams {
                min_size: (w.max(THOROUGH_VIEW_MIN_FACE), h.max(THOROUGH_VIEW_MIN_FACE)),
                ..params
            };
            let cascade = detector.cascade();
            ThoroughDetectors {
                as_is: FaceDetector::new(cascade.clone(), params),
                views: FaceDetector::new(cascade.clone(), views),
                shear_hypotheses: finite(
                    config
                        .shear_hypotheses
                        .as_deref()
                        .unwrap_or(&THOROUGH_SHEARS),
                ),
            }
        });
        let fallback = config
            .fallback_cascade
            .then(|| FallbackDetector::frontal_face_default(config.cascade));
        Ok(Self {
            detector,
            fallback,
            filters: models.filters,
            network: models.network,
            shear_hypotheses,
            roll_hypotheses,
            thorough,
            proposals: config.proposals.then_some(models.proposals),
            face_detector: (config.detector == Detector::Network).then_some(models.detector),
            config,
        })
    }

    /// The settings it runs with: the [`Config`] it was made with, resolved
    /// ([`Config::resolve`]).
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Detects the faces in `img` and estimates the shear from each.
    pub fn estimate(&self, img: &DynamicImage) -> ImageReport {
        self.estimate_gray(&Self::gray(img))
    }

    /// [`Self::estimate`] of a photo read with its [`Metadata`](crate::imageio::Metadata)
    /// ([`read_image_with_metadata`](crate::imageio::read_image_with_metadata)), as the CLI
    /// reports it: a warning first when the decode is mostly without data
    /// (`imageio::missing_data_warning`), and, when the EXIF
    /// orientation turned the photo a quarter (a phone held upright, whose sensor rows are the
    /// picture's columns), the vertical shear of [`Self::read_by_columns`].
    pub fn estimate_photo(
        &self,
        img: &DynamicImage,
        metadata: &crate::imageio::Metadata,
    ) -> ImageReport {
        let mut report = self.estimate(img);
        if metadata.turned {
            report = self.read_by_columns(report);
        }
        if let Some(w) = crate::imageio::missing_data_warning(img) {
            report.warnings.insert(0, w);
        }
        report
    }

    /// `report` (of an upright picture, [`Readout::Rows`]) for a picture read out column by
    /// column: every face's readings converted to the vertical shear `c` of `y' = y + c x` and
    /// the head's roll under it (`estimate::vertical_from_row_reading`),
    /// an estimate beyond [`Config::max_shear`] or without a reading refused, and the image's
    /// shear found again from the faces. Read along its rows, such a skew looks like a roll
    /// and a shear whose correction would turn the picture.
    pub fn read_by_columns(&self, mut report: ImageReport) -> ImageReport {
        if report.readout == Readout::Columns {
            return report;
        }
        for f in &mut report.faces {
            self.face_by_columns(f);
        }
        let consensus = mark_consensus(&mut report.faces);
        report.k = consensus.k;
        report.faces_disagree = consensus.no_majority;
        report.readout = Readout::Columns;
        if !report.faces.is_empty() {
            report.warnings.push(
                "read out column by column (the picture is turned a quarter by its EXIF \
                 orientation, as from a phone held upright): k is the vertical shear \
                 y' = y + k x"
                    .to_string(),
            );
        }
        report
    }

    /// One face's row readings (an upright face in a picture read out by columns) converted to
    /// the vertical shear and the roll under it, as [`Self::read_by_columns`] does for each.
    pub fn face_by_columns(&self, f: &mut FaceReport) {
        use crate::estimate::vertical_from_row_reading;
        let roll = f.roll_degrees.to_radians();
        let column = |k: f64| vertical_from_row_reading(k, roll).map(|v| v.k);
        match vertical_from_row_reading(f.k_measured, roll) {
            Some(v) => {
                f.k_measured = v.k;
                f.roll_degrees = v.roll.to_degrees();
                if f.k.is_some() {
                    if v.k.abs() <= self.config.max_shear {
                        f.k = Some(v.k);
                    } else {
                        f.k = None;
                        f.refused = Some(Refusal::ImplausibleShear);
                    }
                }
            }
            None => {
                if f.k.take().is_some() {
                    f.refused = Some(Refusal::ImplausibleShear);
                }
            }
        }
        f.k_nose = f.k_nose.and_then(column);
        f.k_mouth = f.k_mouth.and_then(column);
        f.k_nose_tip = f.k_nose_tip.and_then(column);
        f.k_network = f.k_network.and_then(column);
        f.k_points = f.k_points.and_then(column);
        f.outvoted = false;
    }

    /// [`Self::estimate`] on a greyscale image.
    pub fn estimate_gray(&self, gray: &GrayImage) -> ImageReport {
        let mut faces: Vec<FaceReport> = self
            .detect_and_estimate(gray)
            .into_iter()
            .filter_map(|(_, face)| face)
            .collect();
        let consensus = mark_consensus(&mut faces);
        ImageReport {
            k: consensus.k,
            faces,
            faces_disagree: consensus.no_majority,
            warnings: self.shape_warnings(gray.width(), gray.height()),
            width: gray.width(),
            height: gray.height(),
            readout: Readout::Rows,
        }
    }

    /// Every detected face box with its estimate, if it gave one (the evaluation needs to tell a
    /// face that was not found from one that was found but gave no estimate). With the landmark
    /// network, boxes it finds no face in are left out (see the minimum face score).
    ///
    /// The network detector (the default) runs once over the image and again over the image
    /// de-sheared by the shear its faces measured (when that is 0.1 or more), each window
    /// judged by the landmark network. With Viola-Jones:
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
        if let Some(net) = self.network_detector() {
            let min_width = f64::from(self.config.min_face);
            let windows = network_windows(net, gray, min_width);
            let budget = self.config.network_budget;
            let mut doubtful = self.judge_windows(gray, windows, None, budget, &mut all);
            doubtful.extend(self.judge_measured_view(net, gray, min_width, budget, &mut all));
            self.judge_doubtful_windows(gray, &doubtful, budget, &mut all);
            return most_confident_of_overlapping(all);
        }
        let thorough = self.thorough_detectors();
        if self.config.search_every_view || thorough.is_some() {
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

    /// Judges the network detector's `windows` in `gray`, strongest first, each against the
    /// faces in `found` so far (a window on a face already found is skipped, [`window_is_new`];
    /// one on a face found unsure is looked at, and the two settled by
    /// [`settle_unsure_faces`]): the landmark
    /// network, started from the window's shear (or `start_k`, a shear known better, such as a
    /// video's filtered one) and roll with `budget`, must find a face there
    /// ([`window_is_face`]) and where the window expects it ([`proposal_shows`]). A face found
    /// elsewhere than the window expects (the window's regressed eyes are off, most often on
    /// strongly sheared faces) gets a second look from where the network landed, and counts
    /// when that look lands there again ([`Self::take_second_looks`]). The faces found join
    /// `found`; the windows whose look was doubtful are returned, each with the shear it was
    /// read from, for [`Self::judge_doubtful_windows`].
    pub(crate) fn judge_windows(
        &self,
        gray: &GrayImage,
        windows: Vec<(Detection, f32)>,
        start_k: Option<f64>,
        budget: Budget,
        found: &mut Vec<(Rect, Option<FaceReport>)>,
    ) -> Vec<DoubtfulWindow> {
        let first_new = found.len();
        // The logit of the window that found each face of `found`; the faces found before
        // count as found by the strongest.
        let mut found_by = vec![f32::INFINITY; found.len()];
        let mut second_looks = Vec::new();
        let looks = self.look_at_windows(gray, &windows, start_k, budget, found);
        let mut doubtful = Vec::new();
        for ((d, logit), (look, doubt)) in windows.iter().zip(looks) {
            if doubt {
                doubtful.push(DoubtfulWindow {
                    window: *d,
                    logit: *logit,
                    start_k,
                });
            }
            match look {
                Some(r) if proposal_shows(d, &r) => {
                    found.push((d.face_box, Some(r)));
                    found_by.push(*logit);
                }
                Some(r) => {
                    let landed = Detection {
                        view_k: r.k_measured,
                        view_roll: r.roll_degrees.to_radians(),
                        ..proposal_detection(
                            r.right_eye.midpoint(r.left_eye),
                            r.right_eye.distance(r.left_eye),
                        )
                    };
                    second_looks.push((landed, *logit));
                }
                None => {}
            }
        }
        // After every window's own look, so that a second look landing on part of a face
        // cannot hide that face's own window.
        self.take_second_looks(gray, &second_looks, start_k, budget, found, found_by);
        settle_unsure_faces(found, first_new);
        doubtful
    }

    /// The last resort for `windows` whose look was doubtful ([`Self::judge_windows`]),
    /// strongest first, once every window has been judged: each that no face found hides, sure
    /// or not ([`proposal_is_new`]), is read again from turned starts ([`Unshear::read_box`]),
    /// and a face found so where the window expects it, hidden by none either and apart from
    /// them (neither box holding the other's eyes), joins `found`, its estimate refused and with
    /// no confidence. Being last, such a face hides no window that reads a face as it is.
    pub(crate) fn judge_doubtful_windows(
        &self,
        gray: &GrayImage,
        windows: &[DoubtfulWindow],
        budget: Budget,
        found: &mut Vec<(Rect, Option<FaceReport>)>,
    ) {
        let mut windows = windows.to_vec();
        windows.sort_by(|a, b| b.logit.total_cmp(&a.logit));
        for w in windows {
            if !proposal_is_new(&w.window, found) {
                continue;
            }
            let start = FaceStart {
                k: w.start_k.unwrap_or(w.window.view_k),
                roll: w.window.view_roll,
                budget: Some(budget),
            };
            let Ok(r) = self.read_box(gray, w.window.face_box, start, true) else {
                continue;
            };
            let read = proposal_detection(
                r.right_eye.midpoint(r.left_eye),
                r.right_eye.distance(r.left_eye),
            );
            // Nor may its box hold a found face's eyes, or its eyes be in a found face's box:
            // a doubtful reading is no reason to nest two faces.
            let apart = found.iter().all(|(b, f)| {
                f.is_none_or(|f| !holds_eyes(&w.window.face_box, &f) && !holds_eyes(b, &r))
            });
            if window_is_face(w.logit, &r)
                && proposal_shows(&w.window, &r)
                && proposal_is_new(&read, found)
                && apart
            {
                found.push((w.window.face_box, Some(r)));
            }
        }
    }

    /// Adds to `found` the faces the network detector finds in `gray` de-sheared by the shear
    /// the faces of `found` measured, when that is at least [`MEASURED_VIEW_MIN_SHEAR`]:
    /// rolling-shutter skew is one per frame, so there the faces the detector missed sheared
    /// are upright, where it is surest of them. Its windows are judged as the first pass's
    /// ([`Self::judge_windows`]), the landmark network started from the measured shear. Faces
    /// are looked for from [`MEASURED_VIEW_MIN_FACE_RATIO`] times the smallest face found (and
    /// `min_width`) up, on the first pass's scales: the pass's cost falls with the square of
    /// its smallest face, so on a frame with one large face it costs little.
    fn judge_measured_view(
        &self,
        net: &ProposalNet,
        gray: &GrayImage,
        min_width: f64,
        budget: Budget,
        found: &mut Vec<(Rect, Option<FaceReport>)>,
    ) -> Vec<DoubtfulWindow> {
        let Some(k) = measured_shear(found).filter(|k| k.abs() >= MEASURED_VIEW_MIN_SHEAR) else {
            return Vec::new();
        };
        let smallest = found
            .iter()
            .filter_map(|(_, r)| r.map(|r| r.right_eye.distance(r.left_eye)))
            .fold(f64::INFINITY, f64::min)
            / EYE_DISTANCE_PER_BOX_WIDTH;
        let step = net.default_params().scale_step;
        let min_width = measured_view_min_width(min_width, smallest, gray.width(), step);
        let windows = network_windows_desheared(net, gray, min_width, k);
        self.judge_windows(gray, windows, Some(k), budget, found)
    }

    /// The second looks of [`Self::judge_windows`], strongest first, among the faces `found`
    /// by windows with logits `found_by`. A second look is skipped when it is on a face found
    /// by a window at least as strong as its own. A face it finds that weaker windows' faces
    /// hide (see [`window_is_new`]) takes their place if it scores higher than each of them,
    /// and is dropped otherwise: a weak window's false face (seen on a dog's muzzle beside a
    /// strongly sheared child) must not hide the face a stronger window saw from a little off.
    fn take_second_looks(
        &self,
        gray: &GrayImage,
        second_looks: &[(Detection, f32)],
        start_k: Option<f64>,
        budget: Budget,
        found: &mut Vec<(Rect, Option<FaceReport>)>,
        mut found_by: Vec<f32>,
    ) {
        // The faces a look from a window with `logit` defers to.
        let stronger = |found: &[(Rect, Option<FaceReport>)], found_by: &[f32], logit: f32| {
            let by_stronger = found.iter().zip(found_by).filter(|&(_, &by)| by >= logit);
            by_stronger.map(|(f, _)| *f).collect::<Vec<_>>()
        };
        let looks: Vec<Option<FaceReport>> = second_looks
            .par_iter()
            .map(|(d, logit)| {
                window_is_new(d, &stronger(found, &found_by, *logit))
                    .then(|| self.look_at_window(gray, d, *logit, start_k, budget).0)
                    .flatten()
            })
            .collect();
        for ((d, logit), look) in second_looks.iter().zip(looks) {
            let Some(r) = look.filter(|r| proposal_shows(d, r)) else {
                continue;
            };
            // Faces found since the looks were taken (other second looks) may hide it now.
            if !window_is_new(d, &stronger(found, &found_by, *logit)) {
                continue;
            }
            // Only weaker windows' faces are left that can hide it.
            let hiding: Vec<usize> = (0..found.len())
                .filter(|&i| !window_is_new(d, &found[i..=i]))
                .collect();
            let scores_higher = |i: &usize| {
                let theirs = found[*i].1.and_then(|h| h.face_score);
                matches!((r.face_score, theirs), (Some(s), Some(t)) if s > t)
            };
            if !hiding.iter().all(scores_higher) {
                continue;
            }
            for &i in hiding.iter().rev() {
                found.remove(i);
                found_by.remove(i);
            }
            found.push((d.face_box, Some(r)));
            found_by.push(*logit);
        }
    }

    /// [`Self::look_at_window`] for each of `windows` in order, `None` for a window on a face
    /// in `found` ([`window_is_new`]) when its turn comes, exactly as looking at one window
    /// after the other and adding each face found to `found` before the next (as `commit`
    /// does). Looks are taken in waves on the thread pool: a wave holds the windows up to the
    /// next one not yet looked at whose box overlaps an earlier window's (that window's face,
    /// once found, may hide it), so a frame's separate windows (a busy scene can give ten) do
    /// not wait for each other on one core, and no look is spent on a window its stronger
    /// neighbour's face will hide. Each look depends only on its window, so the results are
    /// those of one window at a time. Each look comes with whether it was doubtful
    /// ([`Self::look_at_window`]).
    fn look_at_windows(
        &self,
        gray: &GrayImage,
        windows: &[(Detection, f32)],
        start_k: Option<f64>,
        budget: Budget,
        found: &[(Rect, Option<FaceReport>)],
    ) -> Vec<(Option<FaceReport>, bool)> {
        let mut found_now = found.to_vec();
        // Each window's look once taken (`Some`), and each window's outcome once decided.
        let mut taken: Vec<Option<(Option<FaceReport>, bool)>> = vec![None; windows.len()];
        let mut looks: Vec<(Option<FaceReport>, bool)> = Vec::with_capacity(windows.len());
        while looks.len() < windows.len() {
            let next = looks.len();
            // The wave: from `next` on, every window not looked at yet and still new that no
            // earlier window still to be decided (and still new) overlaps.
            let wave: Vec<usize> = (next..windows.len())
                .filter(|&j| {
                    let (d, _) = &windows[j];
                    let overlaps = |e: &Detection| e.face_box.intersection(&d.face_box).is_some();
                    taken[j].is_none()
                        && window_is_new(d, &found_now)
                        && (next..j).all(|i| {
                            let (e, _) = &windows[i];
                            !overlaps(e) || !window_is_new(e, &found_now)
                        })
                })
                .collect();
            let seen: Vec<(usize, (Option<FaceReport>, bool))> = wave
                .par_iter()
                .map(|&j| {
                    let (d, logit) = &windows[j];
                    (j, self.look_at_window(gray, d, *logit, start_k, budget))
                })
                .collect();
            for (j, look) in seen {
                taken[j] = Some(look);
            }
            // Decided in order as far as the looks taken reach (a window no longer new needs
            // none).
            while let Some((d, _)) = windows.get(looks.len()) {
                let look = if !window_is_new(d, &found_now) {
                    (None, false)
                } else if let Some(look) = taken[looks.len()].take() {
                    look
                } else {
                    break;
                };
                if let Some(r) = look.0.filter(|r| proposal_shows(d, r)) {
                    found_now.push((d.face_box, Some(r)));
                }
                looks.push(look);
            }
        }
        looks
    }

    /// The face the landmark network finds from the network detector's window `d` (with
    /// `logit`), started from its shear (or `start_k`) and roll with `budget`, if the network
    /// finds a face there ([`window_is_face`]); strongly rolled ones refused
    /// ([`NETWORK_DETECTOR_MAX_ROLL`]), and rolled ones measured strongly sheared
    /// ([`ROLLED_HEAD`]); with it, whether a window giving no face was read doubtfully
    /// ([`Unshear::read_box`]).
    fn look_at_window(
        &self,
        gray: &GrayImage,
        d: &Detection,
        logit: f32,
        start_k: Option<f64>,
        budget: Budget,
    ) -> (Option<FaceReport>, bool) {
        let start = FaceStart {
            k: start_k.unwrap_or(d.view_k),
            roll: d.view_roll,
            budget: Some(budget),
        };
        let mut r = match self.read_box(gray, d.face_box, start, false) {
            Ok(r) => r,
            Err(doubtful) => return (None, doubtful),
        };
        let (roll, k) = (r.roll_degrees.abs(), r.k_measured.abs());
        let rolled_and_sheared = roll > ROLLED_HEAD && k > ROLLED_HEAD_MAX_SHEAR;
        if (roll > NETWORK_DETECTOR_MAX_ROLL || rolled_and_sheared) && r.k.is_some() {
            // Rolled faces found by the network detector are measured from its rough roll,
            // and can be read as less rolled and sheared instead.
            r.k = None;
            r.refused = Some(Refusal::UnreliablePose);
        }
        (window_is_face(logit, &r).then_some(r), false)
    }

    /// Whether the network detector finds the faces ([`Detector::Network`] with the network
    /// locator).
    pub fn uses_network_detector(&self) -> bool {
        self.network_detector().is_some()
    }

    /// Adds to `found` the faces the network detector finds in `gray` (shrunk to at most
    /// `detect_width` columns for the detector; 0: as it is) that `found` lacks, each judged by
    /// the landmark network at full resolution started from the shear `start_k` with
    /// `budget`. Nothing without the network detector.
    pub(crate) fn find_new_faces(
        &self,
        gray: &GrayImage,
        detect_width: u32,
        start_k: f64,
        budget: Budget,
        found: &mut Vec<(Rect, Option<FaceReport>)>,
    ) {
        let Some(net) = self.network_detector() else {
            return;
        };
        let (shrunk, scale) = crate::detect::shrunk_to_width(gray, detect_width);
        let min_width = f64::from(self.config.min_face) / scale;
        let windows = network_windows(net, &shrunk, min_width)
            .into_iter()
            .map(|(mut d, logit)| {
                let b = d.face_box;
                d.face_box = Rect::new(b.x * scale, b.y * scale, b.width * scale, b.height * scale);
                (d, logit)
            })
            .collect();
        let doubtful = self.judge_windows(gray, windows, Some(start_k), budget, found);
        self.judge_doubtful_windows(gray, &doubtful, budget, found);
    }

    /// The proposal network when it is the face detector ([`Detector::Network`] with the
    /// network locator, which judges its windows).
    pub(crate) fn network_detector(&self) -> Option<&ProposalNet> {
        let network = self.locator() == Locator::Network;
        self.face_detector.as_ref().filter(|_| network)
    }

    /// Says so when the image's shape keeps some of the search's views from being searched
    /// (see [`MAX_VIEW_PIXELS_RATIO`]): faces sheared or rolled beyond what the cascade
    /// tolerates may then be missed.
    fn shape_warnings(&self, width: u32, height: u32) -> Vec<String> {
        if self.network_detector().is_some() {
            return Vec::new();
        }
        let skipped = self
            .every_view(false)
            .iter()
            .filter(|v| !search::view_is_bounded(width, height, v.k, v.roll))
            .count();
        if skipped == 0 {
            return Vec::new();
        }
        vec![format!(
            "{skipped} de-sheared or turned views not searched: the image ({width}x{height}) is too tall or too wide for them to stay within {MAX_VIEW_PIXELS_RATIO} times its pixels"
        )]
    }

    /// The greyscale image the detector and the filters work on.
    pub fn gray(img: &DynamicImage) -> GrayImage {
        crate::detect::to_gray_opencv(img)
    }

    /// What locates the features.
    pub fn locator(&self) -> Locator {
        self.config.locator
    }

    /// The Viola-Jones detector ([`Config::cascade`]): what finds the faces when
    /// [`Self::uses_network_detector`] is false (and what the video tracker holds); otherwise
    /// the face proposal network finds them and this one is not run on stills.
    pub fn cascade_detector(&self) -> &FaceDetector {
        &self.detector
    }

    /// The filters.
    pub fn filters(&self) -> &EyeFilters {
        &self.filters
    }
}
