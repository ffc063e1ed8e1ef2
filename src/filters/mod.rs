//! Correlation filters in the frequency domain: UMACE synthesis ([`umace`]), the versioned
//! filter file ([`file`]), and FFT correlation with peak and peak-to-sidelobe ratio ([`correlate`]).
//!
//! All filters here are square, `size x size` (64 for the eye filters, as the paper), stored as
//! their 2-D DFT in row-major order, and applied to a patch `x` as `c = IDFT(X . conj(H))`. A filter
//! trained on patches with the feature at the patch centre therefore peaks at
//! `c[0, 0]` for a centred feature, and at `c[dy, dx]` (indices modulo `size`) for a feature displaced
//! by `(dx, dy)` from the centre.

pub mod correlate;
pub mod file;
pub mod umace;

pub use correlate::{Correlator, Peak};
pub use file::EyeFilters;
pub use umace::{normalize_patch, UmaceTrainer};

use rustfft::num_complex::Complex32;

/// One correlation filter: its spectrum, `size x size`, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Filter {
    /// Side length in pixels.
    pub size: usize,
    /// `H[v * size + u]`, the 2-D DFT of the spatial filter.
    pub spectrum: Vec<Complex32>,
    /// How many training patches made it (0 if unknown).
    pub training_count: u32,
}
