//! MOSSE (Minimum Output Sum of Squared Error; Bolme, Beveridge, Draper & Lui, "Visual Object
//! Tracking using Adaptive Correlation Filters", CVPR 2010) synthesis.
//!
//! MOSSE finds the one filter whose outputs on all training patches are closest, in summed
//! squared error, to the desired planes `g_i` (a Gaussian peak at each patch's feature,
//! [`desired_output_into`](super::desired_output_into), [`DESIRED_SIGMA`]). In this crate's convention `c = IDFT(X . conj(H))`
//! ([`super::Correlator`]) the minimiser is, frequency by frequency,
//!
//! `H = sum_i conj(G_i) F_i / (sum_i |F_i|^2 + eps)`
//!
//! (Bolme's `H* = sum G_i F_i* / sum F_i F_i*`, conjugated for our convention). Patches are
//! normalised with [`normalize_patch`](super::normalize_patch), as UMACE's. `eps = REGULARIZATION * mean(sum_i |F_i|^2)`
//! guards the bins without energy, as UMACE's floor does; the filter is then Hamming-windowed
//! in space like UMACE's (optional).
//!
//! Unlike ASEF, the quotient is taken after summing, so a bin where one patch has little energy
//! does not blow up: MOSSE is better conditioned on few patches and reproduces the desired plane
//! exactly on one.

use rustfft::num_complex::Complex32;

use super::spectra::TrainingSpectra;
use super::{Filter, SynthesisOptions, DESIRED_SIGMA};

/// Default floor, a fraction of the mean summed power: 0.01, UMACE's. Not tuned on the
/// evaluation set.
pub(crate) const REGULARIZATION: f64 = 1e-2;

/// Default MOSSE settings: [`DESIRED_SIGMA`], [`REGULARIZATION`], windowed.
pub(crate) const DEFAULT_OPTIONS: SynthesisOptions = SynthesisOptions {
    sigma: DESIRED_SIGMA,
    regularization: REGULARIZATION,
    window: true,
};

/// Accumulates the MOSSE numerator and denominator (in `f64`, patches in the order given, so the
/// same patches give the same bits).
pub(crate) struct MosseTrainer {
    options: SynthesisOptions,
    spectra: TrainingSpectra,
    numerator: Vec<(f64, f64)>,
    denominator: Vec<f64>,
    count: u32,
}

impl std::fmt::Debug for MosseTrainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MosseTrainer")
            .field("size", &self.spectra.size())
            .field("options", &self.options)
            .field("count", &self.count)
            .finish()
    }
}

impl MosseTrainer {
    /// A trainer for `size x size` patches with the [`DEFAULT_OPTIONS`].
    pub(crate) fn new(size: usize) -> Self {
        Self::with_options(size, DEFAULT_OPTIONS)
    }

    /// A trainer with explicit settings.
    pub(crate) fn with_options(size: usize, options: SynthesisOptions) -> Self {
        Self {
            options,
            spectra: TrainingSpectra::new(size),
            numerator: vec![(0.0, 0.0); size * size],
            denominator: vec![0.0; size * size],
            count: 0,
        }
    }

    /// Number of patches added so far.
    #[cfg(test)]
    pub(crate) fn count(&self) -> u32 {
        self.count
    }

    /// Adds one patch (`size x size`, row-major) whose feature lies `(dx, dy)` pixels from the
    /// patch centre `(size/2, size/2)`. The patch is normalised with [`normalize_patch`](super::normalize_patch) first.
    ///
    /// # Panics
    /// If `patch.len() != size * size` (a programming error, not a data error).
    pub(crate) fn add(&mut self, patch: &[f32], dx: f64, dy: f64) {
        self.spectra.load(patch, dx, dy, self.options.sigma);
        for (((num, den), f), g) in self
            .numerator
            .iter_mut()
            .zip(self.denominator.iter_mut())
            .zip(&self.spectra.patch_spectrum)
            .zip(&self.spectra.target_spectrum)
        {
            // conj(G) F
            let (fr, fi) = (f64::from(f.re), f64::from(f.im));
            let (gr, gi) = (f64::from(g.re), f64::from(-g.im));
            num.0 += gr * fr - gi * fi;
            num.1 += gr * fi + gi * fr;
            *den += fr * fr + fi * fi;
        }
        self.count += 1;
    }

    /// The MOSSE filter, windowed if so configured. `None` when no patch was added.
    pub(crate) fn finish(self) -> Option<Filter> {
        if self.count == 0 {
            return None;
        }
        let mean = self.denominator.iter().sum::<f64>() / self.denominator.len() as f64;
        let eps = self.options.regularization * mean;
        let quotient: Vec<Complex32> = self
            .numerator
            .iter()
            .zip(&self.denominator)
            .map(|(&(re, im), &d)| {
                let d = d + eps;
                if d > 0.0 {
                    Complex32::new((re / d) as f32, (im / d) as f32)
                } else {
                    Complex32::default()
                }
            })
            .collect();
        Some(
            self.spectra
                .into_filter(quotient, self.options.window, self.count),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filters::test_support::{blob_scene, random_patch};
    use crate::filters::{desired_output, normalize_patch, Correlator};

    /// On one patch, without window and with a negligible floor, MOSSE's output on that patch is
    /// the desired plane (less its mean: the normalised patch has no DC to carry it).
    #[test]
    fn one_sample_reproduces_the_desired_output() {
        let n = 32;
        let options = SynthesisOptions {
            sigma: 2.0,
            regularization: 1e-6,
            window: false,
        };
        let mut trainer = MosseTrainer::with_options(n, options);
        let mut patch = random_patch(n, 11);
        trainer.add(&patch, -4.0, 5.0);
        let filter = trainer.finish().expect("trained");
        normalize_patch(&mut patch);
        let mut c = Correlator::new(n);
        c.compute_plane(&patch, &filter);
        let want = desired_output(n, -4.0, 5.0, 2.0);
        let mean = want.iter().sum::<f32>() / (n * n) as f32;
        let mut worst = 0f32;
        for y in 0..n as isize {
            for x in 0..n as isize {
                let w = want[y as usize * n + x as usize] - mean;
                worst = worst.max((c.value(x, y) - w).abs());
            }
        }
        assert!(worst < 1e-3, "largest deviation {worst}");
        let peak = c.peak_in_window(10, 10);
        assert!(
            (peak.dx + 4.0).abs() < 0.05 && (peak.dy - 5.0).abs() < 0.05,
            "{peak:?}"
        );
    }

    #[test]
    fn filter_trained_on_displaced_blobs_peaks_at_the_blob() {
        let n = 64;
        let mut trainer = MosseTrainer::new(n);
        for (i, (dx, dy)) in [
            (0.0, 0.0),
            (5.0, -3.0),
            (-6.0, 4.0),
            (2.0, 7.0),
            (-4.0, -6.0),
        ]
        .into_iter()
        .enumerate()
        {
            trainer.add(&blob_scene(n, dx, dy, i as u64), dx, dy);
        }
        let filter = trainer.finish().expect("trained");
        assert_eq!(filter.training_count, 5);
        let mut c = Correlator::new(n);
        for (i, (dx, dy)) in [(0.0, 0.0), (8.0, -5.0), (-7.0, 3.0)]
            .into_iter()
            .enumerate()
        {
            let mut patch = blob_scene(n, dx, dy, 100 + i as u64);
            normalize_patch(&mut patch);
            let peak = c.correlate(&patch, &filter, 15, 15);
            assert!(
                (peak.dx - dx).abs() <= 1.0 && (peak.dy - dy).abs() <= 1.0,
                "{peak:?} for a blob at ({dx}, {dy})"
            );
            assert!(peak.psr > 5.0, "psr {}", peak.psr);
        }
    }

    #[test]
    fn training_is_deterministic_and_empty_gives_none() {
        let train = || {
            let mut t = MosseTrainer::new(32);
            for i in 0..4 {
                t.add(
                    &blob_scene(32, i as f64, -(i as f64), i),
                    i as f64,
                    -(i as f64),
                );
            }
            t.finish().expect("trained")
        };
        assert_eq!(train(), train());
        assert!(MosseTrainer::new(8).finish().is_none());
        let f = train();
        assert!(f
            .spectrum
            .iter()
            .all(|c| c.re.is_finite() && c.im.is_finite()));
    }
}
