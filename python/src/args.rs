//! The numeric arguments of the functions and constructors (`#[pyo3(from_py_with = ...)]`), with
//! the checks of the settings ([`integer`], [`real`]): `TypeError` naming the argument for a
//! value of the wrong type (`bool` included), `ValueError` naming it and its range for a value
//! outside it (negative for a count, too large for its type, NaN or infinite). Without them
//! pyo3's conversions raise `OverflowError` for negative counts and take `True` for 1.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::config::{integer, real, U32_MAX, U64_MAX};

/// Most threads `estimate_many` starts (as the CLI's `--jobs`, a `u16`).
pub const MAX_THREADS: i128 = u16::MAX as i128;

/// Frames the smoother may hold back (as `unshear video --smoothing-lag`): frames are held in
/// memory.
pub const MAX_SMOOTHING_LAG: i128 = 250;

fn finite(key: &str, value: &Bound<'_, PyAny>) -> PyResult<f64> {
    let x = real(key, value)?;
    if !x.is_finite() {
        return Err(PyValueError::new_err(format!(
            "{key} must be a finite number, got {x}"
        )));
    }
    Ok(x)
}

fn optional<T>(
    value: &Bound<'_, PyAny>,
    get: impl FnOnce(&Bound<'_, PyAny>) -> PyResult<T>,
) -> PyResult<Option<T>> {
    if value.is_none() {
        Ok(None)
    } else {
        get(value).map(Some)
    }
}

pub fn max_pixels(value: &Bound<'_, PyAny>) -> PyResult<u64> {
    integer("max_pixels", value, 0, U64_MAX)
}

pub fn threads(value: &Bound<'_, PyAny>) -> PyResult<Option<usize>> {
    optional(value, |v| integer("threads", v, 1, MAX_THREADS))
}

/// The JPEG quality, 1 to 100 (`WriteOptions` would clamp what is outside).
pub fn jpeg_quality(value: &Bound<'_, PyAny>) -> PyResult<u8> {
    integer("jpeg_quality", value, 1, 100)
}

pub fn k(value: &Bound<'_, PyAny>) -> PyResult<f64> {
    finite("k", value)
}

pub fn optional_k(value: &Bound<'_, PyAny>) -> PyResult<Option<f64>> {
    optional(value, k)
}

pub fn pivot(value: &Bound<'_, PyAny>) -> PyResult<Option<f64>> {
    optional(value, |v| finite("pivot", v))
}

pub fn fps(value: &Bound<'_, PyAny>) -> PyResult<f64> {
    let x = real("fps", value)?;
    if !(x.is_finite() && x > 0.0) {
        return Err(PyValueError::new_err(format!(
            "fps must be a positive number, got {x}"
        )));
    }
    Ok(x)
}

pub fn readout_fraction(value: &Bound<'_, PyAny>) -> PyResult<Option<f64>> {
    if value.is_none() {
        return Ok(None);
    }
    let x = real("readout_fraction", value)?;
    unshear::video::check_readout_fraction(x)
        .map(Some)
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// ``deblur_exposure``: ``None`` (off), ``"auto"`` (estimated from the blur) or a fraction of
/// the frame interval in (0, 1].
pub fn deblur_exposure(value: &Bound<'_, PyAny>) -> PyResult<Option<unshear::video::Deblur>> {
    if value.is_none() {
        return Ok(None);
    }
    if let Ok(s) = value.extract::<String>() {
        return match s.as_str() {
            "auto" => Ok(Some(unshear::video::Deblur::estimated())),
            other => Err(PyValueError::new_err(format!(
                "deblur_exposure must be a fraction of the frame interval or \"auto\", got {other:?}"
            ))),
        };
    }
    let x = real("deblur_exposure", value)?;
    unshear::video::Deblur::new(x)
        .map(Some)
        .map_err(|e| PyValueError::new_err(e.to_string()))
}

/// ``blur`` of ``correct``: ``None`` (off), ``"auto"`` (found from the image: ``Some(None)``)
/// or a length in pixels, 1 to 256.
pub fn blur(value: &Bound<'_, PyAny>) -> PyResult<Option<Option<f64>>> {
    if value.is_none() {
        return Ok(None);
    }
    if let Ok(s) = value.extract::<String>() {
        return match s.as_str() {
            "auto" => Ok(Some(None)),
            other => Err(PyValueError::new_err(format!(
                "blur must be a length in pixels or \"auto\", got {other:?}"
            ))),
        };
    }
    let x = real("blur", value)?;
    let (lo, hi) = (unshear::deblur::MIN_BLUR, unshear::deblur::MAX_BLUR);
    if (lo..=hi).contains(&x) {
        Ok(Some(Some(x)))
    } else {
        Err(PyValueError::new_err(format!(
            "blur must be in [{lo}, {hi}] pixels, got {x}"
        )))
    }
}

pub fn hold(value: &Bound<'_, PyAny>) -> PyResult<f64> {
    let x = real("hold", value)?;
    if !(x.is_finite() && x >= 0.0) {
        return Err(PyValueError::new_err(format!(
            "hold must be a finite number of seconds >= 0, got {x}"
        )));
    }
    Ok(x)
}

pub fn decay(value: &Bound<'_, PyAny>) -> PyResult<f64> {
    let x = real("decay", value)?;
    if !(x.is_finite() && x > 0.0) {
        return Err(PyValueError::new_err(format!(
            "decay must be a finite number of seconds > 0, got {x}"
        )));
    }
    Ok(x)
}

pub fn smoothing_lag(value: &Bound<'_, PyAny>) -> PyResult<usize> {
    integer("smoothing_lag", value, 0, MAX_SMOOTHING_LAG)
}

pub fn redetect(value: &Bound<'_, PyAny>) -> PyResult<Option<u64>> {
    optional(value, |v| integer("redetect", v, 1, U64_MAX))
}

pub fn lost_interval(value: &Bound<'_, PyAny>) -> PyResult<u64> {
    integer("lost_interval", value, 1, U64_MAX)
}

/// The width full detection shrinks frames to (0: full size).
pub fn detect_width(value: &Bound<'_, PyAny>) -> PyResult<u32> {
    integer("detect_width", value, 0, U32_MAX)
}
