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

/// Which rulers make an image's shear: the faces, the scene's verticals
/// ([`SceneShear`](crate::SceneShear)), or both.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Ruler {
    /// The faces alone; the scene is not read.
    Faces,
    /// The faces make the shear; when no face gives one, the scene is read and reported (not
    /// used). Combining them was measured to lose accuracy on the development photos
    /// (docs/accuracy.md), so it is asked for with `Combine`.
    #[default]
    Auto,
    /// With faces, their shear and the scene's combined by their inverse variances when they
    /// agree within their uncertainties (the faces decide when they do not: the subject moved
    /// differently from the camera); without faces the image gets no shear.
    Combine,
    /// As `Combine`, and without faces the scene's shear is the image's: a leaning structure
    /// would otherwise be "straightened" wrongly, so it is asked for explicitly.
    Scene,
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
    /// Which rulers make the image's shear (stills; video reads the faces alone).
    pub ruler: Ruler,
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
            ruler: Ruler::Auto,
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
            ruler: Ruler::Faces,
            ..Self::default()
        }
    }

    /// The settings a corrector runs with: `self` checked ([`Self::validate`]) and its two
    /// dependent settings made explicit, so the value shows what runs. With
    /// [`Locator::Filters`] the detector is [`Detector::ViolaJones`] (the filters cannot tell
    /// the network detector's false windows); with [`Detector::ViolaJones`] each crop is read
    /// once (`network_budget.mirrored` off: the face-score limits for the cascade's boxes are
    /// set on single readings). [`Unshear::new`](crate::Unshear::new) keeps the result and
    /// [`Unshear::config`](crate::Unshear::config) returns it; resolving twice changes nothing.
    pub fn resolve(mut self) -> Result<Self> {
        self.validate()?;
        if self.locator == Locator::Filters {
            self.detector = Detector::ViolaJones;
        }
        if self.detector == Detector::ViolaJones {
            self.network_budget.mirrored = false;
        }
        Ok(self)
    }

    /// Checks every value once; [`Self::resolve`] calls it.
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

/// The kind of value a user option takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OptionKind {
    /// On or off (a command-line switch: `--name`, or `--no-name` when on by default).
    Flag,
    /// A whole number.
    Integer,
    /// A number.
    Number,
    /// A list of numbers (comma-separated on the command line).
    Numbers,
    /// One of these names.
    Choice(&'static [&'static str]),
}

/// One user option: what the command line's flags and Python's keyword arguments are made
/// from (and checked against by their tests), so that the two cannot drift apart.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OptionInfo {
    /// The name, snake_case: Python's keyword; the command line's flag is it in kebab-case.
    pub name: &'static str,
    /// The kind of value it takes.
    pub kind: OptionKind,
    /// The default, as text.
    pub default: &'static str,
    /// What it does, in one line.
    pub help: &'static str,
    /// The [`Config`] fields it sets (`outer.inner` for a field of a field).
    pub fields: &'static [&'static str],
}

/// The `search` option's names, in [`OptionInfo::kind`] and [`Search`] order.
pub const SEARCH_NAMES: [&str; 3] = ["thorough", "quick", "single"];

/// Every user option, in the order the command line's help and Python's `Unshear.config` list
/// them. [`Options`] has one field for each; [`Options::to_config`] turns them into a
/// [`Config`].
pub const OPTIONS: &[OptionInfo] = &[
    OptionInfo {
        name: "detector",
        kind: OptionKind::Choice(&["network", "viola-jones"]),
        default: "network; viola-jones with locator filters or any Viola-Jones search setting",
        help: "What finds the faces: the face proposal network or the paper's cascade.",
        fields: &["detector"],
    },
    OptionInfo {
        name: "locator",
        kind: OptionKind::Choice(&["network", "filters"]),
        default: "network",
        help: "What locates the eyes, nose and mouth: the landmark network or the filters.",
        fields: &["locator"],
    },
    OptionInfo {
        name: "search",
        kind: OptionKind::Choice(&SEARCH_NAMES),
        default: "none (the network detector searches no views; quick with viola-jones)",
        help: "The Viola-Jones search's views: every view, others only when needed, or none.",
        fields: &["search"],
    },
    OptionInfo {
        name: "min_confidence",
        kind: OptionKind::Number,
        default: "0.25",
        help: "Confidence (0 to 1) below which a face's estimate is refused.",
        fields: &["min_confidence"],
    },
    OptionInfo {
        name: "max_shear",
        kind: OptionKind::Number,
        default: "0.6",
        help: "Largest |k| an estimate may have and be accepted (above 0, at most 2).",
        fields: &["max_shear"],
    },
    OptionInfo {
        name: "max_crops",
        kind: OptionKind::Integer,
        default: "8 for stills, 2 for video",
        help: "Most crops the landmark network reads per face (1 to 64).",
        fields: &["network_budget.max_passes"],
    },
    OptionInfo {
        name: "refinements",
        kind: OptionKind::Integer,
        default: "0",
        help: "Filters only: passes locating the features again in the de-sheared face (0 to 10).",
        fields: &["refinements"],
    },
    OptionInfo {
        name: "shear_model",
        kind: OptionKind::Choice(&["equation5", "shear-roll", "shear-roll-yaw"]),
        default: "shear-roll-yaw for stills, equation5 for video",
        help: "Filters only: how located points become k.",
        fields: &["shear_model"],
    },
    OptionInfo {
        name: "filter_type",
        kind: OptionKind::Choice(&["umace", "asef", "mosse"]),
        default: "mosse",
        help: "Which built-in filter set.",
        fields: &["filter_type"],
    },
    OptionInfo {
        name: "min_face",
        kind: OptionKind::Integer,
        default: "40 for the network detector, the cascade's 20 px window for viola-jones",
        help: "Smallest face to look for, pixels wide.",
        fields: &["min_face", "cascade.min_size"],
    },
    OptionInfo {
        name: "min_neighbors",
        kind: OptionKind::Integer,
        default: "3",
        help: "The cascade's minimum of merged raw hits for a face (OpenCV's minNeighbors).",
        fields: &["cascade.min_neighbors"],
    },
    OptionInfo {
        name: "scale_factor",
        kind: OptionKind::Number,
        default: "1.1",
        help: "The cascade's scale step (OpenCV's scaleFactor, 1.01 to 2).",
        fields: &["cascade.scale_factor"],
    },
    OptionInfo {
        name: "proposals",
        kind: OptionKind::Flag,
        default: "true",
        help: "Whether the thorough search adds the proposal classifier's windows.",
        fields: &["proposals"],
    },
    OptionInfo {
        name: "fallback_cascade",
        kind: OptionKind::Flag,
        default: "false",
        help: "Whether OpenCV's second cascade is asked when the main one finds no trusted face.",
        fields: &["fallback_cascade"],
    },
    OptionInfo {
        name: "search_every_view",
        kind: OptionKind::Flag,
        default: "false",
        help: "With the quick search: every view of every image, not only when needed.",
        fields: &["search_every_view"],
    },
    OptionInfo {
        name: "shear_hypotheses",
        kind: OptionKind::Numbers,
        default: "the search's own",
        help: "Shears whose de-sheared views are searched.",
        fields: &["shear_hypotheses"],
    },
    OptionInfo {
        name: "roll_hypotheses",
        kind: OptionKind::Numbers,
        default: "the search's own",
        help: "Head rolls (degrees) whose turned views are searched.",
        fields: &["roll_hypotheses"],
    },
    OptionInfo {
        name: "ruler",
        kind: OptionKind::Choice(&["faces", "auto", "combine", "scene"]),
        default: "auto for stills, faces for video",
        help: "What makes k: faces (scene not read), auto (faces; the scene reported when no face gives k), combine, or scene.",
        fields: &["ruler"],
    },
];

/// The [`Config`] fields no user option sets, each with why: the presets choose them.
pub const INTERNAL_FIELDS: &[(&str, &str)] = &[
    (
        "network_budget.max_supersampling",
        "the network's reads per crop pixel: set by the presets (Budget::STILL, Budget::VIDEO)",
    ),
    (
        "network_budget.shear_tolerance",
        "when the network stops re-cropping: set by the presets",
    ),
    (
        "network_budget.roll_tolerance",
        "when the network stops re-cropping: set by the presets",
    ),
    (
        "network_budget.mirrored",
        "mirrored readings: set by the presets and by Config::resolve for Viola-Jones",
    ),
    (
        "cascade.max_size",
        "the cascade's largest box: the whole image, as the searches need",
    ),
    (
        "cascade.stage_slack",
        "near misses: set by the thorough search itself",
    ),
    (
        "cascade.scale_offset",
        "the scale ladder's start: OpenCV's, for the video tracker's boxes",
    ),
];

/// Every user option ([`OPTIONS`]).
pub fn options() -> &'static [OptionInfo] {
    OPTIONS
}

/// The `search` option: which views the Viola-Jones search looks in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Search {
    /// Every view of every image ([`FaceSearch::Thorough`]).
    Thorough,
    /// The image as it is, other views when it shows no trusted face ([`FaceSearch::Quick`]).
    Quick,
    /// The image as it is only, as the paper does: no de-sheared or turned views.
    Single,
}

/// The user options ([`OPTIONS`]) as given on the command line or to Python: `None` for one
/// not given. [`Self::to_config`] is the one place they become a [`Config`].
#[derive(Debug, Clone, Default, PartialEq)]
#[non_exhaustive]
pub struct Options {
    /// `detector`.
    pub detector: Option<Detector>,
    /// `locator`.
    pub locator: Option<Locator>,
    /// `search`.
    pub search: Option<Search>,
    /// `min_confidence`.
    pub min_confidence: Option<f64>,
    /// `max_shear`.
    pub max_shear: Option<f64>,
    /// `max_crops`.
    pub max_crops: Option<usize>,
    /// `refinements`.
    pub refinements: Option<usize>,
    /// `shear_model`.
    pub shear_model: Option<ShearModel>,
    /// `filter_type`.
    pub filter_type: Option<FilterType>,
    /// `min_face`.
    pub min_face: Option<u32>,
    /// `min_neighbors`.
    pub min_neighbors: Option<u32>,
    /// `scale_factor`.
    pub scale_factor: Option<f64>,
    /// `proposals`.
    pub proposals: Option<bool>,
    /// `fallback_cascade`.
    pub fallback_cascade: Option<bool>,
    /// `search_every_view`.
    pub search_every_view: Option<bool>,
    /// `shear_hypotheses`.
    pub shear_hypotheses: Option<Vec<f64>>,
    /// `roll_hypotheses`.
    pub roll_hypotheses: Option<Vec<f64>>,
    /// `ruler`.
    pub ruler: Option<Ruler>,
}

impl Options {
    /// Whether an option of the Viola-Jones search is given, which chooses that detector when
    /// none is named.
    fn asks_for_viola_jones(&self) -> bool {
        self.search.is_some()
            || self.locator == Some(Locator::Filters)
            || self.shear_hypotheses.is_some()
            || self.roll_hypotheses.is_some()
            || self.fallback_cascade == Some(true)
            || self.search_every_view == Some(true)
    }

    /// The detector these options run: the one named, else Viola-Jones when a setting of its
    /// search or the filters ask for it, else `base`'s.
    fn detector(&self, base: Detector) -> Detector {
        match self.detector {
            Some(d) => d,
            None if self.asks_for_viola_jones() => Detector::ViolaJones,
            None => base,
        }
    }

    /// `base` ([`Config::default`] for stills, [`Config::video`] for video) with these options
    /// applied, resolved ([`Config::resolve`]). Fails with [`Error::InvalidArgument`] for a
    /// value out of range and for options that contradict each other (a search with
    /// `detector` network; `search` single with views or their settings; `search_every_view`
    /// without `search` quick).
    pub fn to_config(&self, base: Config) -> Result<Config> {
        let bad = |what: &str| Err(Error::InvalidArgument(what.to_string()));
        if self.detector == Some(Detector::Network) && self.search.is_some() {
            return bad(
                "search chooses the views of the viola-jones detector; the network detector has none",
            );
        }
        let single = self.search == Some(Search::Single);
        if single
            && (self.shear_hypotheses.is_some()
                || self.roll_hypotheses.is_some()
                || self.fallback_cascade == Some(true)
                || self.search_every_view == Some(true))
        {
            return bad(
                "search single is one detection pass: no shear or roll hypotheses, fallback \
                 cascade or search of every view",
            );
        }
        if self.search_every_view == Some(true) && self.search != Some(Search::Quick) {
            return bad(
                "search_every_view goes with search quick (the thorough search always searches \
                 every view)",
            );
        }
        if self.max_crops == Some(0) {
            return bad("max_crops must be at least 1");
        }
        let (empty, hypotheses) = (Some(Vec::new()), |given: &Option<Vec<f64>>, base| {
            given.clone().or(base)
        });
        let mut network_budget = base.network_budget;
        if let Some(crops) = self.max_crops {
            network_budget.max_passes = crops;
        }
        let config = Config {
            detector: self.detector(base.detector),
            min_face: self.min_face.unwrap_or(base.min_face),
            locator: self.locator.unwrap_or(base.locator),
            search: match self.search {
                Some(Search::Thorough) => FaceSearch::Thorough,
                _ => FaceSearch::Quick,
            },
            min_confidence: self.min_confidence.unwrap_or(base.min_confidence),
            max_shear: self.max_shear.unwrap_or(base.max_shear),
            network_budget,
            refinements: self.refinements.unwrap_or(base.refinements),
            shear_model: self.shear_model.unwrap_or(base.shear_model),
            filter_type: self.filter_type.unwrap_or(base.filter_type),
            cascade: DetectorParams {
                min_size: self.min_face.map_or(base.cascade.min_size, |f| (f, f)),
                min_neighbors: self.min_neighbors.unwrap_or(base.cascade.min_neighbors),
                scale_factor: self.scale_factor.unwrap_or(base.cascade.scale_factor),
                ..base.cascade
            },
            proposals: self.proposals.unwrap_or(base.proposals),
            fallback_cascade: !single && self.fallback_cascade.unwrap_or(base.fallback_cascade),
            search_every_view: self.search_every_view.unwrap_or(base.search_every_view),
            shear_hypotheses: if single {
                empty.clone()
            } else {
                hypotheses(&self.shear_hypotheses, base.shear_hypotheses)
            },
            roll_hypotheses: if single {
                empty
            } else {
                hypotheses(&self.roll_hypotheses, base.roll_hypotheses)
            },
            ruler: self.ruler.unwrap_or(base.ruler),
        };
        config.resolve()
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

    /// The names of a struct's fields, from a pattern without `..`: adding a field breaks the
    /// build here until it is listed (and so classified below).
    macro_rules! field_names {
        ($value:expr => $ty:ident { $($f:ident),* $(,)? }) => {{
            let $ty { $($f: _),* } = $value;
            vec![$(stringify!($f).to_string()),*]
        }};
    }

    /// Every field of `Config`, a field of a field as `outer.inner`.
    fn config_fields() -> Vec<String> {
        let mut fields = field_names!(Config::default() => Config {
            detector, min_face, locator, search, min_confidence, max_shear, network_budget,
            refinements, shear_model, filter_type, cascade, proposals, fallback_cascade,
            search_every_view, shear_hypotheses, roll_hypotheses, ruler,
        });
        let budget = field_names!(Budget::STILL => Budget {
            max_passes, max_supersampling, shear_tolerance, roll_tolerance, mirrored,
        });
        let cascade = field_names!(DetectorParams::default() => DetectorParams {
            scale_factor, min_neighbors, min_size, max_size, stage_slack, scale_offset,
        });
        fields.retain(|f| f != "network_budget" && f != "cascade");
        fields.extend(budget.into_iter().map(|f| format!("network_budget.{f}")));
        fields.extend(cascade.into_iter().map(|f| format!("cascade.{f}")));
        fields
    }

    #[test]
    fn every_config_field_is_an_option_or_named_internal() {
        let mut claimed: Vec<String> = OPTIONS
            .iter()
            .flat_map(|o| o.fields.iter().map(|f| f.to_string()))
            .chain(INTERNAL_FIELDS.iter().map(|(f, _)| f.to_string()))
            .collect();
        claimed.sort();
        let before = claimed.len();
        claimed.dedup();
        assert_eq!(claimed.len(), before, "a field claimed twice");
        let mut fields = config_fields();
        fields.sort();
        assert_eq!(claimed, fields, "the options table against Config's fields");
    }

    #[test]
    fn options_has_one_field_per_table_entry() {
        let names = field_names!(Options::default() => Options {
            detector, locator, search, min_confidence, max_shear, max_crops, refinements,
            shear_model, filter_type, min_face, min_neighbors, scale_factor, proposals,
            fallback_cascade, search_every_view, shear_hypotheses, roll_hypotheses, ruler,
        });
        let table: Vec<String> = options().iter().map(|o| o.name.to_string()).collect();
        assert_eq!(names, table);
        for o in options() {
            assert!(o
                .name
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'));
            assert!(!o.help.is_empty() && !o.default.is_empty(), "{}", o.name);
        }
    }

    #[test]
    fn numeric_defaults_in_the_table_are_the_configs() {
        let c = Options::default()
            .to_config(Config::default())
            .expect("valid");
        let number = |name: &str| {
            let o = options().iter().find(|o| o.name == name).expect("listed");
            o.default.parse::<f64>().expect("a number")
        };
        assert_eq!(number("min_confidence"), c.min_confidence);
        assert_eq!(number("max_shear"), c.max_shear);
        assert_eq!(number("refinements"), c.refinements as f64);
        assert_eq!(number("min_neighbors"), f64::from(c.cascade.min_neighbors));
        assert_eq!(number("scale_factor"), c.cascade.scale_factor);
    }

    #[test]
    fn no_options_give_the_base_resolved() {
        for base in [Config::default(), Config::video()] {
            let c = Options::default().to_config(base.clone()).expect("valid");
            assert_eq!(
                c,
                Config {
                    search: FaceSearch::Quick,
                    ..base
                }
            );
        }
    }

    #[test]
    fn options_set_their_fields() {
        let o = Options {
            max_shear: Some(0.3),
            max_crops: Some(3),
            min_face: Some(60),
            search: Some(Search::Thorough),
            ..Options::default()
        };
        let c = o.to_config(Config::default()).expect("valid");
        assert_eq!(c.max_shear, 0.3);
        assert_eq!(c.network_budget.max_passes, 3);
        assert_eq!((c.min_face, c.cascade.min_size), (60, (60, 60)));
        assert_eq!(
            c.detector,
            Detector::ViolaJones,
            "a search chooses Viola-Jones"
        );
        assert_eq!(c.search, FaceSearch::Thorough);

        let single = Options {
            search: Some(Search::Single),
            ..Options::default()
        };
        let c = single.to_config(Config::default()).expect("valid");
        assert_eq!(c.shear_hypotheses.as_deref(), Some(&[][..]));
        assert_eq!(c.roll_hypotheses.as_deref(), Some(&[][..]));
    }

    #[test]
    fn contradicting_or_bad_options_are_refused() {
        let network_search = Options {
            detector: Some(Detector::Network),
            search: Some(Search::Quick),
            ..Options::default()
        };
        let single_views = Options {
            search: Some(Search::Single),
            shear_hypotheses: Some(vec![0.2]),
            ..Options::default()
        };
        let every_view = Options {
            search_every_view: Some(true),
            ..Options::default()
        };
        let shear = Options {
            max_shear: Some(3.0),
            ..Options::default()
        };
        let crops = Options {
            max_crops: Some(0),
            ..Options::default()
        };
        for o in [network_search, single_views, every_view, shear, crops] {
            assert!(
                matches!(
                    o.to_config(Config::default()),
                    Err(Error::InvalidArgument(_))
                ),
                "{o:?}"
            );
        }
    }

    #[test]
    fn resolving_makes_the_dependent_settings_explicit_once() {
        let filters = Config {
            locator: Locator::Filters,
            ..Config::default()
        }
        .resolve()
        .expect("valid");
        assert_eq!(filters.detector, Detector::ViolaJones);
        assert!(!filters.network_budget.mirrored);
        assert_eq!(filters.clone().resolve().expect("valid"), filters);
        let network = Config::default().resolve().expect("valid");
        assert_eq!(network, Config::default(), "the default runs as it is");
        assert!(Config {
            min_confidence: 2.0,
            ..Config::default()
        }
        .resolve()
        .is_err());
    }
}
