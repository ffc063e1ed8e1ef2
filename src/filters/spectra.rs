//! What filter training shares: each patch normalised and transformed (for ASEF and MOSSE together
//! with the spectrum of its desired output), into buffers reused from patch to patch, and the finished
//! spectrum windowed into a [`Filter`].

#[cfg(any(test, feature = "dev"))]
use rustfft::num_complex::Complex32;

#[cfg(any(test, feature = "dev"))]
use super::correlate::Correlator;
#[cfg(any(test, feature = "dev"))]
use super::{desired_output_into, Filter};

/// FFT plans and per-patch buffers for a trainer of `size x size` patches.
#[cfg(any(test, feature = "dev"))]
pub(crate) struct TrainingSpectra {
    size: usize,
    correlator: Correlator,
    patch: Vec<f32>,
    desired: Vec<f32>,
    /// Spectrum of the last normalised patch.
    pub(crate) patch_spectrum: Vec<Complex32>,
    /// Spectrum of the last patch's desired output.
    pub(crate) target_spectrum: Vec<Complex32>,
}

#[cfg(any(test, feature = "dev"))]
impl TrainingSpectra {
    pub(crate) fn new(size: usize) -> Self {
        Self {
            size,
            correlator: Correlator::new(size),
            patch: vec![0.0; size * size],
            desired: vec![0.0; size * size],
            patch_spectrum: vec![Complex32::default(); size * size],
            target_spectrum: vec![Complex32::default(); size * size],
        }
    }

    pub(crate) fn size(&self) -> usize {
        self.size
    }

    /// Normalises `patch` ([`normalize_patch`]) and fills [`Self::patch_spectrum`] with its
    /// spectrum (all that UMACE needs).
    ///
    /// # Panics
    /// If `patch.len() != size * size` (a programming error, not a data error).
    pub(crate) fn load_patch(&mut self, patch: &[f32]) {
        assert_eq!(
            patch.len(),
            self.size * self.size,
            "training patch must be size x size"
        );
        self.patch.copy_from_slice(patch);
        normalize_patch(&mut self.patch);
        self.correlator
            .spectrum_into(&self.patch, &mut self.patch_spectrum);
    }

    /// [`Self::load_patch`], and also fills [`Self::target_spectrum`] with that of the desired output for a feature
    /// `(dx, dy)` from the patch centre.
    ///
    /// # Panics
    /// If `patch.len() != size * size` (a programming error, not a data error).
    pub(crate) fn load(&mut self, patch: &[f32], dx: f64, dy: f64, sigma: f64) {
        self.load_patch(patch);
        desired_output_into(self.size, dx, dy, sigma, &mut self.desired);
        self.correlator
            .spectrum_into(&self.desired, &mut self.target_spectrum);
    }

    /// The filter with spectrum `spectrum`, Hamming-windowed in space when `window`.
    pub(crate) fn into_filter(
        mut self,
        spectrum: Vec<Complex32>,
        window: bool,
        training_count: u32,
    ) -> Filter {
        let spectrum = if window {
            hamming_windowed(&mut self.correlator, &spectrum)
        } else {
            spectrum
        };
        Filter {
            size: self.size,
            spectrum,
            training_count,
        }
    }
}

/// Normalises a patch in place to zero mean and unit energy (sum of squares 1).
/// A constant patch becomes all zeros.
pub(crate) fn normalize_patch(patch: &mut [f32]) {
    if patch.is_empty() {
        return;
    }
    let n = patch.len() as f64;
    let mean = patch.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let energy: f64 = patch.iter().map(|&v| (f64::from(v) - mean).powi(2)).sum();
    let scale = if energy > 1e-12 {
        1.0 / energy.sqrt()
    } else {
        0.0
    };
    for v in patch.iter_mut() {
        *v = ((f64::from(*v) - mean) * scale) as f32;
    }
}

/// The spectrum of `IDFT(spectrum)` (real part) multiplied by a 2-D periodic Hamming window
/// centred on the patch centre: the spatial windowing of the module docs, shared by the ASEF and
/// MOSSE trainers. `correlator` must be of the spectrum's size.
#[cfg(any(test, feature = "dev"))]
pub(crate) fn hamming_windowed(
    correlator: &mut Correlator,
    spectrum: &[Complex32],
) -> Vec<Complex32> {
    let n = correlator.size();
    let mut spatial = correlator.inverse_real(spectrum);
    let window = hamming(n);
    for y in 0..n {
        for x in 0..n {
            spatial[y * n + x] *= window[x] * window[y];
        }
    }
    correlator.spectrum(&spatial)
}

/// Periodic Hamming window of length `n`, centred on sample `n / 2` (the patch centre).
#[cfg(any(test, feature = "dev"))]
pub(crate) fn hamming(n: usize) -> Vec<f32> {
    (0..n)
        .map(|i| (0.54 - 0.46 * (2.0 * std::f64::consts::PI * i as f64 / n as f64).cos()) as f32)
        .collect()
}
