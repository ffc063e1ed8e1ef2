//! ASEF (Average of Synthetic Exact Filters; Bolme, Draper & Beveridge, "Average of Synthetic
//! Exact Filters", CVPR 2009) synthesis.
//!
//! For each training patch `f_i` (normalised with [`normalize_patch`](super::normalize_patch), as UMACE's) with its
//! feature `(dx, dy)` from the patch centre, the desired correlation plane `g_i` is a Gaussian
//! peak at `(dx, dy)` ([`desired_output_into`](super::desired_output_into), [`DESIRED_SIGMA`]). The *exact filter* is the one
//! that maps `f_i` to `g_i` exactly. In this crate's convention `c = IDFT(X . conj(H))`
//! ([`super::Correlator`]), so `conj(H_i) = G_i / F_i`, i.e.
//!
//! `H_i = conj(G_i) F_i / (|F_i|^2 + eps_i)`,
//!
//! regularised by `eps_i = REGULARIZATION * mean(|F_i|^2)` because the exact quotient blows up
//! where the patch has almost no energy (DC of a zero-mean patch, high frequencies). The filter
//! is the average of the `H_i`, Hamming-windowed in space like UMACE's (optional).
//!
//! Each exact filter over-fits its own patch; the average keeps what the patches share. ASEF
//! therefore wants many patches, with the feature at different places so the filters learn to
//! move the peak with it: training shows it translated crops ([`crate::dev::train`]).

use rustfft::num_complex::Complex32;

use super::spectra::TrainingSpectra;
use super::{Filter, SynthesisOptions, DESIRED_SIGMA};

/// Default per-patch floor, a fraction of the patch's mean power: 0.1. A single exact filter is
/// far noisier than MOSSE's pooled quotient, so it takes a larger floor than UMACE's and MOSSE's
/// 0.01 (Bolme et al. also regularise ASEF's exact filters). Not tuned on the evaluation set.
pub(crate) const REGULARIZATION: f64 = 0.1;

/// Default ASEF settings: [`DESIRED_SIGMA`], [`REGULARIZATION`], windowed.
pub(crate) const DEFAULT_OPTIONS: SynthesisOptions = SynthesisOptions {
    sigma: DESIRED_SIGMA,
    regularization: REGULARIZATION,
    window: true,
};

/// Accumulates exact filters and averages them (sums in `f64`, patches in the order given, so
/// the same patches give the same bits).
pub(crate) struct AsefTrainer {
    options: SynthesisOptions,
    spectra: TrainingSpectra,
    sum_filter: Vec<(f64, f64)>,
    count: u32,
}

impl std::fmt::Debug for AsefTrainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AsefTrainer")
            .field("size", &self.spectra.size())
            .field("options", &self.options)
            .field("count", &self.count)
            .finish()
    }
}

impl AsefTrainer {
    /// A trainer for `size x size` patches with the [`DEFAULT_OPTIONS`].
    pub(crate) fn new(size: usize) -> Self {
        Self::with_options(size, DEFAULT_OPTIONS)
    }

    /// A trainer with explicit settings.
    pub(crate) fn with_options(size: usize, options: SynthesisOptions) -> Self {
        Self {
            options,
            spectra: TrainingSpectra::new(size),
            sum_filter: vec![(0.0, 0.0); size * size],
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
    /// A constant patch (no information) is counted but adds nothing.
    ///
    /// # Panics
    /// If `patch.len() != size * size` (a programming error, not a data error).
    pub(crate) fn add(&mut self, patch: &[f32], dx: f64, dy: f64) {
        self.spectra.load(patch, dx, dy, self.options.sigma);
        let power = |c: &Complex32| {
            let (re, im) = (f64::from(c.re), f64::from(c.im));
            re * re + im * im
        };
        let spectrum = &self.spectra.patch_spectrum;
        let mean_power = spectrum.iter().map(power).sum::<f64>() / spectrum.len() as f64;
        let eps = self.options.regularization * mean_power;
        self.count += 1;
        if eps <= 0.0 {
            return;
        }
        for ((s, f), g) in self
            .sum_filter
            .iter_mut()
            .zip(spectrum)
            .zip(&self.spectra.target_spectrum)
        {
            // conj(G) F / (|F|^2 + eps)
            let (fr, fi) = (f64::from(f.re), f64::from(f.im));
            let (gr, gi) = (f64::from(g.re), f64::from(-g.im));
            let d = fr * fr + fi * fi + eps;
            s.0 += (gr * fr - gi * fi) / d;
            s.1 += (gr * fi + gi * fr) / d;
        }
    }

    /// The average exact filter, windowed if so configured. `None` when no patch was added.
    pub(crate) fn finish(self) -> Option<Filter> {
        if self.count == 0 {
            return None;
        }
        let count = f64::from(self.count);
        let average: Vec<Complex32> = self
            .sum_filter
            .iter()
            .map(|&(re, im)| Complex32::new((re / count) as f32, (im / count) as f32))
            .collect();
        Some(
            self.spectra
                .into_filter(average, self.options.window, self.count),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filters::test_support::{blob_scene, random_patch};
    use crate::filters::{desired_output, normalize_patch, Correlator};

    #[test]
    fn filter_trained_on_displaced_blobs_peaks_at_the_blob() {
        let n = 64;
        let mut trainer = AsefTrainer::new(n);
        // One blob at several places, each with its own exact filter.
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
        assert_eq!(trainer.count(), 5);
        let filter = trainer.finish().expect("trained");
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

    /// With one patch and no window, ASEF is that patch's exact filter: it reproduces the
    /// desired output wherever the patch has power well above the floor, so the output's peak
    /// sits on the target and the plane correlates strongly with it.
    #[test]
    fn one_exact_filter_maps_its_patch_to_the_target() {
        let n = 32;
        let options = SynthesisOptions {
            sigma: 2.0,
            regularization: 1e-6,
            window: false,
        };
        let mut trainer = AsefTrainer::with_options(n, options);
        let mut patch = random_patch(n, 7);
        trainer.add(&patch, 3.0, -2.0);
        let filter = trainer.finish().expect("trained");
        normalize_patch(&mut patch);
        let mut c = Correlator::new(n);
        c.compute_plane(&patch, &filter);
        let want = desired_output(n, 3.0, -2.0, 2.0);
        let mean = want.iter().sum::<f32>() / (n * n) as f32;
        // The zero-mean patch has no DC, so the output lacks the target's mean.
        for dy in -(n as isize) / 2..(n as isize) / 2 {
            for dx in -(n as isize) / 2..(n as isize) / 2 {
                let w = want
                    [dy.rem_euclid(n as isize) as usize * n + dx.rem_euclid(n as isize) as usize];
                assert!(
                    (c.value(dx, dy) - (w - mean)).abs() < 1e-3,
                    "({dx}, {dy}): {} vs {}",
                    c.value(dx, dy),
                    w - mean
                );
            }
        }
    }

    #[test]
    fn training_is_deterministic_and_empty_gives_none() {
        let train = || {
            let mut t = AsefTrainer::new(32);
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
        assert!(AsefTrainer::new(8).finish().is_none());
        // A constant patch is counted and leaves the filter zero (and finite).
        let mut t = AsefTrainer::new(8);
        t.add(&[3.0; 64], 0.0, 0.0);
        let f = t.finish().expect("one patch");
        assert_eq!(f.training_count, 1);
        assert!(f.spectrum.iter().all(|c| c.norm() == 0.0));
    }
}
