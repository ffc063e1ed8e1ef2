//! Correlation filters in the frequency domain: three synthesis methods — UMACE (`umace`),
//! ASEF (`asef`) and MOSSE (`mosse`) — one `FilterTrainer` front for all three
//! (`trainer`), the versioned filter file (`mod@file`), and FFT correlation with peak and
//! peak-to-sidelobe ratio (`correlate`).
//!
//! All filters here are square, `size x size` (64 for the eye filters, as the paper), stored as
//! their 2-D DFT in row-major order, and applied to a patch `x` as `c = IDFT(X . conj(H))`. A filter
//! trained on patches with the feature at the patch centre therefore peaks at
//! `c[0, 0]` for a centred feature, and at `c[dy, dx]` (indices modulo `size`) for a feature displaced
//! by `(dx, dy)` from the centre. ASEF and MOSSE are trained to give exactly that plane, a
//! Gaussian peak at `(dx, dy)` (`desired_output_into`); UMACE gives it by construction (its
//! filter is a whitened average of centred features). The runtime code is the same for all.

#[cfg(any(test, feature = "dev"))]
pub(crate) mod asef;
pub(crate) mod correlate;
mod file;
#[cfg(any(test, feature = "dev"))]
pub(crate) mod mosse;
mod spectra;
#[cfg(any(test, feature = "dev"))]
pub(crate) mod trainer;
#[cfg(any(test, feature = "dev"))]
pub(crate) mod umace;

pub(crate) use correlate::{Correlator, Peak};
pub use file::EyeFilters;
pub(crate) use spectra::normalize_patch;
#[cfg(feature = "dev")]
pub(crate) use trainer::FilterTrainer;

use rustfft::num_complex::Complex32;

use crate::error::{Error, Result};

/// One correlation filter: its spectrum, `size x size`, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Filter {
    /// Side length in pixels.
    pub size: usize,
    /// `H[v * size + u]`, the 2-D DFT of the spatial filter.
    pub(crate) spectrum: Vec<Complex32>,
    /// How many training patches made it (0 if unknown).
    pub training_count: u32,
}

/// How a set of filters was synthesised. All types are applied the same way at run time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FilterType {
    /// Unconstrained Minimum Average Correlation Energy (Mahalanobis et al. 1994; the paper's).
    Umace,
    /// Average of Synthetic Exact Filters (Bolme, Draper & Beveridge, CVPR 2009).
    Asef,
    /// Minimum Output Sum of Squared Error (Bolme, Beveridge, Draper & Lui, CVPR 2010).
    Mosse,
}

impl FilterType {
    /// Every type, in file-code order.
    pub const ALL: [FilterType; 3] = [FilterType::Umace, FilterType::Asef, FilterType::Mosse];

    /// The type used when none is asked for (the built-in filters, `unshear train`): MOSSE, on
    /// the measurements in the README ("Filter types"). With the nose-tip yaw model and each
    /// type's own confidence model, on the 928 Caltech development faces at k = 0 and +-0.40,
    /// 60% of MOSSE's estimates were within 0.10 of the truth on the 628 faces not used for
    /// fitting (ASEF 60%, UMACE 54.5%), with fewer wrong estimates accepted; on the 15 Yale lab
    /// faces all three put 56 of 75 within 0.05, and all pass the end-to-end fixtures.
    pub const DEFAULT: FilterType = FilterType::Mosse;

    /// Lower-case name, as on the command line (`umace`, `asef`, `mosse`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Umace => "umace",
            Self::Asef => "asef",
            Self::Mosse => "mosse",
        }
    }

    /// The code stored in the filter file (1, 2, 3).
    pub(crate) fn code(self) -> u32 {
        match self {
            Self::Umace => 1,
            Self::Asef => 2,
            Self::Mosse => 3,
        }
    }

    /// The type of a file code, or [`Error::UnknownFilterType`].
    pub(crate) fn from_code(code: u32) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|t| t.code() == code)
            .ok_or(Error::UnknownFilterType(code))
    }

    /// Whether training should show the type translated crops with the feature off-centre
    /// (ASEF and MOSSE learn where the peak goes; UMACE assumes a centred feature).
    #[cfg(any(test, feature = "dev"))]
    pub(crate) fn learns_localisation(self) -> bool {
        !matches!(self, Self::Umace)
    }
}

impl Default for FilterType {
    fn default() -> Self {
        Self::DEFAULT
    }
}

impl std::fmt::Display for FilterType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for FilterType {
    type Err = Error;

    fn from_str(s: &str) -> Result<Self> {
        Self::ALL
            .into_iter()
            .find(|t| t.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| {
                Error::InvalidArgument(format!(
                    "unknown filter type {s:?} (expected umace, asef or mosse)"
                ))
            })
    }
}

/// Standard deviation, in pixels, of the Gaussian peak ASEF and MOSSE are trained to output
/// ([`desired_output_into`]): 2 px, as Bolme et al. use for eyes in 64-128 px face crops; narrow
/// enough for a sharp, well-placed peak, wide enough that a half-pixel annotation error does not
/// turn the target into a different function.
#[cfg(any(test, feature = "dev"))]
pub(crate) const DESIRED_SIGMA: f64 = 2.0;

/// Settings of the ASEF and MOSSE trainers.
#[cfg(any(test, feature = "dev"))]
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SynthesisOptions {
    /// Width of the desired output's Gaussian peak, pixels.
    pub(crate) sigma: f64,
    /// Floor added to the power spectrum, as a fraction of its mean (see each trainer).
    pub(crate) regularization: f64,
    /// Multiply the synthesised spatial filter by a Hamming window centred on the patch centre,
    /// as UMACE does ([`spectra::hamming_windowed`]).
    pub(crate) window: bool,
}

/// [`desired_output_into`] into a new plane.
#[cfg(test)]
pub(crate) fn desired_output(size: usize, dx: f64, dy: f64, sigma: f64) -> Vec<f32> {
    let mut out = vec![0f32; size * size];
    desired_output_into(size, dx, dy, sigma, &mut out);
    out
}

/// The correlation plane a filter should give for a patch whose feature lies `(dx, dy)` pixels
/// from the patch centre, in [`Correlator`]'s convention: a Gaussian of standard deviation
/// `sigma` and height 1 centred on plane index `(dx, dy)`, wrapping modulo `size` (index
/// `size - 1` is displacement -1). Row-major, `size x size`, written into `out`.
///
/// # Panics
/// If `out` holds fewer than `size * size` values (a programming error).
#[cfg(any(test, feature = "dev"))]
pub(crate) fn desired_output_into(size: usize, dx: f64, dy: f64, sigma: f64, out: &mut [f32]) {
    let half = (size / 2) as isize;
    let n = size as isize;
    // Signed displacement of plane index i: 0..half-1 are >= 0, the rest negative.
    let signed = |i: usize| -> f64 {
        let i = i as isize;
        (if i >= half { i - n } else { i }) as f64
    };
    // Wrapped distance from the target along one axis, so a peak near the edge wraps too.
    let wrapped = |d: f64| -> f64 {
        let s = size as f64;
        let d = d.rem_euclid(s);
        if d > s / 2.0 {
            d - s
        } else {
            d
        }
    };
    let inv = 1.0 / (2.0 * sigma * sigma);
    for y in 0..size {
        let ey = wrapped(signed(y) - dy);
        for x in 0..size {
            let ex = wrapped(signed(x) - dx);
            out[y * size + x] = (-(ex * ex + ey * ey) * inv).exp() as f32;
        }
    }
}

/// The normalised (Pearson) correlation of two equally long sample vectors, in [-1, 1]; 0 when
/// either is constant.
#[cfg(test)]
pub(crate) fn zero_mean_correlation(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len().min(b.len()).max(1) as f64;
    let mean_a = a.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
    let mean_b = b.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b) {
        let (x, y) = (f64::from(x) - mean_a, f64::from(y) - mean_b);
        ab += x * y;
        aa += x * x;
        bb += y * y;
    }
    if aa <= 0.0 || bb <= 0.0 {
        0.0
    } else {
        ab / (aa * bb).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn types_round_trip_through_codes_and_names() {
        for t in FilterType::ALL {
            assert_eq!(FilterType::from_code(t.code()).expect("known"), t);
            assert_eq!(t.name().parse::<FilterType>().expect("known"), t);
            assert_eq!(t.to_string(), t.name());
        }
        assert_eq!("MOSSE".parse::<FilterType>().ok(), Some(FilterType::Mosse));
        assert!(matches!(
            FilterType::from_code(0),
            Err(Error::UnknownFilterType(0))
        ));
        assert!(matches!(
            FilterType::from_code(4),
            Err(Error::UnknownFilterType(4))
        ));
        assert!("mace".parse::<FilterType>().is_err());
        assert!(!FilterType::Umace.learns_localisation());
        assert!(FilterType::Mosse.learns_localisation() && FilterType::Asef.learns_localisation());
    }

    #[test]
    fn desired_output_peaks_at_the_displacement_and_wraps() {
        let n = 16;
        let g = desired_output(n, 0.0, 0.0, 2.0);
        assert_eq!(g[0], 1.0);
        // Symmetric about index 0 modulo n: displacement +1 and -1 are equal.
        assert!((g[1] - g[n - 1]).abs() < 1e-7 && (g[n] - g[(n - 1) * n]).abs() < 1e-7);
        assert!((g[1] - (-1.0f32 / 8.0).exp()).abs() < 1e-6);
        // Displaced to (3, -2): the maximum is at column 3, row n - 2.
        let g = desired_output(n, 3.0, -2.0, 2.0);
        let (i, &max) = g
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .expect("non-empty");
        assert_eq!((i % n, i / n), (3, n - 2));
        assert_eq!(max, 1.0);
        // A sub-pixel target splits its height between the two neighbours.
        let g = desired_output(n, 0.5, 0.0, 2.0);
        assert!((g[0] - g[1]).abs() < 1e-7 && g[0] < 1.0);
    }

    #[test]
    fn zero_mean_correlation_ignores_offset_and_gain_and_is_zero_for_constants() {
        let a = [1.0f32, 2.0, 4.0, 3.0];
        let b: Vec<f32> = a.iter().map(|x| 10.0 + 3.0 * x).collect();
        let flipped: Vec<f32> = a.iter().map(|x| -x).collect();
        assert!((zero_mean_correlation(&a, &b) - 1.0).abs() < 1e-9);
        assert!((zero_mean_correlation(&a, &flipped) + 1.0).abs() < 1e-9);
        assert_eq!(zero_mean_correlation(&a, &[5.0; 4]), 0.0);
    }
}

/// Synthetic patches for the trainers' tests.
#[cfg(test)]
pub(crate) mod test_support {
    use crate::rng::SplitMix64;

    /// White noise in [-1, 1), deterministic in `seed`.
    pub(crate) fn random_patch(n: usize, seed: u64) -> Vec<f32> {
        let mut rng = SplitMix64::new(seed);
        (0..n * n).map(|_| rng.symmetric(1.0) as f32).collect()
    }

    /// An "eye": a dark disc with a light ring, `(dx, dy)` from the patch centre, on a
    /// background of a faint gradient, three fainter random blobs and noise (all from `seed`).
    pub(crate) fn blob_scene(n: usize, dx: f64, dy: f64, seed: u64) -> Vec<f32> {
        let mut rng = SplitMix64::new(seed ^ 0x5eed);
        let c = (n / 2) as f64;
        let clutter: Vec<(f64, f64)> = (0..3)
            .map(|_| (rng.next_f64() * n as f64, rng.next_f64() * n as f64))
            .collect();
        let mut v = vec![0f32; n * n];
        for y in 0..n {
            for x in 0..n {
                let (fx, fy) = (x as f64 - c - dx, y as f64 - c - dy);
                let r2 = fx * fx + 1.5 * fy * fy;
                let mut s = -(-r2 / 8.0).exp() + 0.5 * (-((r2.sqrt() - 5.0).powi(2)) / 2.0).exp();
                for &(bx, by) in &clutter {
                    let d2 = (x as f64 - bx).powi(2) + (y as f64 - by).powi(2);
                    s -= 0.3 * (-d2 / 12.0).exp();
                }
                s += 0.003 * x as f64 + 0.1 * (rng.next_f64() - 0.5);
                v[y * n + x] = s as f32;
            }
        }
        v
    }
}
