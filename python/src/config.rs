//! The corrector's settings, as Python keyword arguments: parsed and checked here, turned into
//! the library's `Config` by [`to_config`] (as the CLI turns its flags into one).

use pyo3::exceptions::{PyOverflowError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use unshear::detect::DetectorParams;
use unshear::estimate::ShearModel;
use unshear::filters::FilterType;
use unshear::{Config, Detector, FaceSearch, Locator, Unshear};

/// How hard faces are searched for (`search=`): the CLI's default, `--quick` and
/// `--no-shear-search`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Search {
    Thorough,
    Quick,
    Single,
}

/// Every setting of `unshear.Unshear(**config)`, with the CLI's defaults (`None`: the default
/// of stills or of video, as the CLI leaves it).
#[derive(Debug, Clone, PartialEq)]
pub struct PyConfig {
    /// `None`: the network detector, or Viola-Jones when `search` or the filters ask for it
    /// (as the CLI's `--quick`, `--thorough` and `--locator filters` do).
    pub detector: Option<Detector>,
    pub locator: Locator,
    /// `None`: `quick` (with Viola-Jones; the network detector has no views).
    pub search: Option<Search>,
    pub min_confidence: f64,
    pub max_crops: Option<u16>,
    pub refinements: usize,
    pub shear_model: Option<ShearModel>,
    pub filter_type: FilterType,
    /// `None`: the detector's own (40 px for the network, the cascade's 20 px window).
    pub min_face: Option<u32>,
    pub min_neighbors: u32,
    pub scale_factor: f64,
    pub proposals: bool,
    pub fallback_cascade: bool,
    pub search_every_view: bool,
    pub shear_hypotheses: Option<Vec<f64>>,
    pub roll_hypotheses: Option<Vec<f64>>,
}

impl Default for PyConfig {
    /// The library's defaults for stills (`Config::default()`, the CLI's).
    fn default() -> Self {
        let c = Config::default();
        Self {
            detector: None,
            locator: c.locator,
            search: None,
            min_confidence: c.min_confidence,
            max_crops: None,
            refinements: c.refinements,
            shear_model: None,
            filter_type: c.filter_type,
            min_face: None,
            min_neighbors: c.cascade.min_neighbors,
            scale_factor: c.cascade.scale_factor,
            proposals: c.proposals,
            fallback_cascade: c.fallback_cascade,
            search_every_view: c.search_every_view,
            shear_hypotheses: c.shear_hypotheses,
            roll_hypotheses: c.roll_hypotheses,
        }
    }
}

/// Most crops the network may read per face (as the CLI's `--max-crops`).
const MAX_CROPS: i128 = 64;
/// The largest values of the unsigned types, as [`integer`]'s bounds.
pub const U32_MAX: i128 = u32::MAX as i128;
pub const U64_MAX: i128 = u64::MAX as i128;

/// The keyword names, in the order `Unshear.config` lists them.
pub const KEYS: [&str; 16] = [
    "detector",
    "locator",
    "search",
    "min_confidence",
    "max_crops",
    "refinements",
    "shear_model",
    "filter_type",
    "min_face",
    "min_neighbors",
    "scale_factor",
    "proposals",
    "fallback_cascade",
    "search_every_view",
    "shear_hypotheses",
    "roll_hypotheses",
];

fn choice<T: Copy>(key: &str, value: &Bound<'_, PyAny>, options: &[(&str, T)]) -> PyResult<T> {
    let text: String = value.extract().map_err(|_| {
        PyTypeError::new_err(format!("{key} must be a string, got {}", type_name(value)))
    })?;
    options
        .iter()
        .find(|(name, _)| *name == text)
        .map(|&(_, v)| v)
        .ok_or_else(|| {
            let names: Vec<&str> = options.iter().map(|(n, _)| *n).collect();
            PyValueError::new_err(format!(
                "{key} must be one of {}, got {text:?}",
                names.join(", ")
            ))
        })
}

fn type_name(value: &Bound<'_, PyAny>) -> String {
    value
        .get_type()
        .name()
        .map_or_else(|_| "?".to_string(), |n| n.to_string())
}

/// An integer setting or argument in `min..=max` (and in `T`'s range): `TypeError` for what is
/// not an integer (`bool` included: `True` is no count of pixels or frames), `ValueError`
/// naming the range for one outside it (negative for an unsigned value, or too large).
pub fn integer<T: TryFrom<i128>>(
    key: &str,
    value: &Bound<'_, PyAny>,
    min: i128,
    max: i128,
) -> PyResult<T> {
    if value.is_instance_of::<pyo3::types::PyBool>() {
        return Err(PyTypeError::new_err(format!(
            "{key} must be an integer, got bool"
        )));
    }
    let out_of_range =
        |got: String| PyValueError::new_err(format!("{key} must be {min} to {max}, got {got}"));
    match value.extract::<i128>() {
        Ok(n) if (min..=max).contains(&n) => {
            T::try_from(n).map_err(|_| out_of_range(n.to_string()))
        }
        Ok(n) => Err(out_of_range(n.to_string())),
        // An integer beyond i128: out of range, whatever the range.
        Err(e) if e.is_instance_of::<PyOverflowError>(value.py()) => Err(out_of_range(
            value
                .str()
                .map_or_else(|_| "?".to_string(), |s| s.to_string()),
        )),
        Err(_) => Err(PyTypeError::new_err(format!(
            "{key} must be an integer, got {}",
            type_name(value)
        ))),
    }
}

/// A number setting or argument (a float or an int, not `bool`): `TypeError` for anything
/// else, `ValueError` for an int too large for a float. NaN and infinities pass: the callers
/// check the range.
pub fn real(key: &str, value: &Bound<'_, PyAny>) -> PyResult<f64> {
    if value.is_instance_of::<pyo3::types::PyBool>() {
        return Err(PyTypeError::new_err(format!(
            "{key} must be a number, got bool"
        )));
    }
    value.extract::<f64>().map_err(|e| {
        if e.is_instance_of::<PyOverflowError>(value.py()) {
            PyValueError::new_err(format!(
                "{key} must be a finite number, got an int too large for a float"
            ))
        } else {
            PyTypeError::new_err(format!("{key} must be a number, got {}", type_name(value)))
        }
    })
}

fn flag(key: &str, value: &Bound<'_, PyAny>) -> PyResult<bool> {
    if !value.is_instance_of::<pyo3::types::PyBool>() {
        return Err(PyTypeError::new_err(format!(
            "{key} must be True or False, got {}",
            type_name(value)
        )));
    }
    value.extract()
}

fn floats(key: &str, value: &Bound<'_, PyAny>) -> PyResult<Option<Vec<f64>>> {
    if value.is_none() {
        return Ok(None);
    }
    if value.is_instance_of::<pyo3::types::PyString>() {
        return Err(PyTypeError::new_err(format!(
            "{key} must be a sequence of numbers or None, got str"
        )));
    }
    let items = value.extract::<Vec<Bound<'_, PyAny>>>().map_err(|_| {
        PyTypeError::new_err(format!(
            "{key} must be a sequence of numbers or None, got {}",
            type_name(value)
        ))
    })?;
    let list = items
        .iter()
        .enumerate()
        .map(|(i, item)| real(&format!("{key}[{i}]"), item))
        .collect::<PyResult<_>>()?;
    Ok(Some(list))
}

pub const DETECTORS: [(&str, Detector); 2] = [
    ("network", Detector::Network),
    ("viola-jones", Detector::ViolaJones),
];
pub const LOCATORS: [(&str, Locator); 2] =
    [("network", Locator::Network), ("filters", Locator::Filters)];
pub const SEARCHES: [(&str, Search); 3] = [
    ("thorough", Search::Thorough),
    ("quick", Search::Quick),
    ("single", Search::Single),
];
pub const SHEAR_MODELS: [(&str, ShearModel); 3] = [
    ("equation5", ShearModel::Equation5),
    ("shear-roll", ShearModel::ShearRoll),
    ("shear-roll-yaw", ShearModel::ShearRollYaw),
];
pub const FILTER_TYPES: [(&str, FilterType); 3] = [
    ("umace", FilterType::Umace),
    ("asef", FilterType::Asef),
    ("mosse", FilterType::Mosse),
];

fn name_of<T: PartialEq + Copy>(options: &[(&'static str, T)], value: T) -> &'static str {
    options
        .iter()
        .find(|(_, v)| *v == value)
        .map_or("?", |(n, _)| *n)
}

impl PyConfig {
    /// Parses the keyword arguments `kwargs` (every key must be one of [`KEYS`]; `None` for a
    /// key means its default) and checks the values as the CLI does.
    pub fn from_kwargs(caller: &str, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut c = Self::default();
        let Some(kwargs) = kwargs else {
            return Ok(c);
        };
        for (key, value) in kwargs.iter() {
            let key: String = key.extract()?;
            let optional_none = value.is_none()
                && matches!(
                    key.as_str(),
                    "detector"
                        | "search"
                        | "max_crops"
                        | "shear_model"
                        | "min_face"
                        | "shear_hypotheses"
                        | "roll_hypotheses"
                );
            if optional_none {
                continue;
            }
            match key.as_str() {
                "detector" => c.detector = Some(choice(&key, &value, &DETECTORS)?),
                "locator" => c.locator = choice(&key, &value, &LOCATORS)?,
                "search" => c.search = Some(choice(&key, &value, &SEARCHES)?),
                "min_confidence" => c.min_confidence = real(&key, &value)?,
                "max_crops" => c.max_crops = Some(integer(&key, &value, 1, MAX_CROPS)?),
                "refinements" => {
                    c.refinements =
                        integer(&key, &value, 0, unshear::config::MAX_REFINEMENTS as i128)?
                }
                "shear_model" => c.shear_model = Some(choice(&key, &value, &SHEAR_MODELS)?),
                "filter_type" => c.filter_type = choice(&key, &value, &FILTER_TYPES)?,
                "min_face" => c.min_face = Some(integer(&key, &value, 0, U32_MAX)?),
                "min_neighbors" => c.min_neighbors = integer(&key, &value, 0, U32_MAX)?,
                "scale_factor" => c.scale_factor = real(&key, &value)?,
                "proposals" => c.proposals = flag(&key, &value)?,
                "fallback_cascade" => c.fallback_cascade = flag(&key, &value)?,
                "search_every_view" => c.search_every_view = flag(&key, &value)?,
                "shear_hypotheses" => c.shear_hypotheses = floats(&key, &value)?,
                "roll_hypotheses" => c.roll_hypotheses = floats(&key, &value)?,
                _ => {
                    return Err(PyTypeError::new_err(format!(
                        "{caller}() got an unexpected keyword argument '{key}' (settings: {})",
                        KEYS.join(", ")
                    )))
                }
            }
        }
        c.validate()?;
        Ok(c)
    }

    /// The checks the CLI makes of its flags before the library sees them (clap's conflicts; the
    /// ranges were checked as the values were parsed); `Config::validate` checks the values
    /// themselves when the corrector is built.
    pub fn validate(&self) -> PyResult<()> {
        let bad = |m: &str| Err(PyValueError::new_err(m.to_string()));
        if self.detector == Some(Detector::Network) && self.search.is_some() {
            return bad("search chooses the views of detector=\"viola-jones\"; the network detector has none");
        }
        if self.search == Some(Search::Single)
            && (self.shear_hypotheses.is_some()
                || self.roll_hypotheses.is_some()
                || self.fallback_cascade
                || self.search_every_view)
        {
            return bad(
                "search=\"single\" is one detection pass: no shear_hypotheses, roll_hypotheses, \
                 fallback_cascade or search_every_view",
            );
        }
        if self.search_every_view && self.search != Some(Search::Quick) {
            return bad(
                "search_every_view goes with search=\"quick\" (the thorough search always \
                 searches every view)",
            );
        }
        Ok(())
    }

    /// The detector these settings run: the one asked for, else Viola-Jones when a search or
    /// the filters ask for it (as the CLI decides), else the network. With the filters it is
    /// Viola-Jones even when the network is asked for: the library runs the network detector
    /// only with the network locator, which judges its windows (`Detector::Network`).
    pub fn resolved_detector(&self) -> Detector {
        if self.locator == Locator::Filters {
            return Detector::ViolaJones;
        }
        let viola_jones = self.search.is_some()
            || self.locator == Locator::Filters
            || self.shear_hypotheses.is_some()
            || self.roll_hypotheses.is_some()
            || self.fallback_cascade
            || self.search_every_view;
        match self.detector {
            Some(d) => d,
            None if viola_jones => Detector::ViolaJones,
            None => Detector::Network,
        }
    }

    /// The settings as a dict of the keyword arguments (what `Unshear.config` returns).
    pub fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("detector", name_of(&DETECTORS, self.resolved_detector()))?;
        d.set_item("locator", name_of(&LOCATORS, self.locator))?;
        d.set_item("search", self.search.map(|s| name_of(&SEARCHES, s)))?;
        d.set_item("min_confidence", self.min_confidence)?;
        d.set_item("max_crops", self.max_crops)?;
        d.set_item("refinements", self.refinements)?;
        d.set_item(
            "shear_model",
            self.shear_model.map(|m| name_of(&SHEAR_MODELS, m)),
        )?;
        d.set_item("filter_type", name_of(&FILTER_TYPES, self.filter_type))?;
        d.set_item("min_face", self.min_face)?;
        d.set_item("min_neighbors", self.min_neighbors)?;
        d.set_item("scale_factor", self.scale_factor)?;
        d.set_item("proposals", self.proposals)?;
        d.set_item("fallback_cascade", self.fallback_cascade)?;
        d.set_item("search_every_view", self.search_every_view)?;
        let list = |v: &Option<Vec<f64>>| -> PyResult<Option<Bound<'py, PyList>>> {
            v.as_ref().map(|v| PyList::new(py, v)).transpose()
        };
        d.set_item("shear_hypotheses", list(&self.shear_hypotheses)?)?;
        d.set_item("roll_hypotheses", list(&self.roll_hypotheses)?)?;
        Ok(d)
    }
}

/// Stills or video: what the settings left at `None` default to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Use {
    Stills,
    Video,
}

/// The library's `Config` for `cfg`, on top of `Config::default()` (stills) or
/// `Config::video()`, exactly as the CLI makes it from the same flags (`config_from` in
/// `cli/src/models.rs`).
pub fn to_config(cfg: &PyConfig, use_: Use) -> Config {
    let base = match use_ {
        Use::Stills => Config::default(),
        Use::Video => Config::video(),
    };
    let single = cfg.search == Some(Search::Single);
    let mut c = Config {
        detector: cfg.resolved_detector(),
        min_face: cfg.min_face.unwrap_or(base.min_face),
        locator: cfg.locator,
        search: match cfg.search {
            Some(Search::Thorough) => FaceSearch::Thorough,
            _ => FaceSearch::Quick,
        },
        min_confidence: cfg.min_confidence,
        refinements: cfg.refinements,
        proposals: cfg.proposals,
        search_every_view: cfg.search_every_view,
        shear_hypotheses: cfg.shear_hypotheses.clone(),
        roll_hypotheses: cfg.roll_hypotheses.clone(),
        fallback_cascade: cfg.fallback_cascade && !single,
        filter_type: cfg.filter_type,
        cascade: DetectorParams {
            min_size: (cfg.min_face.unwrap_or(0), cfg.min_face.unwrap_or(0)),
            min_neighbors: cfg.min_neighbors,
            scale_factor: cfg.scale_factor,
            ..DetectorParams::default()
        },
        ..base
    };
    if single {
        c.shear_hypotheses = Some(Vec::new());
        c.roll_hypotheses = Some(Vec::new());
    }
    if let Some(model) = cfg.shear_model {
        c.shear_model = model;
    }
    if let Some(crops) = cfg.max_crops {
        c.network_budget.max_passes = usize::from(crops);
    }
    c
}

/// The corrector for `cfg` with the built-in models (`Config::validate` refuses bad values).
pub fn build(cfg: &PyConfig, use_: Use) -> unshear::Result<Unshear> {
    Unshear::new(to_config(cfg, use_))
}
