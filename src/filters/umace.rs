//! UMACE (Unconstrained Minimum Average Correlation Energy) filter synthesis, `h = D^-1 m`
//! (paper eq. 7; Mahalanobis et al. 1994).
//!
//! `m` is the spectrum of the mean training patch and `D` the mean power spectrum. Each training
//! patch is normalised with [`normalize_patch`] (zero mean, unit energy), the same transform the
//! locator applies at run time, so lighting and contrast do not weigh in the average.
//!
//! **Guarding `D^-1`.** Zero-mean patches have no energy at DC, so `D(0,0) = 0` (and `m(0,0) = 0`);
//! high frequencies can also carry almost no energy. We divide by
//! `D + REGULARIZATION * mean(D)` instead of `D`: a small constant floor relative to the average
//! power, the optimal-trade-off form `(alpha D + (1 - alpha) I)^-1 m` with `alpha` close to 1. It
//! leaves the filter unchanged where `D` is large and keeps it finite (zero at DC) where `D`
//! vanishes.
//!
//! **Hamming window.** As in the paper, the synthesized filter (not the input patch) is windowed:
//! the spatial filter `IDFT(H)` is multiplied by a 2-D periodic Hamming window centred on the
//! patch centre, and transformed back. This tapers the filter's support to the eye and its
//! surroundings and reduces edge effects of the circular correlation.

use rustfft::num_complex::Complex32;

use super::spectra::TrainingSpectra;
use super::Filter;

/// Floor added to the mean power spectrum, as a fraction of its mean (see the module docs): 1% of
/// the average power, enough to keep the vanishing DC and high-frequency bins from dominating the
/// filter. Not tuned: a sweep against the eye-localisation rate is future work.
pub(crate) const REGULARIZATION: f64 = 1e-2;

/// Accumulates training patches and synthesises a UMACE filter from them.
///
/// Sums are kept in `f64` and patches are added in the order given, so the same patches give the
/// same filter bits on every run.
pub(crate) struct UmaceTrainer {
    spectra: TrainingSpectra,
    sum_spectrum: Vec<(f64, f64)>,
    sum_power: Vec<f64>,
    count: u32,
}

impl std::fmt::Debug for UmaceTrainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UmaceTrainer")
            .field("size", &self.spectra.size())
            .field("count", &self.count)
            .finish()
    }
}

impl UmaceTrainer {
    /// A trainer for `size x size` patches.
    pub(crate) fn new(size: usize) -> Self {
        Self {
            spectra: TrainingSpectra::new(size),
            sum_spectrum: vec![(0.0, 0.0); size * size],
            sum_power: vec![0.0; size * size],
            count: 0,
        }
    }

    /// Number of patches added so far.
    #[cfg(test)]
    pub(crate) fn count(&self) -> u32 {
        self.count
    }

    /// Adds one training patch (`size x size`, row-major, feature at the centre `(size/2, size/2)`).
    /// The patch is normalised with [`normalize_patch`] first.
    ///
    /// # Panics
    /// If `patch.len() != size * size` (a programming error, not a data error).
    pub(crate) fn add(&mut self, patch: &[f32]) {
        self.spectra.load_patch(patch);
        for ((s, p), x) in self
            .sum_spectrum
            .iter_mut()
            .zip(self.sum_power.iter_mut())
            .zip(&self.spectra.patch_spectrum)
        {
            let (re, im) = (f64::from(x.re), f64::from(x.im));
            s.0 += re;
            s.1 += im;
            *p += re * re + im * im;
        }
        self.count += 1;
    }

    /// Synthesises the filter `h = (D + floor)^-1 m`, Hamming-windowed in space (module docs).
    /// Returns `None` when no patch was added.
    pub(crate) fn finish(self) -> Option<Filter> {
        if self.count == 0 {
            return None;
        }
        let n = self.spectra.size();
        let count = f64::from(self.count);
        let mean_power = self.sum_power.iter().sum::<f64>() / (count * (n * n) as f64);
        let floor = REGULARIZATION * mean_power;
        let unwindowed: Vec<Complex32> = self
            .sum_spectrum
            .iter()
            .zip(&self.sum_power)
            .map(|(&(re, im), &p)| {
                let d = p / count + floor;
                if d > 0.0 {
                    Complex32::new((re / count / d) as f32, (im / count / d) as f32)
                } else {
                    Complex32::default()
                }
            })
            .collect();
        Some(self.spectra.into_filter(unwindowed, true, self.count))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filters::normalize_patch;
    use crate::filters::spectra::hamming;
    use crate::filters::Correlator;

    /// A textured "eye": a dark blob with a ring and a gradient, deterministic.
    fn eye_patch(n: usize, cx: f64, cy: f64) -> Vec<f32> {
        let mut v = vec![0f32; n * n];
        for y in 0..n {
            for x in 0..n {
                let dx = x as f64 - cx;
                let dy = y as f64 - cy;
                let r2 = dx * dx + 1.8 * dy * dy;
                let iris = -(-r2 / 18.0).exp();
                let lid = 0.4 * (-((dy + 6.0).powi(2)) / 4.0).exp() * (-(dx * dx) / 80.0).exp();
                v[y * n + x] = (iris - lid + 0.002 * x as f64) as f32;
            }
        }
        v
    }

    #[test]
    fn normalised_patch_has_zero_mean_and_unit_energy() {
        let mut p: Vec<f32> = (0..100).map(|i| (i % 7) as f32 * 3.0 + 10.0).collect();
        normalize_patch(&mut p);
        let mean: f32 = p.iter().sum::<f32>() / 100.0;
        let energy: f32 = p.iter().map(|v| v * v).sum();
        assert!(mean.abs() < 1e-6 && (energy - 1.0).abs() < 1e-5);
        let mut flat = vec![5.0f32; 16];
        normalize_patch(&mut flat);
        assert!(flat.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn filter_trained_on_shifted_copies_peaks_at_the_feature() {
        let n = 64;
        let mut trainer = UmaceTrainer::new(n);
        // Copies of one eye jittered by up to a pixel around the centre, as real crops are.
        for (jx, jy) in [
            (0.0, 0.0),
            (0.5, -0.5),
            (-0.5, 0.5),
            (1.0, 0.0),
            (0.0, -1.0),
            (-1.0, 1.0),
        ] {
            trainer.add(&eye_patch(n, 32.0 + jx, 32.0 + jy));
        }
        assert_eq!(trainer.count(), 6);
        let filter = trainer.finish().expect("trained");
        let mut c = Correlator::new(n);
        for (ex, ey) in [(32.0, 32.0), (40.0, 27.0), (25.0, 38.0)] {
            let mut patch = eye_patch(n, ex, ey);
            normalize_patch(&mut patch);
            let peak = c.correlate(&patch, &filter, 20, 20);
            assert!(
                (peak.dx - (ex - 32.0)).abs() <= 1.0,
                "dx {} for eye at {ex}",
                peak.dx
            );
            assert!(
                (peak.dy - (ey - 32.0)).abs() <= 1.0,
                "dy {} for eye at {ey}",
                peak.dy
            );
            assert!(peak.psr > 5.0, "psr {}", peak.psr);
        }
    }

    #[test]
    fn dc_is_zero_and_filter_is_finite() {
        let mut trainer = UmaceTrainer::new(32);
        trainer.add(&eye_patch(32, 16.0, 16.0));
        let f = trainer.finish().expect("trained");
        assert!(f
            .spectrum
            .iter()
            .all(|c| c.re.is_finite() && c.im.is_finite()));
        // The Hamming window spreads a little energy into DC, but it stays tiny.
        let max = f.spectrum.iter().map(|c| c.norm()).fold(0.0, f32::max);
        assert!(f.spectrum[0].norm() < 0.05 * max);
    }

    #[test]
    fn training_is_deterministic() {
        let train = || {
            let mut t = UmaceTrainer::new(32);
            for i in 0..5 {
                t.add(&eye_patch(32, 16.0 + i as f64 * 0.3, 16.0));
            }
            t.finish().expect("trained")
        };
        assert_eq!(train(), train());
    }

    #[test]
    fn empty_trainer_gives_no_filter() {
        assert!(UmaceTrainer::new(8).finish().is_none());
    }

    #[test]
    fn hamming_is_centred() {
        let w = hamming(64);
        assert!((w[32] - 1.0).abs() < 1e-6);
        assert!((w[0] - 0.08).abs() < 1e-6);
        assert!((w[31] - w[33]).abs() < 1e-6);
    }
}
