//! Frequency-domain correlation of a square patch with a [`Filter`], with the FFT plans built
//! once and the work buffers reused across calls (rustfft style: plan once, no allocation per call).

use std::sync::Arc;

use rustfft::num_complex::Complex32;
use rustfft::{Fft, FftPlanner};

use super::Filter;

/// Side of the square excluded around the peak when measuring the sidelobe for the PSR
/// (11 x 11, the usual choice for 64 x 64 correlation planes, e.g. Bolme et al. 2009).
const PSR_EXCLUSION: isize = 5;

/// The 24 other places of a 5 x 5 neighbourhood, nearest first: on a smooth correlation plane
/// most places have a higher neighbour next to them, so the local-maximum test (all of them at
/// most the centre) is mostly settled by the first one or two (it read the far corner first).
const NEIGHBOURHOOD: [(isize, isize); 24] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (-1, -1),
    (1, -1),
    (-1, 1),
    (2, 0),
    (-2, 0),
    (0, 2),
    (0, -2),
    (2, 1),
    (2, -1),
    (-2, 1),
    (-2, -1),
    (1, 2),
    (-1, 2),
    (1, -2),
    (-1, -2),
    (2, 2),
    (-2, -2),
    (2, -2),
    (-2, 2),
];

/// A correlation peak.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub struct Peak {
    /// Displacement of the feature from the patch centre, in pixels, sub-pixel (parabola fit).
    pub dx: f64,
    /// Vertical displacement from the patch centre.
    pub dy: f64,
    /// Correlation value at the integer peak.
    pub value: f32,
    /// Peak-to-sidelobe ratio: (peak - mean of the sidelobe) / std of the sidelobe, where the
    /// sidelobe is the whole plane less an 11 x 11 square around the peak. Higher is surer.
    pub psr: f64,
}

impl Peak {
    /// Whether the peak lies inside a search window of half-size `(max_dx, max_dy)`, not on
    /// its edge (where the highest value of the window may only be the flank of a higher peak
    /// beyond it).
    pub fn is_inside(&self, (max_dx, max_dy): (usize, usize)) -> bool {
        self.dx.round().abs() < max_dx as f64 && self.dy.round().abs() < max_dy as f64
    }
}

/// Correlates `size x size` patches with filters of the same size.
///
/// Holds the forward and inverse FFT plans and the work buffers, so one `Correlator` per thread
/// serves any number of calls without allocating.
pub(crate) struct Correlator {
    size: usize,
    forward: Arc<dyn Fft<f32>>,
    inverse: Arc<dyn Fft<f32>>,
    buffer: Vec<Complex32>,
    transposed: Vec<Complex32>,
    scratch: Vec<Complex32>,
    plane: Vec<f32>,
}

impl std::fmt::Debug for Correlator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Correlator")
            .field("size", &self.size)
            .finish()
    }
}

impl Correlator {
    /// A correlator for `size x size` patches (plans built here, once).
    pub(crate) fn new(size: usize) -> Self {
        let mut planner = FftPlanner::<f32>::new();
        let forward = planner.plan_fft_forward(size);
        let inverse = planner.plan_fft_inverse(size);
        let scratch_len = forward
            .get_inplace_scratch_len()
            .max(inverse.get_inplace_scratch_len());
        Self {
            size,
            forward,
            inverse,
            buffer: vec![Complex32::default(); size * size],
            transposed: vec![Complex32::default(); size * size],
            scratch: vec![Complex32::default(); scratch_len],
            plane: vec![0.0; size * size],
        }
    }

    /// Side length this correlator works on.
    pub(crate) fn size(&self) -> usize {
        self.size
    }

    /// The 2-D DFT of a real `size x size` patch, row-major.
    #[cfg(any(test, feature = "dev"))]
    pub(crate) fn spectrum(&mut self, patch: &[f32]) -> Vec<Complex32> {
        self.load_real(patch);
        self.fft2(true);
        self.buffer.clone()
    }

    /// The 2-D DFT of a real patch written into `out` (no allocation).
    #[cfg(any(test, feature = "dev"))]
    pub(crate) fn spectrum_into(&mut self, patch: &[f32], out: &mut [Complex32]) {
        self.load_real(patch);
        self.fft2(true);
        out.copy_from_slice(&self.buffer);
    }

    /// The real part of the inverse 2-D DFT of `spectrum`, scaled by 1 / size^2.
    #[cfg(any(test, feature = "dev"))]
    pub(crate) fn inverse_real(&mut self, spectrum: &[Complex32]) -> Vec<f32> {
        self.buffer.copy_from_slice(spectrum);
        self.fft2(false);
        let norm = 1.0 / (self.size * self.size) as f32;
        self.buffer.iter().map(|c| c.re * norm).collect()
    }

    /// Correlates `patch` (real, `size x size`, row-major) with `filter` and returns the highest
    /// peak whose displacement from the centre lies within `max_dx`, `max_dy` pixels.
    ///
    /// Restricting the peak to a search window keeps the other eye, the brows or the mouth, which
    /// also correlate, from winning when they fall inside the patch.
    pub(crate) fn correlate(
        &mut self,
        patch: &[f32],
        filter: &Filter,
        max_dx: usize,
        max_dy: usize,
    ) -> Peak {
        self.compute_plane(patch, filter);
        self.peak_in_window(max_dx, max_dy)
    }

    /// Correlates `patch` with `filter` and keeps the correlation plane for [`Self::value`],
    /// [`Self::peak_in_window`] and [`Self::peak_at`].
    pub(crate) fn compute_plane(&mut self, patch: &[f32], filter: &Filter) {
        debug_assert_eq!(filter.size, self.size);
        self.load_real(patch);
        self.fft2(true);
        for (x, h) in self.buffer.iter_mut().zip(&filter.spectrum) {
            *x *= h.conj();
        }
        self.fft2(false);
        let norm = 1.0 / (self.size * self.size) as f32;
        for (p, c) in self.plane.iter_mut().zip(&self.buffer) {
            *p = c.re * norm;
        }
    }

    /// The highest value of the last plane within `max_dx`, `max_dy` of the centre, refined.
    pub(crate) fn peak_in_window(&self, max_dx: usize, max_dy: usize) -> Peak {
        let half = (self.size / 2) as isize;
        let max_dx = (max_dx as isize).min(half - 1);
        let max_dy = (max_dy as isize).min(half - 1);
        let (mut best, mut best_dx, mut best_dy) = (f32::NEG_INFINITY, 0isize, 0isize);
        for dy in -max_dy..=max_dy {
            for dx in -max_dx..=max_dx {
                let v = self.value(dx, dy);
                if v > best {
                    (best, best_dx, best_dy) = (v, dx, dy);
                }
            }
        }
        self.peak_at(best_dx, best_dy)
    }

    /// Up to `count` candidate peaks of the last plane within `max_dx`, `max_dy` of the centre,
    /// highest first, each refined as [`Self::peak_at`]: the window's highest value (always
    /// first: [`Self::peak_in_window`]'s peak, even on the window's edge, where it is the flank
    /// of a peak just beyond), then the local maxima (each the highest of its 5 x 5
    /// neighbourhood).
    pub(crate) fn local_maxima_in_window(
        &self,
        max_dx: usize,
        max_dy: usize,
        count: usize,
    ) -> Vec<Peak> {
        let half = (self.size / 2) as isize;
        let max_dx = (max_dx as isize).min(half - 1);
        let max_dy = (max_dy as isize).min(half - 1);
        let mut highest = (f32::NEG_INFINITY, 0isize, 0isize);
        let mut maxima: Vec<(f32, isize, isize)> = Vec::new();
        for dy in -max_dy..=max_dy {
            for dx in -max_dx..=max_dx {
                let v = self.value(dx, dy);
                if v > highest.0 {
                    highest = (v, dx, dy);
                }
                let local = NEIGHBOURHOOD
                    .iter()
                    .all(|&(ex, ey)| self.value(dx + ex, dy + ey) <= v);
                if local {
                    maxima.push((v, dx, dy));
                }
            }
        }
        maxima.sort_by(|a, b| b.0.total_cmp(&a.0));
        // The plane's sums once; each candidate's sidelobe then drops its own square.
        let totals = self.plane.iter().fold((0f64, 0f64), |(s, q), &v| {
            let v = f64::from(v);
            (s + v, q + v * v)
        });
        std::iter::once(highest)
            .chain(
                maxima
                    .into_iter()
                    .filter(|&(_, dx, dy)| (dx, dy) != (highest.1, highest.2)),
            )
            .take(count)
            .map(|(v, dx, dy)| self.refined(dx, dy, self.psr_from_totals(totals, v, dx, dy)))
            .collect()
    }

    /// [`Self::psr`] from the whole plane's sum and sum of squares, less the exclusion square
    /// around the peak: the same ratio (to rounding) in 121 steps instead of the plane's 4096.
    fn psr_from_totals(&self, (sum, sum_sq): (f64, f64), peak: f32, pdx: isize, pdy: isize) -> f64 {
        let n = self.size as isize;
        if 2 * PSR_EXCLUSION + 1 >= n {
            return self.psr(peak, pdx, pdy);
        }
        let (mut near_sum, mut near_sq) = (0f64, 0f64);
        for ey in -PSR_EXCLUSION..=PSR_EXCLUSION {
            for ex in -PSR_EXCLUSION..=PSR_EXCLUSION {
                let v = f64::from(self.value(pdx + ex, pdy + ey));
                near_sum += v;
                near_sq += v * v;
            }
        }
        let side = (2 * PSR_EXCLUSION + 1) as usize;
        let count = (n * n) as usize - side * side;
        sidelobe_ratio(peak, sum - near_sum, sum_sq - near_sq, count)
    }

    /// The last plane's peak at integer displacement `(dx, dy)`, refined to sub-pixel precision
    /// by a parabola through the neighbours, with its peak-to-sidelobe ratio.
    pub(crate) fn peak_at(&self, dx: isize, dy: isize) -> Peak {
        self.refined(dx, dy, self.psr(self.value(dx, dy), dx, dy))
    }

    /// The peak at integer `(dx, dy)` refined by a parabola through the neighbours, with `psr`.
    fn refined(&self, dx: isize, dy: isize, psr: f64) -> Peak {
        let v = self.value(dx, dy);
        let sub_x = parabola_offset(self.value(dx - 1, dy), v, self.value(dx + 1, dy));
        let sub_y = parabola_offset(self.value(dx, dy - 1), v, self.value(dx, dy + 1));
        Peak {
            dx: dx as f64 + sub_x,
            dy: dy as f64 + sub_y,
            value: v,
            psr,
        }
    }

    /// The last plane's value at displacement `(dx, dy)` from the centre, indices modulo the size.
    pub(crate) fn value(&self, dx: isize, dy: isize) -> f32 {
        let n = self.size as isize;
        let x = wrap(dx, n) as usize;
        let y = wrap(dy, n) as usize;
        self.plane[y * self.size + x]
    }

    fn psr(&self, peak: f32, pdx: isize, pdy: isize) -> f64 {
        let n = self.size as isize;
        let (mut sum, mut sum_sq, mut count) = (0f64, 0f64, 0usize);
        for y in 0..n {
            // Circular distance to the peak, so the exclusion square wraps like the plane does.
            let ddy = wrap(y - pdy, n);
            let near_y = ddy <= PSR_EXCLUSION || ddy >= n - PSR_EXCLUSION;
            for x in 0..n {
                let ddx = wrap(x - pdx, n);
                let near_x = ddx <= PSR_EXCLUSION || ddx >= n - PSR_EXCLUSION;
                if near_x && near_y {
                    continue;
                }
                let v = f64::from(self.plane[(y * n + x) as usize]);
                sum += v;
                sum_sq += v * v;
                count += 1;
            }
        }
        sidelobe_ratio(peak, sum, sum_sq, count)
    }

    fn load_real(&mut self, patch: &[f32]) {
        assert_eq!(
            patch.len(),
            self.size * self.size,
            "patch must be size x size"
        );
        for (b, &p) in self.buffer.iter_mut().zip(patch) {
            *b = Complex32::new(p, 0.0);
        }
    }

    /// In-place 2-D FFT of `self.buffer`: rows, transpose, rows, transpose back.
    fn fft2(&mut self, forward: bool) {
        let fft = if forward {
            &self.forward
        } else {
            &self.inverse
        };
        fft.process_with_scratch(&mut self.buffer, &mut self.scratch);
        transpose::transpose(&self.buffer, &mut self.transposed, self.size, self.size);
        fft.process_with_scratch(&mut self.transposed, &mut self.scratch);
        transpose::transpose(&self.transposed, &mut self.buffer, self.size, self.size);
    }
}

/// `i` modulo `n` (`n > 0`), in `0..n`: `rem_euclid` without its division for the values the
/// correlation planes are read at, which lie within one period of `0..n` (the peak searches read
/// every value of their windows' 5 x 5 neighbourhoods, and `rem_euclid`'s division was most of
/// that time).
#[inline]
fn wrap(i: isize, n: isize) -> isize {
    if (0..n).contains(&i) {
        i
    } else if (-n..0).contains(&i) {
        i + n
    } else if (n..2 * n).contains(&i) {
        i - n
    } else {
        i.rem_euclid(n)
    }
}

/// `(peak - mean) / std` of a sidelobe given by its sum, sum of squares and count; 0 when the
/// sidelobe has fewer than 2 values or no spread.
fn sidelobe_ratio(peak: f32, sum: f64, sum_sq: f64, count: usize) -> f64 {
    if count < 2 {
        return 0.0;
    }
    let mean = sum / count as f64;
    let var = (sum_sq / count as f64 - mean * mean).max(0.0);
    if var <= f64::EPSILON {
        return 0.0;
    }
    (f64::from(peak) - mean) / var.sqrt()
}

/// Vertex of the parabola through three equally spaced samples, relative to the middle one,
/// clamped to half a pixel (a flat or noisy top gives no reliable sub-pixel information beyond).
fn parabola_offset(left: f32, centre: f32, right: f32) -> f64 {
    let denom = f64::from(left) - 2.0 * f64::from(centre) + f64::from(right);
    if denom >= -1e-12 {
        return 0.0;
    }
    (0.5 * (f64::from(left) - f64::from(right)) / denom).clamp(-0.5, 0.5)
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_neighbourhood_is_the_5x5_square_less_its_centre() {
        let mut places: Vec<(isize, isize)> = super::NEIGHBOURHOOD.to_vec();
        places.sort_unstable();
        let square: Vec<(isize, isize)> = (-2..=2)
            .flat_map(|x| (-2..=2).map(move |y| (x, y)))
            .filter(|&p| p != (0, 0))
            .collect();
        assert_eq!(places, square);
    }

    #[test]
    fn wrapping_is_the_euclidean_remainder() {
        for n in [1isize, 2, 7, 64] {
            for i in -3 * n - 2..3 * n + 2 {
                assert_eq!(super::wrap(i, n), i.rem_euclid(n), "{i} mod {n}");
            }
        }
        assert_eq!(super::wrap(isize::MIN, 64), isize::MIN.rem_euclid(64));
        assert_eq!(super::wrap(isize::MAX, 64), isize::MAX.rem_euclid(64));
    }

    use super::*;

    fn blob(n: usize, cx: f64, cy: f64, sigma: f64) -> Vec<f32> {
        let mut v = vec![0f32; n * n];
        for y in 0..n {
            for x in 0..n {
                let d2 = (x as f64 - cx).powi(2) + (y as f64 - cy).powi(2);
                v[y * n + x] = (-d2 / (2.0 * sigma * sigma)).exp() as f32;
            }
        }
        v
    }

    /// The matched filter of a blob of width `sigma` at the centre of an `n x n` patch.
    fn centred_blob_filter(c: &mut Correlator, n: usize, sigma: f64) -> Filter {
        Filter {
            size: n,
            spectrum: c.spectrum(&blob(n, n as f64 / 2.0, n as f64 / 2.0, sigma)),
            training_count: 1,
        }
    }

    #[test]
    fn spectrum_round_trips() {
        let mut c = Correlator::new(16);
        let p = blob(16, 5.0, 9.0, 2.0);
        let spectrum = c.spectrum(&p);
        let back = c.inverse_real(&spectrum);
        for (a, b) in p.iter().zip(&back) {
            assert!((a - b).abs() < 1e-5);
        }
    }

    #[test]
    fn matched_filter_peaks_at_the_displacement() {
        let n = 32;
        let mut c = Correlator::new(n);
        let template = blob(n, 16.0, 16.0, 2.5);
        let filter = Filter {
            size: n,
            spectrum: c.spectrum(&template),
            training_count: 1,
        };
        let shifted = blob(n, 19.0, 13.0, 2.5);
        let peak = c.correlate(&shifted, &filter, 10, 10);
        assert!((peak.dx - 3.0).abs() < 0.05, "dx {}", peak.dx);
        assert!((peak.dy + 3.0).abs() < 0.05, "dy {}", peak.dy);
        assert!(peak.psr > 3.0, "psr {}", peak.psr);
    }

    #[test]
    fn local_maxima_are_listed_highest_first_within_the_window() {
        let n = 32;
        let mut c = Correlator::new(n);
        let filter = centred_blob_filter(&mut c, n, 1.5);
        // Two blobs in the window, the weaker one 7 px left; a third, strongest, outside it.
        let mut scene = blob(n, 19.0, 16.0, 1.5);
        for (s, (w, f)) in scene.iter_mut().zip(
            blob(n, 12.0, 16.0, 1.5)
                .into_iter()
                .zip(blob(n, 28.0, 28.0, 1.5)),
        ) {
            *s += 0.6 * w + 2.0 * f;
        }
        c.compute_plane(&scene, &filter);
        let maxima = c.local_maxima_in_window(8, 8, 4);
        assert!(maxima.len() >= 2, "{maxima:?}");
        assert!((maxima[0].dx - 3.0).abs() < 0.1 && maxima[0].dy.abs() < 0.1);
        assert!((maxima[1].dx + 4.0).abs() < 0.1 && maxima[1].dy.abs() < 0.1);
        assert!(maxima[0].value > maxima[1].value);
        // The same peak as the single search, its sidelobe statistics computed the short way.
        let single = c.peak_in_window(8, 8);
        assert_eq!(
            (maxima[0].dx, maxima[0].dy, maxima[0].value),
            (single.dx, single.dy, single.value)
        );
        assert!((maxima[0].psr - single.psr).abs() < 1e-9 * single.psr.abs().max(1.0));
        assert!(maxima
            .iter()
            .all(|p| p.dx.abs() <= 8.5 && p.dy.abs() <= 8.5));
        assert_eq!(c.local_maxima_in_window(8, 8, 1).len(), 1);
        // In a window of +-2 both blobs lie beyond the edge; the flank of the stronger one comes
        // first, on the edge, though it is no local maximum.
        let narrow = c.local_maxima_in_window(2, 2, 4);
        let single = c.peak_in_window(2, 2);
        assert_eq!((narrow[0].dx, narrow[0].dy), (single.dx, single.dy));
        assert!((narrow[0].dx - 2.0).abs() <= 0.5, "{narrow:?}");
        assert!(!narrow[0].is_inside((2, 2)));
    }

    #[test]
    fn a_peak_on_the_window_edge_is_not_inside() {
        let peak = |dx: f64, dy: f64| Peak {
            dx,
            dy,
            value: 1.0,
            psr: 5.0,
        };
        assert!(peak(3.4, -5.2).is_inside((8, 6)));
        // Sub-pixel refinement can pull an edge peak slightly inwards; it is still on the edge.
        assert!(!peak(7.6, 0.0).is_inside((8, 6)));
        assert!(!peak(-8.0, 0.0).is_inside((8, 6)));
        assert!(!peak(0.0, 6.0).is_inside((8, 6)));
    }

    #[test]
    fn sub_pixel_displacement_is_recovered() {
        let n = 32;
        let mut c = Correlator::new(n);
        let filter = centred_blob_filter(&mut c, n, 3.0);
        let peak = c.correlate(&blob(n, 17.3, 15.6, 3.0), &filter, 8, 8);
        assert!((peak.dx - 1.3).abs() < 0.15, "dx {}", peak.dx);
        assert!((peak.dy + 0.4).abs() < 0.15, "dy {}", peak.dy);
    }

    #[test]
    fn search_window_excludes_a_stronger_far_peak() {
        let n = 32;
        let mut c = Correlator::new(n);
        let filter = centred_blob_filter(&mut c, n, 2.0);
        let mut patch = blob(n, 18.0, 16.0, 2.0);
        for (p, q) in patch.iter_mut().zip(blob(n, 28.0, 16.0, 2.0)) {
            *p = 0.5 * *p + q;
        }
        assert!((c.correlate(&patch, &filter, 15, 15).dx - 12.0).abs() < 0.2);
        assert!((c.correlate(&patch, &filter, 4, 4).dx - 2.0).abs() < 0.3);
    }

    #[test]
    fn parabola_vertex() {
        // Samples of -(x - 0.25)^2 at -1, 0, 1.
        let f = |x: f32| -(x - 0.25) * (x - 0.25);
        assert!((parabola_offset(f(-1.0), f(0.0), f(1.0)) - 0.25).abs() < 1e-6);
        assert_eq!(parabola_offset(1.0, 1.0, 1.0), 0.0);
    }
}
