//! Measurement harnesses behind `unshear eval`: the paper's experiments on data anyone can get.
//!
//! * [`shear`]: annotated faces sheared synthetically; detection, estimate, eye error, tracking
//!   and the oracle per shear (the median estimates of the paper's Table I).
//! * [`nostrils`]: nostril and eye localisation against 68-point markup (dlib's example faces).
//! * [`recognition`]: rank-1 face recognition on undistorted, sheared and corrected probes with a
//!   Gabor + SVM recogniser after the paper's "G96" (Table I's recognition rows).
//! * [`plot`]: small text-free PNG plots written with the `image` crate already used for I/O, so
//!   the default build needs no font or plotting stack (axes are described in `summary.md`).
//!
//! Every harness runs the pipeline as a user would (detection included) and counts a face the
//! detector misses as a failure, as a real system would.

pub mod camera;
pub mod nostrils;
pub mod plot;
pub mod recognition;
pub mod shear;
pub mod video;

pub use shear::{
    evaluate_shear, evaluate_shear_in_context, ShearEvalOptions, ShearEvalResult, ShearSample,
};

/// `count` as a percentage of `total` (0 for an empty total, so empty rows print as 0%).
pub fn pct(count: usize, total: usize) -> f64 {
    if total == 0 {
        0.0
    } else {
        100.0 * count as f64 / total as f64
    }
}

/// Arithmetic mean of finite values; `None` when there are none.
pub fn mean(values: &[f64]) -> Option<f64> {
    let v: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// Formats an optional number with three decimals, `-` when absent (Markdown table cells).
pub fn fmt3(v: Option<f64>) -> String {
    v.map_or_else(|| "-".to_string(), |v| format!("{v:.3}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pct_and_mean_known_values() {
        assert_eq!(pct(1, 4), 25.0);
        assert_eq!(pct(3, 0), 0.0);
        assert_eq!(mean(&[1.0, 2.0, f64::NAN, 6.0]), Some(3.0));
        assert_eq!(mean(&[]), None);
        assert_eq!(fmt3(Some(0.12345)), "0.123");
        assert_eq!(fmt3(None), "-");
    }
}
