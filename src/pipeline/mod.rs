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
pub(crate) mod confidence;
mod correct;
mod face;
mod network_search;
mod photo;
mod proposals;
mod report;
mod row_shear;
#[cfg(test)]
mod tests;
mod viola_jones_search;

use image::{DynamicImage, GrayImage};

pub(crate) use combine::combined_shear;
pub(crate) use combine::fuse;
use combine::mark_consensus;
pub(crate) use correct::FACE_REGION_MARGIN;
pub use face::FaceStart;
pub use photo::FileOptions;
pub(crate) use proposals::{box_from_eyes, follows};
pub(crate) use report::FoundBox;
pub use report::{CorrectOptions, FaceReport, ImageReport, Readout, Refusal, Region, ShearSource};
pub use row_shear::RowShear;
use viola_jones_search::MAX_VIEW_PIXELS_RATIO;
pub use viola_jones_search::{
    Detection, DEFAULT_ROLL_HYPOTHESES, DEFAULT_SHEAR_HYPOTHESES, THOROUGH_ROLL_HYPOTHESES,
    THOROUGH_SHEAR_HYPOTHESES, WEAK_BOX_MIN_WIDTH,
};

use crate::config::Config;
pub use crate::config::{Detector, FaceSearch, Locator, Ruler};
use crate::detect::{Cascade, FaceDetector, ProposalNet};
use crate::error::Result;
use crate::filters::{EyeFilters, FilterType};
use crate::locate::network::LandmarkNet;
use viola_jones_search::{
    FallbackDetector, ThoroughDetectors, THOROUGH_MIN_NEIGHBORS,
    THOROUGH_ROLL_HYPOTHESES as THOROUGH_ROLLS, THOROUGH_SHEAR_HYPOTHESES as THOROUGH_SHEARS,
    THOROUGH_STAGE_SLACK, THOROUGH_VIEW_MIN_FACE,
};

/// The faces' one shear (their consensus) and, when faces at different heights disagree, how it
/// changes down the rows of an image `height` rows tall: what [`Unshear::estimate_gray`] makes
/// of its faces before the scene is read (for the evaluation, which scores both).
#[cfg(feature = "dev")]
pub(crate) fn faces_shear(
    mut faces: Vec<FaceReport>,
    height: u32,
) -> (Option<f64>, Option<RowShear>) {
    let consensus = mark_consensus(&mut faces);
    (consensus.k, row_shear::fit_row_shear(&faces, height))
}

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
        // The scene was read along the rows: a vertical shear is not what it measured.
        report.scene = None;
        report.scene_disagrees = false;
        // A change of shear down the rows is not one across the columns.
        report.row_shear = None;
        report.k_source = report.k.map(|_| ShearSource::Faces);
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
    pub(crate) fn face_by_columns(&self, f: &mut FaceReport) {
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
            .filter_map(|found| found.report)
            .collect();
        let mut consensus = mark_consensus(&mut faces);
        // Faces at different heights that disagree beyond their errors: the shear changes down
        // the rows, and the faces it explains are no longer outvoted.
        let bend = row_shear::fit_row_shear(&faces, gray.height());
        if let Some(rows) = &bend {
            for f in faces.iter_mut().filter(|f| row_shear::explained(rows, f)) {
                f.outvoted = false;
            }
            consensus.k = Some(rows.k_at(f64::from(gray.height()) / 2.0));
            consensus.no_majority = false;
        }
        // `auto` reads the scene only when no face gives `k` (then it is reported, not used):
        // with faces it would cost its time and, as measured, not make `k` better.
        let read_scene = match self.config.ruler {
            Ruler::Faces => false,
            Ruler::Auto => consensus.k.is_none(),
            Ruler::Combine | Ruler::Scene => true,
        };
        let scene = read_scene
            .then(|| crate::scene::estimate_scene_shear(gray, &Default::default()))
            .flatten();
        let agreeing = faces
            .iter()
            .filter(|f| f.k.is_some() && !f.outvoted)
            .count();
        let (k, k_source, scene_disagrees) =
            fuse(consensus.k, agreeing, scene.as_ref(), self.config.ruler);
        // Only a shear the faces alone made bends: the scene's is one for the whole frame.
        let row_shear = bend.filter(|_| k_source == Some(ShearSource::Faces));
        ImageReport {
            k,
            faces,
            faces_disagree: consensus.no_majority,
            warnings: self.shape_warnings(gray.width(), gray.height()),
            width: gray.width(),
            height: gray.height(),
            readout: Readout::Rows,
            scene,
            k_source,
            scene_disagrees,
            row_shear,
        }
    }

    /// Every detected face box with its estimate, if it gave one (the evaluation needs to tell a
    /// face that was not found from one that was found but gave no estimate). With the landmark
    /// network, boxes it finds no face in are left out (see the minimum face score).
    ///
    /// The network detector (the default, [`Self::network_search`]) runs once over the image
    /// and again over the image de-sheared by the shear its faces measured; Viola-Jones searches
    /// every view at once with the thorough search or [`Config::search_every_view`]
    /// ([`Self::every_view_search`]), and otherwise the image as it is first
    /// ([`Self::quick_search`]).
    pub(crate) fn detect_and_estimate(&self, gray: &GrayImage) -> Vec<FoundBox> {
        if let Some(net) = self.network_detector() {
            self.network_search(net, gray)
        } else if self.config.search_every_view || self.thorough_detectors().is_some() {
            self.every_view_search(gray)
        } else {
            self.quick_search(gray)
        }
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
            .filter(|v| !viola_jones_search::view_is_bounded(width, height, v.k, v.roll))
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
