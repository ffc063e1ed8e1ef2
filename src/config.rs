//! How an [`Unshear`](crate::Unshear) corrector behaves, as one plain value.
//!
//! A [`Config`] is built once (from [`Config::default`] or a preset, then fields changed as
//! needed), checked by [`Config::validate`] when the corrector is made, and never changed
//! after: no setting depends on the order in which others were set.
//!
//! ```
//! use unshear::{Config, Locator};
//!
//! let paper = Config::paper();
//! assert_eq!(paper.locator, Locator::Filters);
//! let strict = Config { min_confidence: 0.5, ..Config::default() };
//! assert!(strict.validate().is_ok());
//! ```

use crate::detect::DetectorParams;
use crate::error::{Error, Result};
use crate::estimate::ShearModel;
use crate::filters::FilterType;
use crate::locate::network::Budget;
use serde::{Deserialize, Serialize};

/// Default confidence below which a face's estimate is refused: about the least trustworthy fifth
/// of the estimates on web photos.
pub const DEFAULT_MIN_CONFIDENCE: f64 = 0.25;

/// Largest |shear| a face search's de-sheared views may take (beyond it a view is mostly
/// padding).
pub const MAX_SEARCH_SHEAR: f64 = 2.0;

/// Largest |roll| (degrees, exclusive) a face search's turned views may take.
pub const MAX_SEARCH_ROLL: f64 = 90.0;

/// Default largest |shear| an estimate may have to be accepted ([`Config::max_shear`]).
///
/// A rolling-shutter shear is the motion during the sensor's readout: `|k| = 0.6` means the
/// subject moved 60% of the frame's height sideways while it was read, beyond what usable photos
/// show (the paper's real clips reach 0.54, the development set's shears go to 0.40 and the
/// thorough search's views to 0.45). Beyond it an estimate is a false face or a failed
/// location, and correcting by it would destroy the picture (docs/how-it-works.md).
pub const DEFAULT_MAX_SHEAR: f64 = 0.6;

/// How hard [`Unshear`](crate::Unshear) looks for faces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FaceSearch {
    /// Every view, for every image: the image as it is, each de-sheared view and each turned
    /// view, with lenient detectors whose boxes the landmark network judges (its face score,
    /// not the detector's neighbour count, decides what is a face), then the proposal
    /// classifier's windows where no face was found. Needs the network: with the filters,
    /// which cannot tell a false box, the search is quick with these turned views.
    #[default]
    Thorough,
    /// The image as it is; the de-sheared and turned views only when it gives no face with an
    /// accepted estimate. Several times faster; misses faces the cascade cannot see as they are
    /// in images where another face was found, and heads rolled more than about 25 degrees.
    Quick,
}

/// What finds the faces.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Detector {
    /// The face proposal network (a small convolutional window classifier trained on sheared
    /// and rolled faces) over an image pyramid, each window judged by the landmark network's
    /// face score; once more over the image de-sheared by the shear the faces measure, when
    /// that is 0.1 or more. Needs the network locator: with the filters, which cannot tell a
    /// false window, the Viola-Jones search is used.
    #[default]
    Network,
    /// The paper's Viola-Jones cascade, in the views [`Config::search`] chooses.
    ViolaJones,
}

/// Default smallest face (box width, pixels) the network detector looks for.
pub const DEFAULT_MIN_FACE: u32 = 40;

/// Most refinement passes [`Config::refinements`] may ask for: each locates the features again,
/// and a few settle the estimate; more would only make a run that cannot be stopped.
pub const MAX_REFINEMENTS: usize = 10;

/// Smallest Viola-Jones scale step (`scaleFactor`) [`Config::validate`] takes: the pyramid's
/// levels grow as 1 / ln(step), so a step just above 1 would search for hours.
pub const MIN_SCALE_FACTOR: f64 = 1.01;

/// The smallest face (box width, pixels) the network detector can see: its window's own scale.
pub const MIN_NETWORK_FACE: u32 = 24;

/// What locates a face's features.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Locator {
    /// The landmark network: eyes, nose and mouth from one small convolutional network, and
    /// the shear both from those points and as the network reads it, cropped again around the
    /// face until the estimate settles; the nostrils are still found with the eye filter, as
    /// the paper does, for the report and the annotated picture.
    #[default]
    Network,
    /// The correlation filters throughout, as the paper does (eyes, nostrils; the nose and
    /// mouth filters of this project), with the shear from the configured shear model.
    Filters,
}

/// Every setting of a corrector. `Default` is the recommended behaviour (the command line's
/// defaults for stills); [`Config::quick`], [`Config::paper`] and [`Config::video`] are the
/// other presets.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// What finds the faces.
    pub detector: Detector,
    /// Smallest face (box width, pixels) the network detector looks for; below
    /// [`MIN_NETWORK_FACE`] (0 included) it looks from there.
    pub min_face: u32,
    /// What locates the eyes, nose and mouth.
    pub locator: Locator,
    /// How hard the Viola-Jones detector searches for faces ([`Detector::ViolaJones`]).
    pub search: FaceSearch,
    /// Confidence (0 to 1) below which a face's estimate is refused (`k: None`).
    pub min_confidence: f64,
    /// Largest |shear| a face's estimate may have and be accepted: beyond it the estimate is
    /// refused as physically implausible (`k: None`,
    /// [`Refusal::ImplausibleShear`](crate::pipeline::Refusal::ImplausibleShear)); see
    /// [`DEFAULT_MAX_SHEAR`].
    pub max_shear: f64,
    /// How much work the landmark network may spend on each face.
    pub network_budget: Budget,
    /// Filters only: how many times the features are located again in the face de-sheared by
    /// the last estimate.
    pub refinements: usize,
    /// Filters only: the formula that turns located points into `k`.
    pub shear_model: ShearModel,
    /// Which built-in filter set (ignored when [`Models`](crate::pipeline::Models) bring their
    /// own filters).
    pub filter_type: FilterType,
    /// The Viola-Jones detector's parameters (smallest face, neighbours, scale step).
    pub cascade: DetectorParams,
    /// Whether the thorough search adds the face proposal classifier's windows as candidates.
    pub proposals: bool,
    /// Whether OpenCV's `haarcascade_frontalface_default` is asked when the main cascade finds
    /// no face with an accepted estimate (quick search with views only).
    pub fallback_cascade: bool,
    /// Whether every view is searched for every image, not only when the ones before found no
    /// trusted face.
    pub search_every_view: bool,
    /// Shears whose de-sheared views are searched; `None`: the search's own
    /// ([`THOROUGH_SHEAR_HYPOTHESES`](crate::pipeline::THOROUGH_SHEAR_HYPOTHESES) or
    /// [`DEFAULT_SHEAR_HYPOTHESES`](crate::pipeline::DEFAULT_SHEAR_HYPOTHESES)).
    pub shear_hypotheses: Option<Vec<f64>>,
    /// Head rolls (degrees) whose turned views are searched; `None`: the search's own.
    pub roll_hypotheses: Option<Vec<f64>>,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            detector: Detector::Network,
            min_face: DEFAULT_MIN_FACE,
            locator: Locator::Network,
            search: FaceSearch::Thorough,
            min_confidence: DEFAULT_MIN_CONFIDENCE,
            max_shear: DEFAULT_MAX_SHEAR,
            network_budget: Budget::STILL,
            refinements: 0,
            shear_model: ShearModel::default(),
            filter_type: FilterType::DEFAULT,
            cascade: DetectorParams::default(),
            proposals: true,
            fallback_cascade: false,
            search_every_view: false,
            shear_hypotheses: None,
            roll_hypotheses: None,
        }
    }
}

impl Config {
    /// The Viola-Jones cascade in the image as it is first; de-sheared and turned views only when
    /// it gives no trusted face (the command line's `--detector viola-jones --quick`). Misses
    /// more sheared and rolled faces than the other searches.
    pub fn quick() -> Self {
        Self {
            detector: Detector::ViolaJones,
            search: FaceSearch::Quick,
            ..Self::default()
        }
    }

    /// The Viola-Jones cascade in every de-sheared and turned view of every image, with the
    /// proposal classifier's windows added (the command line's `--detector viola-jones
    /// --thorough`): the most thorough search and the slowest, by about 20 times.
    pub fn thorough() -> Self {
        Self {
            detector: Detector::ViolaJones,
            search: FaceSearch::Thorough,
            ..Self::default()
        }
    }

    /// The paper's pipeline: one Viola-Jones pass over the image as it is, the correlation
    /// filters (UMACE) for eyes and nostrils, and equation 5.
    pub fn paper() -> Self {
        Self {
            detector: Detector::ViolaJones,
            locator: Locator::Filters,
            search: FaceSearch::Quick,
            shear_model: ShearModel::Equation5,
            filter_type: FilterType::Umace,
            proposals: false,
            shear_hypotheses: Some(Vec::new()),
            roll_hypotheses: Some(Vec::new()),
            ..Self::default()
        }
    }

    /// For video frames, where a temporal filter averages the frames' estimates: the landmark
    /// network's video budget (two crops per face), and with the filters equation 5, the
    /// steadiest model from frame to frame.
    pub fn video() -> Self {
        Self {
            network_budget: Budget::VIDEO,
            shear_model: ShearModel::Equation5,
            ..Self::default()
        }
    }

    /// Checks every value once; [`Unshear::new`](crate::Unshear::new) calls it.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(Error::InvalidArgument(what));
        if !(0.0..=1.0).contains(&self.min_confidence) {
            return bad(format!(
                "minimum confidence {} is outside 0 to 1",
                self.min_confidence
            ));
        }
        if !(self.max_shear.is_finite()
            && self.max_shear > 0.0
            && self.max_shear <= MAX_SEARCH_SHEAR)
        {
            return bad(format!(
                "maximum shear {} must be above 0 and at most {MAX_SEARCH_SHEAR}",
                self.max_shear
            ));
        }
        let b = &self.network_budget;
        if b.max_passes == 0 || b.max_supersampling == 0 {
            return bad("the network budget needs at least one crop and one read".into());
        }
        let non_negative = |v: f64| v.is_finite() && v >= 0.0;
        if !(non_negative(b.shear_tolerance) && non_negative(b.roll_tolerance)) {
            return bad("the network budget's tolerances must be finite and >= 0".into());
        }
        if self.refinements > MAX_REFINEMENTS {
            return bad(format!(
                "{} refinement passes: at most {MAX_REFINEMENTS}",
                self.refinements
            ));
        }
        let d = &self.cascade;
        if !(d.scale_factor.is_finite()
            && d.scale_factor >= MIN_SCALE_FACTOR
            && d.scale_factor <= 2.0)
        {
            return bad(format!(
                "scale factor {} must be at least {MIN_SCALE_FACTOR} and at most 2",
                d.scale_factor
            ));
        }
        if !(d.scale_offset.is_finite() && d.scale_offset >= 0.0) {
            return bad(format!("scale offset {} must be >= 0", d.scale_offset));
        }
        if let Some(ks) = &self.shear_hypotheses {
            if ks
                .iter()
                .any(|k| !k.is_finite() || k.abs() > MAX_SEARCH_SHEAR)
            {
                return bad(format!(
                    "shear hypotheses must be numbers between -{MAX_SEARCH_SHEAR} and {MAX_SEARCH_SHEAR}"
                ));
            }
        }
        if let Some(rolls) = &self.roll_hypotheses {
            if rolls
                .iter()
                .any(|r| !r.is_finite() || r.abs() >= MAX_SEARCH_ROLL)
            {
                return bad(format!(
                    "roll hypotheses must be degrees between -{MAX_SEARCH_ROLL} and {MAX_SEARCH_ROLL}"
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_are_valid_and_differ_where_documented() {
        for c in [
            Config::default(),
            Config::thorough(),
            Config::quick(),
            Config::paper(),
            Config::video(),
        ] {
            c.validate().expect("preset valid");
        }
        assert_eq!(Config::quick().search, FaceSearch::Quick);
        assert_eq!(Config::video().network_budget, Budget::VIDEO);
        let paper = Config::paper();
        assert_eq!(paper.shear_model, ShearModel::Equation5);
        assert_eq!(paper.shear_hypotheses.as_deref(), Some(&[][..]));
    }

    #[test]
    fn out_of_range_values_are_refused() {
        let cases = [
            Config {
                min_confidence: 1.5,
                ..Config::default()
            },
            Config {
                min_confidence: f64::NAN,
                ..Config::default()
            },
            Config {
                max_shear: 0.0,
                ..Config::default()
            },
            Config {
                max_shear: f64::INFINITY,
                ..Config::default()
            },
            Config {
                network_budget: Budget {
                    max_passes: 0,
                    ..Budget::STILL
                },
                ..Config::default()
            },
            Config {
                cascade: DetectorParams {
                    scale_factor: 1.0,
                    ..DetectorParams::default()
                },
                ..Config::default()
            },
            Config {
                cascade: DetectorParams {
                    scale_factor: 1.000_000_1,
                    ..DetectorParams::default()
                },
                ..Config::default()
            },
            Config {
                refinements: MAX_REFINEMENTS + 1,
                ..Config::default()
            },
            Config {
                shear_hypotheses: Some(vec![0.3, f64::INFINITY]),
                ..Config::default()
            },
            Config {
                roll_hypotheses: Some(vec![90.0]),
                ..Config::default()
            },
        ];
        for c in cases {
            assert!(
                matches!(c.validate(), Err(Error::InvalidArgument(_))),
                "{c:?}"
            );
        }
    }
}
