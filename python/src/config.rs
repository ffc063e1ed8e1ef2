//! The corrector's settings, as Python keyword arguments (the library's options,
//! `unshear::config::OPTIONS`): parsed here, turned into the library's `Config` by its one
//! resolution, `Options::to_config` (as the CLI's flags are).

use pyo3::exceptions::{PyOverflowError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use unshear::config::{Options, Search};
use unshear::estimate::ShearModel;
use unshear::filters::FilterType;
use unshear::{Config, Detector, Locator, Ruler, Unshear};

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
    pub max_shear: f64,
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
    /// `None`: `auto` for stills, `faces` for video (as the CLI leaves it).
    pub ruler: Option<Ruler>,
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
            max_shear: c.max_shear,
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
            ruler: None,
        }
    }
}

/// Most crops the network may read per face (as the CLI's `--max-crops`).
const MAX_CROPS: i128 = 64;
/// The largest values of the unsigned types, as [`integer`]'s bounds.
pub const U32_MAX: i128 = u32::MAX as i128;
pub const U64_MAX: i128 = u64::MAX as i128;

/// The keyword names, in the order `Unshear.config` lists them: the library's options.
pub fn keys() -> impl Iterator<Item = &'static str> {
    unshear::config::options().iter().map(|o| o.name)
}

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
pub const RULERS: [(&str, Ruler); 4] = [
    ("faces", Ruler::Faces),
    ("auto", Ruler::Auto),
    ("combine", Ruler::Combine),
    ("scene", Ruler::Scene),
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
                        | "ruler"
                );
            if optional_none {
                continue;
            }
            match key.as_str() {
                "detector" => c.detector = Some(choice(&key, &value, &DETECTORS)?),
                "locator" => c.locator = choice(&key, &value, &LOCATORS)?,
                "search" => c.search = Some(choice(&key, &value, &SEARCHES)?),
                "min_confidence" => c.min_confidence = real(&key, &value)?,
                "max_shear" => c.max_shear = real(&key, &value)?,
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
                "ruler" => c.ruler = Some(choice(&key, &value, &RULERS)?),
                _ => {
                    return Err(PyTypeError::new_err(format!(
                        "{caller}() got an unexpected keyword argument '{key}' (settings: {})",
                        keys().collect::<Vec<_>>().join(", ")
                    )))
                }
            }
        }
        // The values and their combinations are checked once, by the library.
        c.options()
            .to_config(Config::default())
            .map_err(crate::to_pyerr)?;
        Ok(c)
    }

    /// The library's options these settings give.
    pub fn options(&self) -> Options {
        let mut o = Options::default();
        o.detector = self.detector;
        o.locator = Some(self.locator);
        o.search = self.search;
        o.min_confidence = Some(self.min_confidence);
        o.max_shear = Some(self.max_shear);
        o.max_crops = self.max_crops.map(usize::from);
        o.refinements = Some(self.refinements);
        o.shear_model = self.shear_model;
        o.filter_type = Some(self.filter_type);
        o.min_face = self.min_face;
        o.min_neighbors = Some(self.min_neighbors);
        o.scale_factor = Some(self.scale_factor);
        o.proposals = Some(self.proposals);
        o.fallback_cascade = Some(self.fallback_cascade);
        o.search_every_view = Some(self.search_every_view);
        o.shear_hypotheses = self.shear_hypotheses.clone();
        o.roll_hypotheses = self.roll_hypotheses.clone();
        o.ruler = self.ruler;
        o
    }

    /// The detector these settings run, as the library resolves it (Viola-Jones when a search
    /// or the filters ask for it).
    pub fn resolved_detector(&self) -> Detector {
        self.options()
            .to_config(Config::default())
            .map_or(Detector::Network, |c| c.detector)
    }

    /// The settings as a dict of the keyword arguments (what `Unshear.config` returns).
    pub fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("detector", name_of(&DETECTORS, self.resolved_detector()))?;
        d.set_item("locator", name_of(&LOCATORS, self.locator))?;
        d.set_item("search", self.search.map(|s| name_of(&SEARCHES, s)))?;
        d.set_item("min_confidence", self.min_confidence)?;
        d.set_item("max_shear", self.max_shear)?;
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
        d.set_item("ruler", self.ruler.map(|r| name_of(&RULERS, r)))?;
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
/// `Config::video()`, by the library's one resolution of the options (as the CLI's flags).
pub fn to_config(cfg: &PyConfig, use_: Use) -> unshear::Result<Config> {
    let base = match use_ {
        Use::Stills => Config::default(),
        Use::Video => Config::video(),
    };
    cfg.options().to_config(base)
}

/// The corrector for `cfg` with the built-in models (`Config::validate` refuses bad values).
pub fn build(cfg: &PyConfig, use_: Use) -> unshear::Result<Unshear> {
    Unshear::new(to_config(cfg, use_)?)
}
